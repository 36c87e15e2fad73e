"""The README's main job (`omnid-demo`) at tiny sizes: record, train, evaluate, report; resumable."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

OMNID_DEMO = Path(sys.executable).parent / "omnid-demo"
TINY = ["--episodes", "2", "--steps", "2", "--eval-episodes", "1", "--episode-length", "10"]


@pytest.fixture
def first_demo_run(tmp_path) -> tuple[Path, subprocess.CompletedProcess]:
    out = tmp_path / "demo"
    return out, subprocess.run(
        [str(OMNID_DEMO), "--out", str(out), *TINY], capture_output=True, text=True, timeout=900
    )


@pytest.mark.slow
def test_main_job_writes_report_and_reuses_finished_stages(first_demo_run):
    out, result = first_demo_run
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    report = (out / "report.md").read_text()
    for row in ("| id | ", "| position_ood | ", "| id_blind | ", "| record |", "| train |", "| eval_id |"):
        assert row in report, row
    assert "| blind_calibration |" in report and "Margin over the blind control in ID" in report
    assert "lerobot-train" in report and "--env_eval_freq=1" in report and "--policy.type=omnid" in report
    assert (
        out / "controls" / "blind.json"
    ).is_file() and "--policy.calibration_path=controls/blind.json" in report
    assert str(out) not in report  # paths relative to the output folder: a committed summary names no machine
    summary = json.loads((out / "summary.json").read_text())
    assert summary["protocol"] == "omnid-demo"
    cells = [(e["setting"], e["control"]) for e in summary["evaluations"]]
    assert cells == [("id", ""), ("position_ood", ""), ("id", "blind")]
    assert all(stage["seconds"] is not None for stage in summary["results"]["stages"])
    assert (out / "train" / "checkpoints" / "last" / "pretrained_model" / "model.safetensors").is_file()
    assert list((out / "eval_id" / "videos").rglob("*.mp4"))
    assert (out / "logs" / "train.log").is_file()

    # Everything exists: a second run redoes nothing and rewrites the report.
    rerun = subprocess.run(
        [str(OMNID_DEMO), "--out", str(out), *TINY], capture_output=True, text=True, timeout=300
    )
    assert rerun.returncode == 0
    assert rerun.stdout.count("already done") == 6
    # The summary alone rebuilds the same report.
    (out / "report.md").unlink()
    rebuilt = subprocess.run(
        [str(OMNID_DEMO), "--out", str(out), "--report-only"], capture_output=True, text=True
    )
    assert rebuilt.returncode == 0 and (out / "report.md").read_text() == report
