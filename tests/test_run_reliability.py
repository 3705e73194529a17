"""Interruptions, damaged checkpoints and bad run directories: nothing lost, one clear line."""

import io
import json
import re
import shutil
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import pytest
import torch
from conftest import load_script, run_main
from test_train import config, rows

from agents import TDMPCAgent
from agents.cli.train import run
from agents.nn.layers import dense_equivariant_layers
from agents.run import checkpoint
from agents.run.presets import compose_config, sweep_dirname, usable_cores

pytestmark = pytest.mark.slow  # trains agents, kills and resumes them

LOGS = ("eval.csv", "train.csv")


def torchrl_steps(run_dir):
    """The steps in every TorchRL CSV file (one file per scalar)."""
    return {str(p.relative_to(run_dir)): [line.split(",")[0] for line in p.read_text().splitlines()]
            for p in sorted((run_dir / "torchrl_csv").rglob("*.csv"))}


@pytest.fixture
def straight(finished_run):
    """An uninterrupted 3000-step run, the reference for every resumed one."""
    return finished_run(config("train.steps=3000"))

def assert_same_logs(run_dir, reference):
    for table in LOGS:
        assert rows(run_dir / table) == rows(reference / table), table
    assert torchrl_steps(run_dir) == torchrl_steps(reference)


def test_logs_without_a_checkpoint_start_over(tmp_path, straight, finished_run):
    """Killed before the first checkpoint, or the checkpoint deleted: the rerun starts
    over and its logs hold one run, not two."""
    finished_run(config("train.steps=2000"), copy_to=tmp_path)
    shutil.rmtree(tmp_path / "checkpoint")
    assert run(config("train.steps=3000"), tmp_path) == 0
    assert_same_logs(tmp_path, straight)


def test_a_restored_run_is_the_agent_its_checkpoint_holds(straight, tmp_path):
    """restore_run (examples/inspect_run.py, scripts/before_reward.py) rebuilds the run's
    agent and task and loads the checkpoint into it: every saved tensor, the loop state."""
    restored = checkpoint.restore_run(straight)
    assert restored.state["env_step"] == 3000 and restored.options.seed == 1
    saved = torch.load(straight / "checkpoint" / "agent.pt", weights_only=False)["agent"]
    torch.testing.assert_close(restored.agent.state_dict(), saved, rtol=0, atol=0)
    assert restored.env.observation_space.shape == (4,)  # PointMass2D: position, velocity
    (tmp_path / "config.yaml").write_text((straight / "config.yaml").read_text())
    with pytest.raises(checkpoint.CheckpointError, match=f"^no checkpoint in {tmp_path} "):
        checkpoint.restore_run(tmp_path)


def flip_byte(path):
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))


def truncate(path):
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


@pytest.mark.parametrize("damage, message", [
    (lambda c: flip_byte(c / "agent.pt"), "agent.pt does not match its checksum"),
    (lambda c: flip_byte(c / "replay.pt"), "replay.pt does not match its checksum"),
    (lambda c: truncate(c / "replay.pt"), "replay.pt does not match its checksum"),
    (lambda c: (c / "replay.pt").unlink(), "missing replay.pt"),
    (lambda c: (c / "manifest.json").unlink(), "has no manifest.json"),
])
def test_damaged_checkpoints_are_refused_in_one_line_and_kept(tmp_path, capsys, finished_run,
                                                              damage, message):
    finished_run(config(), copy_to=tmp_path)
    damage(tmp_path / "checkpoint")
    before = sorted((p.name, p.stat().st_size) for p in (tmp_path / "checkpoint").rglob("*"))
    capsys.readouterr()
    assert run(config("train.steps=3000"), tmp_path) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert sorted((p.name, p.stat().st_size) for p in (tmp_path / "checkpoint").rglob("*")) == before


def test_a_checkpoint_from_another_seed_is_refused(tmp_path, capsys, finished_run):
    finished_run(config("seed=1", "train.steps=1000"), copy_to=tmp_path / "one")
    shutil.rmtree(tmp_path / "one/checkpoint")
    shutil.copytree(finished_run(config("seed=2")) / "checkpoint", tmp_path / "one/checkpoint")
    capsys.readouterr()
    assert run(config("seed=1", "train.steps=3000"), tmp_path / "one") == 2
    err = capsys.readouterr().err
    assert "belongs to another run (seed: 2 there, 1 here)" in err


def test_checkpoints_hold_what_cannot_be_rebuilt_only(tmp_path):
    """No escnn basis buffers (rebuilt with the networks); the replay's stored steps, not
    its capacity (agent.replay.capacity=5000 here, 125 steps stored)."""
    assert run(config("agent.group=D8", "agent.width_strategy=sqrt", "agent.networks.layers=dense",
                      "train.steps=1000"), tmp_path) == 0
    saved = torch.load(tmp_path / "checkpoint/agent.pt", weights_only=False)["agent"]["loss"]
    assert saved and not any("_basisexpansion" in k or k.endswith((".layer.matrix", ".bias_expansion"))
                             for k in saved)
    assert (tmp_path / "checkpoint/agent.pt").stat().st_size < 2e6
    replay = torch.load(tmp_path / "checkpoint/replay.pt", weights_only=False)
    assert replay["len"] == 125 and replay["data"].shape == (125,)
    assert (tmp_path / "checkpoint/replay.pt").stat().st_size < 60_000


def test_full_disk_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(shutil, "disk_usage", lambda path: shutil._ntuple_diskusage(10**9, 10**9, 10**6))
    assert run(config(), tmp_path) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not enough disk space" in err[0]
    assert not (tmp_path / "eval.csv").exists() or len(rows(tmp_path / "eval.csv")) == 0


@pytest.mark.parametrize("error", [
    OSError(28, "No space left on device"),
    RuntimeError("[enforce fail at inline_container.cc] No space left on device")])
def test_a_failed_checkpoint_write_is_one_line_and_keeps_the_last_one(tmp_path, capsys, monkeypatch,
                                                                     finished_run, error):
    """torch.save reports a full disk as OSError or RuntimeError: both are one line."""
    finished_run(config("train.steps=1000"), copy_to=tmp_path)
    step = json.loads((tmp_path / "checkpoint/state.json").read_text())["env_step"]

    def disk_full(*args, **kwargs):
        raise error

    monkeypatch.setattr(checkpoint.torch, "save", disk_full)
    capsys.readouterr()
    assert run(config("train.steps=3000"), tmp_path) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left on device" in err[0] and "previous checkpoint is intact" in err[0]
    assert json.loads((tmp_path / "checkpoint/state.json").read_text())["env_step"] == step
    monkeypatch.undo()
    assert run(config("train.steps=2000"), tmp_path) == 0


def test_run_directory_that_cannot_be_made_is_one_line(tmp_path, capsys):
    (tmp_path / "a_file").write_text("")
    assert run(config(), tmp_path / "a_file" / "run") == 2  # a path that cannot be a directory
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot create the run directory" in err[0]


def test_evaluation_video_is_written_and_playable(tmp_path, monkeypatch, capsys):
    assert run(config("train.steps=1000", "train.video=true", "train.video_every=2",
                      "+env.width=64", "+env.height=48"), tmp_path) == 0
    videos = sorted((tmp_path / "videos").glob("*.mp4"))
    assert [v.name for v in videos] == ["eval_00000000.mp4"]  # evaluations 0 and 2, 4, ...
    reader = imageio.get_reader(videos[0])
    frames = [frame for frame in reader.iter_data()]
    assert len(frames) == 126  # 125 agent steps (action repeat 8) and the final state
    assert reader.get_meta_data()["fps"] == 6  # one frame per agent step: 8 x 0.02 s
    assert frames[0].shape == (48, 64, 3)
    assert frames[0].std() > 0  # not a blank image
    # examples/inspect_run.py writes one from the checkpoint too
    inspect_run = load_script("examples/inspect_run.py")
    planned, error = run_main(inspect_run, monkeypatch, capsys, tmp_path, "--episodes", 1,
                              "--video", tmp_path / "replay.mp4")
    assert error is None
    assert sum(1 for _ in imageio.get_reader(tmp_path / "replay.mp4").iter_data()) == 126
    # --evaluation starts where the run's evaluations started: the evaluation video's first
    # frame again (the agent differs, so only the start state is shared); seed 500 does not
    _, error = run_main(inspect_run, monkeypatch, capsys, tmp_path, "--episodes", 1, "--evaluation",
                        "--video", tmp_path / "evaluation.mp4")
    assert error is None

    def first_frame(path: Path) -> np.ndarray:
        return next(imageio.get_reader(path).iter_data()).astype(float)

    # the same image up to the video codec (8 of 255 at most, measured), against a mass
    # elsewhere (183 where it moved)
    assert np.abs(first_frame(tmp_path / "evaluation.mp4") - frames[0]).max() < 32
    assert np.abs(first_frame(tmp_path / "replay.mp4") - frames[0]).max() > 100
    # --explore plans with the training noise (the planner is told so), --policy not at all
    explored = []
    act = TDMPCAgent.act_with_values
    monkeypatch.setattr(TDMPCAgent, "act_with_values", lambda self, *args, explore, **kw:
                        explored.append(explore) or act(self, *args, explore=explore, **kw))
    for flag in ([], ["--explore"]):
        _, error = run_main(inspect_run, monkeypatch, capsys, tmp_path, "--episodes", 1, *flag)
        assert error is None
    assert explored == [False] * 125 + [True] * 125
    # --policy-after K plans K steps and hands the rest to pi: K = 0 is --policy's episode,
    # K = 5 plans exactly 5 times; --plan-values reports those plans
    explored.clear()
    handed, error = run_main(inspect_run, monkeypatch, capsys, tmp_path, "--episodes", 1,
                             "--policy-after", 5, "--plan-values")
    assert error is None and explored == [False] * 5
    gaps = re.search(r"^  planner: best sample valued (\S+) against the policy's best proposal, "
                     r"mean over 5 plans \(min (\S+), max (\S+)\)$", handed, re.MULTILINE)
    assert gaps, handed
    mean_gap, low, high = (float(v) for v in gaps.groups())
    assert low <= mean_gap <= high
    split = re.search(r"^  policy alone from agent step 5: earned (\S+) \(the planner before it: "
                      r"(\S+)\)$", handed, re.MULTILINE)
    episode_return = re.search(r"; return (\S+); Q", handed)
    assert split and episode_return, handed
    assert float(split.group(1)) + float(split.group(2)) == pytest.approx(
        float(episode_return.group(1)), abs=0.16)  # three roundings to 0.1
    from_start, error = run_main(inspect_run, monkeypatch, capsys, tmp_path, "--episodes", 1,
                                 "--policy-after", 0)
    assert error is None and "planner:" not in from_start
    # and compares the agent's value estimate with the return, planning or with pi alone
    policy, error = run_main(inspect_run, monkeypatch, capsys, tmp_path, "--episodes", 1, "--policy",
                             "--final-observation", "--q-heads")
    assert error is None
    # --final-observation: the whole last observation, which begins with the printed end
    end = re.search(r"episode 0: start \[[^]]*\] end \[\s*(\S+)\s+(\S+)\]", policy)
    final = re.search(r"^  final observation: \[([^]]*)\]$", policy, re.MULTILINE)
    assert end and final, policy
    final = np.array(final.group(1).split(), dtype=float)
    assert final.shape == (4,)  # PointMass2D: position, velocity
    np.testing.assert_allclose(final[:2], np.array(end.groups(), dtype=float), atol=1e-3)
    assert "final observation" not in planned
    # --q-heads: each head at s_0, whose minimum is the printed Q(s_0, pi)
    heads = re.search(r"^  Q heads at s_0: \[([^]]*)\]; last tenth of the episode: Q (\S+) vs "
                      r"(\S+), its mean reward forever$", policy, re.MULTILINE)
    q_start = re.search(r"Q\(s_0, pi\) (\S+) vs", policy)
    assert heads and q_start, policy
    head_values = np.array(heads.group(1).split(), dtype=float)
    assert head_values.shape == (2,)  # TD-MPC's two Q heads
    assert head_values.min() == pytest.approx(float(q_start.group(1)), abs=0.11)
    assert all(np.isfinite(float(v)) for v in heads.groups()[1:])
    assert "Q heads" not in planned
    def episode_line(printed: str) -> str:
        return re.search(r"^episode 0: .*$", printed, re.MULTILINE).group(0)

    # pi from the first step is --policy's episode: the same end, return and values
    assert episode_line(from_start) == episode_line(policy) != episode_line(planned)
    for flags, says in ((["--policy", "--plan-values"], "drop --policy"),
                        (["--policy", "--policy-after", 3], "drop --policy"),
                        (["--policy-after", -1], "0 or more")):
        _, error = run_main(inspect_run, monkeypatch, capsys, tmp_path, "--episodes", 1, *flags)
        assert error is not None and len(error.splitlines()) == 1 and says in error, flags
    for printed in (planned, policy):
        values = re.search(r"Q\(s_0, pi\) (\S+) vs discounted return (\S+), mean over the "
                           r"episode (\S+) vs (\S+)$", printed, re.MULTILINE)
        assert values and all(np.isfinite(float(v)) for v in values.groups()), printed
        rewards = re.search(r"reward model: (\S+) predicted over the episode vs (\S+) earned; "
                            r"at the steps that earned nothing (\S+)$", printed, re.MULTILINE)
        assert rewards and all(np.isfinite(float(v)) for v in rewards.groups()), printed
    # --rotate/--reflect move each start state by a group element before the episode: on
    # PointMass2D the observation starts with the mass's position, so the printed start is
    # the original one moved by g; an element outside the task's exact group (D4: the
    # arena's walls) is said
    def start(*flags: str, episode: int = 0) -> tuple[str, np.ndarray]:
        printed, error = run_main(inspect_run, monkeypatch, capsys, tmp_path, "--episodes", 1,
                                  "--policy", *flags)
        assert error is None
        found = re.search(rf"episode {episode}: start \[\s*(\S+)\s+(\S+)\]", printed)
        return printed, np.array(found.groups(), dtype=float)

    # --only replays the episodes it names, from the starts they have in the full sequence
    _, second = start("--episodes", "2", episode=1)
    only_printed, only = start("--only", "1", episode=1)
    assert "episode 0:" not in only_printed and np.array_equal(only, second)

    printed, (x, y) = start()
    assert abs(x) > 0.01 and abs(y) > 0.01 and abs(abs(x) - abs(y)) > 0.01  # g moves it
    # how far the mass is from the target (at the origin) at the start and the end
    distances = re.search(r"episode 0: start .* distance to target (\S+) -> (\S+); return", printed)
    assert distances, printed
    assert float(distances.group(1)) == pytest.approx(np.hypot(x, y), abs=2e-3)
    rotated_printed, rotated = start("--rotate", "90")
    assert "rotation 90 deg" in rotated_printed and "exact group" not in rotated_printed
    np.testing.assert_allclose(rotated, [-y, x], atol=2e-3)
    np.testing.assert_allclose(start("--reflect")[1], [x, -y], atol=2e-3)
    both_printed, both = start("--rotate", "30", "--reflect")
    assert "not in the task's exact group D4" in both_printed
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    np.testing.assert_allclose(both, [c * x + s * y, s * x - c * y], atol=2e-3)


def test_sweep_directories_stay_short_and_the_launcher_uses_one_process_per_core():
    long = ",".join(f"agent.networks.option{i}=value{i}" for i in range(40))
    name = sweep_dirname(long)
    assert len(name) <= 120 and name != sweep_dirname(long + "x")
    assert sweep_dirname("seed=1,agent.group=D8") == "seed=1,agent.group=D8"
    assert "/" not in sweep_dirname("env.id=GeoMDP/PointMass2D-v0")
    # Hydra sorts the overrides (seed last); a shortened name keeps every swept value
    sweep = ",".join([f"agent.networks.option{i}=value{i}" for i in range(6)]
                     + ["agent.group=icosahedral", "env.target_size=0.02", "seed=3"])
    short = sweep_dirname(sweep)
    assert len(short) <= 120 and short.startswith("seed=3,") and ",icosahedral," in short
    assert all(f"value{i}" in short for i in range(6)) and short != sweep_dirname(sweep[:-1] + "4")
    cfg = compose_config(hydra=True)
    assert cfg.hydra.launcher.n_jobs == usable_cores()


@pytest.mark.parametrize("agent, flipped", [
    (["agent.group=octahedral"], None),  # the first equivariant layer's basis
    (["agent.group=SO3"], "encoder.net.2"),  # a continuous group's sampling grid
])
def test_a_checkpoint_whose_rebuilt_bases_differ_is_refused(tmp_path, capsys, agent, flipped):
    """Checkpoints store the coefficients and the dense layers' bases, not the grids
    sampled from escnn's irreps nor the Fourier transforms: if a layer's map differs
    from the one the checkpoint fingerprinted (another escnn version, another cache),
    resuming must refuse, not run a different network."""
    assert run(config("env=pointmass3d", *agent, "train.steps=1000"), tmp_path) == 0
    agent_file = tmp_path / "checkpoint/agent.pt"
    saved = torch.load(agent_file, weights_only=False)
    fingerprints = saved["agent"]["basis_fingerprints"]
    assert fingerprints, "equivariant layers leave fingerprints"
    name = flipped or next(iter(fingerprints))
    fingerprints[name] = -fingerprints[name]  # as a sign-flipped basis would give
    torch.save(saved, agent_file)
    manifest = json.loads((tmp_path / "checkpoint/manifest.json").read_text())
    manifest["files"]["agent.pt"] = checkpoint._sha256(agent_file)
    (tmp_path / "checkpoint/manifest.json").write_text(json.dumps(manifest))
    capsys.readouterr()
    assert run(config("env=pointmass3d", *agent, "train.steps=2000"), tmp_path) == 2
    err = capsys.readouterr().err
    assert "escnn rebuilt a different basis" in err


def small_agent_factory(group: str, layers: str = "dense"):
    """A maker of small agents of ``group`` on PointMass2D (PointMass3D for the 3D
    groups), and a batch of random transitions for them."""
    import gymnasium
    from tensordict import TensorDict

    from agents.tdmpc.agent import TDMPCAgent, TDMPCConfig

    task = "GeoMDP/PointMass3D-v0" if group in ("octahedral", "icosahedral") else "GeoMDP/PointMass2D-v0"
    sym = gymnasium.make(task).unwrapped.symmetry
    n, h, g = 8, 3, torch.Generator().manual_seed(1)
    cfg = TDMPCConfig.from_dict({"group": group, "width_strategy": "sqrt", "batch_size": n,
                                 "horizon": h, "networks": {
                                     "hidden_dim": 32, "latent_dim": 16, "layers": layers}})
    obs = torch.randn(n, h + 1, sym.observation_size, generator=g)
    batch = TensorDict({
        "observation": obs[:, :-1], "action": torch.rand(n, h, sym.action_size, generator=g) - 0.5,
        "next": {"observation": obs[:, 1:], "reward": torch.rand(n, h, 1, generator=g),
                 "terminated": torch.zeros(n, h, 1, dtype=torch.bool)}}, batch_size=[n, h])
    return (lambda: TDMPCAgent(cfg, sym, sym.observation_size, sym.action_size, seed=0)), batch


@torch.no_grad()
def solve_another_basis(agent, seed: int = 1) -> None:
    """Give every dense equivariant layer another basis of the same space, as escnn
    does on a machine whose BLAS kernels differ (an orthogonal mix of its rows)."""
    g = torch.Generator().manual_seed(seed)
    for layer in [*dense_equivariant_layers(agent.model).values(),
                  *dense_equivariant_layers(agent.loss.target_model).values()]:
        for basis in layer.bases():
            n = basis.shape[0]
            mix, _ = torch.linalg.qr(torch.randn(n, n, generator=g, dtype=torch.float64))
            basis.copy_((mix.T @ basis.double()).to(basis.dtype))


@pytest.mark.parametrize("layers, buffer", [("dense", "_basis0"), ("fourier", "fourier_in")])
def test_fingerprints_follow_the_rebuilt_bases(layers, buffer):
    """The fingerprints are the layers' maps on a probe, applied by their own forward
    (not by expanding the weights, which made saving a paper-preset D8 checkpoint take
    seconds): the same bases load; a different Fourier transform is refused, and so is
    a different dense basis when the checkpoint has no stored bases (written before
    they were stored; with them, the stored ones are applied)."""
    from agents.nn.fourier import FourierLinear
    from agents.nn.layers import EquivariantLinear

    agent, _ = small_agent_factory("D4", layers)
    saved = agent().state_dict()
    agent().load_state_dict(saved)  # rebuilt the same: accepted
    changed = agent()
    kind = EquivariantLinear if layers == "dense" else FourierLinear
    name, layer = next((n, m) for n, m in changed.model.named_modules() if isinstance(m, kind))
    assert name in saved["basis_fingerprints"]
    with torch.no_grad():
        getattr(layer, buffer).neg_()
    if layers == "dense":
        saved = {k: v for k, v in saved.items() if k != "bases"}
    with pytest.raises(ValueError, match=f"escnn rebuilt a different basis .*for {name} "):
        changed.load_state_dict(saved)


@pytest.mark.parametrize("group", ["D4", "octahedral"])
def test_a_resume_applies_the_bases_the_coefficients_were_trained_with(group):
    """escnn solves for some bases numerically and caches them on disk, so a machine
    with other BLAS kernels can rebuild another basis of the same space (seen: D8 on an
    AVX-512 machine, a checkpoint made with AVX2 ones). Checkpoints store the bases: a
    resume applies them in the online and the target model, and training goes on
    exactly as it would have."""
    agent, batch = small_agent_factory(group)
    original = agent()
    original.update(batch)
    buffer = io.BytesIO()
    torch.save(original.state_dict(), buffer)  # as a checkpoint holds it: no tensor shared
    saved = torch.load(io.BytesIO(buffer.getvalue()), weights_only=False)
    assert saved["bases"] and all(saved["bases"].values())
    resumed = agent()
    solve_another_basis(resumed)
    obs = batch["observation"][:, 0]
    assert not torch.equal(resumed.model.encode(obs), original.model.encode(obs))
    resumed.load_state_dict(saved)
    for model in ("model", "target_model"):
        net, reference = getattr(resumed.loss, model), getattr(original.loss, model)
        assert torch.equal(net.encode(obs), reference.encode(obs)), model
    metrics = []
    for agent_ in (resumed, original):
        torch.manual_seed(0)  # the global state the checkpoint restores beside the agent
        metrics.append(agent_.update(batch)[0])
    assert metrics[0] == metrics[1]
    for model in ("model", "target_model"):
        assert all(torch.equal(a, b) for a, b in zip(getattr(resumed.loss, model).parameters(),
                                                     getattr(original.loss, model).parameters()))
    # refused: a basis of other maps (not equivariant here), of fewer maps (a row
    # repeated: inside the space, not all of it), of another shape
    name = next(n for n, bases in saved["bases"].items() if len(bases[0]) > 1)
    basis = saved["bases"][name][0]
    for wrong, message in [(torch.randn_like(basis), "spans other maps"),
                           (basis[[0] * len(basis)], "spans other maps"),
                           (basis[:, :-1], "has shape")]:
        saved["bases"][name][0] = wrong
        with pytest.raises(ValueError, match=f"bases for {name}: basis 0 {message}"):
            agent().load_state_dict(saved)
