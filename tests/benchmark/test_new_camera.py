"""The new-camera protocol: its data and the mini pre-training are the benchmark's own runs, the hypotheses
differ only where they say, validation touches no other seed set and sees camera A alone, and the rule and
the report work from the validation counts alone."""

import dataclasses
import json
from pathlib import Path

import pytest
from omnid_testing import command_options

from lerobot_omnid.benchmark import new_camera as nc
from lerobot_omnid.benchmark import task_sizing
from lerobot_omnid.benchmark.methods import PAPER_RECIPE
from lerobot_omnid.benchmark.plan import (
    EVAL_SEED_STRIDE,
    FEWSHOT_SEED,
    HELDOUT_SEED,
    NEW_CAMERA_RECIPE,
    PROFILES,
    TASK0,
    ZERO_SHOT_RECIPE,
    build_plan,
)
from lerobot_omnid.benchmark.readout_selection import VALIDATION_HELDOUT_SEED, VALIDATION_SEED
from lerobot_omnid.diagnostics.position_extrapolation import PROBE_SEED
from lerobot_omnid.measure import engine
from lerobot_omnid.measure.results import EvalRecord, RunSummary, write_run_summary

ROOT = Path(__file__).resolve().parents[2]


def test_data_and_mini_pretraining_are_the_benchmarks_own_runs(tmp_path):
    fewshot = dataclasses.replace(PROFILES["mini-fewshot"], methods=("omnid",))
    expected = {r.name: r.cmd for r in build_plan(fewshot, tmp_path, (TASK0,))}
    runs = {r.name: r.cmd for r in nc.protocol(tmp_path)}
    for name in ("record/select_apple_bcde", "record/select_apple_a_fewshot", "train/omnid/select_apple"):
        assert runs[name] == expected[name], name
    # The paper's hypothesis is the benchmark's fine-tuning, in a folder of its own.
    paper, benchmark = (
        command_options(runs["finetune_validation/paper"]),
        command_options(expected["finetune/omnid/select_apple"]),
    )
    assert {k: v for k, v in paper.items() if k != "--output_dir"} == {
        k: v for k, v in benchmark.items() if k != "--output_dir"
    }


def test_hypotheses_differ_only_where_they_say(tmp_path):
    runs = {r.name: command_options(r.cmd) for r in nc.protocol(tmp_path)}
    mini, single = runs["train/omnid/select_apple"], runs["train/omnid_single_camera/select_apple"]
    assert set(single.items()) - set(mini.items()) == {
        ("--policy.single_camera_rate", "0.5"),
        ("--output_dir", str(tmp_path / "train" / "omnid_single_camera" / TASK0)),
    }
    long, low = runs["finetune_validation/long"], runs["finetune_validation/long_low_lr"]
    assert long["--steps"] == low["--steps"] == "1000" and low["--policy.optimizer_lr"] == "0.0001"
    assert "--policy.optimizer_lr" not in long
    single_long = runs["finetune_validation/single_camera_long"]
    assert single_long["--policy.path"].startswith(str(tmp_path / "train" / "omnid_single_camera"))
    frozen = runs["finetune_validation/long_frozen_head"]
    assert set(frozen.items()) - set(long.items()) == {
        ("--policy.frozen_modules", '["head"]'),
        ("--output_dir", str(tmp_path / "finetune_validation" / "long_frozen_head")),
    }


def test_replay_mixes_the_camera_a_episodes_with_as_many_training_episodes(tmp_path):
    """Both halves recorded with cameras A-E, camera A shown alone in the few-shot episodes and hidden in
    the replayed training episodes (the same env seeds as the training set's first), then merged; the
    fine-tuning fuses all five cameras, each sample only its visible ones."""
    runs = {r.name: r for r in nc.protocol(tmp_path)}
    fewshot, replayed = (runs[f"record/{nc.REPLAY_DATA}_{part}"] for part in ("a", "bcde"))
    for run, seed, hidden in ((fewshot, FEWSHOT_SEED, "cam_b,cam_c,cam_d,cam_e"), (replayed, 0, "cam_a")):
        cmd = list(run.cmd)
        assert cmd[cmd.index("--cameras") + 1] == "cam_a,cam_b,cam_c,cam_d,cam_e"
        assert cmd[cmd.index("--seed") + 1] == str(seed) and cmd[cmd.index("--hidden-cameras") + 1] == hidden
        assert cmd[cmd.index("--episodes") + 1] == "10"
    merge = runs[f"merge/{nc.REPLAY_DATA}"]
    assert merge.needs == (fewshot.name, replayed.name)
    tuned = runs["finetune_validation/long_replay"]
    assert merge.name in tuned.needs
    opts = command_options(tuned.cmd)
    assert opts["--dataset.root"] == str(merge.output) and opts["--steps"] == "1000"
    assert json.loads(opts["--policy.cameras"]) == ["cam_a", "cam_b", "cam_c", "cam_d", "cam_e"]


def test_validation_sees_camera_a_alone_on_seeds_of_its_own(tmp_path):
    evals = [command_options(r.cmd) for r in nc.protocol(tmp_path) if r.kind == "eval"]
    assert len(evals) == len(nc.PRETRAINED) + len(nc.HYPOTHESES)
    for opts in evals:
        assert opts["--env.cameras"] == "[cam_a]" and opts["--policy.cameras"] == '["cam_a"]'
        assert opts["--env.per_frame_calibration"] == "true" and opts["--seed"] == str(nc.VALIDATION_SEED)
    first, last = nc.VALIDATION_SEED, nc.VALIDATION_SEED + nc.VALIDATION_EPISODES - 1
    used = [(0, 999), (FEWSHOT_SEED, FEWSHOT_SEED + 999), (HELDOUT_SEED, HELDOUT_SEED + 999)]
    used += [(k * EVAL_SEED_STRIDE, k * EVAL_SEED_STRIDE + 99) for k in range(1, 50)]
    used += [
        (s, s + 999)
        for s in (VALIDATION_SEED, VALIDATION_HELDOUT_SEED, PROBE_SEED, task_sizing.VALIDATION_SEED)
    ]
    assert all(last < low or first > high for low, high in used)


@pytest.mark.parametrize(
    ("successes", "selected"),
    [
        ({"paper": 3, "long": 9, "single_camera_long": 10}, "long"),  # within 1: fewer steps, order
        ({"paper": 9, "long": 10, "single_camera_long": 2}, "paper"),  # fewer steps
        ({"paper": 0, "long": 2, "single_camera_long": 8}, "single_camera_long"),
        ({"paper": 0, "long": 2, "long_frozen_head": 10, "single_camera_long": 8}, "long_frozen_head"),
    ],
)
def test_rule_takes_the_most_successes_then_the_shortest_fine_tuning(successes, selected):
    counts = {h: successes.get(h, 1) for h in nc.HYPOTHESES}  # the others: 1 of 20
    assert nc.select({h: (s, 20) for h, s in counts.items()}) == selected


def test_report_only_rebuilds_the_report_from_a_summary(tmp_path, capsys):
    results = {"zero_shot_mini": (1, 20), "paper": (3, 20), "long": (7, 20), "long_frozen_head": (2, 20)}
    results["long_replay"] = (5, 20)
    settings = {
        "task": TASK0,
        "validation_seed": nc.VALIDATION_SEED,
        "validation_episodes": nc.VALIDATION_EPISODES,
        "hypotheses": {h: dataclasses.asdict(recipe) for h, recipe in nc.HYPOTHESES.items()},
    }
    evaluations = [
        EvalRecord((m, TASK0, "validation"), "", 1000, nc.VALIDATION_SEED, s, n, "x", "abc")
        for m, (s, n) in results.items()
    ]
    summary = RunSummary(nc.PROTOCOL, settings, evaluations, {"selected": None})
    source = write_run_summary(tmp_path / "summary.json", summary)
    assert nc.main(["--out", str(tmp_path / "out"), "--report-only", "--summary", str(source)]) == 0
    report = (tmp_path / "out" / "report.md").read_text()
    assert "| zero_shot_mini | mini | none (zero-shot) | 1/20 (0.9-23.6 %) |  |" in report
    assert "| long | mini | 1000 steps, mini's lr | 7/20 (18.1-56.7 %) |  |" in report
    assert "| long_frozen_head | mini | 1000 steps, mini's lr, head frozen | 2/20 (" in report
    assert "| long_replay | mini | 1000 steps, mini's lr, B-E episodes replayed | 5/20 (" in report


def test_summary_selects_only_once_every_hypothesis_is_validated(tmp_path):
    runs = nc.protocol(tmp_path)
    counts = {"paper": 2, "long": 8, "long_low_lr": 5, "single_camera_long": 7}
    counts |= {"long_frozen_head": 3, "long_frozen_backbone": 8, "long_replay": 1}
    for run in runs:
        hypothesis = run.name.removeprefix("validation/")
        if run.kind != "eval" or hypothesis not in counts:
            continue
        run.output.mkdir(parents=True)
        overall = {"pc_success": 100 * counts[hypothesis] / 20, "n_episodes": 20}
        (run.output / "eval_info.json").write_text(json.dumps({"overall": overall}))
        engine.write_stamp(run, "abc", 1.0)
        summary = nc.summarise(runs)
        found = {r.key[0]: (r.successes, r.episodes, r.commit) for r in summary.evaluations}
        assert found[hypothesis] == (counts[hypothesis], 20, "abc")
        assert summary.results["selected"] == ("long" if len(found) == len(counts) else None)


def test_the_test_profile_is_the_committed_selection_on_the_validations_runs(tmp_path):
    """``new-camera`` fine-tunes by the recipe the validation selected, beside the paper's and zero-shot,
    and reuses the validation's recordings and pre-trained OmniD (the same commands in the same --out)."""
    validation = json.loads((ROOT / "docs" / "results" / "new_camera_validation_cpu2.json").read_text())
    selected = validation["results"]["selected"]
    profile = PROFILES["new-camera"]
    assert profile.fewshot_recipes == (PAPER_RECIPE, NEW_CAMERA_RECIPE, ZERO_SHOT_RECIPE)
    assert dataclasses.replace(nc.HYPOTHESES[selected], label=NEW_CAMERA_RECIPE.label) == NEW_CAMERA_RECIPE
    assert (profile.train_seeds, profile.eval_seeds, profile.eval_episodes) == ((1000, 1001), (1, 2), 15)
    test_runs = {r.name: r.cmd for r in build_plan(profile, tmp_path, (TASK0,))}
    validation_runs = {r.name: r.cmd for r in nc.protocol(tmp_path)}
    for name in ("record/select_apple_bcde", "record/select_apple_a_fewshot", "train/omnid/select_apple"):
        assert test_runs[name] == validation_runs[name], name
    # Controls: each camera-A model's blind one; the B-E models' are mini's, not run again.
    controls = [name for name in test_runs if name.startswith(("eval_", "calibration/"))]
    assert controls and all("/fewshot_a/" in name and "blind" in name for name in controls), controls
    tuned = command_options(test_runs[f"finetune/omnid_{selected}/select_apple"])
    chosen = command_options(validation_runs[f"finetune_validation/{selected}"])
    assert {k: v for k, v in tuned.items() if k != "--output_dir"} == {
        k: v for k, v in chosen.items() if k != "--output_dir"
    }
    # The validation's report, summary and selection live where none of the test's runs or outputs go.
    results = nc.results_dir(tmp_path)
    assert results != tmp_path
    for run in build_plan(profile, tmp_path, (TASK0,)):
        assert not run.output.is_relative_to(results), run.name
