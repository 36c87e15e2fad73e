"""calibration_shift: the object's displacement per camera and draw, their mean and spread, joined with a
robustness run's per-draw success."""

from __future__ import annotations

import json

import pytest
import torch
from omnid_testing import synthetic_calibration

from lerobot_omnid.benchmark.robustness_plan import camera_offsets, perturbed_calibrations
from lerobot_omnid.calibration.schema import CameraCalibration
from lerobot_omnid.diagnostics import calibration_shift
from lerobot_omnid.diagnostics.calibration_shift import displacements, draw_row, main
from lerobot_omnid.measure.results import RunSummary, read_run_summary, write_run_summary

CAMS = ("cam_b", "cam_c", "cam_d", "cam_e")
POINT = torch.tensor([0.55, 0.12, 0.035], dtype=torch.float64)


def calibrations() -> dict[str, CameraCalibration]:
    return {c: CameraCalibration.from_dict(synthetic_calibration(c, 32), c) for c in CAMS}


def test_no_error_no_displacement_and_larger_errors_move_it_further():
    true = calibrations()
    assert all(v == pytest.approx([0, 0], abs=1e-9) for v in displacements(true, true, POINT).values())
    sizes = []
    for level in (1.0, 4.0):
        believed = perturbed_calibrations(true, camera_offsets(level, 1, 0))
        sizes.append(draw_row(displacements(true, believed, POINT))["cameras_cm"])
    assert all(sizes[1][c] > sizes[0][c] > 0 for c in CAMS)


def test_draw_row_separates_agreement_from_disagreement():
    agree = draw_row({"a": [2.0, 0.0], "b": [2.0, 0.0]})
    assert agree["mean_cm"] == pytest.approx(2.0) and agree["spread_cm"] == pytest.approx(0.0)
    cancel = draw_row({"a": [2.0, 0.0], "b": [-2.0, 0.0]})
    assert cancel["mean_cm"] == pytest.approx(0.0) and cancel["spread_cm"] == pytest.approx(2.0)


def test_joins_each_draw_with_its_success(tmp_path, monkeypatch):
    monkeypatch.setattr(calibration_shift, "code_commit", lambda: "abc123")  # git runs only in tests/e2e
    checkpoint = tmp_path / "pretrained_model"
    checkpoint.mkdir()
    config = {
        "type": "omnid",
        "input_features": {f"observation.images.{c}": {"type": "VISUAL", "shape": [3, 32, 32]} for c in CAMS},
        "camera_calibration": {f"observation.images.{c}": synthetic_calibration(c, 32) for c in CAMS},
    }
    (checkpoint / "config.json").write_text(json.dumps(config))
    rows = [{"condition": "calibration", "level": 2.0, "parts": [["draw 1", 3, 10], ["draw 2", 9, 10]]}]
    results = {"checkpoints": {"omnid": {"rows": rows}}}
    settings = {"perturbation_seed": 0}
    write_run_summary(tmp_path / "robustness.json", RunSummary("omnid-robustness", settings, results=results))
    args = ["--out", str(tmp_path / "out"), "--checkpoint", str(checkpoint), "--levels", "2", "--draws", "3"]
    assert main([*args, "--robustness-summary", str(tmp_path / "robustness.json")]) == 0
    draws = read_run_summary(tmp_path / "out", "calibration_shift").results["draws"]
    assert [(d["draw"], d.get("successes")) for d in draws] == [(1, 3), (2, 9), (3, None)]
    assert set(draws[0]["cameras_cm"]) == set(CAMS) and draws[0]["mean_cm"] > 0
    report = (tmp_path / "out" / "report.md").read_text()
    assert "- 2 cm, 2 deg: Spearman rho (success, mean displacement) = " in report
    assert (tmp_path / "out" / calibration_shift.CHART).stat().st_size > 10_000
    assert main(["--out", str(tmp_path / "again"), "--report-only", str(tmp_path / "out")]) == 0
    assert "| 2 | 1 |" in (tmp_path / "again" / "report.md").read_text()
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path / "x"), "--checkpoint", str(tmp_path)])


def test_a_robustness_summary_of_other_draws_or_labels_is_refused(tmp_path, capsys):
    results = {"checkpoints": {"omnid": {"rows": []}}}
    write_run_summary(
        tmp_path / "r.json", RunSummary("omnid-robustness", {"perturbation_seed": 3}, results=results)
    )
    with pytest.raises(ValueError, match="perturbation_seed: expected 0, got 3"):
        calibration_shift.draw_successes(tmp_path / "r.json", "omnid", 0)
    with pytest.raises(ValueError, match=r"--label: expected one of \['omnid'\], got 'dp'"):
        calibration_shift.draw_successes(tmp_path / "r.json", "dp", 3)


def test_relation_splits_draws_at_the_grasp_tolerance():
    """The apple (7 cm) in the open pads (9 cm apart) may be 1 cm off; draws beyond it that fail give a
    negative rho and a split; a level where every draw did alike has no rho."""
    assert pytest.approx(1.0) == calibration_shift.GRASP_TOLERANCE_CM
    draws = [
        {"level": 2.0, "draw": i, "mean_cm": m, "successes": k, "episodes": 10}
        for i, (m, k) in enumerate([(0.3, 9), (0.8, 8), (1.5, 3), (3.0, 0)], start=1)
    ] + [
        {"level": 1.0, "draw": i, "mean_cm": m, "successes": 7, "episodes": 10}
        for i, m in ((1, 0.2), (2, 0.4))
    ]
    lines = calibration_shift.relation_lines(draws)
    two = next(line for line in lines if line.startswith("- 2 cm"))
    assert "rho (success, mean displacement) = -1.00" in two
    assert "2 draws within 1.0 cm 17/20, 2 beyond 3/20 (Fisher p = " in two
    one = next(line for line in lines if line.startswith("- 1 cm"))
    assert "n/a (constant)" in one and "beyond 0/0" in one and "Fisher" not in one
    assert any(line.startswith("- all levels:") for line in lines)
    assert calibration_shift.relation_lines([{"level": 2.0, "draw": 1, "mean_cm": 1.0}]) == []
