"""The readout-selection protocol: the candidates differ only in their readout, validation never touches a
test or training seed, the rule picks as written, the test phase only evaluates the selected readout and
the paper's, and the report reads only runs made for the plan."""

import json
from pathlib import Path

import pytest
from omnid_testing import COMMITTED_SUMMARIES, command_options

from lerobot_omnid.benchmark import readout_selection as rs
from lerobot_omnid.benchmark.plan import FEWSHOT_SEED, HELDOUT_SEED, PROFILES
from lerobot_omnid.measure import engine
from lerobot_omnid.policy.plane_readout import PLANE_READOUTS

OUT, DATA = Path("out"), Path("data")


def test_candidates_differ_only_in_their_readout():
    keypoints = command_options(rs.train(OUT, DATA, "keypoints", "cpu"))
    assert keypoints["--policy.plane_readout"] == "keypoints" and keypoints["--steps"] == "1000"
    for readout in PLANE_READOUTS:
        other = command_options(rs.train(OUT, DATA, readout, "cpu"))
        differ = {k for k in keypoints.keys() | other.keys() if keypoints.get(k) != other.get(k)}
        expected = set() if readout == "keypoints" else {"--policy.plane_readout", "--output_dir"}
        if readout == "flatten":  # the paper compresses the plane to one channel
            expected.add("--policy.compressed_channels")
            assert other["--policy.compressed_channels"] == "1"
        assert differ == expected


def env_seeds(first: int, episodes: int) -> set[int]:
    return set(range(first, first + episodes))


def test_validation_seeds_are_disjoint_from_training_test_and_other_recordings():
    validation = env_seeds(rs.VALIDATION_SEED, rs.VALIDATION_EPISODES)
    validation |= env_seeds(rs.VALIDATION_HELDOUT_SEED, rs.VALIDATION_HELDOUT_EPISODES)
    paper = PROFILES["paper"]
    test = {s for k in paper.eval_seeds for s in env_seeds(k * 1000, paper.eval_episodes)}
    others = env_seeds(0, 1000) | env_seeds(FEWSHOT_SEED, 1000) | env_seeds(HELDOUT_SEED, 1000)
    assert not validation & (test | others | env_seeds(rs.TEST_SEED, rs.TEST_EPISODES))
    cmd = command_options(rs.evaluation(OUT, "validation", "bev_conv", "id", "cpu").cmd)
    assert cmd["--seed"] == str(rs.VALIDATION_SEED) and cmd["--eval.n_episodes"] == "20"
    assert cmd["--env.layout"] == "id" and cmd["--env.background"] == "id"
    record_cmd = rs.validation_runs(OUT, DATA, "cpu", record_data=False)[0].cmd
    assert record_cmd[record_cmd.index("--seed") + 1] == str(rs.VALIDATION_HELDOUT_SEED)


def result(successes: int, position_cm: float) -> dict:
    return {"successes": successes, "episodes": 20, "position_cm": position_cm, "gripper": 0.03}


@pytest.mark.parametrize(
    ("results", "expected"),
    [
        ({"flatten": result(3, 1.0), "keypoints": result(9, 2.0), "bev_conv": result(6, 0.5)}, "keypoints"),
        # within one success of the most: the lower open-loop error decides
        ({"flatten": result(3, 1.0), "keypoints": result(9, 2.0), "bev_conv": result(8, 0.5)}, "bev_conv"),
        # equal on both: the order of PLANE_READOUTS (the paper's first)
        ({"flatten": result(5, 1.0), "keypoints": result(5, 1.0)}, "flatten"),
    ],
)
def test_selection_rule(results, expected):
    assert rs.select(results) == expected


def test_test_phase_evaluates_only_the_selected_readout_and_the_papers():
    runs = rs.test_runs(OUT, "latent_queries", "cpu")
    readouts = {run.name.split("/")[2] for run in runs if run.kind == "eval"}
    assert readouts == {"latent_queries", "flatten"}
    evals = [command_options(run.cmd) for run in runs if run.kind == "eval"]
    assert {e["--seed"] for e in evals} == {str(rs.TEST_SEED)} and {
        e["--eval.n_episodes"] for e in evals
    } == {"30"}
    assert len(evals) == 2 * (len(rs.TEST_SETTINGS) + 1)
    blind = [e for e in evals if "--policy.calibration_path" in e]
    assert len(blind) == 2 and all(e["--policy.calibration_path"].endswith("blind.json") for e in blind)
    assert len(rs.test_runs(OUT, "flatten", "cpu")) == len(runs) // 2  # flatten selected: once


def write_eval(folder: Path, successes: int, episodes: int) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    overall = {"pc_success": 100 * successes / episodes, "n_episodes": episodes}
    (folder / "eval_info.json").write_text(json.dumps({"overall": overall}))


def finish(runs, made: dict[str, tuple[int, int] | float]) -> None:
    """Leave each run named in ``made`` finished for its plan: an evaluation's counts (successes,
    episodes), an open-loop run's TCP error (cm), and its stamp."""
    for run in runs:
        if run.name not in made:
            continue
        run.output.mkdir(parents=True, exist_ok=True)
        if run.kind == "eval":
            write_eval(run.output, *made[run.name])
        else:
            errors = {"position_cm": made[run.name], "gripper": 0.02}
            (run.output / rs.OFFLINE_OUTPUT).write_text(json.dumps(errors))
        engine.write_stamp(run, "abc", 1.0)


def test_report_tables_the_validation_and_tests_selected_against_flatten(tmp_path):
    (tmp_path / rs.SELECTION_FILE).write_text(json.dumps({"selected": "bev_conv"}))
    runs = rs.protocol(tmp_path, tmp_path / "data", "cpu", True, "bev_conv")
    made = {"eval/validation/flatten": (2, 20), "offline/flatten": 1.5}
    made |= {"eval/validation/bev_conv": (11, 20), "offline/bev_conv": 0.7}
    made |= {"eval/test/bev_conv/id": (7, 30), "eval/test/flatten/id": (4, 30)}
    finish(runs, made)
    summary = rs.report(tmp_path, runs)
    validation = {r.key[0]: r.successes for r in summary.evaluations if r.tag("phase") == "validation"}
    assert validation == {"flatten": 2, "bev_conv": 11}
    assert {r.commit for r in summary.evaluations} == {"abc"}
    assert rs.validation_results(runs)["bev_conv"] == {
        "successes": 11,
        "episodes": 20,
        "position_cm": 0.7,
        "gripper": 0.02,
    }
    text = (tmp_path / "report.md").read_text()
    assert "| bev_conv | 11/20 (34.2-74.2 %) | 0.70 | 0.020 | **yes** |" in text
    assert "| flatten | 2/20 (2.8-30.1 %) | 1.50 | 0.020 |  |" in text
    assert "| id | 4/30 (5.3-29.7 %) | 7/30 (11.8-40.9 %) | 0.506 |" in text  # PLANE_READOUTS' order
    assert "| ood1 | — | — |  |" in text


def test_report_leaves_out_runs_not_made_for_the_plan(tmp_path):
    """Outputs without a stamp of this plan (another plan's, or a copied folder's) are not results."""
    runs = rs.protocol(tmp_path, tmp_path / "data", "cpu", True, None)
    finish(runs, {"eval/validation/flatten": (2, 20), "offline/flatten": 1.5})
    other = rs.protocol(tmp_path, tmp_path / "other_data", "cpu", True, None)
    assert rs.report(tmp_path, other).evaluations == []
    assert rs.validation_results(other) == {}
    assert [r.key[0] for r in rs.report(tmp_path, runs).evaluations] == ["flatten"]


def test_dry_run_plans_validation_then_test_once_selected(tmp_path, capsys):
    rs.main(["--out", str(tmp_path), "--dry-run"])
    planned = capsys.readouterr().out
    assert planned.count("lerobot-train") == len(PLANE_READOUTS) and "eval/test/" not in planned
    (tmp_path / rs.SELECTION_FILE).write_text(json.dumps({"selected": "keypoints"}))
    rs.main(["--out", str(tmp_path), "--test", "--dry-run"])
    assert "eval/test/keypoints/id_blind" in capsys.readouterr().out


def test_data_of_another_size_is_refused(tmp_path, capsys):
    data = tmp_path / "data"
    (data / "meta").mkdir(parents=True)
    (data / "meta" / "info.json").write_text(json.dumps({"total_episodes": 3}))
    with pytest.raises(SystemExit):
        rs.main(["--out", str(tmp_path / "out"), "--data", str(data)])
    assert "--data: expected a dataset of 50 episodes, got 3" in capsys.readouterr().err


def test_report_only_rebuilds_the_committed_tables_from_their_summary_alone(tmp_path, capsys):
    """``--report-only --summary`` needs no run folder: the committed summary gives the validation table
    with its selection and the test table that docs/results.md quotes, the pooled unseen tables included."""
    summary = COMMITTED_SUMMARIES / "readouts_seed1000_cpu2.json"
    rs.main(["--out", str(tmp_path), "--report-only", "--summary", str(summary)])
    report = (tmp_path / "report.md").read_text()
    assert "| keypoints | 13/20 (43.3-81.9 %) | 0.83 | 0.030 | **yes** |" in report
    assert "| id | 2/30 (1.8-21.3 %) | 24/30 (62.7-90.5 %) | 7.51e-09 |" in report
    assert "| unseen tables, pooled | 10/120 (4.6-14.7 %) | 26/120 (15.2-29.9 %) | 0.0061 |" in report
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.md"]
