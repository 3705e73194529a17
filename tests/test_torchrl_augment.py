import re
import runpy
import sys
from pathlib import Path

import gymnasium
import numpy as np
import pytest
import torch
from tensordict import TensorDict
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer
from torchrl.data.replay_buffers.samplers import SamplerWithoutReplacement, SliceSampler
from torchrl.envs import GymEnv, TransformedEnv

from geomdp_envs import SimState, groups
from geomdp_envs.torchrl_augment import SymmetryAugment

ROOT = Path(__file__).resolve().parents[1]
TRAJ = ("collector", "traj_ids")


@pytest.fixture
def one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def pointmass():
    return gymnasium.make("GeoMDP/PointMass2D-v0").unwrapped


def _trajectories(base, n, steps, seed=0):
    """n simulated trajectories of PointMass2D, a TensorDict [n, steps] (float64)."""
    rng = np.random.default_rng(seed)
    obs, action, next_obs, reward = (np.zeros((n, steps, k)) for k in (4, 2, 4, 1))
    for i in range(n):
        base.set_state(base.sample_state(rng))
        o = base.observe()
        for t in range(steps):
            a = rng.uniform(-1, 1, 2)  # box actions: D4 keeps them in the box
            obs[i, t], action[i, t] = o, a
            o, r = base.simulate(a)
            next_obs[i, t], reward[i, t] = o, r
    done = rng.uniform(size=(n, steps, 1)) < 0.3
    return TensorDict({
        "observation": torch.from_numpy(obs), "action": torch.from_numpy(action),
        ("next", "observation"): torch.from_numpy(next_obs), ("next", "reward"): torch.from_numpy(reward),
        ("next", "done"): torch.from_numpy(done),
        TRAJ: torch.arange(n).unsqueeze(-1).expand(n, steps).clone(),
    }, batch_size=[n, steps])


def _element(sym, before, after):
    """The one element of D4 that maps transition ``before`` to ``after`` (obs, action and next obs)."""
    found = [g for g in groups.group_elements("D4")
             if all(np.allclose(sym.transform_observation(before[k].numpy(), g), after[k].numpy(), atol=1e-12)
                    for k in ("observation", ("next", "observation")))
             and np.allclose(sym.transform_action(before["action"].numpy(), g), after["action"].numpy(),
                             atol=1e-12)]
    assert len(found) == 1, f"{len(found)} elements of D4 explain the augmented transition"
    return found[0]


def _assert_simulator_agrees(base, before, after, g):
    """From g.s, the simulator driven by the moved actions gives the moved observations and rewards."""
    obs = before["observation"][0].numpy()
    state = SimState(obs[:2], obs[2:])  # for a point mass the state is the observation
    base.set_state(base.transform_state(state, g))  # moved the simulator's way, as check_symmetry does
    np.testing.assert_allclose(base.observe(), after["observation"][0].numpy(), atol=1e-12)
    for t in range(after.shape[0]):
        o, r = base.simulate(after["action"][t].numpy())
        np.testing.assert_allclose(o, after["next", "observation"][t].numpy(), atol=1e-9)
        assert r == pytest.approx(after["next", "reward"][t].item(), abs=1e-9)


def test_replay_buffer_samples_are_moved_transitions_of_the_task(pointmass):
    data = _trajectories(pointmass, 32, 1).reshape(-1)
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(32), sampler=SamplerWithoutReplacement(),
                                batch_size=32, transform=SymmetryAugment(pointmass.symmetry, seed=0))
    rb.extend(data)
    assert (rb.storage[:].exclude("index") == data.exclude("index")).all()  # nothing moved on write
    sample = rb.sample()
    before = data[sample["index"]]
    assert sample["observation"].dtype == torch.float64
    for key in (("next", "reward"), ("next", "done"), TRAJ):
        assert torch.equal(sample[key], before[key])
    elements = [_element(pointmass.symmetry, before[i], sample[i]) for i in range(32)]
    assert len({g.tobytes() for g in elements}) > 2  # an independent element per transition
    for i, g in enumerate(elements):
        _assert_simulator_agrees(pointmass, before[i : i + 1], sample[i : i + 1], g)


def test_slices_move_by_one_element_and_stay_trajectories(pointmass):
    data = _trajectories(pointmass, 12, 5)
    out = SymmetryAugment(pointmass.symmetry, seed=1)(data.clone())  # shape [B, T]
    torch.testing.assert_close(out["next", "reward"], data["next", "reward"])
    assert torch.equal(out["next", "done"], data["next", "done"])
    elements = []
    for i in range(12):
        g = _element(pointmass.symmetry, data[i], out[i])  # the same g explains all 5 steps
        _assert_simulator_agrees(pointmass, data[i], out[i], g)
        elements.append(g.tobytes())
    assert len(set(elements)) > 2

    # flat samples of a SliceSampler: one element per contiguous run of the slice key
    rb = TensorDictReplayBuffer(storage=LazyTensorStorage(60), batch_size=20,
                                sampler=SliceSampler(slice_len=5, traj_key=TRAJ),
                                transform=SymmetryAugment(pointmass.symmetry, slice_key=TRAJ, seed=2))
    rb.extend(data.reshape(-1))
    sample = rb.sample().reshape(4, 5)
    for i in range(4):
        assert (sample[TRAJ][i] == sample[TRAJ][i, 0]).all()
        before = rb.storage[sample["index"][i].reshape(-1)]  # SliceSampler indices are [N, 1]
        g = _element(pointmass.symmetry, before, sample[i])
        _assert_simulator_agrees(pointmass, before, sample[i], g)


def test_seeds_dtypes_and_devices(pointmass):
    data = _trajectories(pointmass, 64, 1).reshape(-1).float()
    aug = SymmetryAugment(pointmass.symmetry, seed=0)
    first = aug(data.clone())
    assert first["observation"].dtype == torch.float32
    assert first["observation"].device == data["observation"].device
    assert (SymmetryAugment(pointmass.symmetry, seed=0)(data.clone()) == first).all()
    assert (aug.manual_seed(0)(data.clone()) == first).all()
    assert not torch.equal(SymmetryAugment(pointmass.symmetry, seed=1)(data.clone())["action"],
                           first["action"])
    assert not torch.equal(aug(data.clone())["action"], first["action"])  # fresh draws per sample
    as_int = aug(data.clone().apply(lambda x: x.round().long()))
    assert as_int["observation"].dtype == torch.float64 and as_int[TRAJ].dtype == torch.long


def test_continuous_groups_use_the_declared_matrices():
    sym = gymnasium.make("GeoMDP/Reacher-v0").unwrapped.symmetry
    aug = SymmetryAugment(sym, seed=0)
    assert aug.group == "O(2)"  # Reacher's actions are torques: scalars, any g keeps the box
    g, rho_s, rho_a = aug.sample_elements(16)
    assert np.any(np.linalg.det(g) < 0) and np.any(np.linalg.det(g) > 0)
    for h, s, a in zip(g, rho_s, rho_a):
        np.testing.assert_allclose(s.numpy(), sym.observation_matrix(h), atol=1e-12)
        np.testing.assert_allclose(a.numpy(), sym.action_matrix(h), atol=1e-12)


def test_refusals(pointmass):
    with pytest.raises(ValueError, match=r"O\(2\) is not an exact symmetry.*valid: D4 or a subgroup"):
        SymmetryAugment(pointmass.symmetry, group="O(2)")  # approximate: only away from the walls
    with pytest.raises(ValueError, match="valid groups"):
        SymmetryAugment(pointmass.symmetry, group="D5x")
    sym3 = gymnasium.make("GeoMDP/PointMass3D-v0").unwrapped.symmetry
    td = TensorDict({"observation": torch.zeros(4, 6), ("next", "observation"): torch.zeros(4, 6),
                     "action": torch.ones(4, 3)}, batch_size=[4])
    aug = SymmetryAugment(sym3, group="icosahedral", seed=0)
    with pytest.raises(ValueError, match="may move box actions out of"):
        aug(td.clone())
    td["action"] = td["action"] / 3**0.5  # in the declared action domain (unit ball)
    torch.testing.assert_close(aug(td.clone())["action"].norm(dim=-1), torch.ones(4))
    with pytest.raises(KeyError, match="'obs' not in the sampled tensordict"):
        SymmetryAugment(pointmass.symmetry, observation_keys=["obs"])(td.clone())
    env = TransformedEnv(GymEnv("GeoMDP/PointMass2D-v0"), SymmetryAugment(pointmass.symmetry))
    with pytest.raises(ValueError, match="replay-buffer transform"):
        env.reset()


@pytest.mark.slow
@pytest.mark.parametrize("flags", [[], ["--augment"]])
def test_torchrl_sac_example_trains_with_and_without_augmentation(flags, monkeypatch, capsys, one_thread):
    monkeypatch.setattr(sys, "argv", ["torchrl_sac", "--steps", "300", "--eval-episodes", "1", *flags])
    runpy.run_path(str(ROOT / "examples" / "torchrl_sac_augmented.py"), run_name="__main__")
    captured = capsys.readouterr()
    out = captured.out
    assert "over 1 episodes after 300 steps" in out
    assert ("augmenting with D4" in out) == bool(flags)
    assert "300/300" in captured.err and "steps/s" in captured.err  # the progress bar
    assert torch.get_num_threads() == 1  # --threads 1 is the default
    moved = re.search(r"augmentation moved (\d+) of (\d+) sampled transitions", out)
    if not flags:
        assert moved is None, out
        return
    n_moved, n_sampled = map(int, moved.groups())
    # an update of 256 samples per step once 100 are stored; D4 moves all but the identity's
    assert n_sampled >= 100 * 256 and 0.8 * n_sampled < n_moved < 0.95 * n_sampled, out
