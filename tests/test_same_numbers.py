"""scripts/same_numbers.py: two runs' logs compared in every column but the wall-clock ones."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import load_script

from agents.run.run_tables import added_columns, differing_tables


def load(name: str):
    return load_script(f"scripts/{name}.py")


def write_tables(run_dir: Path, losses: list[str], wall: list[str], evals: int = 2) -> None:
    run_dir.mkdir(parents=True)
    (run_dir / "train.csv").write_text("env_step,wall_time,loss_model,q_mean,steps_per_second\n" + "".join(
        f"{1000 * (i + 1)},{w},{loss},0.5,{100 + i}\n" for i, (loss, w) in enumerate(zip(losses, wall))))
    (run_dir / "eval.csv").write_text("env_step,wall_time,episode_reward\n" + "".join(
        f"{1000 * i},{i * 3.5},12.5\n" for i in range(evals)))


def test_runs_equal_but_for_the_clock_are_identical_and_any_other_digit_is_named(tmp_path):
    write_tables(tmp_path / "a", ["0.125", "0.0999991"], ["10.0", "20.0"])
    write_tables(tmp_path / "b", ["0.125", "0.0999991"], ["11.5", "23.0"])  # another machine load
    assert differing_tables(tmp_path / "a", tmp_path / "b") == []
    write_tables(tmp_path / "c", ["0.125", "0.0999992"], ["10.0", "20.0"])  # one digit
    assert differing_tables(tmp_path / "a", tmp_path / "c") == [
        "train.csv: from env step 2000, loss_model"]
    write_tables(tmp_path / "d", ["0.125", "0.0999991"], ["10.0", "20.0"], evals=3)
    assert differing_tables(tmp_path / "a", tmp_path / "d") == ["eval.csv: 2 rows against 3"]


def test_a_column_only_one_commit_logs_is_named_not_compared(tmp_path):
    write_tables(tmp_path / "old", ["0.125", "0.0999991"], ["10.0", "20.0"])
    write_tables(tmp_path / "new", ["0.125", "0.0999991"], ["10.0", "20.0"])
    eval_csv = tmp_path / "new/eval.csv"
    lines = eval_csv.read_text().splitlines()
    eval_csv.write_text("\n".join([lines[0] + ",q_start"] + [f"{x},1.5" for x in lines[1:]]) + "\n")
    assert differing_tables(tmp_path / "old", tmp_path / "new") == []
    assert added_columns(tmp_path / "old", tmp_path / "new", ("2729c50", "621c290")) == [
        "eval.csv: q_start (only in 621c290)"]
    eval_csv.write_text(eval_csv.read_text().replace("12.5,1.5", "12.6,1.5", 1))  # a shared column
    assert differing_tables(tmp_path / "old", tmp_path / "new") == [
        "eval.csv: from env step 0, episode_reward"]


def test_configs_are_name_equals_overrides():
    same_numbers = load("same_numbers")
    assert same_numbers.parse_configs(["paper_plain=env=reacher agent=tdmpc_paper"]) == {
        "paper_plain": "env=reacher agent=tdmpc_paper"}
    for bad in ("env=reacher agent=tdmpc_paper", "paper_plain", "=env=reacher"):
        with pytest.raises(SystemExit, match="is not NAME=OVERRIDES"):
            same_numbers.parse_configs([bad])
