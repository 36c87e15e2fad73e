"""The README's main job (`omnid-demo`): its report's blind-control margin, argument errors, the CPU profile's
training command. (The command at tiny sizes: tests/e2e/test_omnid_demo.py.)"""

import pytest
from gym_omnid import TRAIN_CAMERAS

from lerobot_omnid.benchmark.demo import PROFILES, blind_margin, main, train_command, write_report
from lerobot_omnid.benchmark.methods import method_flags
from lerobot_omnid.benchmark.plan import MINI
from lerobot_omnid.measure.results import EvalRecord, RunSummary, write_run_summary


def summary(id_counts: tuple[int, int], blind_counts: tuple[int, int]) -> RunSummary:
    cells = [("id", "", id_counts), ("position_ood", "", (1, 10)), ("id", "blind", blind_counts)]
    evaluations = [
        EvalRecord(("omnid", "select_apple", setting), control, None, None, s, n, "x", "0123456789abcdef")
        for setting, control, (s, n) in cells
    ]
    stages = [{"name": "train", "seconds": 806.4, "command": "lerobot-train --steps=1000"}]
    return RunSummary("omnid-demo", {"profile": "cpu"}, evaluations, {"stages": stages})


def test_report_gives_the_blind_control_beside_the_success_rate(tmp_path):
    margin = write_report(summary((7, 10), (0, 10)), tmp_path / "report.md")
    report = (tmp_path / "report.md").read_text()
    assert "| id | 7/10 | 70.0 | 39.7-89.2 | 0123456789ab |" in report
    assert "| id_blind | 0/10 | 0.0 | 0.0-27.8 |" in report
    assert "| train | 806 | `lerobot-train --steps=1000` |" in report
    # Known values (the mini OmniD against its blind control): +70, Newcombe +28.9 to +89.2.
    assert margin in report
    assert "+70.0 points (Newcombe 95 % +28.9 to +89.2), two-sided Fisher p = 0.0031" in margin
    assert "significantly above its blind control" in margin
    assert "not distinguishable" in blind_margin((3, 10), (2, 10))


def test_report_only_rebuilds_the_report_from_a_summary_and_runs_nothing(tmp_path, capsys):
    source = write_run_summary(tmp_path / "kept.json", summary((8, 10), (1, 10)))
    out = tmp_path / "out"
    assert main(["--out", str(out), "--report-only", "--summary", str(source)]) == 0
    assert "| id | 8/10 | 80.0 |" in (out / "report.md").read_text()
    assert sorted(p.name for p in out.iterdir()) == ["report.md"]
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path / "empty"), "--report-only"])
    assert "--report-only: expected a summary file, got none at" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--steps", "0"], "--steps"),
        (["--profile", "tpu"], "--profile"),
        (["--summary", "s.json"], "--summary: expected with --report-only"),
    ],
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
