"""action_reach: the generable range of a clipped MIN_MAX head, a plan's excess, a real run on the env."""

from __future__ import annotations

import json

import numpy as np
import pytest
from gym_omnid import ACTION_DIM

from lerobot_omnid.diagnostics import action_reach
from lerobot_omnid.diagnostics.action_reach import excess, generable_range, main
from lerobot_omnid.measure.results import read_run_summary


def test_generable_range_widens_by_the_clip_margin() -> None:
    low, high = np.array([0.0, -1.0]), np.array([1.0, 1.0])
    assert [v.tolist() for v in generable_range(low, high, 1.0)] == [[0.0, -1.0], [1.0, 1.0]]
    # clip 2: normalised [-2, 2] maps to half the width again on each side.
    wide_low, wide_high = generable_range(low, high, 2.0)
    assert wide_low.tolist() == [-0.5, -2.0] and wide_high.tolist() == [1.5, 2.0]


def test_excess_is_the_largest_reach_beyond_either_bound_per_dim() -> None:
    low, high = np.zeros(3), np.ones(3)
    actions = np.array([[0.5, -0.2, 1.0], [1.3, 0.5, 0.9]])
    assert excess(actions, low, high) == pytest.approx([0.3, 0.2, 0.0])


def test_counts_expert_plans_against_the_datasets_action_range(tmp_path, capsys, monkeypatch) -> None:
    monkeypatch.setattr(action_reach, "code_commit", lambda: "abc123")  # git runs only in tests/e2e
    dataset = tmp_path / "data"
    (dataset / "meta").mkdir(parents=True)
    # A range no plan fits in (a 1 mm box at the origin) and one every plan fits in.
    tight = {"min": [0.0] * ACTION_DIM, "max": [0.001] * ACTION_DIM}
    (dataset / "meta" / "stats.json").write_text(json.dumps({"action": tight}))
    args = ["--dataset", str(dataset), "--task", "select_apple", "--layouts", "id", "--episodes", "2"]
    assert main([*args, "--out", str(tmp_path / "tight")]) == 0
    result = read_run_summary(tmp_path / "tight", "action_reach").results["layouts"]["id"]
    assert read_run_summary(tmp_path / "tight", "action_reach").commit == "abc123"
    assert result["beyond"] == 2 and result["beyond_by_dim"]["ee_x"] == 2
    assert result["max_position_excess_cm"] > 30  # the apple is about half a metre from the origin
    # The same dataset, clipped 3000 times wider: 1.5 m on each side, every plan inside.
    assert main([*args, "--out", str(tmp_path / "wide"), "--clip-range", "3000"]) == 0
    assert read_run_summary(tmp_path / "wide", "action_reach").results["layouts"]["id"]["beyond"] == 0
    assert "| id | 0/2" in capsys.readouterr().out
    assert main(["--out", str(tmp_path / "again"), "--report-only", str(tmp_path / "wide")]) == 0
    assert "| id | 0/2" in (tmp_path / "again" / "report.md").read_text()


def test_bad_input_names_the_flag(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path), "--dataset", str(tmp_path / "missing")])
    assert "--dataset: expected a LeRobot dataset folder" in capsys.readouterr().err
