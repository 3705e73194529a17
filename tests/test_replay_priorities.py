"""scripts/replay_priorities.py reads a saved replay's zero-error slots and sampling mass."""


import torch
from conftest import load_script, run_main
from tensordict import TensorDict

from agents.tdmpc.replay import ReplayConfig, make_replay_buffer, save_replay

replay_priorities = load_script("scripts/replay_priorities.py")


def test_counts_zero_error_slots_and_mass_per_part(tmp_path, monkeypatch, capsys):
    buffer = make_replay_buffer(ReplayConfig(capacity=64), horizon=3, batch_size=4)
    buffer.extend(TensorDict({"observation": torch.zeros(10, 2),
                              "episode": torch.zeros(10, dtype=torch.long)}, [10]))
    # warm-up slots 0-3: errors 0, 0, 1, 1; slots 4-9: error 1 (mass (1 + 1e-8) ** 0.6 each)
    buffer.update_priority(torch.arange(10), (torch.arange(10) >= 2).float())
    save_replay(buffer, tmp_path / "replay.pt")
    out, error = run_main(replay_priorities, monkeypatch, capsys, tmp_path / "replay.pt", "--warmup-slots", 4)
    assert error is None
    warmup, after = [line for line in out.splitlines() if "slots (" in line]
    assert "4 slots (40.0%); zero TD error: 2 (50.00%); share of the sampling mass 25.0%" in warmup
    assert "6 slots (60.0%); zero TD error: 0 (0.00%); share of the sampling mass 75.0%" in after


def test_a_missing_file_is_one_line(monkeypatch, capsys):
    _, error = run_main(replay_priorities, monkeypatch, capsys, "nowhere.pt", "--warmup-slots", 1)
    assert error == "nowhere.pt: no such file (a checkpoint's replay.pt)"
