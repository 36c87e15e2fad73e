"""The README's main job (`omnid-demo`) at tiny sizes: record, train, evaluate, report; resumable."""

import subprocess
import sys
from pathlib import Path

import pytest
from gym_omnid import TRAIN_CAMERAS
from omnid_jobs import Job, job

from lerobot_omnid.benchmark.demo import PROFILES, blind_margin, main, train_command, write_report
from lerobot_omnid.benchmark.plan import MINI, method_flags

OMNID_DEMO = Path(sys.executable).parent / "omnid-demo"
TINY = ["--episodes", "2", "--steps", "2", "--eval-episodes", "1", "--episode-length", "10"]


@job("demo", seconds=60)
def _first_demo_run(job: Job) -> tuple[Path, subprocess.CompletedProcess]:
    out = job.tmp / "demo"
    return out, job.run([str(OMNID_DEMO), "--out", str(out), *TINY], timeout=900)


@pytest.mark.slow
@pytest.mark.jobs("demo")
def test_main_job_writes_report_and_reuses_finished_stages(jobs):
    out, result = jobs.result("demo")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    report = (out / "report.md").read_text()
    for row in ("| id | ", "| position_ood | ", "| id_blind | ", "| record |", "| train |", "| eval_id |"):
        assert row in report, row
    assert "| blind_calibration |" in report and "Margin over the blind control in ID" in report
    assert "lerobot-train" in report and "--env_eval_freq=1" in report and "--policy.type=omnid" in report
    blind_file = out / "controls" / "blind.json"
    assert blind_file.is_file() and f"--policy.calibration_path={blind_file}" in report
    assert (out / "train" / "checkpoints" / "last" / "pretrained_model" / "model.safetensors").is_file()
    assert list((out / "eval_id" / "videos").rglob("*.mp4"))
    assert (out / "logs" / "train.log").is_file()

    # Everything exists: a second run redoes nothing and rewrites the report.
    rerun = subprocess.run(
        [str(OMNID_DEMO), "--out", str(out), *TINY], capture_output=True, text=True, timeout=300
    )
    assert rerun.returncode == 0
    assert rerun.stdout.count("already done") == 6


def test_report_gives_the_blind_control_beside_the_success_rate(tmp_path):
    rows = [("id", (7, 10), tmp_path / "a"), ("position_ood", (1, 10), tmp_path / "b")]
    rows.append(("id_blind", (0, 10), tmp_path / "c"))
    margin = write_report(tmp_path / "report.md", "cpu", rows, tmp_path / "ck", {}, {})
    report = (tmp_path / "report.md").read_text()
    assert "| id | 7/10 | 70.0 | 39.7-89.2 |" in report and "| id_blind | 0/10 | 0.0 | 0.0-27.8 |" in report
    # Known values (docs/results.md, the mini OmniD against its blind control): +70, Newcombe +28.9 to +89.2.
    assert margin in report
    assert "+70.0 points (Newcombe 95 % +28.9 to +89.2), two-sided Fisher p = 0.0031" in margin
    assert "significantly above its blind control" in margin
    assert "not distinguishable" in blind_margin((3, 10), (2, 10))  # the demo's checkpoint of issue 18


@pytest.mark.parametrize(
    ("argv", "message"), [(["--steps", "0"], "--steps"), (["--profile", "tpu"], "--profile")]
)
def test_bad_arguments_name_the_option(argv, message, capsys):
    with pytest.raises(SystemExit):
        main(argv)
    assert message in capsys.readouterr().err


def test_cpu_profile_trains_the_benchmark_mini_omnid(tmp_path):
    """The main job's CPU profile is the `mini` OmniD, the checkpoint measured above its blind control."""
    cmd = train_command(
        tmp_path / "data", tmp_path / "train", PROFILES["cpu"], "cpu", "select_apple", TRAIN_CAMERAS
    )
    mini = [flag for flag, _ in method_flags("omnid", MINI)]
    assert set(mini) <= set(cmd)
    assert f"--steps={MINI.steps}" in cmd and f"--batch_size={MINI.batch_size}" in cmd
    assert (PROFILES["cpu"].episodes, PROFILES["cpu"].image_size) == (MINI.episodes, MINI.image_size)
    assert sum(flag.startswith("--policy.cameras=") for flag in cmd) == 1
