"""The rigs-and-wrist protocol: each pair differs only where it should, and every evaluation gives the policy
the evaluated rig's own calibration."""

import json
from pathlib import Path

import pytest
from omnid_testing import COMMITTED_SUMMARIES, command_options

from lerobot_omnid.benchmark import rigs_and_wrist as rw
from lerobot_omnid.measure import engine
from lerobot_omnid.measure.results import read_run_summary

OUT = Path("out")


@pytest.mark.parametrize("pair", sorted(rw.PAIRS))
def test_pairs_train_with_the_same_steps_seed_and_options(pair):
    first, second = (command_options(rw.train(OUT, m)) for m in rw.PAIRS[pair])
    differ = {k for k in first.keys() | second.keys() if first.get(k) != second.get(k)}
    expected = {"--dataset.repo_id", "--dataset.root", "--output_dir"}
    assert differ == (expected | {"--policy.cameras"} if pair == "wrist" else expected)
    assert first["--steps"] == str(rw.PROFILE.steps) and first["--seed"] == str(rw.TRAIN_SEED)


def test_two_rigs_merge_the_default_and_closer_halves_into_the_size_of_one_rig():
    merge = command_options(rw.merge(OUT))
    assert merge["--operation.type"] == "merge"
    parts = [Path(root).name for root in json.loads(merge["--operation.roots"])]
    assert {rw.DATASETS[p][0] for p in parts} == {"default", "closer"}
    assert sum(rw.DATASETS[p][2] for p in parts) == rw.DATASETS["default_bcde"][2]
    # The unseen rigs are neither of the trained ones.
    assert {r for r, _ in rw.EVALS["two_rigs"]} - {"default"} == {"higher", "bumped"}


@pytest.mark.parametrize("blind", [False, True])
def test_evaluations_read_the_rig_calibration_of_every_frame(blind):
    cmd = command_options(rw.evaluate(OUT, "wrist", OUT / "ck", "higher", "id", 30, blind))
    assert cmd["--env.rig"] == "higher" and cmd["--env.per_frame_calibration"] == "true"
    assert "observation.images.cam_wrist" in cmd["--policy.frame_calibration"]
    assert cmd["--eval.n_episodes"] == "30" and cmd["--seed"] == str(rw.EVAL_SEED)
    assert ("--env.blackout_cameras" in cmd) == blind
    if blind:
        assert cmd["--env.blackout_cameras"] == cmd["--env.cameras"]


def test_report_gives_each_evaluation_its_own_commit_and_tests_the_pairs(tmp_path, capsys):
    """The report reads the counts of every finished evaluation and the commit that ran it (not the commit
    checked out when the report is written), and Fisher-tests each pair's shared cells."""
    finished = {
        ("two_rigs", "higher", "id", False): (7, "aaa"),
        ("one_rig", "higher", "id", False): (4, "bbb"),
    }
    checkpoints = {m: tmp_path / "train" / m / "ck" for m in rw.MODELS}
    runs = rw.protocol(tmp_path, checkpoints, {}, 30)
    by_output = {run.output: run for run in runs}
    for (model, rig, layout, blind), (successes, commit) in finished.items():
        folder = rw.eval_dir(tmp_path, model, rig, layout, blind)
        folder.mkdir(parents=True)
        overall = {"pc_success": 100 * successes / 30, "n_episodes": 30}
        (folder / "eval_info.json").write_text(json.dumps({"overall": overall}))
        engine.write_stamp(by_output[folder], commit, 1.0)
    rw.report(tmp_path, 30, {}, runs)
    rows = read_run_summary(tmp_path, rw.PROTOCOL).evaluations
    assert {(r.key[0], r.successes, r.commit) for r in rows} == {
        ("two_rigs", 7, "aaa"),
        ("one_rig", 4, "bbb"),
    }
    report = (tmp_path / "report.md").read_text()
    assert "Commits: aaa, bbb." in report
    assert "| rigs: two_rigs vs one_rig | higher | id | 7/30 | 4/30 | 0.506 |" in report


def test_report_only_rebuilds_the_committed_table_from_its_summary_alone(tmp_path, capsys):
    """``--report-only --summary`` needs no run folder: the committed summary gives every cell and the
    pooled unseen-rig comparison that docs/results.md quotes."""
    summary = COMMITTED_SUMMARIES / "rigs_and_wrist_cpu2.json"
    rw.main(["--out", str(tmp_path), "--report-only", "--summary", str(summary)])
    report = (tmp_path / "report.md").read_text()
    assert "| two_rigs | higher | id | - | 7/30 | 12-41 % |" in report
    pooled = "pooled (+5.0 pp, -11.3 to +21.0) | higher + bumped | id | 20/60 | 17/60 | 0.693 |"
    assert pooled in report
    assert not (tmp_path / "eval").exists()


def test_summary_without_report_only_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit):
        rw.main(["--out", str(tmp_path), "--summary", str(COMMITTED_SUMMARIES / "rigs_and_wrist_cpu2.json")])
    assert "--summary: expected with --report-only" in capsys.readouterr().err
