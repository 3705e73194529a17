"""Experiment configs compose, sweeps run on Hydra's launchers, and plots cope with real runs."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from test_train import TINY, TRAIN

from agents.cli import plot
from agents.run import results, statistics
from agents.run.presets import CONFIG_DIR, compose_config
from agents.run.run_tables import TrainingEpisode, evaluation_share, training_episodes, wall_minutes
from agents.run.td_invariants import bootstrapped_returns, td_invariants, value_at_start

EXPERIMENTS = sorted(p.stem for p in (CONFIG_DIR / "experiment").glob("*.yaml"))


def test_there_is_a_paper_and_a_cpu_config_per_figure():
    paper = [e for e in EXPERIMENTS if not e.endswith("_cpu")]
    assert len(paper) == 8
    assert all(f"{e}_cpu" in EXPERIMENTS for e in paper)


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_experiment_config_composes_into_a_valid_sweep(name):
    cfg = compose_config([f"+experiment={name}"], hydra=True)
    params = cfg.hydra.sweeper.params
    assert "seed" in params and len(str(params.seed).split(",")) == (3 if name.endswith("_cpu") else 5)
    hidden = cfg.agent.networks.hidden_dim
    assert hidden == (128 if name.endswith("_cpu") else 512)
    assert str(cfg.hydra.mode) == "RunMode.MULTIRUN"


@pytest.mark.slow
@pytest.mark.parametrize("launcher", ["joblib", "submitit_local"])
def test_a_sweep_runs_on_the_launcher(launcher, tmp_path):
    out = subprocess.run(
        [*TRAIN, "+experiment=pointmass2d_curves_cpu", *TINY, "train.steps=1000", "seed=1",
         f"hydra.sweep.dir={tmp_path}", f"hydra/launcher={launcher}"]
        + (["hydra.launcher.timeout_min=10"] if launcher == "submitit_local" else []),
        capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert sorted(p.parent.relative_to(tmp_path).as_posix()
                  for p in tmp_path.rglob("eval.csv")) == ["D8/seed1", "none/seed1"]


def write_run(path: Path, group: str, seed: int, returns: list[float]):
    path.mkdir(parents=True)
    (path / "config.yaml").write_text(f"seed: {seed}\nagent:\n  group: {group}\n")
    lines = ["env_step,episode_reward"] + [f"{1000 * i},{r}" for i, r in enumerate(returns)]
    (path / "eval.csv").write_text("\n".join(lines) + "\n")


def test_plot_handles_unequal_and_unfinished_runs(tmp_path, capsys):
    write_run(tmp_path / "a/1", "none", 1, [0, 100, 500, 900])
    write_run(tmp_path / "a/2", "none", 2, [0, 50, 850])  # still running
    write_run(tmp_path / "b/1", "D8", 1, [0, 900, 950, 960])
    out = tmp_path / "curves.png"
    plot.main([str(tmp_path), "--out", str(out), "--threshold", "800", "--reference", "884:LQR"])
    assert out.stat().st_size > 10_000
    table = capsys.readouterr().out
    assert "| group=none | 2 | 2000/3000 |" in table
    assert ("| group=D8 | 1 | 3000 | 960.0 [960.0, 960.0] | 960.0 | 702.5 [702.5, 702.5] | – "
            "| 1000 |") in table
    assert "3000, 2000 |" in table  # steps to 800, per seed
    plot.main([str(tmp_path), "--threshold", "800", "--threshold", "880"])  # a column each
    table = capsys.readouterr().out
    assert "| env steps to reach 800 (per seed) | env steps to reach 880 (per seed) |" in table
    assert "| 3000, 2000 | 3000, – |" in table and "| 1000 | 1000 |" in table
    runs = results.group_runs(results.find_runs([tmp_path]))
    steps, mean, low, high, n = statistics.curve(runs["group=none"])
    assert list(n) == [2, 2, 2, 1] and low[2] <= mean[2] <= high[2]
    # an option only some runs have splits them, unless ignored
    with (tmp_path / "a/2/config.yaml").open("a") as f:
        f.write("  layers: auto\n")
    found = results.find_runs([tmp_path])
    assert "group=none, layers=auto" in results.group_runs(found)
    assert set(results.group_runs(found, ("agent.layers",))) == {"group=none", "group=D8"}


def test_plot_pairs_runs_by_seed(tmp_path, capsys):
    for seed, (plain, d8) in enumerate([([0, 100, 200], [0, 500, 900]),
                                        ([0, 0, 100], [0, 300, 700]),
                                        ([0, 400, 800], [0, 400, 800])], start=1):
        write_run(tmp_path / f"none/{seed}", "none", seed, plain)
        write_run(tmp_path / f"D8/{seed}", "D8", seed, d8)
    write_run(tmp_path / "D8/4", "D8", 4, [0, 1000, 1000])  # no plain seed 4: not paired
    plot.main([str(tmp_path), "--paired", "group=none"])
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("| group=D8 − group=none"))
    # mean over evaluations: seed 1 +366.7, seed 2 +300.0, seed 3 0
    assert "| 3 | 1: +366.7, 2: +300.0, 3: +0.0 | +222.2 [" in row and "| 2 of 3 |" in row
    p = float(row.split("|")[5])
    assert 0.05 < p < 0.2  # scipy's paired t-test on (366.7, 300, 0)
    with pytest.raises(SystemExit, match="--paired 'group=C4' is not a group"):
        plot.main([str(tmp_path), "--paired", "group=C4"])


def test_plot_pairs_against_several_baselines_each_pair_once(tmp_path, capsys):
    for seed, (plain, d4, d8) in enumerate([([0, 100], [0, 600], [0, 900]),
                                            ([0, 0], [0, 500], [0, 700])], start=1):
        for group, returns in (("none", plain), ("D4", d4), ("D8", d8)):
            write_run(tmp_path / f"{group}/{seed}", group, seed, returns)
    plot.main([str(tmp_path), "--paired", "group=none", "--paired", "group=D4"])
    comparisons = [line.split("|")[1].strip() for line in capsys.readouterr().out.splitlines()
                   if " − " in line]
    assert sorted(comparisons) == ["group=D4 − group=none", "group=D8 − group=D4",
                                   "group=D8 − group=none"]
    # D8 - D4 over evaluations: seed 1 (450 - 300), seed 2 (350 - 250)
    plot.main([str(tmp_path), "--paired", "group=D4"])
    row = next(line for line in capsys.readouterr().out.splitlines()
               if line.startswith("| group=D8 − group=D4"))
    assert "| 2 | 1: +150.0, 2: +100.0 | +125.0 [" in row and "| 2 of 2 |" in row
    # a p-value below 0.001 is written in full, not rounded to 0.000
    for seed, (plain, d8) in enumerate([([0, 0], [0, 700]), ([0, 0], [0, 702]),
                                        ([0, 0], [0, 699]), ([0, 0], [0, 701])], start=1):
        write_run(tmp_path / f"more/none/{seed}", "none", seed, plain)
        write_run(tmp_path / f"more/D8/{seed}", "D8", seed, d8)
    plot.main([str(tmp_path / "more"), "--paired", "group=none"])
    row = next(line for line in capsys.readouterr().out.splitlines() if " − " in line)
    assert 0 < float(row.split("|")[5]) < 0.001 and "e-" in row.split("|")[5]


def test_plot_labels_rename_groups_everywhere(tmp_path, capsys):
    for seed in (1, 2):
        write_run(tmp_path / f"none/{seed}", "none", seed, [0, 100 * seed])
        write_run(tmp_path / f"D8/{seed}", "D8", seed, [0, 900])
    out = tmp_path / "curves.png"
    # --paired may name the group by either name
    for baseline in ("group=none", "plain"):
        plot.main([str(tmp_path), "--label", "group=none:plain", "--label", "group=D8:D8 `linear`",
                   "--paired", baseline, "--runs", "--out", str(out)])
        text = capsys.readouterr().out
        assert "group=" not in text
        assert "| plain | 2 |" in text and "| D8 `linear` − plain | 2 |" in text
        assert "| D8 `linear` | 1 |" in text  # the runs table
    for bad, message in (("group=none", "is not GROUP:NAME"), ("group=C4:x", "is not a group"),
                         ("group=none:group=D8", "already names a group")):
        with pytest.raises(SystemExit, match=message):
            plot.main([str(tmp_path), "--label", bad])


def test_plot_contrasts_margins_of_two_experiments(tmp_path, capsys):
    # D8's margin over plain, mean over evaluations: hard +500, +450, +400; easy +100, +50
    for seed, (hard, easy) in enumerate([(500, 100), (450, 50), (400, None)], start=1):
        for task, margin in (("hard", hard), ("easy", easy)):
            if margin is None:
                continue  # easy has 2 seeds: the margins are compared unpaired
            write_run(tmp_path / f"{task}/none/{seed}", "none", seed, [0, 0])
            write_run(tmp_path / f"{task}/D8/{seed}", "D8", seed, [0, 2 * margin])
            for group in ("none", "D8"):
                with (tmp_path / f"{task}/{group}/{seed}/config.yaml").open("a") as f:
                    f.write(f"env:\n  difficulty: {task}\n")
    labels = [f"--label=group={group}, difficulty={task}:{name} {task}" for task in ("hard", "easy")
              for group, name in (("none", "plain"), ("D8", "D8"))]
    plot.main([str(tmp_path), *labels,
               "--contrast", "D8 hard", "plain hard", "D8 easy", "plain easy"])
    row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("| (D8"))
    cells = [c.strip() for c in row.split("|")[1:-1]]
    assert cells[:3] == ["(D8 hard − plain hard) − (D8 easy − plain easy)", "3, 2",
                         "+450.0 [+400.0, +500.0]"]
    assert cells[3].startswith("+75.0 [") and cells[4].startswith("+375.0 [")
    low, high = (float(x) for x in cells[4].split("[")[1].rstrip("]").split(","))
    assert 300 <= low <= 375 <= high <= 450
    # scipy's Welch test on (500, 450, 400) vs (100, 50)
    welch = stats.ttest_ind([500, 450, 400], [100, 50], equal_var=False).pvalue
    assert cells[5] == statistics.p_value(welch) and 0.001 < welch < 0.05
    assert cells[6].startswith("+750.0 [")  # the final returns' margins are twice as large
    with pytest.raises(SystemExit, match="--contrast 'D8 medium' is not a group"):
        plot.main([str(tmp_path), *labels, "--contrast", "D8 hard", "plain hard", "D8 medium",
                   "plain easy"])
    with pytest.raises(SystemExit, match="at least 2 seeds"):
        plot.main([str(tmp_path / "hard"), str(tmp_path / "easy/D8"),
                   str(tmp_path / "easy/none/1"), *labels, "--contrast", "D8 hard",
                   "plain hard", "D8 easy", "plain easy"])


def test_plot_from_step_leaves_out_earlier_evaluations_everywhere(tmp_path, capsys):
    # plain: a short warm-up; D8: a long one (zeros until 2000), then ahead
    for seed, (plain, d8) in enumerate([([0, 500, 500, 600], [0, 0, 900, 1000]),
                                        ([0, 300, 400, 500], [0, 0, 800, 900])], start=1):
        write_run(tmp_path / f"none/{seed}", "none", seed, plain)
        write_run(tmp_path / f"D8/{seed}", "D8", seed, d8)
    plot.main([str(tmp_path), "--paired", "group=none", "--threshold", "800",
               "--contrast", "group=D8", "group=none", "group=D8", "group=none"])
    everything = capsys.readouterr().out
    # over all evaluations: seed 1 475 − 400 = +75, seed 2 425 − 300 = +125
    assert "| 2 | 1: +75.0, 2: +125.0 | +100.0 [" in everything
    plot.main([str(tmp_path), "--paired", "group=none", "--threshold", "800", "--runs",
               "--contrast", "group=D8", "group=none", "group=D8", "group=none",
               "--from-step", "2000", "--out", str(tmp_path / "late.png")])
    late = capsys.readouterr().out
    # from 2000 on: seed 1 950 − 550 = +400, seed 2 850 − 450 = +400
    assert "| 2 | 1: +400.0, 2: +400.0 | +400.0 [+400.0, +400.0] |" in late
    assert "| group=D8 | 2 | 3000 | 950.0 [900.0, 1000.0] | 950.0 | 900.0 [850.0, 950.0] |" in late
    assert "| 2000, 2000 |" in late  # steps to 800 count from 2000
    for header in ("| mean return over evaluations from env step 2000 on (mean, 95% CI) |",
                   "| per-seed difference, mean return over evaluations from env step 2000 on |",
                   "| first margin, mean return over evaluations from env step 2000 on (95% CI) |"):
        assert header in late and header not in everything
    assert "| group=D8 | 1 | 900 1000 |" in late  # the runs table too
    run = results.find_runs([tmp_path / "D8/1"])[0]
    assert list(run.from_step(1000).steps) == [1000, 2000, 3000]
    assert list(run.from_step(2500).returns) == [1000.0]
    write_run(tmp_path / "D8/3", "D8", 3, [0, 0])  # unfinished: nothing from 2000 on
    with pytest.raises(SystemExit, match=r"--from-step 2000: .*D8/3 has no evaluation at or "
                                         r"after it \(its last is at env step 1000\); --complete"):
        plot.main([str(tmp_path), "--from-step", "2000"])
    plot.main([str(tmp_path), "--from-step", "2000", "--complete", "2000"])
    assert "| group=D8 | 2 |" in capsys.readouterr().out


def test_plot_title_defaults_to_the_folder_the_runs_share(tmp_path):
    runs = [tmp_path / "sweep" / agent / "seed1" for agent in ("plain", "D8")]
    assert plot.default_title(runs) == "sweep"
    assert plot.default_title([tmp_path / "sweep"]) == "sweep"


@pytest.mark.slow
def test_plot_without_runs_is_a_clear_error(tmp_path):
    out = subprocess.run([sys.executable, "-m", "agents.cli.plot", str(tmp_path)],
                         capture_output=True, text=True)
    assert out.returncode != 0 and "no run directories" in out.stderr


def write_train_log(path: Path, q: list[float], lag: list[float], reward: list[float]):
    """A train.csv with one row per episode of 1000 env steps (the first without updates)."""
    path.mkdir(parents=True, exist_ok=True)
    lines = ["env_step,wall_time,q_mean,target_lag,episode_reward",
             f"1000,1.0,,,{reward[0]}"]
    lines += [f"{1000 * (i + 2)},{60.0 * (i + 2)},{qi},{li},{ri}"
              for i, (qi, li, ri) in enumerate(zip(q, lag, reward[1:]))]
    (path / "train.csv").write_text("\n".join(lines) + "\n")


def test_bootstrapped_returns_are_what_q_estimates_along_an_episode():
    assert bootstrapped_returns([1.0, 0.0, 2.0], 0.5, final_value=4.0) == [2.0, 2.0, 4.0]
    assert bootstrapped_returns([1.0, 0.0, 2.0], 0.5) == [1.5, 1.0, 2.0]  # after a termination
    # the TD fixed point of a constant reward is a fixed point of the returns too
    np.testing.assert_allclose(bootstrapped_returns([3.0] * 50, 0.99, 300.0), [300.0] * 50)
    assert bootstrapped_returns([], 0.99, 7.0) == []


def test_value_at_start_says_whether_q_tells_solved_episodes_from_failed_ones():
    check = value_at_start([154.2, 211.6, 132.2, 172.1], [13.5, 370.8, 318.7, 232.3])
    assert check["q_start"] == pytest.approx(167.525)
    assert check["discounted_return"] == pytest.approx(233.825)
    assert check["q_return_corr"] == pytest.approx(
        stats.pearsonr([154.2, 211.6, 132.2, 172.1], [13.5, 370.8, 318.7, 232.3])[0])
    assert value_at_start([2.0, 4.0], [3.0, 5.0])["q_return_corr"] == pytest.approx(1.0)
    for values, returns in (([5.0], [7.0]), ([1.0, 1.0], [2.0, 3.0]), ([1.0, 2.0], [0.0, 0.0])):
        check = value_at_start(values, returns)  # one episode, or a Q or a return that does not vary
        assert np.isnan(check["q_return_corr"]) and np.isfinite(check["q_start"])
    for values, returns in (([], []), ([1.0], [1.0, 2.0])):
        with pytest.raises(ValueError, match="one value per episode"):
            value_at_start(values, returns)


def test_td_invariants_name_each_way_value_learning_breaks(tmp_path):
    n = 20
    # the lag spikes after initialisation and when the reward is first found, then settles
    healthy = dict(q=list(np.linspace(0.1, 200, n)), lag=[0.3] + [0.02] * 12 + [0.24] + [0.02] * 6,
                   reward=[0.0] * 5 + [500.0] * (n - 4))
    broken = {
        "frozen": {**healthy, "lag": list(np.linspace(0.02, 0.9, n))},  # the target never moves
        "copy": {**healthy, "lag": [0.0] * n},  # the target is the online network
        "sign": {**healthy, "q": list(np.linspace(0, -50, n))},  # rewards positive, Q negative
        "drift": {**healthy, "reward": [0.0] * (n + 1)},  # no reward, Q grows anyway
        "nan": {**healthy, "q": [*healthy["q"][:-1], float("nan")]},
        "nan_lag": {**healthy, "lag": [*healthy["lag"][:-1], float("nan")]},
        "nan_reward": {**healthy, "reward": [*healthy["reward"][:-1], float("nan")]},
    }
    expected = {"frozen": "does not track", "copy": "target_lag is 0", "sign": "not of the sign",
                "drift": "with no reward seen", "nan": "Q is not finite",
                "nan_lag": "target_lag is not finite", "nan_reward": "reward is not finite"}
    write_train_log(tmp_path / "healthy", **healthy)
    td = td_invariants(tmp_path / "healthy/train.csv")
    assert td.failures == () and (td.target_lag_high, td.target_lag_end) == (0.24, 0.02)
    assert td.q_end == 200 and td.q_half == healthy["q"][8]  # at 10k of 21k env steps
    for name, log in broken.items():
        write_train_log(tmp_path / name, **log)
        failures = td_invariants(tmp_path / name / "train.csv").failures
        assert len(failures) == 1 and expected[name] in failures[0], (name, failures)
    # a cost task (negative rewards) learns negative values; no reward and Q ~ 0 is healthy
    write_train_log(tmp_path / "cost", q=list(np.linspace(0, -12, n)), lag=[0.02] * n,
                    reward=[-40.0] * (n + 1))
    write_train_log(tmp_path / "unlucky", q=[0.02] * n, lag=[0.02] * n, reward=[0.0] * (n + 1))
    # rewards of both signs that cancel out were still seen
    write_train_log(tmp_path / "mixed", q=[0.02] * (n - 1) + [3.0], lag=[0.02] * n,
                    reward=[50.0, -50.0] * (n // 2) + [0.0])
    # too short a run to judge the lag: its only update is the start-of-training spike
    write_train_log(tmp_path / "short", q=[0.0], lag=[0.4], reward=[0.0, 0.0])
    for name in ("cost", "unlucky", "mixed", "short"):
        assert td_invariants(tmp_path / name / "train.csv").failures == (), name
    assert "target_lag not judged" in td_invariants(tmp_path / "short/train.csv").notes[0]
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty/train.csv").write_text("env_step,q_mean\n1000,\n")
    with pytest.raises(ValueError, match="empty/train.csv: no row with an update"):
        td_invariants(tmp_path / "empty/train.csv")


def test_plot_lists_runs_with_their_td_invariants(tmp_path, capsys):
    write_run(tmp_path / "D8/1", "D8", 1, [0, 900, 950])
    write_train_log(tmp_path / "D8/1", q=[1.0, 50.0, 100.0, 150.0], lag=[0.02] * 4,
                    reward=[0, 10, 20, 30, 40])
    write_run(tmp_path / "none/1", "none", 1, [0, 5.5, 7])
    write_train_log(tmp_path / "none/1", q=[1.0, 2.0, 3.0, 4.0], lag=[0.5] * 4,
                    reward=[0, 10, 20, 30, 40])
    # the value check of the last evaluation (eval.csv from 2026-12-06 on); the earlier row's is not shown
    (tmp_path / "D8/1/eval.csv").write_text(
        "env_step,episode_reward,q_start,discounted_return,q_return_corr\n0,0,0.0,1.5,nan\n"
        "1000,900,1.0,2.0,0.5\n2000,950,255.7,368.04,-0.1234\n")
    write_run(tmp_path / "none/2", "none", 2, [0, 0, 0])  # no train.csv (e.g. copied evals only)
    write_run(tmp_path / "none/10", "none", 10, [0, 0, 0])  # a log from before q_mean was logged
    (tmp_path / "none/10/train.csv").write_text("env_step,wall_time,episode_reward\n1000,1.0,0\n")
    plot.main([str(tmp_path), "--runs"])
    out = capsys.readouterr().out
    lines = out[out.index("| group | seed | evaluation returns"):].splitlines()[2:]
    rows = {tuple(cell.strip() for cell in line.split("|")[1:3]): line for line in lines}
    assert list(rows) == [("group=D8", "1"), ("group=none", "1"), ("group=none", "2"),
                          ("group=none", "10")]  # seeds in numeric order
    assert rows["group=D8", "1"].endswith(
        "| 0 900 950 | 5 | 1 → 150 | 0.020–0.020 (0.020) | hold | 256 vs 368 (-0.12) |")
    assert "| 0 5.5 7.0 | 5 |" in rows["group=none", "1"]
    assert "FAIL: target_lag ends at 0.500" in rows["group=none", "1"]
    assert rows["group=none", "1"].endswith(" | – |")  # an eval.csv from before the value check
    assert rows["group=none", "2"].endswith("| – | – | – | no train.csv | – |")
    assert rows["group=none", "10"].endswith(
        "| – | – | no update logged (q_mean, target_lag): not judged | – |")


def test_evaluation_share_is_the_wall_time_not_spent_training(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    # 1000 env steps at 100/s (10 s) and 1000 at 50/s (20 s): 30 s of training
    (run / "train.csv").write_text("env_step,wall_time,steps_per_second\n"
                                   "1000,10.0,100\n2000,30.0,50\n")
    (run / "eval.csv").write_text("env_step,wall_time,episode_reward\n0,0.0,0\n2000,60.0,5\n")
    assert wall_minutes(run) == 1.0 and evaluation_share(run) == pytest.approx(0.5)
    write_run(tmp_path / "plot/D8/1", "D8", 1, [0, 5])
    for name in ("train.csv", "eval.csv"):
        (tmp_path / "plot/D8/1" / name).write_text((run / name).read_text())
    plot.main([str(tmp_path / "plot"), "--runs"])
    assert "| 0 5.0 | 1 (50%) |" in capsys.readouterr().out
    (run / "train.csv").write_text("env_step,wall_time\n1000,10.0\n")  # a log from before
    assert evaluation_share(run) is None and evaluation_share(tmp_path / "missing") is None


def test_training_episodes_start_where_the_previous_one_ended(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "train.csv").write_text("env_step,q_mean,episode_reward\n250,,0.5\n"
                                   "500,0.1,12.0\n1250.0,0.2,900\n")
    assert training_episodes(run) == [TrainingEpisode(0, 250, 0.5), TrainingEpisode(250, 500, 12.0),
                                      TrainingEpisode(500, 1250, 900.0)]
    with pytest.raises(FileNotFoundError, match="train.csv: no such file"):
        training_episodes(tmp_path)


def test_plot_shows_published_per_seed_results_up_to_the_longest_run(tmp_path, capsys):
    write_run(tmp_path / "a/1", "none", 1, [0, 100, 500, 900])
    published = tmp_path / "published.csv"
    published.write_text("algorithm,task,seed,env_step,episode_reward\n"
                         "tdmpc,hard,2,0,20.7\ntdmpc,hard,1,0,7.4\ntdmpc,hard,1,2000,975.1\n"
                         "tdmpc,hard,2,2000,675.1\ntdmpc,hard,1,9000,970.0\n"
                         "tdmpc2,hard,1,2000,507.3\n")
    out = tmp_path / "curves.png"
    plot.main([str(tmp_path / "a"), "--out", str(out), "--published", f"{published}:tdmpc:hard"])
    assert out.stat().st_size > 10_000
    table = capsys.readouterr().out
    assert "| tdmpc, hard | 0 | 7.4 (seed 1), 20.7 (seed 2) | 14.1 |" in table
    assert "| tdmpc, hard | 2000 | 975.1 (seed 1), 675.1 (seed 2) | 825.1 |" in table
    assert "9000" not in table  # beyond the runs' 3000 steps
    assert "final return − published" not in table  # one seed: nothing to test
    write_run(tmp_path / "a/2", "none", 2, [0, 100, 300, 700])
    write_run(tmp_path / "a/3", "none", 3, [0, 100, 300])  # ends at 2000, as the series
    (tmp_path / "a/3/config.yaml").write_text("seed: 3\nagent:\n  group: D8\n")
    write_run(tmp_path / "a/4", "none", 4, [0, 100, 500])
    (tmp_path / "a/4/config.yaml").write_text("seed: 4\nagent:\n  group: D8\n")
    plot.main([str(tmp_path / "a"), "--published", f"{published}:tdmpc:hard",
               "--published", f"{published}:tdmpc2:hard"])
    rows = [line for line in capsys.readouterr().out.splitlines() if " − tdmpc" in line]
    # plain's seeds end at 3000 (no published point there); D8's at 2000: 300, 500 against
    # 975.1, 675.1 (tdmpc2 has one seed at 2000: not tested)
    assert len(rows) == 1 and rows[0].startswith("| group=D8 − tdmpc (hard) | 2, 2 | 2000 | -425.1 [")
    welch = stats.ttest_ind([300, 500], [975.1, 675.1], equal_var=False).pvalue
    assert rows[0].endswith(f"| {statistics.p_value(welch)} |")
    for spec, message in [(f"{published}:tdmpc", "is not PATH:ALGORITHM:TASK"),
                          (f"{published}:tdmpc:easy", "valid: tdmpc2:hard, tdmpc:hard"),
                          (f"{tmp_path}/none.csv:tdmpc:hard", "cannot read")]:
        with pytest.raises(SystemExit, match=message):
            plot.main([str(tmp_path / "a"), "--published", spec])


def test_plot_spread_measures_how_much_each_agent_depends_on_an_option(tmp_path, capsys):
    # returns per seed at seed_steps 1000 (and 6000, the same) and 20000
    runs = {"none": {1: ([0, 800], [0, 200]), 2: ([0, 600], [0, 400]), 3: ([0, 1000], [0, 0])},
            "icosahedral": {1: ([0, 900], [0, 800]), 2: ([0, 900], [0, 900]),
                            3: ([0, 1000], [0, 700])}}
    for group, seeds in runs.items():
        for seed, (short, long) in seeds.items():
            for level, returns in ((1000, short), (6000, short), (20000, long)):
                write_run(tmp_path / f"{group}/{level}/{seed}", group, seed, returns)
                with (tmp_path / f"{group}/{level}/{seed}/config.yaml").open("a") as f:
                    f.write(f"train:\n  seed_steps: {level}\n")
    write_run(tmp_path / "icosahedral/1000/4", "icosahedral", 4, [0, 0])  # no other level
    write_run(tmp_path / "octahedral/1000/1", "octahedral", 1, [0, 0])
    for path in ("icosahedral/1000/4", "octahedral/1000/1"):
        with (tmp_path / path / "config.yaml").open("a") as f:
            f.write("train:\n  seed_steps: 1000\n")
    out = tmp_path / "curves.png"
    plot.main([str(tmp_path), "--spread", "train.seed_steps", "--label", "group=none:plain",
               "--out", str(out)])
    text = capsys.readouterr().out
    assert (tmp_path / "curves_spread.png").stat().st_size > 10_000
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]]
            for line in text.splitlines() if line.startswith("| ")}
    # plain's ranges of the mean over evaluations: 400 − 100, 300 − 200, 500 − 0
    assert rows["plain"][:4] == ["3", "1000: 400.0, 6000: 400.0, 20000: 100.0",
                                 "1: 300.0, 2: 100.0, 3: 500.0", rows["plain"][3]]
    assert rows["plain"][3].startswith("300.0 [") and rows["plain"][5].startswith("600.0 [")
    assert rows["plain"][4] == "1000: 800.0, 6000: 800.0, 20000: 200.0"
    assert rows["group=icosahedral"][:3] == ["3", "1000: 466.7, 6000: 466.7, 20000: 400.0",
                                             "1: 50.0, 2: 0.0, 3: 150.0"]  # seed 4: one level
    assert rows["group=octahedral"][0] == "0 (runs per seed_steps: 1000: 1, 6000: 0, 20000: 0)"
    comparison = rows["group=icosahedral − plain"]
    assert comparison[:2] == ["3", "1: -250.0, 2: -100.0, 3: -350.0"]
    assert comparison[2].startswith("-233.3 [") and comparison[4] == "3 of 3"
    assert comparison[3] == statistics.p_value(stats.ttest_1samp([-250, -100, -350], 0).pvalue)
    assert not any("octahedral −" in line or "− group=octahedral" in line for line in rows)
    with pytest.raises(SystemExit, match=r"--spread 'train.steps' is not an option whose value "
                                         r"differs between these runs; those that do: agent.group, "
                                         r"train.seed_steps"):
        plot.main([str(tmp_path), "--spread", "train.steps"])
    spread = statistics.spread_over(results.find_runs([tmp_path / "none"]), "train.seed_steps")
    assert spread.levels == ["1000", "6000", "20000"] and spread.seeds == [1, 2, 3]


def test_plot_panels_draw_one_axes_per_value_with_the_same_groups(tmp_path, capsys):
    for n_balls, groups in ((2, ("none", "icosahedral")), (3, ("none",))):
        for group in groups:
            for seed in (1, 2):
                path = tmp_path / f"n{n_balls}/{group}/{seed}"
                write_run(path, group, seed, [0, 100 * n_balls + seed])
                with (path / "config.yaml").open("a") as f:
                    f.write(f"env:\n  n_balls: {n_balls}\n")
    runs = results.find_runs([tmp_path])
    panels = plot.panel_groups(runs, "env.n_balls", ())
    assert {panel: {label: sorted(r.options["seed"] for r in rs) for label, rs in groups.items()}
            for panel, groups in panels.items()} == {
        "n_balls=2": {"group=icosahedral": [1, 2], "group=none": [1, 2]},
        "n_balls=3": {"group=none": [1, 2]}}
    out = tmp_path / "panels.png"
    plot.main([str(tmp_path), "--panels", "env.n_balls", "--label", "group=none:plain",
               "--out", str(out)])
    width = int.from_bytes(out.read_bytes()[16:20], "big")  # the PNG header's width
    assert width == int(2 * 4.4 * 120)  # two panels side by side
    table = capsys.readouterr().out  # the table keeps one row per group
    assert "| group=none, n_balls=2 | 2 |" in table and "| group=none, n_balls=3 | 2 |" in table
    with pytest.raises(SystemExit, match="--panels 'env.target_size' is not an option whose value "
                                         "differs between these runs; those that do: agent.group, "
                                         "env.n_balls"):
        plot.main([str(tmp_path), "--panels", "env.target_size", "--out", str(out)])
