"""``geomdp-plot``: reward curves with 95% bootstrap confidence intervals, and a table.

    geomdp-plot results/experiments/pointmass2d_curves_cpu --out assets/pointmass2d_curves_cpu.png \\
        --threshold 800 --reference 884:LQR

Finds every run directory (one with ``eval.csv`` and ``config.yaml``) under the
given paths, groups runs by the options in which they differ (all but the
seed), and draws, per group, the mean evaluation return over seeds with a 95%
bootstrap confidence interval (``scipy.stats.bootstrap``). Runs of unequal
length, or still in progress, are fine: at each evaluation step, the seeds
that have reached it are used. Prints a markdown table of final returns (mean
with 95% CI, IQM), of each seed's mean return over its evaluations (the area
under its curve: sample efficiency; compare runs of equal length) and of the
environment steps each seed took to reach each ``--threshold``; with ``--paired GROUP``,
every group against that one seed by seed (differences, bootstrap CI, paired t-test;
repeat it to compare against several groups, each pair once); with ``--contrast A B C D``,
whether A's margin over B is larger than C's over D (e.g. the same agents on two tasks);
with ``--published``, another project's per-seed results as markers, a table, and each
group's final returns against them (Welch); with ``--runs``, one row per run: its
evaluations, wall time and the invariants of a working TD learner
(``agents.run.td_invariants``), failures named. ``--from-step STEP``
keeps only the evaluations from STEP on, everywhere (e.g. agents whose warm-ups differ,
compared after the longest one). ``--spread OPTION`` asks how much each agent's returns move
across the values of one option (e.g. ``train.seed_steps``: is an agent robust to its
warm-up?): per seed, the range across the values, and the agents' ranges paired by seed.
``--panels OPTION`` draws one panel per value of an option (e.g. ``env.n_balls``).

Runs are found and grouped by ``agents.run.results`` and their statistics computed by
``agents.run.statistics``; this module is the command line, the tables and the figure.
"""

from __future__ import annotations

import argparse
import itertools
import os
from pathlib import Path

import numpy as np
from scipy import stats

from agents.run.results import (
    Published,
    Run,
    find_runs,
    group_runs,
    read_published,
    seed_order,
    varying_options,
)
from agents.run.run_tables import evaluation_share, last_value_check, wall_minutes
from agents.run.statistics import (
    Spread,
    curve,
    differences,
    level_order,
    mean_ci,
    mean_ci_of_difference,
    paired_p,
    seed_pairs,
    spread_over,
    steps_to_threshold,
    welch_p,
)
from agents.run.td_invariants import td_invariants


def signed(mean_low_high: tuple[float, float, float]) -> str:
    """A difference with its CI, as the paired tables print it: ``+12.3 [-4.5, +20.1]``."""
    return "{:+.1f} [{:+.1f}, {:+.1f}]".format(*mean_low_high)


def seeds_text(count: int) -> str:
    return f"{count} seed" if count == 1 else f"{count} seeds"


def require_groups(option: str, names: list[str], groups: dict[str, list[Run]]) -> None:
    """A one-line error for an option naming a group that is not in the table."""
    unknown = [n for n in names if n not in groups]
    if unknown:
        raise SystemExit(f"geomdp-plot: error: {option} {unknown[0]!r} is not a group; groups: "
                         f"{', '.join(groups)}")


ALL_EVALUATIONS = "all evaluations"


def table(groups: dict[str, list[Run]], thresholds: list[float],
          evaluations: str = ALL_EVALUATIONS) -> str:
    header = ("| runs | seeds | env steps | final return (mean, 95% CI) | IQM "
              f"| mean return over {evaluations} (mean, 95% CI) "
              "| final return with training noise (mean, 95% CI) |")
    sep = "|---|---|---|---|---|---|---|"
    for threshold in thresholds:
        header += f" env steps to reach {threshold:g} (per seed) |"
        sep += "---|"
    rows = [header, sep]
    for label, runs in groups.items():
        finals = np.array([r.returns[-1] for r in runs])
        mean, low, high = mean_ci(finals)
        iqm = stats.trim_mean(finals, 0.25)
        steps = sorted({int(r.steps[-1]) for r in runs})
        noisy = np.array([r.noisy_returns[-1] for r in runs])
        noisy_cell = ("–" if np.isnan(noisy).any() else
                      "{:.1f} [{:.1f}, {:.1f}]".format(*mean_ci(noisy)))
        # The area under the curve per seed, divided by its length: sample efficiency.
        area_cell = "{:.1f} [{:.1f}, {:.1f}]".format(
            *mean_ci(np.array([r.returns.mean() for r in runs])))
        row = (f"| {label} | {len(runs)} | {'/'.join(map(str, steps))} | "
               f"{mean:.1f} [{low:.1f}, {high:.1f}] | {iqm:.1f} | {area_cell} | {noisy_cell} |")
        for threshold in thresholds:
            reached = [steps_to_threshold(r, threshold) for r in runs]
            row += " " + ", ".join("–" if s is None else str(s) for s in reached) + " |"
        rows.append(row)
    return "\n".join(rows)


def paired_table(groups: dict[str, list[Run]], baselines: list[str],
                 evaluations: str = ALL_EVALUATIONS) -> str:
    """Every group against each of ``baselines``, seed by seed (runs of the same seed
    pair): the per-seed differences of the mean return over all evaluations (the area
    under the curve) and of the final return, their mean with a 95% bootstrap CI, a
    paired t-test and on how many seeds the group did better. Only seeds both groups have
    count; a pair already compared (the other way round) is not repeated."""
    require_groups("--paired", baselines, groups)
    rows = [f"| comparison | seeds | per-seed difference, mean return over {evaluations} "
            "| mean difference (95% CI) | paired t-test p | better on | final return: mean "
            "difference (95% CI), p |", "|---|---|---|---|---|---|---|"]
    compared: set[frozenset[str]] = set()
    for baseline in baselines:
        for label, runs in groups.items():
            if label == baseline or frozenset((label, baseline)) in compared:
                continue
            compared.add(frozenset((label, baseline)))
            pairs = seed_pairs(runs, groups[baseline])
            if pairs:
                rows.append(paired_row(f"{label} − {baseline}", pairs))
    return "\n".join(rows)


def paired_row(comparison: str, pairs: list[tuple[object, Run, Run]]) -> str:
    """One row of ``paired_table``: ``pairs`` are (seed, run, baseline run)."""
    area, final = differences(pairs)
    per_seed = ", ".join(f"{seed}: {d:+.1f}" for (seed, _, _), d in zip(pairs, area))
    return (f"| {comparison} | {len(pairs)} | {per_seed} | {signed(mean_ci(area))} | "
            f"{paired_p(area)} | {int((area > 0).sum())} of {len(pairs)} | "
            f"{signed(mean_ci(final))}, {paired_p(final)} |")


def contrast_table(groups: dict[str, list[Run]], contrasts: list[list[str]],
                   evaluations: str = ALL_EVALUATIONS) -> str:
    """``--contrast A B C D``: is A's margin over B larger than C's over D? E.g. D8 over
    plain on Reacher hard against D8 over plain on easy. Each margin is paired by seed
    within its own pair of groups; the two sets of per-seed margins come from different
    experiments, so they are compared unpaired: the difference of their means with a 95%
    bootstrap CI and Welch's t-test."""
    rows = [f"| contrast | seeds | first margin, mean return over {evaluations} (95% CI) "
            "| second margin (95% CI) | first − second (95% CI) | Welch t-test p "
            "| final return: first − second (95% CI), p |", "|---|---|---|---|---|---|---|"]
    for names in contrasts:
        require_groups("--contrast", names, groups)
        first, second = (seed_pairs(groups[a], groups[b]) for a, b in (names[:2], names[2:]))
        if len(first) < 2 or len(second) < 2:
            raise SystemExit(f"geomdp-plot: error: --contrast {' '.join(map(repr, names))}: "
                             "each margin needs at least 2 seeds that both of its groups have")
        (area_1, final_1), (area_2, final_2) = differences(first), differences(second)
        cells = [f"({names[0]} − {names[1]}) − ({names[2]} − {names[3]})",
                 f"{len(first)}, {len(second)}",
                 signed(mean_ci(area_1)), signed(mean_ci(area_2)),
                 signed(mean_ci_of_difference(area_1, area_2)), welch_p(area_1, area_2),
                 f"{signed(mean_ci_of_difference(final_1, final_2))}, {welch_p(final_1, final_2)}"]
        rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows)


def runs_table(groups: dict[str, list[Run]]) -> str:
    """One row per run: evaluation returns, wall time (and the share of it spent
    evaluating), Q half-way and at the end, the target network's lag late in training,
    which TD invariants fail, and at the last evaluation Q at the episodes' first states
    against the discounted returns earned from them, with their correlation (logs from
    2026-12-06 on)."""
    rows = ["| group | seed | evaluation returns | wall time (min; evaluation share) | Q half-way → end "
            "| target_lag, second half (end) | TD invariants | last evaluation: Q(s₀) vs "
            "discounted return (correlation) |", "|---|---|---|---|---|---|---|---|"]
    for label, runs in groups.items():
        for run in sorted(runs, key=lambda r: seed_order(r.options.get("seed"))):
            returns = " ".join(f"{r:.0f}" if abs(r) >= 10 or r == 0 else f"{r:.1f}" for r in run.returns)
            minutes, share = wall_minutes(run.path), evaluation_share(run.path)
            wall = "–" if minutes is None else f"{minutes:.0f}"
            if share is not None:
                wall += f" ({100 * share:.0f}%)"
            try:
                td = td_invariants(run.path / "train.csv")
                verdict = f"FAIL: {'; '.join(td.failures)}" if td.failures else "hold"
                cells = (f"{td.q_half:.3g} → {td.q_end:.3g} | {td.target_lag_low:.3f}–"
                         f"{td.target_lag_high:.3f} ({td.target_lag_end:.3f}) | "
                         f"{'; '.join((verdict, *td.notes))}")
            except FileNotFoundError:
                cells = "– | – | no train.csv"
            except ValueError:
                cells = "– | – | no update logged (q_mean, target_lag): not judged"
            check = last_value_check(run.path)
            value = ("–" if check is None else f"{check['q_start']:.3g} vs "
                     f"{check['discounted_return']:.3g} ({check['q_return_corr']:.2f})")
            rows.append(f"| {label} | {run.options.get('seed')} | {returns} | {wall} | {cells} "
                        f"| {value} |")
    return "\n".join(rows)


def published_table(published: list[Published], last_step: float) -> str:
    """``--published``: the other project's per-seed returns at its evaluation steps up
    to ``last_step`` (the longest run here), so that a reader compares like with like."""
    rows = ["| published | env steps | per seed | mean |", "|---|---|---|---|"]
    for series in published:
        for step, points in series.until(last_step).items():
            per_seed = ", ".join(f"{value:.1f} (seed {seed})" for seed, value in points)
            mean = sum(v for _, v in points) / len(points)
            rows.append(f"| {series.algorithm}, {series.task} | {step} | {per_seed} | {mean:.1f} |")
    return "\n".join(rows)


def published_comparison_table(groups: dict[str, list[Run]], published: list[Published]) -> str:
    """Each group's final returns against each published series at the group's last
    evaluation step (where the series has one): the difference of the means with a 95%
    bootstrap CI and Welch's t-test. Unpaired: the other project's seeds are not ours, and
    its runs were made with other code on other machines; a published series has few seeds
    (TD-MPC's: 3), so read the p-value before the CI."""
    rows = ["| final return − published | seeds (ours, published) | env steps | mean difference "
            "(95% CI) | Welch t-test p |", "|---|---|---|---|---|"]
    for label, runs in groups.items():
        last = {int(r.steps[-1]) for r in runs}
        if len(runs) < 2 or len(last) > 1:
            continue  # one seed, or runs that end at different steps: nothing to test
        step = last.pop()
        finals = np.array([r.returns[-1] for r in runs])
        for series in published:
            theirs = np.array([value for _, value in series.points.get(step, [])])
            if len(theirs) < 2:
                continue
            rows.append(f"| {label} − {series.algorithm} ({series.task}) | {len(finals)}, "
                        f"{len(theirs)} | {step} | {signed(mean_ci_of_difference(finals, theirs))} | "
                        f"{welch_p(finals, theirs)} |")
    return "\n".join(rows) if len(rows) > 2 else ""


def spread_tables(agents: dict[str, Spread], option: str,
                  evaluations: str = ALL_EVALUATIONS) -> str:
    """``--spread OPTION``: per agent (the runs' options but OPTION and the seed), the mean
    return over evaluations and the final return at each value of OPTION, and per seed
    their range across the values (max − min: how much that seed's result depends on
    OPTION), with a 95% bootstrap CI over seeds; then every two agents' ranges paired by
    seed: the difference, its CI, a paired t-test and on how many seeds the first agent's
    range is the smaller (the more robust one)."""
    name = option.split(".")[-1]
    rows = [f"| agent | seeds with every {name} | mean return over {evaluations} per {name} "
            "(mean over seeds) | per-seed range across them | range (mean, 95% CI) "
            f"| final return per {name} (mean over seeds) | final return: range (mean, 95% CI) |",
            "|---|---|---|---|---|---|---|"]
    for label, spread in agents.items():
        if not spread.seeds:
            counts = ", ".join(f"{level}: {n}" for level, n in spread.runs_per_level.items())
            rows.append(f"| {label} | 0 (runs per {name}: {counts}) "
                        "| – | – | – | – | – |")
            continue
        area_range, final_range = spread.ranges()
        per_level = ", ".join(f"{level}: {value:.1f}"
                              for level, value in zip(spread.levels, spread.area.mean(axis=0)))
        finals = ", ".join(f"{level}: {value:.1f}"
                           for level, value in zip(spread.levels, spread.final.mean(axis=0)))
        per_seed = ", ".join(f"{seed}: {r:.1f}" for seed, r in zip(spread.seeds, area_range))
        rows.append(f"| {label} | {len(spread.seeds)} | {per_level} | {per_seed} | "
                    "{:.1f} [{:.1f}, {:.1f}] | ".format(*mean_ci(area_range)) + finals +
                    " | {:.1f} [{:.1f}, {:.1f}] |".format(*mean_ci(final_range)))
    rows += ["", "| comparison of ranges | seeds | per-seed difference of ranges, mean return over "
             f"{evaluations} | mean difference (95% CI) | paired t-test p | smaller range on "
             "| final return: range difference (95% CI), p |", "|---|---|---|---|---|---|---|"]
    for (label, spread), (baseline, base) in itertools.combinations(agents.items(), 2):
        seeds = [s for s in spread.seeds if s in base.seeds]
        if not seeds:
            continue
        ranges = [dict(zip(x.seeds, zip(*x.ranges()))) for x in (spread, base)]
        area, final = (np.array([ranges[0][s][i] - ranges[1][s][i] for s in seeds])
                       for i in (0, 1))
        per_seed = ", ".join(f"{seed}: {d:+.1f}" for seed, d in zip(seeds, area))
        rows.append(f"| {label} − {baseline} | {len(seeds)} | {per_seed} | "
                    f"{signed(mean_ci(area))} | {paired_p(area)} | {int((area < 0).sum())} of "
                    f"{len(seeds)} | {signed(mean_ci(final))}, {paired_p(final)} |")
    return "\n".join(rows)


def spread_plot(agents: dict[str, Spread], option: str, out: Path, title: str,
                evaluations: str = ALL_EVALUATIONS) -> None:
    """``--spread`` with ``--out``: each agent's mean return over evaluations against the
    values of OPTION (evenly spaced, in order), the mean over seeds with its 95% CI and one
    thin line per seed."""
    levels = sorted({level for s in agents.values() for level in s.levels}, key=level_order)
    fig, (ax,) = new_figure()
    for label, spread in agents.items():
        if not spread.seeds:
            continue
        x = np.array([levels.index(level) for level in spread.levels])
        cis = np.array([mean_ci(column) for column in spread.area.T])
        line = ax.errorbar(x, cis[:, 0], yerr=np.stack([cis[:, 0] - cis[:, 1], cis[:, 2] - cis[:, 0]]),
                           marker="o", capsize=4, label=f"{label} ({seeds_text(len(spread.seeds))})")
        for per_seed in spread.area:
            ax.plot(x, per_seed, color=line[0].get_color(), alpha=0.3, linewidth=1)
    ax.set_xticks(range(len(levels)), [str(level) for level in levels])
    ax.set_xlabel(option)
    ax.set_ylabel(f"mean return over {evaluations}")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, out)


PUBLISHED_MARKERS = ("D", "^", "s", "v", "P")


def new_figure(panels: int = 1) -> tuple[object, list[object]]:
    """A figure of ``panels`` axes side by side (sharing the y axis), drawn off-screen."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, panels, figsize=(6.4 if panels == 1 else 4.4 * panels, 4.2),
                             dpi=120, sharey=True, squeeze=False)
    return fig, list(axes[0])


def save_figure(fig: object, out: Path) -> None:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)


def plot(panels: dict[str, dict[str, list[Run]]], out: Path, title: str,
         references: list[tuple[float, str]], published: list[Published] = (),
         last_step: float | None = None) -> None:
    """The curves with their 95% CIs, one axes per panel (``{"": groups}`` for one; with
    ``--panels OPTION``, one per value of OPTION, each group in the same colour in every
    panel); ``published`` results are drawn up to ``last_step`` (default: the longest run)."""
    fig, axes = new_figure(len(panels))
    if last_step is None:
        last_step = max(run.steps[-1] for groups in panels.values() for runs in groups.values()
                        for run in runs)
    colours: dict[str, str] = {}
    for ax, (panel, groups) in zip(axes, panels.items()):
        for label, runs in groups.items():
            colour = colours.setdefault(label, f"C{len(colours) % 10}")
            steps, mean, low, high, n = curve(runs)
            ax.plot(steps, mean, color=colour, label=f"{label} ({seeds_text(len(runs))})")
            ax.fill_between(steps, low, high, color=colour, alpha=0.2, linewidth=0)
        for value, name in references:
            ax.axhline(value, color="black", linestyle="--", linewidth=1, label=name)
        for series, marker in zip(published, itertools.cycle(PUBLISHED_MARKERS)):
            points = [(step, value) for step, values in series.until(last_step).items()
                      for _, value in values]
            if points:
                seeds = len(next(iter(series.points.values())))
                ax.scatter(*zip(*points), marker=marker, color="black", facecolors="none",
                           zorder=3, label=f"{series.algorithm}, published ({seeds} seeds, "
                                           "one marker each)")
        ax.set_xlabel("environment steps")
        ax.set_title(panel or title)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8 if len(panels) == 1 else 7)
    axes[0].set_ylabel("evaluation return")
    if len(panels) > 1:
        fig.suptitle(title)
    save_figure(fig, out)


def rename_groups(labels: list[str], *tables: dict[str, object]) -> dict[str, str]:
    """Apply ``--label GROUP:NAME`` (a table's label to the name a reader should see, e.g.
    ``group=none:plain``) to each of ``tables`` (the groups; with ``--spread``, its agents)
    in place, wherever the label is one of its keys; returns the renaming, so that options
    naming a group (``--paired``) accept either name."""
    renamed: dict[str, str] = {}
    for spec in labels:
        old, sep, new = spec.partition(":")
        if not sep or not new:
            raise SystemExit(f"geomdp-plot: error: --label {spec!r} is not GROUP:NAME "
                             "(e.g. 'group=none:plain')")
        if not any(old in table for table in tables):
            require_groups("--label", [old], dict.fromkeys(k for t in tables for k in t))
        if any(new in table for table in tables) or new in renamed.values():
            raise SystemExit(f"geomdp-plot: error: --label {spec!r}: {new!r} already names a group")
        renamed[old] = new
    for table in tables:
        for old in list(table):  # rebuilt in order, so that the table keeps the groups' order
            table[renamed.get(old, old)] = table.pop(old)
    return renamed


def values_of(flag: str, option: str, runs: list[Run]) -> list[str]:
    """The values ``option`` takes in ``runs``, in order; a one-line error naming the options
    that do vary if it does not."""
    varying = [k for k in varying_options(runs) if k != "seed"]
    if option not in varying:
        raise SystemExit(f"geomdp-plot: error: {flag} {option!r} is not an option whose value "
                         f"differs between these runs; those that do: {', '.join(varying) or 'none'}")
    return sorted({str(r.options.get(option)) for r in runs}, key=level_order)


def spread_agents(runs: list[Run], option: str, ignored: tuple[str, ...]) -> dict[str, Spread]:
    """``--spread OPTION``: the runs grouped by their other options (one group per agent),
    each as a ``Spread`` over OPTION's values."""
    levels = values_of("--spread", option, runs)
    return {label: spread_over(agent_runs, option, levels)
            for label, agent_runs in group_runs(runs, (*ignored, option)).items()}


def panel_groups(runs: list[Run], option: str,
                 ignored: tuple[str, ...]) -> dict[str, dict[str, list[Run]]]:
    """``--panels OPTION``: one panel per value of OPTION (``n_balls=2``), holding the runs
    grouped by their other options, labelled alike in every panel."""
    name = option.split(".")[-1]
    agents = group_runs(runs, (*ignored, option))
    panels = {}
    for value in values_of("--panels", option, runs):
        in_panel = {label: [r for r in agent_runs if str(r.options.get(option)) == value]
                    for label, agent_runs in agents.items()}
        panels[f"{name}={value}"] = {label: rs for label, rs in in_panel.items() if rs}
    return panels


def default_title(paths: list[Path]) -> str:
    """The name of the folder the runs share (``pointmass2d_cpu`` for
    ``results/pointmass2d_cpu/{plain,D8}/seed1``), not the first path's name, which for
    run directories is just ``seed1``."""
    return Path(os.path.commonpath([p.resolve() for p in paths])).name


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", type=Path, help="directories holding run directories")
    parser.add_argument("--out", type=Path, help="PNG to write")
    parser.add_argument("--title", default=None)
    parser.add_argument("--threshold", type=float, action="append", default=[],
                        help="report env steps to reach this return (repeatable: a column each)")
    parser.add_argument("--reference", action="append", default=[],
                        help="VALUE:NAME, a horizontal line (e.g. 884:LQR oracle)")
    parser.add_argument("--markdown", type=Path, help="also write the table to this file")
    parser.add_argument("--complete", type=int, default=None,
                        help="only runs whose last evaluation is at this env step or later")
    parser.add_argument("--ignore", action="append", default=[],
                        help="an option not to group runs by (e.g. one added later with a "
                             "default that changes nothing: agent.networks.layers)")
    parser.add_argument("--paired", metavar="GROUP", action="append", default=[],
                        help="also compare every group with this one seed by seed "
                             "(a label of the table, e.g. 'group=none'); repeat it for "
                             "more baselines")
    parser.add_argument("--label", metavar="GROUP:NAME", action="append", default=[],
                        help="show a group under another name in the table and the plot "
                             "(e.g. 'group=none:plain'); repeatable")
    parser.add_argument("--contrast", nargs=4, metavar=("GROUP", "BASELINE", "GROUP2", "BASELINE2"),
                        action="append", default=[],
                        help="is GROUP's margin over BASELINE (paired by seed) larger than "
                             "GROUP2's over BASELINE2? e.g. D8 over plain on hard vs on easy; "
                             "repeatable")
    parser.add_argument("--published", metavar="PATH:ALGORITHM:TASK", action="append", default=[],
                        help="another project's per-seed returns (CSV: algorithm, task, seed, "
                             "env_step, episode_reward) as markers and a table, e.g. "
                             "results/published/reacher.csv:tdmpc:reacher-hard; repeatable")
    parser.add_argument("--from-step", type=int, default=None, metavar="STEP",
                        help="use only the evaluations at this env step or later in the tables "
                             "and the figure (e.g. 25000: compare agents after warm-ups of "
                             "different lengths); steps to a threshold count from it too")
    parser.add_argument("--spread", metavar="OPTION", default=None,
                        help="how much each agent's returns move across the values of this "
                             "option (e.g. train.seed_steps), per seed, and the agents' "
                             "ranges compared seed by seed; with --out, also OPTION's figure "
                             "(<out>_spread.png)")
    parser.add_argument("--panels", metavar="OPTION", default=None,
                        help="draw one panel per value of this option (e.g. env.n_balls), the "
                             "groups by their other options; the tables are unchanged")
    parser.add_argument("--runs", action="store_true",
                        help="also list every run: evaluations, wall time, TD learner invariants")
    args = parser.parse_args(argv)
    runs = [r for r in find_runs(args.paths) if args.complete is None or r.steps[-1] >= args.complete]
    if not runs:
        raise SystemExit(f"geomdp-plot: error: no run directories (eval.csv + config.yaml) under "
                         f"{', '.join(map(str, args.paths))}")
    evaluations = ALL_EVALUATIONS
    if args.from_step is not None:
        short = next((r for r in runs if r.steps[-1] < args.from_step), None)
        if short is not None:
            raise SystemExit(f"geomdp-plot: error: --from-step {args.from_step}: {short.path} has "
                             f"no evaluation at or after it (its last is at env step "
                             f"{int(short.steps[-1])}); --complete {args.from_step} leaves such "
                             "runs out")
        runs = [r.from_step(args.from_step) for r in runs]
        evaluations = f"evaluations from env step {args.from_step} on"
    groups = group_runs(runs, tuple(args.ignore))
    agents = spread_agents(runs, args.spread, tuple(args.ignore)) if args.spread else {}
    panels = (panel_groups(runs, args.panels, tuple(args.ignore)) if args.panels
              else {"": groups})
    renamed = rename_groups(args.label, groups, agents, *(panels.values() if args.panels else ()))
    paired = [renamed.get(b, b) for b in args.paired]
    references = []
    for ref in args.reference:
        value, _, name = ref.partition(":")
        references.append((float(value), name or "reference"))
    try:
        published = [read_published(spec) for spec in args.published]
    except ValueError as err:
        raise SystemExit(f"geomdp-plot: error: {err}") from None
    last_step = max(run.steps[-1] for run in runs)  # published results are shown up to it
    if args.out:
        plot(panels, args.out, args.title or default_title(args.paths), references, published,
             last_step)
        if agents:
            spread_plot(agents, args.spread, args.out.with_name(f"{args.out.stem}_spread.png"),
                        args.title or default_title(args.paths), evaluations)
    text = table(groups, args.threshold, evaluations)
    if published:
        text += "\n\n" + published_table(published, last_step)
        comparison = published_comparison_table(groups, published)
        if comparison:
            text += "\n\n" + comparison
    if args.paired:
        text += "\n\n" + paired_table(groups, paired, evaluations)
    if args.contrast:
        text += "\n\n" + contrast_table(groups, [[renamed.get(n, n) for n in names]
                                                  for names in args.contrast], evaluations)
    if agents:
        text += "\n\n" + spread_tables(agents, args.spread, evaluations)
    if args.runs:
        text += "\n\n" + runs_table(groups)
    print(text)
    if args.markdown:
        args.markdown.write_text(text + "\n")


if __name__ == "__main__":
    main()
