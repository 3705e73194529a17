"""geomdp-train: smoke run, determinism, resume, and bad input."""

import json
import math
import os
import signal
import subprocess
import sys
import time
from types import SimpleNamespace

import gymnasium
import pytest
import torch
from conftest import TINY_AGENT
from tensordict import TensorDict

import geomdp_envs  # noqa: F401  (registers GeoMDP/*)
from agents import TDMPCAgent, agent_config
from agents.cli.train import rewrite_env_shorthand, run
from agents.run.presets import CONFIG_DIR, compose_config
from agents.run.run_tables import rows_without_wall_clock
from agents.run.trainer import Trainer

# A run small enough for CI: 125-step episodes, one evaluation episode, a tiny agent.
TINY = ["env.action_repeat=8", "train.steps=2000", "train.seed_steps=1000",
        "train.eval_every=1000", *TINY_AGENT]
TRAIN = [sys.executable, "-c", "from agents.cli.train import main; main()"]


def config(*overrides):
    return compose_config([*TINY, *overrides])


rows = rows_without_wall_clock  # what a resumed run must share with an uninterrupted one


@pytest.mark.slow
def test_smoke_run_writes_everything(tmp_path):
    assert run(config("agent.group=D4", "train.eval_noisy_episodes=1"), tmp_path) == 0
    for name in ("config.yaml", "eval.csv", "train.csv", "checkpoint/agent.pt",
                 "checkpoint/state.json", "torchrl_csv"):
        assert (tmp_path / name).exists(), name
    evals = rows(tmp_path / "eval.csv")
    assert [int(r["env_step"]) for r in evals] == [0, 1000, 2000]
    assert evals[-1]["eval_episodes"] == "1" and evals[-1]["noisy_eval_episodes"] == "1"
    assert evals[-1]["noisy_episode_reward"] != ""
    assert float(evals[0]["q_start"]) == 0.0  # the Q heads' last layers start at zero
    # learned by now; the return is bootstrapped at the time limit by Q (of either sign early on)
    assert float(evals[-1]["q_start"]) != 0.0 and math.isfinite(float(evals[-1]["discounted_return"]))
    assert evals[-1]["q_return_corr"] == "nan"  # one episode: no correlation to measure
    train = rows(tmp_path / "train.csv")
    assert train[-1]["updates"] == "125" and float(train[-1]["loss_model"]) > 0
    assert 0 < float(train[-1]["target_lag"]) < 1 and train[-1]["q_mean"] != ""
    assert json.loads((tmp_path / "checkpoint/state.json").read_text())["env_step"] == 2000
    (session,) = rows(tmp_path / "sessions.csv")
    head = subprocess.run(["git", "-C", str(CONFIG_DIR), "rev-parse", "HEAD"], capture_output=True,
                          text=True, check=False).stdout.strip()
    assert session["git_commit"] == (head or "unknown") and session["env_step"] == "0"
    assert session["git_dirty"] in ("True", "False", "unknown") and session["torch"] != "absent"


def played_episode(first_coordinates: list[float], rewards: list[float], terminated: bool):
    """A rollout's TensorDict: observations whose first coordinate is the given one."""
    obs = torch.zeros(len(first_coordinates), 4)
    obs[:, 0] = torch.tensor(first_coordinates)
    n = len(rewards)
    done = torch.zeros(n, 1, dtype=torch.bool)
    done[-1] = terminated
    return TensorDict({"observation": obs[:-1], "next": {
        "observation": obs[1:], "reward": torch.tensor(rewards).reshape(n, 1), "terminated": done}},
        batch_size=[n])


def test_value_check_bootstraps_past_the_time_limit_only_and_leaves_the_agent_as_it_was():
    # arithmetic: Q is the observation's first coordinate, discount 0.5
    fake = SimpleNamespace(agent=SimpleNamespace(
        config=SimpleNamespace(loss=SimpleNamespace(discount=0.5)),
        value=lambda obs: obs[..., 0]))
    time_limit = played_episode([10.0, 0.0, 0.0, 8.0], [1.0, 0.0, 2.0], terminated=False)
    terminated = played_episode([4.0, 0.0, 0.0, 100.0], [1.0, 0.0, 2.0], terminated=True)
    # 1 + 0.5 (0 + 0.5 (2 + 0.5 * 8)) = 2.5; terminated: the last state is worth 0, so 1.5
    check = Trainer.value_check(fake, [time_limit, terminated])
    assert check["q_start"] == 7.0 and check["discounted_return"] == 2.0
    assert check["q_return_corr"] == pytest.approx(1.0)
    # a real agent (plain and equivariant): no random number drawn, no parameter moved
    env = gymnasium.make("GeoMDP/PointMass2D-v0")
    symmetry = env.unwrapped.symmetry
    for group in ("none", "D4"):
        agent = TDMPCAgent(agent_config("tdmpc", f"group={group}", "networks.hidden_dim=16",
                                        "networks.latent_dim=8"),
                           symmetry, symmetry.observation_size, symmetry.action_size, seed=3)
        real = SimpleNamespace(agent=agent)
        before = (agent.generator.get_state(), torch.get_rng_state(),
                  [p.clone() for p in agent.model.parameters()])
        episode = played_episode([0.1, 0.2, -0.1], [0.5, 0.25], terminated=False)
        episode["observation"][:, 1] = 0.05
        check = Trainer.value_check(real, [episode])
        q_first = float(agent.value(episode["observation"][0]))
        q_last = float(agent.value(episode["next", "observation"][-1]))
        assert check["q_start"] == pytest.approx(q_first, abs=1e-6)
        assert check["discounted_return"] == pytest.approx(
            0.5 + 0.99 * (0.25 + 0.99 * q_last), abs=1e-5)
        assert torch.equal(agent.generator.get_state(), before[0])
        assert torch.equal(torch.get_rng_state(), before[1])
        assert all(torch.equal(p, q) for p, q in zip(agent.model.parameters(), before[2]))


@pytest.mark.slow
def test_same_seed_gives_the_same_eval_csv(tmp_path, finished_run):
    """Here and in the session's shared run (made by this process or another worker's)."""
    assert run(config(), tmp_path) == 0
    for table in ("eval.csv", "train.csv"):
        assert rows(tmp_path / table) == rows(finished_run(config()) / table), table


def train_and_evaluations(run_dir, at_step: int) -> tuple[list[dict], list[dict]]:
    """A run's train rows, and its eval rows at ``at_step`` without the columns that
    depend on how many noisy episodes were played."""
    evals = [{k: v for k, v in r.items() if not k.startswith("noisy_")}
             for r in rows(run_dir / "eval.csv") if int(r["env_step"]) == at_step]
    return rows(run_dir / "train.csv"), evals


@pytest.mark.slow
@pytest.mark.parametrize("group", ["none", "D8"])
def test_separate_evaluation_noise_leaves_training_untouched(finished_run, group):
    """``train.eval_noise=separate``: evaluating every 1000 steps with no noisy episode, or
    every 2000 with one, gives the same training run and the same evaluation at 2000 (its
    generator is a function of seed and step); ``shared`` (the default) does not, since its
    evaluations draw from the agent's generator (the evaluation at step 0 moves the warm-up)."""
    settings = {"often": ["train.eval_every=1000", "train.eval_noisy_episodes=0"],
                "rarely": ["train.eval_every=2000", "train.eval_noisy_episodes=1"]}
    noises = ["separate", "shared"] if group == "none" else ["separate"]
    made = {}
    for noise in noises:
        for name, overrides in settings.items():
            run_dir = finished_run(config(f"agent.group={group}", f"train.eval_noise={noise}",
                                          *overrides))
            made[noise, name] = train_and_evaluations(run_dir, at_step=2000)
    assert made["separate", "often"] == made["separate", "rarely"]
    assert len(made["separate", "often"][1]) == 1
    if "shared" in noises:
        assert made["shared", "often"][0] != made["shared", "rarely"][0]


AGENTS = {"plain": [], "D8": ["agent.group=D8"],
          "octahedral-pointmass3d": ["env=pointmass3d", "agent.group=octahedral"],
          "SO3-pointmass3d": ["env=pointmass3d", "agent.group=SO3"],
          "O2-reacher": ["env=reacher", "agent.group=O2"],
          "plain-augmented": ["agent.augment=auto"],
          "D8-separate-evaluation": ["agent.group=D8", "train.eval_noise=separate"],
          # TD-MPC's replay priorities (both non-defaults): restored with the buffer
          "D8-tdmpc-priorities": ["agent.group=D8", "agent.replay.priority_eps=1e-6",
                                  "agent.replay.max_priority_within_buffer=true"]}
# (agent, kill point, the env step the rerun resumes from). A TINY run: the warm-up episode
# (actions 1-125), its 125 updates, the evaluation and checkpoint at 1000; the second episode
# (actions and updates 126-250), the evaluation (evaluation actions 251-375) and checkpoint at
# 2000. Every agent but the first case is killed after the first checkpoint, so that its
# rerun restores the agent, optimiser, target network, replay and generators mid-run.
KILLS = [("plain", "seeding:100", 0),  # before any checkpoint: the run starts over
         ("plain", "checkpoint_write:2", 1000),  # a torn second checkpoint: the first stays
         ("plain", "checkpoint_cleanup:2", 2000),  # the old one left beside the new
         ("D8", "update:130", 1000),
         ("octahedral-pointmass3d", "update:130", 1000), ("SO3-pointmass3d", "update:130", 1000),
         ("O2-reacher", "checkpoint_swap:1", 1000),  # between the two renames of the second
         ("plain-augmented", "update:130", 1000),
         ("D8-separate-evaluation", "evaluation:300", 1000),
         ("D8-tdmpc-priorities", "update:130", 1000)]


@pytest.mark.slow
@pytest.mark.parametrize("agent, kill_at, resumed_at", KILLS)
def test_killed_run_resumes_to_the_same_result(tmp_path, finished_run, agent, kill_at, resumed_at):
    """kill -9 at a chosen point (random seeding, an update, an evaluation, the middle
    of a checkpoint write or swap); the same command then finishes the run from the
    checkpoint it should, and the logs equal an uninterrupted run's in every column but the
    wall-clock ones."""
    args = [*TINY, *AGENTS[agent], f"hydra.run.dir={tmp_path}"]
    killed = subprocess.run([*TRAIN, *args], capture_output=True, text=True, timeout=300,
                            env={**os.environ, "GEOMDP_KILL_AT": kill_at})
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-2000:]
    finished = subprocess.run([*TRAIN, *args], capture_output=True, text=True, timeout=300)
    assert finished.returncode == 0, finished.stderr[-2000:]
    for table in ("eval.csv", "train.csv"):
        assert rows(tmp_path / table) == rows(finished_run(config(*AGENTS[agent])) / table), table
    sessions = rows(tmp_path / "sessions.csv")  # one row per start, kept across the resume
    assert [s["env_step"] for s in sessions] == ["0", str(resumed_at)], sessions
    assert not (tmp_path / "checkpoint.old").exists() and not (tmp_path / "checkpoint.tmp").exists()


# Two random episodes, so that the burst after them (250 updates) is longer than an
# episode's own 125: it is checkpointed every ceil(250 / 8) = 32 updates.
BURST = ["train.seed_steps=2000", "train.steps=3000", "train.checkpoint_every=250"]


def checkpoint_format(run_dir):
    return json.loads((run_dir / "checkpoint/manifest.json").read_text())["format"]


@pytest.mark.slow
@pytest.mark.parametrize("agent, steps, kill_at, resumed_at", [
    ("D8", 3000, "update:100", "96 of its 250"),
    ("plain", 3000, "checkpoint_write:3", "32 of its 250"),  # killed writing the 2nd in the burst
    ("plain", 2000, "update:100", "96 of its 250")])  # the burst is the run's last episode
def test_a_run_killed_inside_the_burst_resumes_from_its_middle(tmp_path, finished_run,
                                                                agent, steps, kill_at, resumed_at):
    """The burst of updates after the warm-up (TD-MPC's: 5000) is checkpointed every
    ``checkpoint_every`` env steps' worth of updates: killed inside it, a run resumes there,
    not at the burst's start, and its logs equal an uninterrupted run's (checkpointed at
    episode ends only: the default checkpoint_every, 1000, is an episode of TINY's) in every
    column but the wall-clock ones. Code from before these checkpoints would redo the whole
    burst: they have a format of their own, 4."""
    args = [*TINY, *AGENTS[agent], *BURST, f"train.steps={steps}", f"hydra.run.dir={tmp_path}"]
    killed = subprocess.run([*TRAIN, *args], capture_output=True, text=True, timeout=300,
                            env={**os.environ, "GEOMDP_KILL_AT": kill_at})
    assert killed.returncode == -signal.SIGKILL, killed.stderr[-2000:]
    assert checkpoint_format(tmp_path) == 4
    finished = subprocess.run([*TRAIN, *args], capture_output=True, text=True, timeout=300)
    assert finished.returncode == 0, finished.stderr[-2000:]
    assert f"at env step 2000, {resumed_at} updates done" in finished.stdout, finished.stdout
    reference = finished_run(config(*AGENTS[agent], *BURST[:2]))
    for table in ("eval.csv", "train.csv"):
        expected = [r for r in rows(reference / table) if int(r["env_step"]) <= steps]
        assert rows(tmp_path / table) == expected, table
    state = json.loads((tmp_path / "checkpoint/state.json").read_text())
    assert state["unfinished_episode"] is None and state["env_step"] == steps
    assert checkpoint_format(tmp_path) == 3


@pytest.mark.slow
def test_sigterm_stops_at_a_safe_point_with_one_line(tmp_path):
    """SIGTERM during an equivariant run's second episode (planning or its updates): the
    loop stops at a safe point, with one line naming the checkpoint it keeps and no
    traceback; the same command then finishes the run."""
    args = [*TINY, "agent.group=D8", f"hydra.run.dir={tmp_path}"]
    proc = subprocess.Popen([*TRAIN, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    state = tmp_path / "checkpoint" / "state.json"
    deadline = time.time() + 180
    while not state.exists():  # the first episode, its updates and evaluation are done
        assert proc.poll() is None and time.time() < deadline, proc.communicate()
        time.sleep(0.05)
    time.sleep(0.3)  # inside the second episode
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "Traceback" not in err, err
    assert "the last checkpoint is at env step 1000: run the same command to continue" in err, err
    finished = subprocess.run([*TRAIN, *args], capture_output=True, text=True, timeout=300)
    assert finished.returncode == 0, finished.stderr[-2000:]


@pytest.mark.slow
def test_a_second_signal_while_stopping_exits_130(tmp_path):
    """SIGTERM, then another while the process is stopping or shutting down (as a
    supervisor that repeats its signal does): the status stays 130, never 143."""
    for pause in (0.0, 0.5, 1.5):
        run_dir = tmp_path / f"pause{pause}"
        proc = subprocess.Popen([*TRAIN, *TINY, "train.steps=4000", f"hydra.run.dir={run_dir}"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        deadline = time.time() + 180
        while not (run_dir / "eval.csv").exists():  # training (signal handlers installed)
            assert proc.poll() is None and time.time() < deadline, proc.communicate()
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        time.sleep(pause)
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, (pause, proc.returncode, err[-1000:])


@pytest.mark.slow
def test_corrupted_checkpoint_is_reported_and_kept(tmp_path, capsys):
    assert run(config(), tmp_path) == 0
    agent_file = tmp_path / "checkpoint/agent.pt"
    agent_file.write_bytes(b"not a checkpoint")
    assert run(config("train.steps=3000"), tmp_path) == 2
    assert "is corrupted" in capsys.readouterr().err
    assert agent_file.read_bytes() == b"not a checkpoint"  # never overwritten


@pytest.mark.slow
def test_changed_options_are_refused_on_resume(tmp_path, capsys):
    assert run(config(), tmp_path) == 0
    assert run(config("agent.group=D8"), tmp_path) == 2
    assert "agent.group: 'none' -> 'D8'" in capsys.readouterr().err


@pytest.mark.parametrize("overrides, message", [
    (["env=CartPoleX-v9"], "unknown environment 'CartPoleX-v9'"),
    (["agent.group=Q8"], "agent.group='Q8'; valid: none, C<N>, D<N> (N >= 1), SO2, O2"),
    (["agent.group=D7", "env=pointmass3d"], "group D7 acts in 2D but the task is 3D"),
    (["agent.group=icosahedral"], "acts in 3D but the task is 2D"),
    (["env=reacher", "agent.group=octahedral"], "acts in 3D but the task is 2D"),
    (["env=pointmass3d", "agent.group=D8"], "acts in 2D but the task is 3D"),
    (["agent.group=O2"], "O2 is only an approximate symmetry of GeoMDP/PointMass2D-v0 (exact "
                         "group: D4); set agent.allow_approximate=true"),
    (["agent.group=D8", "agent.networks.max_frequency=2"], "apply to the continuous groups"),
    (["env=pointmass3d", "agent.group=SO3", "agent.networks.max_frequency=2",
      "agent.networks.grid_frequency=3"], "grid_frequency must be >= 2 * max_frequency = 4"),
    (["agent.group=SO2", "agent.networks.max_frequency=two"], "max_frequency must be an integer"),
    (["env=Pendulum-v1", "agent.group=D4"], "needs a task that declares its symmetry"),
    (["train.steps=0"], "train.steps must be >= 1, got 0"),
    (["env=pointmass3d", "env.n_balls=0"], "n_balls must be an integer >= 1"),
    (["env=reacher", "env.frame=body"], "frame='body'; valid: 'local', 'global'"),
    (["agent.width_strategy=cube"], "width_strategy='cube'; valid: sqrt, linear"),
    (["train.eval_noise=own"], "train.eval_noise='own'; valid: shared, separate"),
    (["+agent.planner.samples=3"], "unknown option agent.planner.samples; valid: discount,"),
    (["train.steps=abc"], "train.steps must be an integer, got 'abc'"),
    (["train.steps=2.5"], "train.steps must be an integer, got 2.5"),
    (["seed=abc"], "seed must be an integer, got 'abc'"),
    (["seed=1.5"], "seed must be an integer, got 1.5"),
    (["+train.stepz=100"], "unknown option train.stepz; valid:"),
    (["+foo=1"], "unknown option 'foo'"),
    (["agent.lr=-1"], "agent.lr must be > 0, got -1"),
    (["agent.lr=fast"], "agent.lr must be a number, got 'fast'"),
    (["agent.networks.activation=swish"], "activation='swish'; valid: mish, elu"),
    (["agent.networks.layers=sparse"], "layers='sparse'; valid: auto, dense, fourier"),
    (["agent.planner.num_pi_trajs=-3"], "planner.num_pi_trajs must be >= 0, got -3"),
    (["agent.replay.capacity=2"], "agent.replay.capacity (2) must hold at least one batch"),
    (["logger.tensorboard=maybe"], "logger.tensorboard='maybe'; valid: true, false, auto"),
    (["train.video=yes"], "train.video must be true or false, got 'yes'"),
    (["agent.networks.latent_dim=0"], "latent_dim must be >= 1, got 0"),
    (["+agent.equivariant.transtion=false"],
     "unknown option agent.equivariant.transtion; valid: policy, q, transition"),
    (["agent.replay.beta=1.5"], "agent.replay.beta must be in [0, 1], got 1.5"),
    (["agent.group=D8", "agent.equivariant.transition=false"],
     "an equivariant Q or policy needs an equivariant latent state"),
    (["agent.replay.alpha=-0.1"], "agent.replay.alpha must be >= 0, got -0.1"),
    (["agent.tau=0"], "agent.tau must be in (0, 1], got 0"),
    (["agent.std_schedule.steps=-1"], "agent.std_schedule.steps must be >= 0, got -1"),
    (["env.action_repeat=0"], "env.action_repeat must be >= 1, got 0"),
    (["agent.planner.num_elites=300"], "agent.planner.num_elites (300) exceeds the number of "
                                        "sampled trajectories"),
])
def test_bad_input_fails_fast_with_one_clear_line(overrides, message, tmp_path, capsys):
    start = time.time()
    run_dir = tmp_path / "run"
    try:
        status = run(config(*rewrite_env_shorthand(overrides)), run_dir)
    except Exception as err:  # noqa: BLE001  (Hydra refuses some overrides while composing)
        pytest.fail(f"{overrides}: {type(err).__name__}: {err}")
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and err[0].startswith("geomdp-train: error")
    assert message in err[0], err
    assert not run_dir.exists(), "a refused run leaves no directory"
    assert time.time() - start < 30


def test_prioritized_replay_without_torchrls_extension_is_refused_before_the_run(tmp_path, capsys,
                                                                                 monkeypatch):
    """TorchRL's compiled extension loads only with the torch it was built for; without it
    a prioritised sampler fails after the run has started. Refused up front instead, and
    by the buffer's maker too (the same line), for code that builds an agent itself."""
    import agents.compat.torchrl
    from agents.tdmpc.replay import ReplayConfig, make_replay_buffer

    monkeypatch.setattr(agents.compat.torchrl, "prioritized_replay_available", lambda: False)
    assert run(config(), tmp_path / "run") == 2
    (err,) = capsys.readouterr().err.strip().splitlines()
    assert err.startswith("geomdp-train: error: agent.replay.prioritized=true needs TorchRL's "
                          "compiled extension") and "agent.replay.prioritized=false" in err
    assert not (tmp_path / "run").exists()
    with pytest.raises(ValueError) as refused:
        make_replay_buffer(ReplayConfig(capacity=8), horizon=2, batch_size=2)
    assert f"geomdp-train: error: {refused.value}" == err
    make_replay_buffer(ReplayConfig(capacity=8, prioritized=False), horizon=2, batch_size=2)


@pytest.mark.slow
def test_bad_input_on_the_command_line_exits_2_and_leaves_no_directory(tmp_path):
    """The same through the console script: Hydra makes the run directory before the
    app starts; a refused run removes it again."""
    run_dir = tmp_path / "run"
    out = subprocess.run([*TRAIN, *TINY, "train.steps=abc", f"hydra.run.dir={run_dir}"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "Traceback" not in out.stderr
    errors = [line for line in out.stderr.splitlines() if line.startswith("geomdp-train: error")]
    assert errors == ["geomdp-train: error: train.steps must be an integer, got 'abc'"], out.stderr
    assert not run_dir.exists()


@pytest.mark.slow
def test_approximate_group_warns_once_and_trains(tmp_path):
    with pytest.warns(UserWarning, match="D8 is only an approximate symmetry") as record:
        assert run(config("agent.group=D8", "train.steps=1000"), tmp_path) == 0
    assert sum("approximate" in str(w.message) for w in record) == 1


@pytest.mark.slow
def test_plain_agent_on_any_gymnasium_env(tmp_path):
    out = subprocess.run([*TRAIN, *TINY, "env=Pendulum-v1", "train.steps=400",
                          "train.seed_steps=200", "train.eval_every=400",
                          f"hydra.run.dir={tmp_path}"], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    assert [int(r["env_step"]) for r in rows(tmp_path / "eval.csv")] == [0, 400]
    # Pendulum's episodes last 200 steps (action_repeat 8 applies: 25 agent steps):
    # one random (seeding) episode, one planned; an update per agent step from the
    # end of seeding, logged once per episode.
    train = rows(tmp_path / "train.csv")
    assert [(int(r["env_step"]), int(r["updates"])) for r in train] == [(200, 25), (400, 25)]
    # It learned: Q starts at exactly 0 (a zero output layer, as TD-MPC's) and moves
    # towards the TD targets (about -50: eight steps of Pendulum's negative reward).
    # Mean Q over the first 25 updates ~ -0.13 and over the next 25 ~ -0.5, for any
    # seed; without learning it stays at 0.
    q = [float(r["q_mean"]) for r in train]
    assert q[1] < 2 * q[0] < 0 and all(float(r["td_target_mean"]) < -10 for r in train), train


@pytest.mark.slow
def test_progress_bar_shows_returns_for_people(tmp_path, capsys):
    assert run(config("train.progress=true", "train.steps=1000"), tmp_path) == 0
    err = capsys.readouterr().err
    assert "eval return 0.0" in err and "e-" not in err.split("eval return ")[-1][:12]
