"""omnid-benchmark's plan per profile: flags, the same data, steps and seeds across methods, new tasks,
training seeds, controls, position bands, few-shot fine-tuning; every training command parsed by LeRobot's
own config classes."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import draccus
import gym_omnid.constants
import pytest
from omnid_testing import by_name, flag

from lerobot_omnid.benchmark import plan as plan_module
from lerobot_omnid.benchmark import task_sizing
from lerobot_omnid.benchmark.methods import METHODS, with_options
from lerobot_omnid.benchmark.plan import (
    BANDS,
    FEWSHOT_SEED,
    HELDOUT_SEED,
    PROFILES,
    SETTINGS,
    TASK0,
    TASK1,
    TRAIN_SEED,
    available_tasks,
    build_plan,
)
from lerobot_omnid.measure.engine import CHECKPOINT, plan


def test_mini_plan_same_data_steps_and_seeds_for_omnid_and_dp(tmp_path):
    runs = build_plan(PROFILES["mini"], tmp_path, (TASK0,))
    # training set + held-out sets of every setting but the graded bands
    assert [r.kind for r in runs].count("record") == 1 + len(SETTINGS) - len(BANDS)
    trains = [r for r in runs if r.kind == "train"]
    evals = [r for r in runs if r.kind == "eval" and not r.control]
    assert [r.name for r in trains] == ["train/omnid/select_apple", "train/diffusion/select_apple"]
    assert {r.result for r in evals} == {(m, TASK0, s) for m in ("omnid", "diffusion") for s in SETTINGS}
    for option in ("dataset.root", "steps", "batch_size", "seed", "save_freq", "num_workers"):
        assert len({flag(r.cmd, option) for r in trains}) == 1, option
    assert flag(trains[0].cmd, "dataset.root") == str(tmp_path / "data" / "select_apple_bcde")
    assert all(flag(r.cmd, "env.type") is None for r in trains)  # no in-training env evaluation
    for option in ("seed", "eval.n_episodes", "env.episode_length", "env.image_size", "env.cameras"):
        assert len({flag(r.cmd, option) for r in evals}) == 1, option
    assert flag(evals[0].cmd, "env.cameras") == "[cam_b,cam_c,cam_d,cam_e]"
    settings = {(flag(r.cmd, "env.layout"), flag(r.cmd, "env.background")) for r in evals}
    assert settings == {("id", "id"), ("position_ood", "id")} | {("id", f"ood{i}") for i in range(1, 5)} | {
        (f"position_band_{k}", "id") for k in range(1, 5)
    }
    dp = by_name(runs)["train/diffusion/select_apple"].cmd
    for expected in (
        "--policy.pretrained_backbone_weights=null",
        "--policy.crop_shape=null",
        "--policy.use_separate_rgb_encoder_per_camera=false",
        "--policy.horizon=16",
        "--policy.n_action_steps=8",
        "--policy.use_group_norm=true",
    ):
        assert expected in dp
    omnid = by_name(runs)["train/omnid/select_apple"].cmd
    head = (
        "down_dims",
        "noise_scheduler_type",
        "num_inference_steps",
        "prediction_type",
        "optimizer_lr",
        "scheduler_warmup_steps",
    )
    assert [flag(omnid, f"policy.{h}") for h in head] == [flag(dp, f"policy.{h}") for h in head]
    assert flag(dp, "policy.prediction_type") == "sample"  # a short run: see diffusion_head_flags
    for r in evals:  # each eval reads the checkpoint of its own training run
        assert flag(r.cmd, "policy.path").startswith(str(tmp_path / "train" / r.result[0]))


def test_mini_plan_open_loop_diagnostic_on_held_out_episodes(tmp_path):
    runs = by_name(build_plan(PROFILES["mini"], tmp_path, (TASK0,)))
    for setting, (layout, background) in {
        "position_ood": ("position_ood", "id"),
        "ood3": ("id", "ood3"),
    }.items():
        record = runs[f"record/{TASK0}_bcde_heldout_{setting}"].cmd
        option = {name: record[record.index(name) + 1] for name in ("--layout", "--background", "--seed")}
        assert option == {"--layout": layout, "--background": background, "--seed": str(HELDOUT_SEED)}
        assert record[record.index("--cameras") + 1] == "cam_b,cam_c,cam_d,cam_e"
        for method in ("omnid", "diffusion"):
            run = runs[f"offline/{method}/{TASK0}/{setting}"]
            assert run.needs == (f"train/{method}/{TASK0}", f"record/{TASK0}_bcde_heldout_{setting}")
            cmd = run.cmd
            assert Path(cmd[0]).name == "omnid-offline-eval" and run.result == (method, TASK0, setting)
            assert cmd[cmd.index("--checkpoint") + 1].startswith(str(tmp_path / "train" / method))
            assert cmd[cmd.index("--root") + 1] == str(tmp_path / "data" / f"{TASK0}_bcde_heldout_{setting}")
            assert cmd[cmd.index("--episodes") + 1] == str(PROFILES["mini"].heldout_episodes)
    assert FEWSHOT_SEED + PROFILES["paper"].fewshot_episodes <= HELDOUT_SEED  # never trained on
    no_heldout = dataclasses.replace(PROFILES["mini"], heldout_episodes=0)
    assert not any(r.kind == "offline" for r in build_plan(no_heldout, tmp_path, (TASK0,)))


def test_paper_plan_every_method_task_fewshot_and_ablation(tmp_path):
    p = PROFILES["paper"]
    plan = build_plan(p, tmp_path, available_tasks())
    runs = by_name(plan)
    assert len(runs) == len(plan)  # unique names
    for i, run in enumerate(plan):  # every run needs only runs that come before it
        assert set(run.needs) <= {r.name for r in plan[:i]}, run.name
    for task in available_tasks():
        for m in ("omnid", "diffusion", "act", "vqbet"):
            assert flag(runs[f"train/{m}/{task}"].cmd, "steps") == "100000"
            assert [flag(runs[f"eval/{m}/{task}/id/seed{k}"].cmd, "seed") for k in (1, 2, 3, 4)] == [
                "1000",
                "2000",
                "3000",
                "4000",
            ]
    assert flag(runs["eval/act/select_apple/ood3/seed2"].cmd, "eval.n_episodes") == "50"
    assert "eval/act/select_chemistry_tube/ood3/seed2" not in runs  # OOD settings: task 0 only
    vqbet = runs["train/vqbet/select_apple"].cmd
    assert json.loads(flag(vqbet, "policy.input_features")) == {
        "observation.state": {"type": "STATE", "shape": [16]},
        "observation.images.cam_b": {"type": "VISUAL", "shape": [3, 128, 128]},
    }
    assert flag(vqbet, "policy.n_vqvae_training_steps") == "20000"
    assert flag(runs["eval/vqbet/select_apple/id/seed1"].cmd, "env.cameras") == "[cam_b]"
    assert flag(runs["train/act/select_apple"].cmd, "policy.chunk_size") == "16"
    # Few-shot: every method's task-0 checkpoint, fine-tuned on camera-A sets of task 0 and task 1.
    for m in METHODS:
        for task in (TASK0, TASK1):
            run = runs[f"finetune/{m}/{task}"]
            assert flag(run.cmd, "dataset.root") == str(tmp_path / "data" / f"{task}_a_fewshot")
            assert flag(run.cmd, "steps") == "5000" and flag(run.cmd, "policy.type") is None
            assert flag(runs[f"eval/{m}/{task}/fewshot_a/seed1"].cmd, "env.cameras") == "[cam_a]"
    task0_checkpoint = str(tmp_path / "train" / "omnid" / TASK0 / "checkpoints" / "last" / "pretrained_model")
    omnid = runs["finetune/omnid/select_apple"]
    assert flag(omnid.cmd, "policy.path") == task0_checkpoint and "train/omnid/select_apple" in omnid.needs
    assert flag(omnid.cmd, "policy.cameras") == '["cam_a"]'
    for m in ("diffusion", "act", "vqbet"):  # a copy of the task-0 checkpoint with camera A as its input
        prepare = runs[f"prepare/{m}/cam_a"]
        assert prepare.needs == (f"train/{m}/{TASK0}",)
        assert prepare.cmd[prepare.cmd.index("--src") + 1] == task0_checkpoint.replace("/omnid/", f"/{m}/")
        assert prepare.cmd[prepare.cmd.index("--cameras") + 1] == "cam_a"
        for task in (TASK0, TASK1):
            run = runs[f"finetune/{m}/{task}"]
            assert flag(run.cmd, "policy.path") == str(prepare.output) and prepare.name in run.needs
            assert flag(run.cmd, "policy.input_features") is None
    assert flag(runs["finetune/vqbet/select_apple"].cmd, "policy.n_vqvae_training_steps") == "0"
    assert flag(runs["record/select_apple_a_fewshot"].cmd, "seed") is None  # omnid-record: "--seed N"
    record = runs["record/select_chemistry_tube_a_fewshot"].cmd
    assert record[record.index("--seed") + 1] == "100000" and record[record.index("--episodes") + 1] == "10"
    # Ablations on task 0.
    assert flag(runs["train/omnid_resnet101/select_apple"].cmd, "policy.vision_backbone") == "resnet101"
    assert flag(runs["train/omnid_no_ofg/select_apple"].cmd, "policy.use_ofg") == "false"
    cam_a = runs["train/omnid_cam_a/select_apple"].cmd
    assert flag(cam_a, "policy.cameras") == '["cam_a"]'
    assert flag(cam_a, "dataset.root") == str(tmp_path / "data" / "select_apple_a")
    assert flag(runs["eval/omnid_cam_a/select_apple/id/seed4"].cmd, "env.cameras") == "[cam_a]"


def test_new_tasks_are_picked_up(monkeypatch, tmp_path):
    monkeypatch.setattr(gym_omnid.constants, "TASKS", (*gym_omnid.constants.TASKS, "make_tea"))
    assert available_tasks()[-1] == "make_tea"
    runs = by_name(build_plan(PROFILES["paper"], tmp_path, available_tasks()))
    assert "record/make_tea_bcde" in runs
    assert {f"train/{m}/make_tea" for m in ("omnid", "diffusion", "act", "vqbet")} <= set(runs)
    assert [n for n in runs if n.startswith("eval/omnid/make_tea/")] == [
        f"eval/omnid/make_tea/id/seed{k}" for k in (1, 2, 3, 4)
    ]


@pytest.mark.parametrize("profile", ["mini", "paper", "position-validation", "rigs-validation"])
def test_lerobot_parses_every_training_command(profile, tmp_path):
    """Each from-scratch training command is a valid `lerobot-train` configuration (option names, values
    and the policy configs' own checks)."""
    import lerobot.policies  # noqa: F401  (registers the stock policy configs)
    from lerobot.configs.train import TrainPipelineConfig

    p = dataclasses.replace(PROFILES[profile], methods=("omnid", "diffusion", "act", "vqbet"))
    for run in build_plan(p, tmp_path, (TASK0,)):
        if run.kind == "train" and flag(run.cmd, "policy.type"):
            cfg = draccus.parse(TrainPipelineConfig, args=list(run.cmd[1:]))
            assert cfg.policy.type == flag(run.cmd, "policy.type"), run.name
            assert cfg.steps == p.steps and cfg.seed == TRAIN_SEED
            if "clip2" in run.name:
                assert cfg.policy.clip_sample_range == 2.0, run.name
            if "_rot" in run.name:
                assert cfg.policy.camera_rotation_deg in (5, 10), run.name


def test_training_seeds_repeat_the_models_in_their_own_folders(tmp_path):
    """The default seed keeps the folders and names of the single-seed plan (finished runs stay valid);
    another seed repeats every training run and its evaluations in ``train_seed<seed>/`` on the same data."""
    single = by_name(build_plan(PROFILES["mini"], tmp_path, (TASK0,)))
    p = dataclasses.replace(PROFILES["mini"], train_seeds=(TRAIN_SEED, 1001))
    runs = by_name(build_plan(p, tmp_path, (TASK0,)))
    for name, run in single.items():
        assert runs[name] == run, name
    extra = {name: run for name, run in runs.items() if name not in single}
    assert all(name.startswith("train_seed1001/") for name in extra)
    assert len(extra) == len([r for r in single.values() if r.kind != "record"])  # the data is shared
    train = runs["train_seed1001/train/omnid/select_apple"]
    assert flag(train.cmd, "seed") == "1001" and train.train_seed == 1001
    assert train.output == tmp_path / "train_seed1001" / "train" / "omnid" / TASK0
    assert flag(train.cmd, "dataset.root") == flag(single["train/omnid/select_apple"].cmd, "dataset.root")
    evaluation = runs["train_seed1001/eval/diffusion/select_apple/ood3/seed1"]
    assert (
        evaluation.needs == ("train_seed1001/train/diffusion/select_apple",) and evaluation.train_seed == 1001
    )
    assert flag(evaluation.cmd, "seed") == flag(single["eval/diffusion/select_apple/ood3/seed1"].cmd, "seed")
    assert flag(evaluation.cmd, "output_dir").startswith(str(tmp_path / "train_seed1001" / "eval"))
    assert "train_seed1001/eval_blind/omnid/select_apple/id/seed1" in runs
    assert "train_seed1001/offline/omnid/select_apple/id" in runs


CONTROL_MODULE = "lerobot_omnid.benchmark.control_calibration"


def test_controls_and_position_bands_in_the_plan(tmp_path):
    runs = by_name(build_plan(PROFILES["mini"], tmp_path, (TASK0,)))
    checkpoint = str(tmp_path / "train" / "omnid" / TASK0 / "checkpoints" / "last" / "pretrained_model")
    for control in ("blind", "scrambled"):
        calibration = runs[f"calibration/omnid/{TASK0}/{control}"]
        assert calibration.needs == (f"train/omnid/{TASK0}",) and CONTROL_MODULE in calibration.cmd
        assert calibration.cmd[calibration.cmd.index("--checkpoint") + 1] == checkpoint
        assert calibration.cmd[calibration.cmd.index("--control") + 1] == control
        assert calibration.output == tmp_path / "controls" / "omnid" / TASK0 / f"{control}.json"
        evaluation = runs[f"eval_{control}/omnid/{TASK0}/id/seed1"]
        assert evaluation.control == control and evaluation.result == ("omnid", TASK0, "id")
        assert evaluation.needs == (f"train/omnid/{TASK0}", calibration.name)
        assert flag(evaluation.cmd, "policy.calibration_path") == str(calibration.output)
        assert flag(evaluation.cmd, "policy.path") == checkpoint
        assert flag(evaluation.cmd, "env.blackout_cameras") is None
        reference = runs[f"eval/omnid/{TASK0}/id/seed1"].cmd  # the same episodes as the trained model's
        for option in ("seed", "env.layout", "env.background", "env.cameras", "eval.n_episodes"):
            assert flag(evaluation.cmd, option) == flag(reference, option), option
    blind_dp = runs[f"eval_blind/diffusion/{TASK0}/id/seed1"]
    assert flag(blind_dp.cmd, "env.blackout_cameras") == "[cam_b,cam_c,cam_d,cam_e]"
    assert flag(blind_dp.cmd, "policy.calibration_path") is None
    assert not any(
        "scrambled/diffusion" in name or "eval_blind/omnid/select_apple/ood1" in name for name in runs
    )
    assert not [name for name in runs if name.startswith("eval_") and "/id/" not in name]  # mini: ID only
    for k, band in enumerate(BANDS, 1):
        run = runs[f"eval/omnid/{TASK0}/{band}/seed1"]
        assert (flag(run.cmd, "env.layout"), flag(run.cmd, "env.background")) == (f"position_band_{k}", "id")
        assert f"record/{TASK0}_bcde_heldout_{band}" not in runs  # no open-loop diagnostic for the bands
    paper = by_name(build_plan(PROFILES["paper"], tmp_path, (TASK0,)))
    assert f"eval_blind/vqbet/{TASK0}/position_ood/seed4" in paper
    assert flag(paper[f"eval_blind/vqbet/{TASK0}/id/seed1"].cmd, "env.blackout_cameras") == "[cam_b]"
    no_controls = dataclasses.replace(PROFILES["mini"], control_settings=())
    assert not any(r.control or r.kind == "calibration" for r in build_plan(no_controls, tmp_path, (TASK0,)))


def test_mini_fewshot_profile_fine_tunes_minis_own_task0_models(tmp_path):
    """``--profile mini-fewshot`` with mini's ``--out`` reuses mini's recordings and trainings (the same
    commands, so the resumable runner skips them) and adds OmniD's and DP's camera-A fine-tuning on both
    tasks, evaluated with camera A only; DP starts from a copy of its checkpoint with camera A as input."""
    mini = by_name(build_plan(PROFILES["mini"], tmp_path, (TASK0,)))
    fewshot = by_name(build_plan(PROFILES["mini-fewshot"], tmp_path, (TASK0,)))
    for name, run in fewshot.items():
        if name in mini:
            assert run.cmd == mini[name].cmd, name
    assert {
        "train/omnid/select_apple",
        "train/diffusion/select_apple",
        "eval_blind/omnid/select_apple/id/seed1",
    } <= set(mini) & set(fewshot)
    for task in (TASK0, TASK1):
        tuned = fewshot[f"finetune/omnid/{task}"]
        assert flag(tuned.cmd, "policy.path") == str(tmp_path / "train" / "omnid" / TASK0 / CHECKPOINT)
        assert flag(tuned.cmd, "steps") == str(PROFILES["mini"].finetune_steps)
        assert flag(fewshot[f"eval/omnid/{task}/fewshot_a/seed1"].cmd, "env.cameras") == "[cam_a]"
        dp = fewshot[f"finetune/diffusion/{task}"]
        assert flag(dp.cmd, "policy.path") == str(tmp_path / "finetune" / "diffusion" / "start_cam_a")
        assert "prepare/diffusion/cam_a" in dp.needs
        assert flag(fewshot[f"eval/diffusion/{task}/fewshot_a/seed1"].cmd, "env.cameras") == "[cam_a]"
        # Each fine-tuned model's blind control: OmniD's camera A turned away, computed from the fine-tuned
        # checkpoint into its own file (not the task-0 model's); DP's camera A black.
        calibration = fewshot[f"calibration/omnid/{task}/fewshot_a/blind"]
        assert calibration.needs == (f"finetune/omnid/{task}",)
        assert calibration.output == tmp_path / "controls" / "omnid" / task / "fewshot_a" / "blind.json"
        blind = fewshot[f"eval_blind/omnid/{task}/fewshot_a/seed1"]
        assert flag(blind.cmd, "policy.calibration_path") == str(calibration.output)
        assert blind.control == "blind" and blind.result == ("omnid", task, "fewshot_a")
        dp_blind = fewshot[f"eval_blind/diffusion/{task}/fewshot_a/seed1"].cmd
        assert flag(dp_blind, "env.blackout_cameras") == "[cam_a]"
        assert flag(dp_blind, "policy.path") == str(tmp_path / "finetune" / "diffusion" / task / CHECKPOINT)
    assert fewshot["calibration/omnid/select_apple/blind"].output != calibration.output
    prepare = list(fewshot["prepare/diffusion/cam_a"].cmd)
    assert prepare[prepare.index("--src") + 1] == str(tmp_path / "train" / "diffusion" / TASK0 / CHECKPOINT)
    assert not any(n.startswith(("offline/", "record/select_apple_bcde_heldout")) for n in fewshot)


def test_task_steps_size_every_method_on_that_task_only(tmp_path):
    """A sized task trains every method for its steps (VQ-BeT's tokeniser phase with them), in the folder
    that names them; the others keep the profile's, so their runs are the unsized plan's."""
    p = dataclasses.replace(PROFILES["mini"], methods=METHODS, task_steps=(("get_coffee", 3000),))
    runs = by_name(build_plan(p, tmp_path, (TASK0, "get_coffee")))
    unsized = by_name(build_plan(dataclasses.replace(p, task_steps=()), tmp_path, (TASK0, "get_coffee")))
    for method in METHODS:
        sized = runs[f"train_steps3000/{method}/get_coffee"]
        assert flag(sized.cmd, "steps") == "3000"
        assert flag(sized.cmd, "output_dir") == str(tmp_path / "train_steps3000" / method / "get_coffee")
        assert runs[f"eval/{method}/get_coffee/id/seed1"].needs == (sized.name,)
        assert runs[f"train/{method}/{TASK0}"].cmd == unsized[f"train/{method}/{TASK0}"].cmd
    assert flag(runs["train_steps3000/vqbet/get_coffee"].cmd, "policy.n_vqvae_training_steps") == "600"


def test_six_tasks_profile_reuses_the_sizing_runs_and_controls_every_task(tmp_path):
    """The six-task profile trains DP with the task sizing's very commands (its runs are reused, at either
    budget) and evaluates every method on every task in ID and one unseen table on two ranges of env seeds,
    with each method's blind control and OmniD's scrambled one in ID; no perturbed control, no open-loop
    runs."""
    p = dataclasses.replace(PROFILES["six-tasks"], task_steps=(("get_coffee", 3000),))
    tasks = ("add_condiment", "get_coffee")
    runs = by_name(build_plan(p, tmp_path, tasks))
    sizing_runs = task_sizing.task_runs(tmp_path, "add_condiment", [1000])
    sizing_runs += task_sizing.task_runs(tmp_path, "get_coffee", [1000, 3000])
    sizing = by_name(plan(sizing_runs, tmp_path))
    for name in (
        "record/get_coffee_bcde",
        "train/diffusion/add_condiment",
        "train_steps3000/diffusion/get_coffee",
    ):
        assert runs[name].fingerprint == sizing[name].fingerprint, name
    for task in tasks:
        for method in METHODS:
            for k in (1, 2):
                for setting in ("id", "ood2"):
                    assert runs[f"eval/{method}/{task}/{setting}/seed{k}"].result == (method, task, setting)
                blind = runs[f"eval_blind/{method}/{task}/id/seed{k}"]
                assert blind.control == "blind" and flag(blind.cmd, "eval.n_episodes") == "15"
                assert f"eval_blind/{method}/{task}/ood2/seed{k}" not in runs  # the ID one's serves
        assert f"eval_scrambled/omnid/{task}/id/seed1" in runs
        assert f"eval_scrambled/diffusion/{task}/id/seed1" not in runs
    assert not any(n.startswith(("eval_perturbed/", "offline/")) for n in runs)
    assert "--policy.fuse_last_step_only=true" in runs["train/omnid/add_condiment"].cmd


def test_six_tasks_profile_trains_one_model_for_every_task(tmp_path, monkeypatch):
    """OmniD and DP also trained on the tasks' episodes recorded again with the task one-hot and merged,
    for the single-task models' steps together, evaluated on every task with the one-hot beside their blind
    controls; the single-task runs are those of the plan without them. (Here the benchmark has two tasks.)"""
    p = dataclasses.replace(PROFILES["six-tasks"], task_steps=(("get_coffee", 3000),))
    tasks = ("add_condiment", "get_coffee")
    monkeypatch.setattr(plan_module, "available_tasks", lambda: tasks)
    runs = by_name(build_plan(p, tmp_path, tasks))
    alone = by_name(build_plan(dataclasses.replace(p, multitask=False), tmp_path, tasks))
    assert {n: r.fingerprint for n, r in alone.items()} == {n: runs[n].fingerprint for n in alone}
    for task in tasks:
        record = runs[f"record/{task}_bcde_onehot"].cmd
        same = tuple(arg.replace("_bcde_onehot", "_bcde") for arg in record[:-1])
        assert record[-1] == "--task-onehot" and same == runs[f"record/{task}_bcde"].cmd
    merge = runs["merge/all_tasks_bcde_onehot"]
    assert merge.needs == ("record/add_condiment_bcde_onehot", "record/get_coffee_bcde_onehot")
    assert json.loads(flag(merge.cmd, "operation.roots")) == [
        str(tmp_path / "data" / f"{task}_bcde_onehot") for task in tasks
    ]
    for method in ("omnid", "diffusion"):
        trained = runs[f"train_multitask/{method}/all_tasks"]
        assert trained.needs == ("merge/all_tasks_bcde_onehot",) and flag(trained.cmd, "steps") == "4000"
        assert flag(trained.cmd, "dataset.root") == str(merge.output)
        for task in tasks:
            for k in (1, 2):
                for folder in ("eval", "eval_blind"):
                    run = runs[f"{folder}/{method}_multitask/{task}/id/seed{k}"]
                    assert run.result == (f"{method}_multitask", task, "id")
                    assert "--env.task_onehot=true" in run.cmd and run.needs[0] == trained.name
    assert not any(n.startswith("train_multitask/act") for n in runs)
    no_dp = by_name(build_plan(dataclasses.replace(p, methods=("omnid", "act")), tmp_path, tasks))
    assert [n for n in no_dp if n.startswith("train_multitask/")] == ["train_multitask/omnid/all_tasks"]
    # Some tasks of the benchmark only: no model of all tasks (it would be another model under its name).
    monkeypatch.setattr(plan_module, "available_tasks", lambda: (*tasks, "texas_holdem"))
    assert not any("multitask" in r.name for r in build_plan(p, tmp_path, tasks))


def test_variants_train_like_their_method_with_their_options_in_the_same_cells(tmp_path):
    """The position validation: each variant is its method's training command with its own options
    replacing or added to the method's, evaluated in the same settings and env seeds under its own name."""
    p = PROFILES["position-validation"]
    runs = by_name(build_plan(p, tmp_path, (TASK0,)))
    variants = {v.name: v for v in p.variants}
    assert set(variants) == {"omnid_clip2", "omnid_clip2_shift5", "omnid_clip2_shift10", "diffusion_clip2"}
    for name, variant in variants.items():
        base, own = runs[f"train/{variant.method}/{TASK0}"].cmd, runs[f"train/{name}/{TASK0}"].cmd
        changed = {f.split("=", 1)[0] for f, _ in variant.flags}
        strip = [a for a in base if a.split("=", 1)[0] not in changed and not a.startswith("--output_dir=")]
        assert strip == [
            a for a in own if a.split("=", 1)[0] not in changed and not a.startswith("--output_dir=")
        ]
        assert flag(own, "policy.clip_sample_range") == "2.0"
        for setting in ("id", *BANDS):
            evaluation = runs[f"eval/{name}/{TASK0}/{setting}/seed80"]
            assert flag(evaluation.cmd, "seed") == "80000" and evaluation.result == (name, TASK0, setting)
            assert evaluation.needs == (f"train/{name}/{TASK0}",)
    assert flag(runs[f"train/omnid_clip2_shift10/{TASK0}"].cmd, "policy.position_shift_m") == "0.1"
    assert flag(runs[f"train/omnid/{TASK0}"].cmd, "policy.clip_sample_range") is None  # as trained
    assert not any(r.control for r in runs.values())  # validation: no controls


def test_with_options_replaces_an_option_of_the_same_name_and_appends_new_ones():
    base = [("--policy.a=1", "x"), ("--policy.b=2", "y")]
    assert with_options(base, [("--policy.b=3", "z"), ("--policy.c=4", "w")]) == [
        ("--policy.a=1", "x"),
        ("--policy.b=3", "z"),
        ("--policy.c=4", "w"),
    ]


def test_rigs_validation_evaluates_each_model_on_the_moved_rigs_with_their_true_calibration(tmp_path):
    """OmniD reads each moved rig's calibration from every frame, DP sees its images; ID stays the
    training rig; OmniD and DP as trained are position-validation's runs (the same commands)."""
    p = PROFILES["rigs-validation"]
    runs = by_name(build_plan(p, tmp_path, (TASK0,)))
    position = by_name(build_plan(PROFILES["position-validation"], tmp_path, (TASK0,)))
    for name in ("record/select_apple_bcde", f"train/omnid/{TASK0}", f"train/diffusion/{TASK0}"):
        assert runs[name].cmd == position[name].cmd, name
    assert {v.name for v in p.variants} == {"omnid_rot5", "omnid_rot10", "omnid_single_camera"}
    for model in ("omnid", "omnid_rot10", "diffusion"):
        same = runs[f"eval/{model}/{TASK0}/id/seed81"].cmd
        assert flag(same, "env.rig") is None and flag(same, "seed") == "81000"
        for rig in ("higher", "bumped"):
            cmd = runs[f"eval/{model}/{TASK0}/rig_{rig}/seed81"].cmd
            assert flag(cmd, "env.rig") == rig and flag(cmd, "env.layout") == "id"
            calibrated = model.startswith("omnid")
            assert flag(cmd, "env.per_frame_calibration") == ("true" if calibrated else None)
            keys = json.dumps([f"observation.images.{c}" for c in ("cam_b", "cam_c", "cam_d", "cam_e")])
            assert flag(cmd, "policy.frame_calibration") == (keys.replace(" ", "") if calibrated else None)
    rotated = runs[f"train/omnid_rot5/{TASK0}"].cmd
    assert flag(rotated, "policy.camera_rotation_deg") == "5" and not any(r.control for r in runs.values())
    with pytest.raises(ValueError, match="control_settings: expected none of"):
        dataclasses.replace(p, control_settings=("rig_higher",))


def test_validation_profiles_use_env_seeds_no_other_profile_or_protocol_uses():
    from lerobot_omnid.benchmark import new_camera, readout_selection

    def span(p):
        return [(k * 1000, k * 1000 + p.eval_episodes - 1) for k in p.eval_seeds]

    others = [(0, 999), (FEWSHOT_SEED, FEWSHOT_SEED + 999), (HELDOUT_SEED, HELDOUT_SEED + 999)]
    others += [(s, s + 99) for s in (readout_selection.VALIDATION_SEED, new_camera.VALIDATION_SEED)]
    others += [(task_sizing.VALIDATION_SEED, task_sizing.VALIDATION_SEED + 99)]
    validations = [name for name in PROFILES if name.endswith("-validation")]
    assert {"position-validation", "rigs-validation"} <= set(validations)
    for name in validations:
        theirs = others + [r for other, p in PROFILES.items() if other != name for r in span(p)]
        for low, high in span(PROFILES[name]):
            assert all(high < a or low > b for a, b in theirs), name
