"""The MetaWorld feature-stage validation: the candidates differ from the comparison's OmniD in their stage
alone, the comparison's trained model is reused, the validation seeds are disjoint from the
demonstrations' and the test's, and the rule chooses as the protocol says."""

import json

import pytest
from omnid_testing import COMMITTED_SUMMARIES, command_options

from lerobot_omnid.benchmark import metaworld_comparison as mw
from lerobot_omnid.benchmark import metaworld_validation as mv
from lerobot_omnid.measure import engine
from lerobot_omnid.measure.results import CellResult, read_run_summary, write_run_summary

COMMITTED = COMMITTED_SUMMARIES / "metaworld_stage_validation_cpu2.json"


def test_candidates_differ_from_the_comparisons_omnid_in_the_stage_alone(tmp_path):
    runs = {r.name: r for r in mv.protocol(tmp_path)}
    compared = {r.name: r for r in mw.protocol(tmp_path, [mv.TASK], {"omnid": mw.MODELS["omnid"]})}
    # The comparison's record and OmniD run are the same runs (fingerprints): a copied folder reuses them.
    for name in (f"record/{mv.TASK}", f"train/omnid/{mv.TASK}"):
        assert runs[name].fingerprint == compared[name].fingerprint
    reference = command_options(runs[f"train/omnid/{mv.TASK}"].cmd)
    for name, model in mv.CANDIDATES.items():
        trained = command_options(runs[f"train/{name}/{mv.TASK}"].cmd)
        assert trained.pop("--policy.backbone_layer") == str(model.backbone_layer)
        assert trained.pop("--output_dir").endswith(f"train/{name}/{mv.TASK}")
        assert trained == {
            k: v for k, v in reference.items() if k not in ("--policy.backbone_layer", "--output_dir")
        }
    assert sorted(m.backbone_layer for m in mv.CANDIDATES.values()) == [1, 2, 3]


def test_validation_seeds_are_disjoint_from_the_demonstrations_and_the_test(tmp_path):
    evals = [command_options(r.cmd) for r in mv.protocol(tmp_path) if r.kind == "eval"]
    assert len(evals) == 2 * len(mv.CANDIDATES)  # each with its blind control
    assert {e["--seed"] for e in evals} == {str(mv.VALIDATION_SEED)}
    assert all(e["--eval.n_episodes"] == str(mv.VALIDATION_EPISODES) for e in evals)
    validated = set(range(mv.VALIDATION_SEED, mv.VALIDATION_SEED + mv.VALIDATION_EPISODES))
    used = set(range(mw.DEMONSTRATIONS)).union(*(range(s, s + mw.TEST_EPISODES) for s in mw.TEST_SEEDS))
    assert not validated & used
    assert sum("--env.blackout_cameras" in e for e in evals) == len(mv.CANDIDATES)


def cells(counts: dict[str, tuple[int, int]]) -> dict[tuple[str, str], CellResult]:
    """(candidate, control) -> counts of 20, from candidate -> (validation, blind) successes."""
    found = {}
    for name, (seen, blind) in counts.items():
        found[name, ""] = CellResult(seen, mv.VALIDATION_EPISODES, ())
        found[name, "blind"] = CellResult(blind, mv.VALIDATION_EPISODES, ())
    return found


@pytest.mark.parametrize(
    ("counts", "chosen"),
    [
        ({"omnid": (4, 4), "omnid_layer1": (9, 3), "omnid_layer2": (7, 2)}, "omnid_layer1"),
        (
            {"omnid": (4, 4), "omnid_layer1": (9, 9), "omnid_layer2": (7, 2)},
            "omnid_layer2",
        ),  # not above blind
        (
            {"omnid": (8, 4), "omnid_layer1": (8, 3), "omnid_layer2": (8, 2)},
            "omnid",
        ),  # ties: the comparison's
        (
            {"omnid": (4, 4), "omnid_layer1": (8, 3), "omnid_layer2": (8, 2)},
            "omnid_layer1",
        ),  # then the cheaper
        ({"omnid": (2, 4), "omnid_layer1": (3, 3), "omnid_layer2": (1, 2)}, "omnid"),  # none qualifies
    ],
)
def test_the_rule(counts, chosen):
    assert mv.choose(cells(counts)) == chosen


def test_no_choice_while_a_validation_is_missing():
    found = cells({"omnid": (4, 4), "omnid_layer1": (9, 3), "omnid_layer2": (7, 2)})
    del found["omnid_layer2", "blind"]
    assert mv.choose(found) is None


def test_report_from_the_summary_alone(tmp_path):
    runs = mv.protocol(tmp_path)
    counts = {"omnid": (4, 4), "omnid_layer1": (11, 3), "omnid_layer2": (7, 2)}
    for run in runs:
        if run.kind != "eval":
            continue
        successes = counts[run.result[0]][run.control == "blind"]
        run.output.mkdir(parents=True)
        overall = {
            "pc_success": 100 * successes / mv.VALIDATION_EPISODES,
            "n_episodes": mv.VALIDATION_EPISODES,
        }
        (run.output / "eval_info.json").write_text(json.dumps({"overall": overall}))
        engine.write_stamp(run, "abc", 1.0)
    summary = mv.summarise(runs)
    assert summary.results["chosen"] == "omnid_layer1"
    source = write_run_summary(tmp_path / "summary.json", summary)
    assert mv.main(["--out", str(tmp_path / "rebuilt"), "--report-only", "--summary", str(source)]) == 0
    report = (tmp_path / "rebuilt" / "report.md").read_text()
    assert "| omnid | 3 (4x4) | 4/20 (" in report
    assert (
        "| omnid_layer1 | 1 (16x16) | 11/20 (34.2-74.2 %) | 3/20 (" in report and "| **chosen** |" in report
    )
    assert "| omnid_layer2 | 2 (8x8) | 7/20" in report


def test_the_comparison_trains_omnid_at_the_stage_the_committed_validation_chose():
    summary = read_run_summary(COMMITTED, mv.PROTOCOL)
    chosen = mv.choose(mv.validation_cells(summary.evaluations))  # the rule again, on the committed counts
    assert chosen == summary.results["chosen"]
    assert mv.CANDIDATES[chosen].backbone_layer == mw.CHOSEN_STAGE
    for name in mw.DEFAULT_MODELS:
        model = mw.MODELS[name]
        assert model.policy != "omnid" or model.backbone_layer == mw.CHOSEN_STAGE, name
    assert mw.BASES[0] in mw.DEFAULT_MODELS
