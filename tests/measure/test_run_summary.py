"""The one run-summary format of every protocol: written and read back whole (tags included), and a file of
another format or another protocol refused with the field, what was expected and what was found."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lerobot_omnid.measure.results import (
    SUMMARY_FORMAT,
    EvalRecord,
    RunSummary,
    check_comparable,
    merge_run_summaries,
    read_run_summary,
    tags_of,
    write_run_summary,
)


def test_a_summary_reads_back_as_written(tmp_path):
    record = EvalRecord(
        ("omnid", "select_apple", "id"),
        "blind",
        1000,
        2,
        3,
        15,
        "x",
        "abc",
        ("lerobot-eval",),
        tags_of({"rig": "higher", "steps": 3000}),
    )
    summary = RunSummary("a_protocol", {"episodes": 15}, [record], {"selected": "keypoints"}, "abc", ["cmd"])
    write_run_summary(tmp_path / "summary.json", summary)
    back = read_run_summary(tmp_path, "a_protocol")  # a folder reads its summary.json
    assert back.settings == {"episodes": 15} and back.results == {"selected": "keypoints"}
    assert back.commit == "abc" and list(back.command) == ["cmd"]
    (read,) = back.evaluations
    assert read.identity == record.identity and read.tag("steps") == "3000" and read.tag("other") is None
    assert (read.successes, read.episodes, read.command) == (3, 15, ("lerobot-eval",))


def test_other_formats_and_protocols_are_refused(tmp_path):
    path = write_run_summary(tmp_path / "s.json", RunSummary("a_protocol", {}))
    with pytest.raises(ValueError, match=r"s.json: protocol: expected 'other', got 'a_protocol'"):
        read_run_summary(path, "other")
    data = json.loads(path.read_text()) | {"format": 1}
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=rf"s.json: format: expected {SUMMARY_FORMAT}, got 1"):
        read_run_summary(path, "a_protocol")
    with pytest.raises(ValueError, match="expected a run summary of a_protocol"):
        read_run_summary(tmp_path / "missing.json", "a_protocol")


def test_parts_of_one_run_merge_and_others_are_refused():
    def part(task: str, settings: dict | None = None, commit: str = "abc") -> RunSummary:
        record = EvalRecord(("omnid", task, "id"), "", 1000, 1000, 3, 15, "x", commit)
        return RunSummary("a_protocol", settings or {"steps": 2000}, [record], {"published": {}}, commit)

    merged = merge_run_summaries([part("push-v3"), part("assembly-v3", commit="def")], ["a", "b"])
    assert [r.key[1] for r in merged.evaluations] == ["push-v3", "assembly-v3"]
    assert merged.settings == {"steps": 2000} and merged.commit == "abc, def"
    with pytest.raises(
        ValueError, match=r"b: settings: expected those of a to merge with it, got \{'steps': 1\}"
    ):
        merge_run_summaries([part("push-v3"), part("assembly-v3", {"steps": 1})], ["a", "b"])
    with pytest.raises(
        ValueError, match=r"b: evaluation .*push-v3.*: expected it in one summary only, got it in a"
    ):
        merge_run_summaries([part("push-v3"), part("push-v3")], ["a", "b"])


COMMITTED = Path(__file__).resolve().parents[2] / "docs" / "results"
WRITERS = {
    "omnid-benchmark": "lerobot_omnid.benchmark.benchmark",
    "omnid-demo": "lerobot_omnid.benchmark.demo",
    "omnid-robustness": "lerobot_omnid.benchmark.robustness",
    "task_sizing": "lerobot_omnid.benchmark.task_sizing",
    "rigs_and_wrist": "lerobot_omnid.benchmark.rigs_and_wrist",
    "new_camera": "lerobot_omnid.benchmark.new_camera",
    "readout_selection": "lerobot_omnid.benchmark.readout_selection",
    "metaworld_comparison": "lerobot_omnid.benchmark.metaworld_comparison",
    "metaworld_validation": "lerobot_omnid.benchmark.metaworld_validation",
    "position_extrapolation": "lerobot_omnid.diagnostics.position_extrapolation",
    "action_reach": "lerobot_omnid.diagnostics.action_reach",
    "layout_success": "lerobot_omnid.diagnostics.layout_success",
    "calibration_shift": "lerobot_omnid.diagnostics.calibration_shift",
    "bench_policy": "benchmarks/bench_policy.py",
    "fuse_last_step_only_validation": "the validation of --policy.fuse_last_step_only (docs/benchmark.md)",
}
"""The protocol of each committed summary and what wrote it."""


@pytest.mark.parametrize("path", sorted(COMMITTED.glob("*.json")), ids=lambda p: p.name)
def test_every_committed_summary_is_in_the_one_format(path):
    protocol = json.loads(path.read_text()).get("protocol")
    assert protocol in WRITERS, f"{path.name}: protocol {protocol!r} is not one of {sorted(WRITERS)}"
    summary = read_run_summary(path, protocol)
    assert summary.evaluations or summary.results, f"{path.name}: neither evaluations nor results"


def test_folders_of_other_training_lengths_or_encodings_are_not_combined():
    """Per-task steps and OmniD's last-step-only encoding decide the models too; a summary's JSON lists
    equal the profile's tuples, and a summary written before a field existed means its default."""
    profile = {"steps": 1000, "task_steps": (("get_coffee", 3000),), "fuse_last_step_only": True}
    check_comparable(
        profile, {"steps": 1000, "task_steps": [["get_coffee", 3000]], "fuse_last_step_only": True}, "s"
    )
    with pytest.raises(ValueError, match=r"s: task_steps: expected \[\['get_coffee', 3000\]\] .*got \[\]"):
        check_comparable(profile, {"steps": 1000, "fuse_last_step_only": True}, "s")
    with pytest.raises(ValueError, match=r"s: fuse_last_step_only: expected True .*got False"):
        check_comparable(profile, {"steps": 1000, "task_steps": [["get_coffee", 3000]]}, "s")
