"""The README's main job (`omnid-demo`) at tiny sizes: record, train, evaluate, report; resumable."""

import subprocess
import sys
from pathlib import Path

import pytest
from omnid_jobs import Job, job

from lerobot_omnid.benchmark.demo import main

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
    for row in ("| id | 1 |", "| position_ood | 1 |", "| record |", "| train |", "| eval_id |"):
        assert row in report, row
    assert "lerobot-train" in report and "--env_eval_freq=1" in report and "--policy.type=omnid" in report
    assert (out / "train" / "checkpoints" / "last" / "pretrained_model" / "model.safetensors").is_file()
    assert list((out / "eval_id" / "videos").rglob("*.mp4"))
    assert (out / "logs" / "train.log").is_file()

    # Everything exists: a second run redoes nothing and rewrites the report.
    rerun = subprocess.run(
        [str(OMNID_DEMO), "--out", str(out), *TINY], capture_output=True, text=True, timeout=300
    )
    assert rerun.returncode == 0
    assert rerun.stdout.count("already done") == 4


@pytest.mark.parametrize(
    ("argv", "message"), [(["--steps", "0"], "--steps"), (["--profile", "tpu"], "--profile")]
)
def test_bad_arguments_name_the_option(argv, message, capsys):
    with pytest.raises(SystemExit):
        main(argv)
    assert message in capsys.readouterr().err
