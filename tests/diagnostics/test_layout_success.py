"""layout_success: each evaluated episode's layout replayed beside its success; the permutation test."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lerobot_omnid.diagnostics import layout_success
from lerobot_omnid.diagnostics.layout_success import compare, main, option, permutation_p
from lerobot_omnid.measure.results import (
    BENCHMARK,
    EvalRecord,
    RunSummary,
    read_run_summary,
    write_run_summary,
)


def test_option_reads_one_flag_and_refuses_two():
    assert option(("lerobot-eval", "--seed=2000", "--output_dir=o"), "seed") == "2000"
    with pytest.raises(ValueError, match="expected one --seed="):
        option(("--seed=1", "--seed=2"), "seed")


def test_permutation_p_separates_a_clear_difference_from_none():
    rng = np.random.default_rng(0)
    success = np.array([True] * 10 + [False] * 10)
    assert permutation_p(np.r_[np.ones(10), np.zeros(10)], success, rng) < 0.001
    assert permutation_p(np.tile([0.0, 1.0], 10), success, rng) > 0.5


def test_compare_needs_both_groups():
    episodes = [
        {"success": s, "objects": {"cube": [0.1 * i, 0.0]}} for i, s in enumerate([True, True, False])
    ]
    result = compare(episodes)
    assert result["cube.x"]["success_cm"] == pytest.approx(5.0) and result["cube.x"]["failure_cm"] == 20.0
    assert compare([{**e, "success": True} for e in episodes]) == {}


def test_replays_the_layouts_of_a_benchmark_summarys_evaluations(tmp_path, monkeypatch):
    monkeypatch.setattr(layout_success, "code_commit", lambda: "abc123")  # git runs only in tests/e2e
    monkeypatch.chdir(tmp_path)  # portable commands: output folders relative to where they ran
    records = []
    for k, successes in ((1, [True, False, True]), (2, [False, False, True])):
        folder = f"out/eval/omnid/select_apple/id/seed{k}"
        (tmp_path / folder).mkdir(parents=True)
        info = {"per_task": [{"metrics": {"successes": successes}}]}
        (tmp_path / folder / "eval_info.json").write_text(json.dumps(info))
        command = ("lerobot-eval", f"--seed={1000 * k}", f"--output_dir={folder}")
        key = ("omnid", "select_apple", "id")
        records.append(EvalRecord(key, "", 1000, k, sum(successes), 3, "summary.json", "c", command))
    write_run_summary(tmp_path / "summary.json", RunSummary(BENCHMARK, {"profile": {}}, records))
    args = ["--out", str(tmp_path / "diag"), "--summary", str(tmp_path / "summary.json")]
    assert main([*args, "--task", "select_apple"]) == 0
    summary = read_run_summary(tmp_path / "diag", "layout_success")
    # the command as a committed summary keeps it: no folder of this machine
    assert summary.command[3:7] == ["--out", "diag", "--summary", "summary.json"]
    model = summary.results["models"]["omnid"]
    assert (model["successes"], model["episodes"]) == (3, 6) and summary.commit == "abc123"
    assert {"apple.x", "apple.y", "bowl.x", "bowl.y"} <= set(model["axes"])  # distractors too
    ranges = summary.results["range_means"]
    assert [(r["first"], r["episodes"]) for r in ranges] == [(1000, 3), (2000, 3)]
    assert 45 < ranges[0]["means"]["apple.x"] < 65  # the apple's ID square: 50-60 cm
    assert main(["--out", "again", "--report-only", "diag"]) == 0
    assert "| omnid | 3/6 | apple.x |" in (tmp_path / "again" / "report.md").read_text()
    with pytest.raises(SystemExit):
        main(["--out", "diag", "--summary", "summary.json", "--task", "get_coffee"])
