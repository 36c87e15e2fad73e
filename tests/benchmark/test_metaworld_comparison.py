"""The MetaWorld comparison: every model trains on the same demonstrations with the same steps and seed,
each sees exactly its cameras, the test seeds are disjoint from the demonstrations', every evaluation has
its blind control, and the report is rebuilt from a summary alone."""

import json
from pathlib import Path

import pytest
from gym_omnid.metaworld_suite import STATE_DIM
from omnid_testing import command_options

from lerobot_omnid.benchmark import metaworld_comparison as mw
from lerobot_omnid.measure import engine
from lerobot_omnid.measure.results import write_run_summary

OUT = Path("out")


def test_models_train_alike_on_the_same_demonstrations():
    trainings = {
        name: command_options(mw.train(OUT, name, model, "push-v3")) for name, model in mw.MODELS.items()
    }
    for opts in trainings.values():
        assert opts["--dataset.root"] == str(OUT / "data" / "push-v3")
        assert opts["--steps"] == str(mw.STEPS) and opts["--seed"] == "1000"
    # What differs: the policy and its cameras (OmniD: by name; DP: its input features, state included).
    assert json.loads(trainings["omnid"]["--policy.cameras"]) == list(mw.MODELS["omnid"].cameras)
    assert json.loads(trainings["omnid_fixed"]["--policy.cameras"]) == ["corner", "corner2", "corner3"]
    assert trainings["omnid"]["--policy.volume_bounds"] == mw.VOLUME_BOUNDS
    features = json.loads(trainings["dp_corner2"]["--policy.input_features"])
    assert features == {
        "observation.state": {"type": "STATE", "shape": [STATE_DIM]},
        "observation.images.corner2": {"type": "VISUAL", "shape": [3, mw.IMAGE_SIZE, mw.IMAGE_SIZE]},
    }
    assert len(json.loads(trainings["dp"]["--policy.input_features"])) == 1 + 4
    common = {
        k: v for k, v in trainings["dp"].items() if k not in ("--policy.input_features", "--output_dir")
    }
    assert common == {
        k: v
        for k, v in trainings["dp_corner2"].items()
        if k not in ("--policy.input_features", "--output_dir")
    }


def test_demonstrations_and_test_seeds_are_disjoint():
    cmd = mw.record(OUT, "push-v3")
    record = dict(zip(cmd[1::2], cmd[2::2], strict=True))  # omnid-record takes "--option value" pairs
    assert record["--suite"] == "metaworld" and record["--episodes"] == str(mw.DEMONSTRATIONS)
    demonstrations = range(int(record["--seed"]), int(record["--seed"]) + mw.DEMONSTRATIONS)
    tested = [range(s, s + mw.TEST_EPISODES) for s in mw.TEST_SEEDS]
    seeds = [set(demonstrations), *map(set, tested)]
    assert sum(map(len, seeds)) == len(set().union(*seeds))


def test_every_evaluation_has_its_blind_control_on_the_same_seeds(tmp_path):
    runs = mw.protocol(tmp_path, ["push-v3"], mw.MODELS)
    evals = [command_options(r.cmd) for r in runs if r.kind == "eval"]
    assert len(evals) == len(mw.MODELS) * len(mw.TEST_SEEDS) * 2
    seen = [e for e in evals if "--env.blackout_cameras" not in e]
    blind = [e for e in evals if "--env.blackout_cameras" in e]
    assert {(e["--policy.path"], e["--seed"]) for e in seen} == {
        (e["--policy.path"], e["--seed"]) for e in blind
    }
    assert all(e["--env.blackout_cameras"] == e["--env.cameras"] for e in blind)
    assert all(e["--env.episode_length"] == str(mw.EPISODE_LENGTH) for e in evals)


def test_report_pools_the_ranges_and_puts_the_published_numbers_beside(tmp_path, capsys):
    runs = mw.protocol(tmp_path, ["push-v3"], {m: mw.MODELS[m] for m in ("omnid_layer2", "dp")})
    counts = {"eval/omnid_layer2": 12, "eval_blind/omnid_layer2": 1, "eval/dp": 6, "eval_blind/dp": 0}
    for run in runs:
        if run.kind != "eval":
            continue
        successes = next(v for k, v in counts.items() if run.name.startswith(k + "/"))
        run.output.mkdir(parents=True)
        overall = {"pc_success": 100 * successes / mw.TEST_EPISODES, "n_episodes": mw.TEST_EPISODES}
        (run.output / "eval_info.json").write_text(json.dumps({"overall": overall}))
        engine.write_stamp(run, "abc", 1.0)
    source = write_run_summary(tmp_path / "summary.json", mw.summarise(runs))
    assert mw.main(["--out", str(tmp_path / "rebuilt"), "--report-only", "--summary", str(source)]) == 0
    report = (tmp_path / "rebuilt" / "report.md").read_text()
    # Pooled over the ranges, each range, the blind control; OmniD's difference to DP and Fisher's p.
    assert (
        "| push-v3 | OmniD | 80.0 (62.7-90.5) | 12/15 (54.8-93.0 %) | 12/15 (54.8-93.0 %) | 2/30 (" in report
    )
    assert "| push-v3 | DP | 40.0 (24.6-57.7) | 6/15 (19.8-64.3 %) | 6/15 (19.8-64.3 %) | 0/30" in report
    assert "| +40.0 (+15.3 to +58.6) | 0.0033 |" in report
    assert "| push-v3 | 80.0 (62.7-90.5) | 40.0 (24.6-57.7) | 51 | 30 |" in report  # published DP3, DP beside
    assert (tmp_path / "rebuilt" / mw.CHART).stat().st_size > 0


def test_a_run_split_by_task_is_reported_as_one(tmp_path):
    """One task a session: each folder's summary alone, then the report of them merged."""
    sources = []
    for task, successes in (("push-v3", 9), ("assembly-v3", 4)):
        out = tmp_path / task
        runs = mw.protocol(out, [task], {"omnid_layer2": mw.MODELS["omnid_layer2"]})
        for run in runs:
            if run.kind == "eval":
                run.output.mkdir(parents=True)
                overall = {"pc_success": 100 * successes / mw.TEST_EPISODES, "n_episodes": mw.TEST_EPISODES}
                (run.output / "eval_info.json").write_text(json.dumps({"overall": overall}))
                engine.write_stamp(run, "abc", 1.0)
        sources.append(str(write_run_summary(out / "summary.json", mw.summarise(runs))))
    assert mw.main(["--out", str(tmp_path / "rebuilt"), "--report-only", "--summary", *sources]) == 0
    report = (tmp_path / "rebuilt" / "report.md").read_text()
    assert "| assembly-v3 | OmniD | 26.7 (14.2-44.4) † | 4/15" in report  # 8/30, as its blind control
    assert "| push-v3 | OmniD | 60.0 (42.3-75.4) † | 9/15" in report
    assert "| **pooled, 2 tasks** | OmniD | 43.3 (31.6-55.9) † |" in report
    assert "| mean of 2 | 43.3 | 75.0 | 22.5 |" in report  # the published means over the same tasks
    with pytest.raises(SystemExit):  # the same part twice would count its episodes twice
        mw.main(["--out", str(tmp_path / "twice"), "--report-only", "--summary", sources[0], sources[0]])


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["--tasks", "push-v3,make-tea-v3"],
            "--tasks: expected comma-separated distinct values from ['assembly-v3',",
        ),
        (
            ["--models", "omnid,act"],
            "--models: expected comma-separated distinct values from ['omnid_layer2',",
        ),
        (["--summary", "s.json"], "--summary: expected with --report-only"),
    ],
)
def test_bad_arguments_name_the_option(argv, message, tmp_path, capsys):
    with pytest.raises(SystemExit):
        mw.main(["--out", str(tmp_path), *argv])
    assert message in capsys.readouterr().err


def test_the_chosen_stage_is_the_base_and_the_first_stage_stands_beside(tmp_path):
    runs = mw.protocol(tmp_path, ["push-v3"], {m: mw.MODELS[m] for m in ("omnid_layer2", "omnid")})
    for run in runs:
        if run.kind == "eval":
            successes = 9 if run.name.startswith("eval/omnid_layer2/") else 3
            run.output.mkdir(parents=True)
            overall = {"pc_success": 100 * successes / mw.TEST_EPISODES, "n_episodes": mw.TEST_EPISODES}
            (run.output / "eval_info.json").write_text(json.dumps({"overall": overall}))
            engine.write_stamp(run, "abc", 1.0)
    mw.write_report(mw.summarise(runs), tmp_path / "report.md")
    report = (tmp_path / "report.md").read_text()
    assert "| push-v3 | OmniD | 60.0 (42.3-75.4) | 9/15" in report
    assert "| push-v3 | OmniD, stride 16 | 20.0 (9.5-37.3) † | 3/15" in report
    assert "| +40.0 (+15.3 to +58.6) | 0.0033 |" in report  # the chosen stage against the first
