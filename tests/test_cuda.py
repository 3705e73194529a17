"""On a CUDA device: the symmetry claims and the run lifecycle hold there as on the CPU.

Skipped without a GPU (CI has none). The CPU tests prove equivariance with float32
networks on the CPU; here the same networks and planner run on the GPU, where other
kernels (and TF32 matrix products, if a user turns them on) could break it, and a run
trained on the GPU is continued on the CPU and the other way round, as a run moved
between a GPU cluster and a laptop is.
"""

import numpy as np
import pytest
import torch
from test_networks import SMALL, elements_of, relative_error, rep, task_symmetry
from test_planner import RecordingNoise, TransformedNoise, _element, _make_agent, plan_twice
from test_train import config, rows

from agents import NetworkConfig, build_networks
from agents.cli.train import run
from geomdp_envs import groups

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")

GROUPS = [("C8", "pointmass2d"), ("D8", "pointmass2d"), ("D8", "reacher"),
          ("octahedral", "pointmass3d"), ("icosahedral", "pointmass3d")]


@pytest.mark.parametrize("group_name, task", GROUPS)
def test_networks_on_cuda_are_equivariant_and_compute_what_they_compute_on_the_cpu(
        group_name, task, randomise_heads):
    nets = randomise_heads(build_networks(
        NetworkConfig(group=group_name, width_strategy="linear", networks=SMALL), task_symmetry(task)))
    heads = {"encoder": nets.encoder, "dynamics": nets.dynamics, "reward": nets.reward,
             "q0": nets.qs[0], "policy": nets.policy}
    for name, net in heads.items():
        x = torch.randn(64, net.in_layout.size, generator=torch.Generator().manual_seed(0))
        on_cpu = net(x)
        net.to("cuda")
        y = net(x.cuda())
        assert relative_error(y.cpu(), on_cpu) < 1e-5, f"{name}: cuda and cpu outputs differ"
        for e in elements_of(nets.group):
            moved = net(x.cuda() @ rep(net.in_layout, e).T.cuda())
            err = relative_error(moved, y @ rep(net.out_layout, e).T.cuda())
            assert err < 1e-4, f"{name} on cuda not equivariant to {e}: relative error {err:.1e}"
        net.to("cpu")


@pytest.mark.parametrize("env_id, kwargs, group, element", [
    ("GeoMDP/PointMass2D-v0", {}, "D8", groups.rotation_2d(3 * np.pi / 4) @ np.diag([1.0, -1])),
    ("GeoMDP/PointMass3D-v0", {}, "icosahedral", None)])
def test_planner_on_cuda_is_equivariant(env_id, kwargs, group, element, randomise_heads):
    """As tests/test_planner.py, in float64 on the GPU (noise drawn on the CPU, moved)."""
    env, sym, agent = _make_agent(env_id, kwargs, group, randomise_heads)
    agent.model.to("cuda")
    g = _element(agent, element)
    obs = [torch.as_tensor(env.reset(seed=s)[0], dtype=torch.float64).cuda() for s in (0, 1)]
    recording = RecordingNoise(seed=0)
    actions = plan_twice(agent, obs, recording)
    moved = [torch.as_tensor(sym.transform_observation(o.cpu().numpy(), g)).cuda() for o in obs]
    moved_actions = plan_twice(agent, moved, TransformedNoise(recording, sym.action_matrix(g)))
    for a, b in zip(actions, moved_actions):
        assert a.device.type == "cuda"
        np.testing.assert_allclose(b.cpu().numpy(), sym.transform_action(a.cpu().numpy(), g), atol=1e-8)


@pytest.mark.slow
@pytest.mark.parametrize("group, prioritized", [("none", "true"), ("D4", "false")])
def test_a_run_moves_between_cuda_and_cpu_at_its_checkpoint(tmp_path, group, prioritized):
    """Trained on the GPU to 1000 steps, continued on the CPU to 2000, then on the GPU
    to 3000: each start resumes the last (no second evaluation at a step), with finite
    losses and a target network that tracks the online one."""
    agent = [f"agent.group={group}", f"agent.replay.prioritized={prioritized}"]
    assert run(config("device=cuda", "train.steps=1000", *agent), tmp_path) == 0
    assert run(config("device=cpu", "train.steps=2000", *agent), tmp_path) == 0
    assert run(config("device=cuda", "train.steps=3000", *agent), tmp_path) == 0
    assert [int(r["env_step"]) for r in rows(tmp_path / "eval.csv")] == [0, 1000, 2000, 3000]
    assert [r["env_step"] for r in rows(tmp_path / "sessions.csv")] == ["0", "1000", "2000"]
    train = rows(tmp_path / "train.csv")
    assert all(np.isfinite(float(r["loss_model"])) for r in train)
    assert 0 < float(train[-1]["target_lag"]) < 1
