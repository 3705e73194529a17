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
