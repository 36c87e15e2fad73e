"""omnid-robustness: the perturbation files (level 0 is the calibration, level L moves every camera by L cm
and turns it by L degrees, seeded draws), the mirror image of the env's bumped cameras, the plan and its
options (parsed by LeRobot's env config), the tables and the chart, argument errors, resumability with
stand-in tools. (The real tools at tiny size: tests/e2e/test_omnid_robustness.py; the env options
themselves: tests/sim/test_gym_robustness_options.py.)"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import draccus
import gymnasium as gym
import numpy as np
import pytest
from gym_omnid import TRAIN_CAMERAS
from lerobot.envs.configs import EnvConfig
from omnid_testing import COMMITTED_SUMMARIES, checkpoint_config, checkpoint_dir

from lerobot_omnid.benchmark import robustness
from lerobot_omnid.benchmark.robustness_plan import (
    LEVELS,
    Cell,
    Checkpoint,
    RobustnessSettings,
    build_runs,
    camera_offsets,
    checkpoint_from_config,
    perturbed_calibrations,
    plan_cells,
)
from lerobot_omnid.benchmark.robustness_report import (
    ANY_CAMERA,
    between_lines,
    checkpoint_lines,
    comparison_chart,
    comparison_lines,
    draw_spread_lines,
    robustness_chart,
    table_rows,
    target_lines,
)
from lerobot_omnid.calibration.rig_file import load_calibration_file
from lerobot_omnid.calibration.schema import CameraCalibration
from lerobot_omnid.env_config import OmniDEnvConfig
from lerobot_omnid.keys import image_key
from lerobot_omnid.measure import engine
from lerobot_omnid.measure.results import CellResult

SIZE = 64


@pytest.fixture(scope="module")
def calibrations() -> dict[str, dict]:
    """The env's calibrations of cameras B-E at 64 px, keyed like a checkpoint's (built once)."""
    return OmniDEnvConfig(image_size=SIZE).camera_calibrations()


def flag(cmd, name: str) -> str | None:
    return next((c.split("=", 1)[1] for c in cmd if c.startswith(f"--{name}=")), None)


def centre_and_turn(before: CameraCalibration, after: CameraCalibration) -> tuple[float, float]:
    """How far (m) the optical centre moved and by how much (degrees) the camera turned."""
    a, b = np.array(before.T_cam_world), np.array(after.T_cam_world)
    centre = lambda T: -T[:3, :3].T @ T[:3, 3]  # noqa: E731
    turn = b[:3, :3] @ a[:3, :3].T
    angle = math.degrees(math.acos(np.clip((np.trace(turn) - 1) / 2, -1, 1)))
    return float(np.linalg.norm(centre(b) - centre(a))), angle


def test_level_zero_file_is_the_calibration_and_level_l_moves_by_l(tmp_path, calibrations):
    path = checkpoint_dir(tmp_path / "ckpt", "omnid", calibrations)
    checkpoint = checkpoint_from_config("omnid", path, json.loads((path / "config.json").read_text()))
    original = checkpoint.calibrations
    zero = perturbed_calibrations(original, camera_offsets(0.0, 1, 0))
    assert zero == dict(original)
    # Through the files the command writes and the policy reads.
    settings = RobustnessSettings("select_apple", levels=LEVELS, draws=2, groups=("calibration",))
    config = json.loads((path / "config.json").read_text())
    written = robustness.write_calibration_files(checkpoint, config, settings, tmp_path / "out")
    assert written == (len(LEVELS) - 1) * 2
    for level in LEVELS[1:]:
        for draw in (1, 2):
            file = tmp_path / "out" / "calibration" / "omnid" / "calibration" / f"{level:g}cm_{level:g}deg"
            loaded = load_calibration_file(file / f"draw{draw}.json")
            assert sorted(loaded) == [image_key(c) for c in TRAIN_CAMERAS]
            for cam in TRAIN_CAMERAS:
                moved = loaded[image_key(cam)]
                distance, angle = centre_and_turn(original[cam], moved)
                assert distance == pytest.approx(level / 100, abs=1e-8), (level, cam)
                assert angle == pytest.approx(level, abs=1e-5), (level, cam)
                assert moved.K == original[cam].K and moved.image_size == original[cam].image_size


def test_draw_ids_pick_draws_and_the_report_names_them():
    settings = RobustnessSettings("select_apple", draws=3, draw_ids=(7, 2))
    assert settings.draw_numbers == (7, 2)
    assert RobustnessSettings("select_apple", draws=3).draw_numbers == (1, 2, 3)
    assert robustness.draws_text({"draws": 3, "draw_ids": [7, 2]}) == "draws 7, 2"
    assert robustness.draws_text({"draws": 3}) == "3"  # a summary written before the option


def test_draws_are_seeded_different_and_paired_across_levels():
    first = camera_offsets(1.0, 1, 0)
    assert first == camera_offsets(1.0, 1, 0)
    assert first != camera_offsets(1.0, 2, 0) and first != camera_offsets(1.0, 1, 1)
    assert sorted(first) == [f"cam_{c}" for c in "abcde"]
    directions = {cam: np.array(v) for cam, v in first.items()}
    for cam, v in camera_offsets(4.0, 1, 0).items():  # the same directions, 4x the size
        np.testing.assert_allclose(np.array(v), 4 * directions[cam], atol=1e-8)
    rotations = np.array([v[:3] for v in first.values()])
    assert len({tuple(np.round(r, 6)) for r in rotations}) == 5  # a random axis per camera


def test_bumped_env_is_the_mirror_of_the_perturbed_calibration(calibrations):
    """The env's cameras moved by a draw's offsets have exactly the calibration the calibration-error file of
    that draw gives the policy: the two conditions are mirror images."""
    offsets = camera_offsets(2.0, 3, 0)
    originals = {c: CameraCalibration.from_dict(calibrations[image_key(c)]) for c in TRAIN_CAMERAS}
    believed = perturbed_calibrations(originals, offsets)
    env = gym.make("gym_omnid/select_apple", image_size=SIZE, camera_offsets=offsets).unwrapped
    try:
        for cam in TRAIN_CAMERAS:
            actual = env.camera_calibration(cam)["T_cam_world"]
            np.testing.assert_allclose(actual, np.array(believed[cam].T_cam_world), atol=1e-9)
    finally:
        env.close()


def test_plan_cells_and_options_per_policy(tmp_path, calibrations):
    omnid_config = checkpoint_config("omnid", calibrations)
    omnid = checkpoint_from_config("omnid", tmp_path / "o", omnid_config, {"seed": 1000})
    dp = checkpoint_from_config("dp", tmp_path / "d", checkpoint_config("diffusion", calibrations))
    settings = RobustnessSettings("select_apple", eval_seeds=(1, 2), episodes=3, episode_length=50)
    conditions = lambda c: [cell.condition for cell in plan_cells(c, settings)]  # noqa: E731
    assert conditions(omnid).count("calibration") == 4 * 3 and conditions(omnid).count("bumped") == 12
    assert conditions(omnid).count("dead_removed") == 4 and "scrambled" in conditions(omnid)
    assert set(conditions(dp)) == {"nominal", "bumped", "dead_black", "dead_black_mid", "blind"}
    runs = build_runs([omnid, dp], settings, tmp_path / "out")
    assert len(runs) == 2 * (39 + 22) and len({r.name for r in runs}) == len(runs)
    assert {flag(r.cmd, "seed") for r in runs} == {"1000", "2000"}
    assert {flag(r.cmd, "eval.batch_size") for r in runs} == {"3"}  # at most the episodes of a run
    two_envs = build_runs([dp], dataclasses.replace(settings, batch_size=2), tmp_path / "out")
    assert {flag(r.cmd, "eval.batch_size") for r in two_envs} == {"2"}
    by_name = {r.name: r for r in runs}
    calib = by_name["omnid/calibration/0.5cm_0.5deg/draw2/seed1"].cmd
    assert flag(calib, "policy.calibration_path").endswith(
        "calibration/omnid/calibration/0.5cm_0.5deg/draw2.json"
    )
    bumped = by_name["dp/bumped/2cm_2deg/draw1/seed2"].cmd
    offsets = json.loads(flag(bumped, "env.camera_offsets"))
    assert offsets == {c: list(v) for c, v in camera_offsets(2.0, 1, 0).items() if c in TRAIN_CAMERAS}
    removed = by_name["omnid/dead_removed/cam_c/seed1"].cmd
    assert flag(removed, "env.cameras") == "[cam_b,cam_d,cam_e]"
    assert json.loads(flag(removed, "policy.cameras")) == ["cam_b", "cam_d", "cam_e"]
    mid = by_name["dp/dead_black_mid/cam_e/seed1"].cmd
    assert flag(mid, "env.blackout_cameras") == "[cam_e]" and flag(mid, "env.blackout_from_step") == "25"
    assert flag(by_name["dp/blind/seed1"].cmd, "env.blackout_cameras") == "[cam_b,cam_c,cam_d,cam_e]"
    assert flag(by_name["omnid/blind/seed1"].cmd, "policy.calibration_path").endswith("omnid/blind.json")
    assert (
        by_name["omnid/nominal/seed1"].train_seed == 1000 and by_name["dp/nominal/seed1"].train_seed is None
    )
    # Every --env option is one LeRobot's env config parses and validates.
    for run in runs:
        env = draccus.parse(EnvOptions, args=[c for c in run.cmd if c.startswith("--env.")]).env
        assert env.episode_length == 50 and env.cameras == flag(run.cmd, "env.cameras")[1:-1].split(",")


@dataclasses.dataclass
class EnvOptions:
    """The ``--env.*`` options of a lerobot-eval command line."""

    env: EnvConfig


def rows_of(counts: dict[Cell, tuple[int, int]]) -> list:
    """Table rows of counts that all ran on eval seed 1."""
    return table_rows({cell: {1: value} for cell, value in counts.items()})


def test_rows_compare_with_as_trained_on_the_same_eval_seeds():
    counts = {
        Cell("nominal"): {1: (8, 10), 2: (2, 10)},  # seed 2's layouts are harder
        Cell("calibration", 1.0, 1): {1: (6, 10)},
        Cell("dead_black", camera="cam_b"): {1: (4, 10)},
        Cell("dead_black", camera="cam_c"): {1: (4, 10), 2: (1, 10)},
        Cell("blind"): {1: (0, 10), 2: (0, 10)},
    }
    rows = {r.key: r for r in table_rows(counts)}
    assert rows[("nominal", "none")].result == CellResult(10, 20, ())
    assert rows[("calibration", "1 cm, 1 deg")].as_trained == CellResult(8, 10, ())
    assert rows[("dead_black", "cam_c")].as_trained == CellResult(10, 20, ())
    assert rows[("dead_black", ANY_CAMERA)].as_trained == CellResult(10, 20, ())  # seeds of any part
    assert rows[("blind", "-")].as_trained == CellResult(10, 20, ())
    lines = "\n".join(checkpoint_lines("omnid", "x", list(rows.values()), None))
    assert "| calibration error (scene unchanged) | 1 cm, 1 deg | 6/10 | 60 (31-83) | 75 % |" in lines
    assert "against its blind control: +50 pp" in lines  # 10/20 against 0/20
    assert "(6/10 against 8/10; target >= 80 %): missed by 5 points" in "\n".join(
        target_lines(list(rows.values()))
    )


def test_table_pools_draws_and_cameras_and_names_the_controls(tmp_path):
    counts = {
        Cell("nominal"): (8, 10),
        Cell("calibration", 1.0, 1): (6, 10),
        Cell("calibration", 1.0, 2): (4, 10),
        Cell("bumped", 1.0, 1): (7, 10),
        Cell("dead_black", camera="cam_b"): (5, 10),
        Cell("dead_black", camera="cam_c"): (3, 10),
        Cell("blind"): (0, 10),
        Cell("scrambled"): (2, 10),
    }
    rows = rows_of(counts)
    keyed = {(r.condition, r.perturbation): r for r in rows}
    assert keyed[("calibration", "1 cm, 1 deg")].result.successes == 10
    assert keyed[("calibration", "1 cm, 1 deg")].parts == (("draw 1", 6, 10), ("draw 2", 4, 10))
    assert keyed[("dead_black", ANY_CAMERA)].result == CellResult(8, 20, ())
    conditions = [r.condition for r in rows]
    assert conditions[0] == "nominal" and conditions[-2:] == ["blind", "scrambled"]
    lines = "\n".join(checkpoint_lines("omnid", "a checkpoint", rows, "robustness_omnid.png"))
    assert "against its blind control: +80 pp" in lines and "significantly above it" in lines
    assert "| calibration error (scene unchanged) | 1 cm, 1 deg | 10/20 | 50 (30-70) | 62 % |" in lines
    assert "draw 1 6/10, draw 2 4/10" in lines and "![omnid" in lines
    table = comparison_lines({"omnid": rows, "dp": rows_of({Cell("nominal"): (5, 10)})})
    assert table[0] == "| Condition | Perturbation | omnid | dp |"
    assert any(
        line.startswith("| dead camera, black from the first step | any one | 40 (22-61), 8/20 | - |")
        for line in table
    )
    assert not any("| cam_b |" in line for line in table)  # pooled rows only
    png = robustness_chart("omnid", rows, tmp_path / "chart.png")
    assert png.stat().st_size > 10_000
    dp_rows = rows_of({Cell("nominal"): (5, 10), Cell("bumped", 1.0, 1): (2, 10), Cell("blind"): (1, 10)})
    both = comparison_chart({"omnid": rows, "dp": dp_rows}, tmp_path / "both.png")
    assert both.stat().st_size > 10_000


def test_spread_across_draws_names_the_worst_draw_and_tests_equal_rates():
    """A level's draws: worst, median and best named with their counts; draws that split 10/10 and 0/10 differ
    beyond chance, draws alike do not; one draw (bumped here) and dead cameras give no spread line."""
    counts = {
        Cell("nominal"): (9, 10),
        Cell("calibration", 2.0, 1): (10, 10),
        Cell("calibration", 2.0, 2): (0, 10),
        Cell("calibration", 2.0, 3): (6, 10),
        Cell("calibration", 4.0, 1): (5, 10),
        Cell("calibration", 4.0, 2): (5, 10),
        Cell("bumped", 2.0, 1): (7, 10),
        Cell("dead_black", camera="cam_b"): (5, 10),
        Cell("dead_black", camera="cam_c"): (3, 10),
    }
    lines = draw_spread_lines(rows_of(counts))
    assert lines[0] == "Spread across draws:" and len(lines) == 5
    two, four = lines[2], lines[3]
    assert two.startswith(
        "- calibration error (scene unchanged) at 2 cm, 2 deg, 3 draws: worst draw 2 0/10, median 6/10, "
        "best draw 1 10/10; equal rates across draws: chi2 = 20.4 (df 2), permutation p = "
    )
    assert float(two.rsplit("= ", 1)[1]) < 0.001
    assert four.endswith("chi2 = 0.0 (df 1), permutation p = 1")
    assert draw_spread_lines(rows_of({Cell("nominal"): (5, 10), Cell("calibration", 1.0, 1): (2, 10)})) == []
    report = "\n".join(checkpoint_lines("omnid", "a checkpoint", rows_of(counts), None))
    assert "Spread across draws:" in report and "worst draw 2 0/10" in report


def test_targets_are_shares_of_as_trained_counted_only_above_blind():
    counts = {
        Cell("nominal"): (8, 10),
        Cell("calibration", 1.0, 1): (7, 10),
        Cell("calibration", 2.0, 1): (1, 10),
        Cell("dead_removed", camera="cam_b"): (2, 10),
        Cell("dead_removed", camera="cam_c"): (4, 10),
        Cell("dead_black", camera="cam_b"): (5, 10),
        Cell("blind"): (0, 10),
    }
    lines = target_lines(rows_of(counts))
    assert lines[0] == "Robustness targets (counted: significantly above its blind control):"
    # 7/10 of 8/10 is 88 %; removed pooled 6/20 is 38 % (cam_b alone 25 %); black cam_b alone 62 %
    assert "at 1 cm, 1 deg: 88 % of as trained (7/10 against 8/10; target >= 80 %): met" in lines[2]
    assert (
        "removed from the inputs, any one: 38 % of as trained (6/20 against 8/10; target >= 50 %): "
        "missed by 12 points" in lines[3]
    )
    assert lines[3].endswith("worst camera cam_b 25 %")
    assert (
        "black from the first step, cam_b: 62 % of as trained (5/10 against 8/10; target >= 50 %): met"
        in lines[4]
    )
    weak = target_lines(rows_of({**counts, Cell("nominal"): (2, 10)}))
    assert weak[0].startswith("Robustness targets (not counted: not significantly above its blind control)")
    assert target_lines(rows_of({Cell("nominal"): (0, 10), Cell("calibration", 1.0, 1): (1, 10)})) == []


def test_between_checkpoints_compares_every_pair_on_shared_rows():
    a = rows_of(
        {Cell("nominal"): (9, 10), Cell("bumped", 1.0, 1): (8, 10), Cell("calibration", 1.0, 1): (8, 10)}
    )
    b = rows_of({Cell("nominal"): (1, 10), Cell("bumped", 1.0, 1): (8, 10)})
    c = rows_of({Cell("nominal"): (5, 10)})
    lines = between_lines({"omnid": a, "omnid_noise": b, "dp": c})
    assert lines[0] == "| Condition | Perturbation | omnid - omnid_noise | omnid - dp | omnid_noise - dp |"
    assert lines[2].startswith("| as trained | none | +80 pp (")
    assert "p = 0.0011" in lines[2]  # Fisher, 9/10 against 1/10
    bumped = "| bumped cameras (calibration unchanged) | 1 cm, 1 deg | +0 pp (-34 to +34), p = 1 | - | - |"
    assert lines[3] == bumped  # 8/10 both: Newcombe +-34
    assert len(lines) == 4  # calibration error: only omnid has it
    assert between_lines({"omnid": a}) == []


def test_description_names_every_eval_seed_and_how_rows_pool_them():
    checkpoint = Checkpoint("omnid", Path("ckpt"), "omnid", ("cam_b",), 64, {}, 1000)
    one = robustness.describe(checkpoint, RobustnessSettings("select_apple", eval_seeds=(1,), episodes=10))
    assert "env seeds 1000-1009, episodes" in one and "pools" not in one
    two = robustness.describe(checkpoint, RobustnessSettings("select_apple", eval_seeds=(1, 2), episodes=10))
    assert "env seeds 1000-1009, 2000-2009 (each row pools the eval seeds it ran on and is compared" in two


def test_paths_under_the_working_folder_are_shown_relative(tmp_path, monkeypatch):
    """A committed summary or report never carries one machine's absolute path."""
    monkeypatch.chdir(tmp_path)
    inside = (tmp_path / "outputs" / "ckpt").absolute()
    checkpoint = Checkpoint("omnid", inside, "omnid", ("cam_b",), 64, {}, 1000)
    text = robustness.describe(checkpoint, RobustnessSettings("select_apple", eval_seeds=(1,), episodes=10))
    assert text.startswith("`outputs/ckpt` (policy") and str(tmp_path) not in text
    outside = tmp_path.parent / "elsewhere"
    assert robustness.shown_path(outside) == str(outside)


def test_no_control_no_verdict_and_no_nominal():
    rows = rows_of({Cell("nominal"): (0, 4)})
    lines = checkpoint_lines("dp", "x", rows, None)
    assert "| as trained | none | 0/4 | 0 (0-49) | n/a |" in "\n".join(lines)
    assert "No evaluation as trained yet." in checkpoint_lines("dp", "x", [], None)


def _fake_eval(calls: list[str], rates: dict[str, float]):
    """A stand-in for run_logged: writes the eval_info.json lerobot-eval would (success % per cell name)."""

    def run(cmd, log_path, on_line=None):
        log_path.parent.mkdir(parents=True, exist_ok=True)
        out = Path(flag(cmd, "output_dir"))  # <out>/eval/<label>/<cell name>/seed<k>
        cell = "/".join(out.relative_to(out.parents[-1]).parts[-4:-1])
        calls.append(cell)
        out.mkdir(parents=True, exist_ok=True)
        rate = next((v for k, v in rates.items() if k in cell), 50.0)
        n = int(flag(cmd, "eval.n_episodes"))
        (out / "eval_info.json").write_text(json.dumps({"overall": {"pc_success": rate, "n_episodes": n}}))
        return 0

    return run


def test_main_runs_reports_and_resumes(monkeypatch, tmp_path, calibrations, capsys):
    monkeypatch.setattr(robustness, "code_commit", lambda: "abc123")  # git runs in a subprocess
    omnid = checkpoint_dir(tmp_path / "omnid", "omnid", calibrations)
    dp = checkpoint_dir(tmp_path / "dp", "diffusion", calibrations)
    calls: list[str] = []
    monkeypatch.setattr(engine, "run_logged", _fake_eval(calls, {"nominal": 80.0, "blind": 0.0}))
    out = tmp_path / "out"
    common = ["--checkpoint", f"omnid={omnid}", "--checkpoint", str(dp), "--out", str(out), "--draws", "2"]
    common += ["--eval-episodes", "5", "--dead-cameras", "cam_b,cam_c"]
    argv = [*common, "--levels", "0,1,2"]
    assert robustness.main(argv) == 0
    n_omnid = 1 + 2 * 2 + 2 * 2 + 3 * 2 + 2
    n_dp = 1 + 2 * 2 + 2 * 2 + 1
    assert len(calls) == n_omnid + n_dp
    text = capsys.readouterr().out
    assert f"{n_omnid + n_dp} evaluations: {n_omnid + n_dp} ran" in text
    assert "omnid as trained none: 4/5 = 80%" in text and "diffusion blind control -: 0/5 = 0%" in text
    report = (out / "report.md").read_text()
    assert "## omnid" in report and "## diffusion" in report and "| omnid | diffusion |" in report
    assert (out / "robustness_omnid.png").is_file() and (out / "robustness_diffusion.png").is_file()
    assert (out / robustness.COMPARISON_CHART).stat().st_size > 10_000
    assert f"]({robustness.COMPARISON_CHART})" in report
    assert "| Condition | Perturbation | omnid - diffusion |" in report and "Robustness targets" in report
    summary = json.loads((out / "summary.json").read_text())
    nominal = summary["results"]["checkpoints"]["omnid"]["rows"][0]
    assert nominal["condition"] == "nominal" and nominal["successes"] == 4
    records = [e for e in summary["evaluations"] if e["model"] == "omnid" and e["setting"] == "nominal"]
    assert [(e["eval_seed"], e["successes"], e["tags"]["condition"]) for e in records] == [(1, 4, "nominal")]
    stamp = json.loads((out / "stamps" / "omnid" / "nominal" / "seed1.json").read_text())
    assert "lerobot-eval" in stamp["command"] and len(stamp["fingerprint"]) == 16
    assert len(list((out / "calibration" / "omnid").rglob("*.json"))) == 2 * 2 + 2
    # Its summary.json alone rebuilds the same report, with no checkpoint and no run folder.
    rebuilt = tmp_path / "rebuilt"
    argv_summary = ["--out", str(rebuilt), "--report-only", "--summary", str(out / "summary.json")]
    assert robustness.main(argv_summary) == 0
    assert (rebuilt / "report.md").read_text() == report
    assert (rebuilt / robustness.COMPARISON_CHART).is_file() and not (rebuilt / "stamps").exists()
    # Resumed: nothing runs again; a new level adds only its runs.
    calls.clear()
    assert robustness.main(argv) == 0 and calls == []
    assert robustness.main([*common, "--levels", "0,1,2,4"]) == 0
    assert len(calls) == 2 * 2 + 2 * 1  # OmniD: calibration and bumped, 2 draws; DP: bumped
    # Settings that would mix with the finished runs are refused, by option.
    with pytest.raises(SystemExit):
        robustness.main([*argv, "--eval-episodes", "3"])
    assert "--eval-episodes: expected 5 as in the finished runs" in capsys.readouterr().err


def test_dry_run_prints_every_command_and_writes_nothing(tmp_path, calibrations, capsys):
    omnid = checkpoint_dir(tmp_path / "omnid", "omnid", calibrations)
    out = tmp_path / "out"
    assert robustness.main(["--checkpoint", str(omnid), "--out", str(out), "--dry-run"]) == 0
    text = capsys.readouterr().out
    assert "39 evaluations, 39 to run" in text and text.count("lerobot-eval --policy.path=") == 39
    assert "calibration error (scene unchanged) 12" in text
    assert text.count("--eval.batch_size=5 ") == 39  # the mini benchmark's envs at once by default
    assert not out.exists()
    # --draw-ids: only the draws asked for (each level, the same offsets as in a full run), named by number.
    capsys.readouterr()
    argv = ["--checkpoint", str(omnid), "--out", str(out), "--dry-run", "--conditions", "calibration"]
    assert robustness.main([*argv, "--levels", "2", "--draw-ids", "7,3"]) == 0
    text = capsys.readouterr().out
    assert text.count("lerobot-eval --policy.path=") == 3  # as trained, draws 7 and 3
    assert "calibration/2cm_2deg/draw7" in text and "calibration/2cm_2deg/draw3" in text
    assert "draw1" not in text and not out.exists()


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--checkpoint", "nowhere"], "--checkpoint: expected a pretrained_model folder with a config.json"),
        (["--levels", "0,-1"], "--levels: expected numbers >= 0"),
        (["--draws", "0"], "--draws: expected an integer >= 1"),
        (["--eval-seeds", "0"], "--eval-seeds: expected positive integers"),
        (["--draw-ids", "0,3"], "--draw-ids: expected draws in [1, 999], got [0, 3]"),
        (["--eval-batch-size", "0"], "--eval-batch-size: expected an integer >= 1"),
        (["--dead-cameras", "cam_a"], "--dead-cameras: expected inputs of checkpoint omnid"),
        (["--conditions", "calibration,nope"], "--conditions: expected comma-separated distinct values"),
        (["--dry-run", "--report-only"], "expected at most one of them"),
        (["DUP"], "expected a distinct label"),
        (["--summary", "summary.json"], "--summary: expected with --report-only"),
        (["NONE", "--out", "o"], "--checkpoint: expected at least one [LABEL=]PATH, got none"),
    ],
)
def test_bad_arguments_are_named(argv, expected, tmp_path, calibrations, capsys):
    omnid = checkpoint_dir(tmp_path / "omnid", "omnid", calibrations)
    if argv == ["DUP"]:
        argv = ["--checkpoint", f"a={omnid}", "--checkpoint", f"a={omnid}"]
    elif argv[0] == "NONE":
        argv = argv[1:]
    elif "--checkpoint" not in argv:
        argv = ["--checkpoint", str(omnid), *argv]
    with pytest.raises(SystemExit):
        robustness.main([*argv, "--out", str(tmp_path / "out")])
    assert expected in capsys.readouterr().err


def test_checkpoint_config_errors_name_the_field(tmp_path, calibrations):
    config = checkpoint_config("omnid", calibrations)
    with pytest.raises(ValueError, match="camera_calibration: expected every image input"):
        checkpoint_from_config("o", tmp_path, {**config, "camera_calibration": {}})
    with pytest.raises(ValueError, match="input_features: expected images of fixed cameras"):
        checkpoint_from_config("o", tmp_path, {**config, "input_features": {}})
    with pytest.raises(ValueError, match="frame_calibration: expected a static calibration"):
        checkpoint_from_config("o", tmp_path, {**config, "frame_calibration": ["observation.images.cam_b"]})
    wide = {**config["input_features"], "observation.images.cam_b": {"type": "VISUAL", "shape": [3, 64, 96]}}
    with pytest.raises(ValueError, match="expected square images of one size"):
        checkpoint_from_config("o", tmp_path, {**config, "input_features": wide})


def test_report_only_rebuilds_the_committed_table_from_its_summary_alone(tmp_path, capsys):
    """The committed summary of the three-checkpoint sweep rebuilds the table docs/results.md quotes."""
    summary = COMMITTED_SUMMARIES / "robustness_mini_three_cpu2.json"
    assert robustness.main(["--out", str(tmp_path), "--report-only", "--summary", str(summary)]) == 0
    report = (tmp_path / "report.md").read_text()
    row = "| calibration error (scene unchanged) | 1 cm, 1 deg | 73 (56-86), 22/30 | 37 (22-54), 11/30 | - |"
    assert row in report
    assert "| dead camera, black from mid-episode | any one | 70 (55-82), 28/40 |" in report
    assert (tmp_path / "robustness_omnid_noise.png").is_file()
