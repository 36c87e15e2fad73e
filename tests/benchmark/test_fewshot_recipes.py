"""Few-shot recipes in a benchmark profile: the profile's own (the paper's) keeps its runs; another recipe
fine-tunes each method under a row of its own, OmniD all of the recipe, the others its steps and learning
rate; the new-camera hypotheses, as the benchmark plans them, are the commands validation ran."""

from __future__ import annotations

import dataclasses
import json

import pytest
from omnid_testing import by_name, flag

from lerobot_omnid.benchmark import new_camera as nc
from lerobot_omnid.benchmark.methods import PAPER_RECIPE, SINGLE_CAMERA, FewshotRecipe
from lerobot_omnid.benchmark.plan import FEWSHOT, PROFILES, TASK0, TASK1, build_plan
from lerobot_omnid.measure.engine import CHECKPOINT

TUNED = ("long_frozen_head", "single_camera_long", "long_replay")
RECIPES = (PAPER_RECIPE, *(nc.HYPOTHESES[h] for h in TUNED))


def profile(recipes=RECIPES, variants=(SINGLE_CAMERA,)):
    return dataclasses.replace(PROFILES["mini-fewshot"], fewshot_recipes=recipes, variants=variants)


def options(cmd) -> dict[str, str]:
    return dict(a.partition("=")[::2] for a in cmd[1:] if a.startswith("--") and "=" in a)


def test_the_profiles_own_recipe_keeps_its_runs(tmp_path):
    before = by_name(build_plan(PROFILES["mini-fewshot"], tmp_path, (TASK0,)))
    after = by_name(build_plan(profile(), tmp_path, (TASK0,)))
    assert {n: r.cmd for n, r in before.items()} == {n: after[n].cmd for n in before}


def test_each_recipe_fine_tunes_a_model_of_its_own(tmp_path):
    runs = by_name(build_plan(profile(), tmp_path, (TASK0,)))
    for task in (TASK0, TASK1):
        frozen = runs[f"finetune/omnid_long_frozen_head/{task}"]
        assert flag(frozen.cmd, "steps") == "1000" and flag(frozen.cmd, "policy.frozen_modules") == '["head"]'
        assert flag(frozen.cmd, "policy.path") == str(tmp_path / "train" / "omnid" / TASK0 / CHECKPOINT)
        evaluation = runs[f"eval/omnid_long_frozen_head/{task}/{FEWSHOT}/seed1"]
        assert evaluation.result == ("omnid_long_frozen_head", task, FEWSHOT)
        assert flag(evaluation.cmd, "env.cameras") == "[cam_a]"
        blind = runs[f"eval_blind/omnid_long_frozen_head/{task}/{FEWSHOT}/seed1"]
        calibration = runs[f"calibration/omnid_long_frozen_head/{task}/{FEWSHOT}/blind"]
        assert calibration.needs == (frozen.name,) and blind.result == evaluation.result
        single = runs[f"finetune/omnid_single_camera_long/{task}"]
        start = tmp_path / "train" / SINGLE_CAMERA.name / TASK0 / CHECKPOINT
        assert flag(single.cmd, "policy.path") == str(start)
        assert single.needs[-1] == f"train/{SINGLE_CAMERA.name}/{TASK0}"
        replay = runs[f"finetune/omnid_long_replay/{task}"]
        merged = runs[f"merge/{task}_a_fewshot_replay"]
        assert merged.name in replay.needs and flag(replay.cmd, "dataset.root") == str(merged.output)
        assert json.loads(flag(replay.cmd, "policy.cameras")) == ["cam_a", "cam_b", "cam_c", "cam_d", "cam_e"]
    assert flag(runs[f"train/{SINGLE_CAMERA.name}/{TASK0}"].cmd, "policy.single_camera_rate") == "0.5"


def test_dp_follows_a_recipes_steps_and_learning_rate_once(tmp_path):
    """Frozen parts, replay and single-camera pre-training are OmniD's: for DP the three recipes are one
    1000-step fine-tuning, planned under the first's name, from its camera-A copy."""
    runs = by_name(build_plan(profile(), tmp_path, (TASK0,)))
    tuned = sorted(n for n in runs if n.startswith("finetune/diffusion") and n.endswith(TASK1))
    assert tuned == [f"finetune/diffusion/{TASK1}", f"finetune/diffusion_long_frozen_head/{TASK1}"]
    dp = runs[f"finetune/diffusion_long_frozen_head/{TASK1}"].cmd
    assert flag(dp, "steps") == "1000" and flag(dp, "policy.frozen_modules") is None
    assert flag(dp, "policy.path") == str(tmp_path / "finetune" / "diffusion" / "start_cam_a")
    low = nc.HYPOTHESES["long_low_lr"]
    dp_low = by_name(build_plan(profile((PAPER_RECIPE, low)), tmp_path, (TASK0,)))
    assert flag(dp_low[f"finetune/diffusion_long_low_lr/{TASK0}"].cmd, "policy.optimizer_lr") == "0.0001"
    labels = profile().labels
    assert labels["diffusion_long_frozen_head"] == "DP 1000 steps, head frozen"


@pytest.mark.parametrize("hypothesis", sorted(nc.HYPOTHESES))
def test_a_selected_hypothesis_is_fine_tuned_as_validation_did(hypothesis, tmp_path):
    """The test phase (the benchmark's few-shot phase with the selected recipe) fine-tunes task 0 with the
    very options validation used; only the folders differ."""
    recipe = nc.HYPOTHESES[hypothesis]
    runs = by_name(build_plan(profile((recipe,)), tmp_path, (TASK0,)))
    validation = {r.name: r for r in nc.protocol(tmp_path)}[f"finetune_validation/{hypothesis}"]
    benchmark = options(runs[f"finetune/omnid_{hypothesis}/{TASK0}"].cmd)
    pretraining = {r.name: r.cmd for r in nc.protocol(tmp_path) if r.kind in ("record", "train", "merge")}
    assert all(runs[n].cmd == cmd for n, cmd in pretraining.items() if n in runs)  # reused with its --out
    start = f"train/{recipe.start or 'omnid'}/{TASK0}"
    assert start in pretraining and start in runs[f"finetune/omnid_{hypothesis}/{TASK0}"].needs
    assert {k: v for k, v in benchmark.items() if k != "--output_dir"} == {
        k: v for k, v in options(validation.cmd).items() if k != "--output_dir"
    }


@pytest.mark.parametrize(
    ("recipes", "variants"),
    [
        ((PAPER_RECIPE, PAPER_RECIPE), ()),
        ((FewshotRecipe("x", "x", 10, start="omnid_other"),), (SINGLE_CAMERA,)),
        ((nc.HYPOTHESES["single_camera_long"],), ()),
    ],
)
def test_profile_refuses_recipes_it_cannot_plan(recipes, variants):
    with pytest.raises(ValueError, match="fewshot_recipes: expected distinct names"):
        profile(recipes, variants)


def test_fewshot_probe_reads_every_fine_tuned_task0_model(tmp_path):
    """One probe run per training seed: fitted on the camera-A episodes of task 0, every model fine-tuned
    on them named by its table row; off unless the profile asks for it."""
    assert not [r for r in build_plan(profile(), tmp_path, (TASK0,)) if r.kind == "probe"]
    p = dataclasses.replace(profile(), fewshot_probe=True, train_seeds=(1000, 1001))
    probes = [r for r in build_plan(p, tmp_path, (TASK0,)) if r.kind == "probe"]
    assert [r.name for r in probes] == [f"probe/{FEWSHOT}", f"train_seed1001/probe/{FEWSHOT}"]
    cmd = list(probes[0].cmd)
    assert cmd[cmd.index("--train-root") + 1] == str(tmp_path / "data" / f"{TASK0}_a_fewshot")
    named = [cmd[i + 1].split("=")[0] for i, a in enumerate(cmd) if a == "--checkpoint"]
    expected = ["omnid", "omnid_long_frozen_head", "omnid_single_camera_long", "omnid_long_replay"]
    assert named == [*expected, "diffusion", "diffusion_long_frozen_head"]
    assert set(probes[0].needs) == {f"record/{TASK0}_a_fewshot", *(f"finetune/{m}/{TASK0}" for m in named)}


def test_a_zero_shot_recipe_evaluates_the_start_models_on_camera_a(tmp_path):
    """Steps 0: no fine-tuning; the B-E OmniD takes camera A alone with its calibration from every frame,
    DP its camera-A copy; each beside a black-image blind control; task 0 only."""
    zero_shot = FewshotRecipe("zero_shot", "zero-shot", 0)
    runs = by_name(build_plan(profile((PAPER_RECIPE, zero_shot), ()), tmp_path, (TASK0,)))
    assert not [n for n in runs if "zero_shot" in n and runs[n].kind != "eval"]
    assert not [n for n in runs if "zero_shot" in n and TASK1 in n]
    omnid = runs[f"eval/omnid_zero_shot/{TASK0}/{FEWSHOT}/seed1"]
    assert omnid.result == ("omnid_zero_shot", TASK0, FEWSHOT) and omnid.needs == (f"train/omnid/{TASK0}",)
    assert flag(omnid.cmd, "policy.path") == str(tmp_path / "train" / "omnid" / TASK0 / CHECKPOINT)
    assert flag(omnid.cmd, "policy.cameras") == '["cam_a"]' and flag(omnid.cmd, "env.cameras") == "[cam_a]"
    assert flag(omnid.cmd, "env.per_frame_calibration") == "true"
    assert flag(omnid.cmd, "policy.frame_calibration") == '["observation.images.cam_a"]'
    blind = runs[f"eval_blind/omnid_zero_shot/{TASK0}/{FEWSHOT}/seed1"]
    assert blind.control == "blind" and flag(blind.cmd, "env.blackout_cameras") == "[cam_a]"
    assert flag(blind.cmd, "env.per_frame_calibration") == "true"
    dp = runs[f"eval/diffusion_zero_shot/{TASK0}/{FEWSHOT}/seed1"]
    assert dp.needs == ("prepare/diffusion/cam_a",) and "--env.per_frame_calibration=true" not in dp.cmd
    assert flag(dp.cmd, "policy.path") == str(runs["prepare/diffusion/cam_a"].output)
    with pytest.raises(ValueError, match=r"expected a zero-shot recipe \(steps 0\) to have no learning rate"):
        profile((PAPER_RECIPE, FewshotRecipe("zero_shot", "zero-shot", 0, lr=1e-4)), ())
