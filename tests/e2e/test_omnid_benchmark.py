"""omnid-benchmark with the real tools at tiny sizes: the mini run (omnid-record, lerobot-train of OmniD and
stock DP, lerobot-eval with the controls, the open-loop diagnostic), then the few-shot profile on its
folder. (The plan, the command with stand-in tools, the report: tests/benchmark, tests/measure.)"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from lerobot_omnid.benchmark.plan import TASK0, TASK1
from lerobot_omnid.calibration.rig_file import load_calibration_file

# The few-shot run continues the mini run's folder (a module fixture): both tests on one worker.
pytestmark = pytest.mark.xdist_group("omnid_benchmark")


TINY = "--episodes 1 --steps 2 --batch-size 2 --image-size 64 --num-workers 0 --eval-episodes 1 "
TINY += "--episode-length 10"
# omnid-benchmark's smallest sizes, shared by the tiny runs so that the few-shot one reuses mini's runs.


def _omnid_benchmark(out: Path, *options: str) -> subprocess.CompletedProcess:
    argv = [str(Path(sys.executable).parent / "omnid-benchmark"), "--out", str(out), *TINY.split(), *options]
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    return subprocess.run(argv, capture_output=True, text=True, timeout=900, env=env)


@pytest.fixture(scope="module")
def real_tools_tiny(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    """The tiny mini run, read by its own test and continued by the few-shot run."""
    out = tmp_path_factory.mktemp("benchmark") / "bench"
    return out, _omnid_benchmark(out, "--settings", "id", "--heldout-episodes", "1")


@pytest.mark.slow
def test_real_tools_end_to_end_tiny(real_tools_tiny):
    """The real omnid-record, lerobot-train (OmniD and stock DP) and lerobot-eval, controls included, at the
    smallest sizes."""
    out, proc = real_tools_tiny
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    summary = json.loads((out / "results.json").read_text())
    cells = {(c["model"], c["setting"]): c for c in summary["cells"]}
    assert set(cells) == {("omnid", "id"), ("diffusion", "id")}
    assert all(c["episodes"] == 1 for c in cells.values())
    # The controls ran through the real tools: OmniD with the calibration files written from its checkpoint
    # (lerobot-eval --policy.calibration_path), DP with black images (--env.blackout_cameras).
    controls = {(c["model"], c["control"]): c["episodes"] for c in summary["controls"]}
    assert controls == {("omnid", c): 1 for c in ("blind", "scrambled", "perturbed")} | {
        ("diffusion", "blind"): 1
    }
    for control in ("blind", "scrambled", "perturbed"):
        calibrations = load_calibration_file(out / "controls" / "omnid" / TASK0 / f"{control}.json")
        assert sorted(calibrations) == [f"observation.images.cam_{c}" for c in "bcde"]
    stamp = json.loads(
        (out / "stamps" / "eval_blind" / "diffusion" / TASK0 / "id" / "seed1.json").read_text()
    )
    assert "--env.blackout_cameras=[cam_b,cam_c,cam_d,cam_e]" in stamp["command"]
    assert len(json.loads((out / "summary.json").read_text())["evaluations"]) == 6
    report = (out / "report.md").read_text()
    assert "| Method | Select Apple | Average |" in report
    for method in ("omnid", "diffusion"):  # the open-loop diagnostic ran with the real checkpoints
        result = json.loads((out / "offline" / method / TASK0 / "id" / "offline_eval.json").read_text())
        assert result["episodes"] == 1 and result["frames"] > 10 and result["position_cm"] >= 0.0
    assert "open-loop action error" in report


@pytest.fixture
def real_tools_fewshot_tiny(real_tools_tiny, tmp_path) -> tuple[Path, subprocess.CompletedProcess]:
    """``--profile mini-fewshot`` on the tiny mini run's folder: its task-0 models fine-tuned on camera A."""
    mini, first = real_tools_tiny
    if first.returncode != 0:
        return mini, first
    out = tmp_path / "bench"  # a copy: the mini test reads its own folder's results
    shutil.copytree(mini, out)
    options = ("--profile", "mini-fewshot", "--fewshot-episodes", "1", "--finetune-steps", "2")
    return out, _omnid_benchmark(out, *options)


@pytest.mark.slow
def test_real_tools_fewshot_tiny(real_tools_fewshot_tiny):
    """Both task-0 models fine-tuned on camera A of both tasks through the real lerobot-train, DP from its
    one-camera copy, and evaluated with camera A beside its blind control; mini's trainings are reused."""
    out, proc = real_tools_fewshot_tiny
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    results = json.loads((out / "results.json").read_text())
    cells = {(c["model"], c["task"], c["setting"]) for c in results["cells"]}
    for model in ("omnid", "diffusion"):
        for task in (TASK0, TASK1):
            assert (model, task, "fewshot_a") in cells
    controls = {(c["model"], c["task"], c["setting"], c["control"]) for c in results["controls"]}
    assert {(m, t, "fewshot_a", "blind") for m in ("omnid", "diffusion") for t in (TASK0, TASK1)} <= controls
    report = (out / "report.md").read_text()
    assert "Few-shot on camera A, select_chemistry_tube: each fine-tuned model" in report
    copy = json.loads((out / "finetune" / "diffusion" / "start_cam_a" / "config.json").read_text())
    assert [k for k in copy["input_features"] if k.startswith("observation.images.")] == [
        "observation.images.cam_a"
    ]
    assert "train/omnid/select_apple: done" not in proc.stdout + proc.stderr  # reused, not retrained
