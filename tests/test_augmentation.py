"""``agent.augment``: replayed slices moved by random group elements. A moved slice is one
the task could have produced (replayed in the simulator); an exactly equivariant agent's
loss does not see the move (a cross-check of the augmentation against the networks);
a plain agent's does."""

import gymnasium
import numpy as np
import pytest
import torch
from tensordict import TensorDict
from test_train import config

from agents.cli.train import run
from agents.options import OptionError
from agents.tdmpc.agent import TDMPCAgent, TDMPCConfig
from agents.tdmpc.augmentation import SliceAugmentation, augmentation_group
from geomdp_envs import declare, symmetry_of
from geomdp_envs.check import simulator_of

HORIZON = 4
DECLARED = {"Reacher-v5": "reacher_v5"}  # a third-party env, with its shipped declaration


def slices(env_id, n=3, seed=0, **kwargs):
    """``n`` slices of ``HORIZON`` steps from random in-domain actions, with the
    simulator state each starts from."""
    env = gymnasium.make(env_id, **kwargs)
    if env_id in DECLARED:
        env = declare(env, DECLARED[env_id])
    sym, sim = symmetry_of(env), simulator_of(env)  # the simulator's state access
    rng = np.random.default_rng(seed)
    starts, steps = [], []
    for k in range(n):
        env.reset(seed=seed + k)
        starts.append(sim.get_state())
        obs, rows = sim.observe(), []
        for _ in range(HORIZON):
            action = rng.uniform(-1, 1, sym.action_size)
            action = np.where(sym.action_in_domain(action[None])[0], action, action / 2)
            next_obs, reward = sim.simulate(action)
            rows.append((obs, action, next_obs, reward))
            obs = next_obs
        steps.append(rows)
    batch = TensorDict({
        "observation": torch.tensor(np.array([[r[0] for r in s] for s in steps])),
        "action": torch.tensor(np.array([[r[1] for r in s] for s in steps])),
        "next": {"observation": torch.tensor(np.array([[r[2] for r in s] for s in steps])),
                 "reward": torch.tensor(np.array([[[r[3]] for r in s] for s in steps])),
                 "terminated": torch.zeros(n, HORIZON, 1, dtype=torch.bool)}},
        batch_size=[n, HORIZON])
    return sim, sym, starts, batch


@pytest.mark.parametrize("env_id, kwargs, name", [
    ("GeoMDP/PointMass2D-v0", {}, "auto"),            # D4: box actions stay in the box
    ("GeoMDP/Reacher-v0", {"difficulty": "hard"}, "auto"),  # O(2), sign fields
    ("GeoMDP/PointMass3D-v0", {"n_balls": 2}, "octahedral"),
    ("Reacher-v5", {}, "auto"),  # declared: non-contiguous fields, reordered
])
def test_a_moved_slice_is_one_the_task_could_have_produced(env_id, kwargs, name):
    sim, sym, starts, batch = slices(env_id, **kwargs)
    augmentation = SliceAugmentation(name, sym, seed=3)
    elements, _, _ = SliceAugmentation(name, sym, seed=3).transform.sample_elements(len(starts))
    moved = augmentation(batch)
    assert not torch.allclose(moved["observation"], batch["observation"])
    assert torch.equal(moved["next", "reward"], batch["next", "reward"])
    for k, g in enumerate(elements):
        sim.set_state(sim.transform_state(starts[k], g))
        np.testing.assert_allclose(sim.observe(), moved["observation"][k, 0], atol=1e-9)
        for t in range(HORIZON):
            next_obs, reward = sim.simulate(moved["action"][k, t].numpy())
            np.testing.assert_allclose(next_obs, moved["next", "observation"][k, t], atol=1e-8)
            assert reward == pytest.approx(float(batch["next", "reward"][k, t]), abs=1e-9)


def losses(group, batch, sym):
    cfg = TDMPCConfig.from_dict({"group": group, "batch_size": 3, "horizon": HORIZON,
                                 "loss": {"policy_noise": 0.0},  # a deterministic TD target
                                 "networks": {"hidden_dim": 32, "latent_dim": 16}})
    torch.manual_seed(0)
    agent = TDMPCAgent(cfg, sym, sym.observation_size, sym.action_size, seed=0)
    with torch.no_grad():
        for p in agent.model.parameters():  # Q and reward heads start at 0: make them speak
            p.add_(0.1 * torch.randn_like(p))
    agent.loss.target_model.load_state_dict(agent.model.state_dict())
    agent.loss.double()
    return lambda b: {k: float(v) for k, v in agent.loss(b.double()).items()
                      if k in ("loss_model", "loss_pi", "consistency", "value_error")}


# escnn keeps its bases in float32: exact for D4 and the octahedral group (entries 0, ±1),
# ~1e-9 relative in float64 for D8's 45-degree rotations. A plain agent's losses move by
# 1e-2 or more.
@pytest.mark.parametrize("env_id, kwargs, group, rel", [
    ("GeoMDP/PointMass2D-v0", {}, "D4", 1e-9),  # the exact group: vectors moved in the box
    ("GeoMDP/Reacher-v0", {"difficulty": "hard"}, "D8", 1e-7),  # sign fields (sin q2, torques)
    ("GeoMDP/PointMass3D-v0", {"n_balls": 2}, "octahedral", 1e-9),  # one element, every ball
])
def test_an_exactly_equivariant_agent_does_not_see_the_move_and_a_plain_one_does(env_id, kwargs,
                                                                                   group, rel):
    _, sym, _, batch = slices(env_id, **kwargs)
    moved = SliceAugmentation(group, sym, seed=1)(batch)
    assert not torch.allclose(moved["action"], batch["action"])
    equivariant = losses(group, batch, sym)
    before, after = equivariant(batch), equivariant(moved)
    for k, v in before.items():
        assert after[k] == pytest.approx(v, rel=rel, abs=1e-12), k
    plain = losses("none", batch, sym)
    before, after = plain(batch), plain(moved)
    for k in ("loss_model", "value_error"):
        assert abs(after[k] - before[k]) > 1e-3 * abs(before[k]), k


def test_augmentation_options_are_checked():
    sym = gymnasium.make("GeoMDP/PointMass2D-v0").unwrapped.symmetry
    assert augmentation_group("auto", sym) == "D4" and augmentation_group("C4", sym) == "C4"
    with pytest.raises(OptionError, match=r"agent.augment=D8 is not a subgroup of D4.*valid: none, auto"):
        augmentation_group("D8", sym)  # takes box actions out of the box
    with pytest.raises(OptionError, match="agent.augment=Q8 is not a subgroup"):
        augmentation_group("Q8", sym)
    reacher = gymnasium.make("GeoMDP/Reacher-v0").unwrapped.symmetry
    assert augmentation_group("auto", reacher) == "O(2)" and augmentation_group("SO2", reacher) == "SO(2)"
    with pytest.raises(OptionError, match="needs a task that declares its symmetry"):
        augmentation_group("auto", None)


def test_the_cli_refuses_a_bad_augmentation_in_one_line(tmp_path, capsys):
    assert run(config("agent.augment=D8"), tmp_path / "run") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "agent.augment=D8 is not a subgroup of D4" in err[0]
    assert run(config("env=gym", "env.id=Pendulum-v1", "agent.augment=auto"),
               tmp_path / "run2") == 2
    assert "needs a task that declares its symmetry" in capsys.readouterr().err
