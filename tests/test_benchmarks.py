"""The benchmark scripts' own logic (what they measure is recorded in BENCHMARKS.md)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))
import agent_speed  # noqa: E402


def test_agent_speed_only_picks_a_whole_label_alone_and_words_by_substring():
    def picked(*words: str) -> set[str]:
        return {label for _, label, _ in agent_speed.CONFIGS
                if any(agent_speed.picks(w, label) for w in words)}

    assert picked("plain") == {"plain"}  # not "plain augmented"
    assert picked("augmented") == {"plain augmented"}
    assert picked("D8") == {"D8 linear", "D8 sqrt (irrep basis)", "D8 sqrt (dense, reference)"}
    assert picked("D8 linear", "icosahedral linear") == {"D8 linear", "icosahedral linear"}


def _result(plan, update, gflop=2.0):
    return {"plan": plan, "update": update, "width": 128, "step_gflop": gflop,
            "planner_gflops": 1.0, "matmul_gflops": 1.0}


def test_agent_speed_table_divides_by_plain_on_the_same_device_and_by_the_first_device():
    runs = {("reacher", "plain", "cuda"): [_result(0.01, 0.01), _result(0.02, 0.02)],
            ("reacher", "plain", "cpu"): [_result(0.1, 0.1), _result(0.1, 0.5)],
            ("reacher", "D8 linear", "cuda"): [_result(0.01, 0.02, 4.0), _result(0.03, 0.03, 4.0)],
            ("reacher", "D8 linear", "cpu"): [_result(0.2, 0.2, 4.0), _result(0.2, 0.6, 4.0)]}
    rows = {tuple(cell.strip() for cell in line.split("|")[1:4]): line.split("|")[8:10]
            for line in agent_speed.table(runs, ["cuda", "cpu"]).splitlines()[2:]}
    # x plain step (per round in brackets), then x cuda step: medians over the rounds
    assert [c.strip() for c in rows["reacher", "plain", "cuda"]] == ["1.00 [1.00, 1.00]", "1.000"]
    assert [c.strip() for c in rows["reacher", "D8 linear", "cuda"]] == ["1.50 [1.50, 1.50]", "1.000"]
    assert [c.strip() for c in rows["reacher", "plain", "cpu"]] == ["1.00 [1.00, 1.00]", "12.500"]
    assert [c.strip() for c in rows["reacher", "D8 linear", "cpu"]] == ["1.67 [2.00, 1.33]", "13.333"]
    single = agent_speed.table({k: v for k, v in runs.items() if k[2] == "cpu"}, ["cpu"])
    assert "x cpu step" not in single and single.splitlines()[0].count("|") == 13
