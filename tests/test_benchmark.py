"""omnid-benchmark: the plan per profile (flags, same data/steps/seeds across methods, new tasks, training
seeds, controls, position bands), the options parsed by LeRobot's own config classes, resumability, the
report (intervals, tests, controls, curve) and charts, aggregation of several folders, argument errors; one
slow end-to-end run of the real tools at tiny sizes."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import draccus
import gym_omnid.constants
import pytest
import torch
from omnid_jobs import Job, job
from omnid_testing import tiny_diffusion_config

import lerobot_omnid.benchmark.benchmark as bench
from lerobot_omnid.benchmark import checkpoint_cameras
from lerobot_omnid.benchmark.outputs import BANDS_CM
from lerobot_omnid.benchmark.plan import (
    ABLATIONS,
    BANDS,
    CONTROL_LABELS,
    CONTROLS,
    FEWSHOT_SEED,
    HELDOUT_SEED,
    METHODS,
    PROFILES,
    SETTINGS,
    TASK0,
    TASK1,
    TRAIN_SEED,
    available_tasks,
    build_plan,
    control_setting,
)
from lerobot_omnid.calibration.rig_file import load_calibration_file
from lerobot_omnid.measure import engine
from lerobot_omnid.measure.charts import bar_chart, position_curve_chart
from lerobot_omnid.measure.engine import CHECKPOINT, is_done
from lerobot_omnid.measure.report import (
    ablation_table,
    comparison_table,
    controls_table,
    curve_area,
    curve_table,
    generalisation_table,
    id_table,
    offline_table,
    raw_table,
)
from lerobot_omnid.measure.results import EvalEntry, EvalRecord, collect, record_of
from lerobot_omnid.measure.stats import fisher_exact

LABELS = bench.LABELS


def flag(cmd, name: str) -> str | None:
    """Value of ``--name=value`` in a command (None if absent)."""
    values = [a.split("=", 1)[1] for a in cmd if a.startswith(f"--{name}=")]
    assert len(values) <= 1, (name, values)
    return values[0] if values else None


def by_name(runs):
    return {r.name: r for r in runs}


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


@pytest.mark.parametrize("profile", ["mini", "paper"])
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


CONTROL_MODULE = "lerobot_omnid.benchmark.control_calibration"


def _fake_tools(calls: list[str], rates: dict[str, float], fail: tuple[str, ...] = ()):
    """A stand-in for run_logged: writes what each real tool would leave behind. ``rates``: success (%) per
    model, and per "model/control" for its control evaluations (default 0)."""

    def run(cmd, log_path, on_line=None):
        log_path.parent.mkdir(parents=True, exist_ok=True)
        log_path.write_text(" ".join(cmd))
        tool = "control_calibration" if CONTROL_MODULE in cmd else Path(cmd[0]).name
        calls.append(tool)
        if tool in fail:
            return 1
        if tool == "omnid-record":
            root = Path(cmd[cmd.index("--root") + 1])
            (root / "meta").mkdir(parents=True)
            (root / "meta" / "info.json").write_text(
                json.dumps({"total_episodes": int(cmd[cmd.index("--episodes") + 1])})
            )
        elif tool == "omnid-offline-eval":
            out = Path(cmd[cmd.index("--out") + 1])  # .../offline/<model>/<task>/<setting>/offline_eval.json
            out.parent.mkdir(parents=True, exist_ok=True)
            error = 10.0 - rates.get(out.parents[2].name, 0.0) / 10.0
            out.write_text(json.dumps({"position_cm": error, "gripper": 0.25}))
        elif tool == "control_calibration":
            out = Path(cmd[cmd.index("--out") + 1])
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text("{}")
        elif "lerobot_omnid.benchmark.checkpoint_cameras" in cmd:
            dst = Path(cmd[cmd.index("--dst") + 1])
            dst.mkdir(parents=True)
            (dst / "config.json").write_text("{}")
        elif tool == "lerobot-train":
            ckpt = Path(flag(cmd, "output_dir")) / "checkpoints" / "last" / "pretrained_model"
            ckpt.mkdir(parents=True)
            (ckpt / "model.safetensors").write_bytes(b"")
        else:
            out = Path(flag(cmd, "output_dir"))  # .../eval[_<control>]/<model>/<task>/<setting>/seed<k>
            out.mkdir(parents=True, exist_ok=True)
            model, control = out.parents[2].name, out.parents[3].name.removeprefix("eval").lstrip("_")
            rate = rates.get(f"{model}/{control}" if control else model, 0.0)
            n = int(flag(cmd, "eval.n_episodes"))
            (out / "eval_info.json").write_text(
                json.dumps({"overall": {"pc_success": rate, "n_episodes": n}})
            )
        return 0

    return run


def test_fewshot_report_has_each_fine_tuned_models_blind_control(monkeypatch, tmp_path):
    calls: list[str] = []
    rates = {"omnid": 60.0, "omnid/blind": 10.0, "diffusion": 20.0}
    monkeypatch.setattr(engine, "run_logged", _fake_tools(calls, rates))
    assert bench.main(["--profile", "mini-fewshot", "--out", str(tmp_path)]) == 0
    report = (tmp_path / "report.md").read_text()
    for task in (TASK0, TASK1):
        section = report.split(f"## Few-shot on camera A, {task}: each fine-tuned model against its blind")[1]
        rows = [line for line in section.split("\n\n")[1].splitlines() if "| fewshot_a |" in line]
        assert [r.split(" | ")[:5] for r in rows] == [
            ["| OmniD", "blind", "fewshot_a", "6/10 (31.3-83.2 %)", "1/10 (1.8-40.4 %)"],
            ["| DP", "blind", "fewshot_a", "2/10 (5.7-51.0 %)", "0/10 (0.0-27.8 %)"],
        ]
    assert calls.count("control_calibration") == 5  # task 0's three, one per fine-tuned OmniD


def test_main_runs_reports_and_resumes(monkeypatch, tmp_path, capsys):
    calls: list[str] = []
    rates = {"omnid": 60.0, "diffusion": 20.0, "omnid/scrambled": 10.0}
    monkeypatch.setattr(engine, "run_logged", _fake_tools(calls, rates))
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")
    out = tmp_path / "bench"
    assert bench.main(["--out", str(out)]) == 0
    assert calls.count("omnid-record") == 7 and calls.count("lerobot-train") == 2
    # 10 task-0 settings per method; controls in ID: OmniD blind, scrambled and perturbed (each with its
    # calibration file), DP blind
    assert calls.count("lerobot-eval") == 24 and calls.count("control_calibration") == 3
    report = (out / "report.md").read_text()
    sixty, twenty = "60.0 (31.3-83.2)", "20.0 (5.7-51.0)"  # 6/10 and 2/10 with Wilson 95 % intervals
    assert f"| OmniD | **{sixty}** | {sixty} |" in report  # ID table: best per task in bold, then the average
    assert f"| DP | {twenty} | {twenty} | {twenty} | {twenty} | {twenty} | {twenty} | — | — |" in report
    assert "--policy.use_separate_rgb_encoder_per_camera=false" in report  # the options and their reasons
    assert "| DP blind | `--env.blackout_cameras=[cam_b,cam_c,cam_d,cam_e]` |" in report
    # OmniD against DP: 6/10 vs 2/10, Newcombe's interval, Fisher p = 0.17
    assert "| select_apple | id | DP | 6/10 (31.3-83.2 %) | 2/10 (5.7-51.0 %) | +40.0 (" in report
    assert "| 0.17 |" in report
    # Against the controls: OmniD 6/10 vs blind 0/10 (p = 0.011) and scrambled 1/10; a background OOD's
    # blind control is the ID one's, position OOD has none in mini.
    assert "| OmniD | blind | id | 6/10 (31.3-83.2 %) | 0/10 (0.0-27.8 %) | +60.0 (" in report
    assert "| 0.011 |" in report
    assert "| OmniD | scrambled geometry | id | 6/10 (31.3-83.2 %) | 1/10 (" in report
    assert "| OmniD | calibration off by 2 cm and 2 deg | id | 6/10 (31.3-83.2 %) | 0/10 (" in report
    assert "| DP | blind | ood3 (control of id) | 2/10 (5.7-51.0 %) | 0/10 (0.0-27.8 %) |" in report
    assert "| OmniD | blind | position_ood" not in report
    # The position-shift curve: every band, its area, the chart.
    assert f"| OmniD | **{sixty}** | **{sixty}** | **{sixty}** | **{sixty}** | 60.0 (44.6-73.7) |" in report
    assert "Area, OmniD - DP: +40.0 (" in report and (out / "position_curve.png").stat().st_size > 0
    assert (out / "benchmark.png").stat().st_size > 0
    summary = json.loads((out / "results.json").read_text())
    assert len(summary["cells"]) == 20 and all(Path(c["sources"][0]).is_file() for c in summary["cells"])
    cell = next(c for c in summary["cells"] if c["model"] == "omnid" and c["setting"] == "id")
    assert (cell["successes"], cell["episodes"]) == (6, 10) and cell["wilson_95"] == pytest.approx(
        [31.27, 83.18], abs=0.01
    )
    assert {(c["model"], c["control"]) for c in summary["controls"]} == {
        ("omnid", "blind"),
        ("omnid", "scrambled"),
        ("omnid", "perturbed"),
        ("diffusion", "blind"),
    }
    assert "| OmniD | **4.0 / 0.25** | **4.0 / 0.25** |" in report  # open-loop error: lowest in bold
    assert "| DP | 8.0 / 0.25 |" in report
    assert calls.count("omnid-offline-eval") == 12
    assert "48 runs: 48 ran" in capsys.readouterr().out
    # Each finished evaluation's stamp (commit, command), and the folder's summary.
    stamp = json.loads((out / "stamps" / "eval_blind" / "omnid" / TASK0 / "id" / "seed1.json").read_text())
    assert stamp["commit"] == "abc123"
    assert (
        "--policy.calibration_path=" + str(out / "controls" / "omnid" / TASK0 / "blind.json")
        in (stamp["command"])
    )
    folder = json.loads((out / "summary.json").read_text())
    assert folder["commit"] == "abc123" and folder["command"] == ["omnid-benchmark", "--out", str(out)]
    assert len(folder["evaluations"]) == 24
    blind = next(e for e in folder["evaluations"] if e["control"] == "blind" and e["model"] == "omnid")
    counts = (blind["successes"], blind["episodes"], blind["train_seed"], blind["commit"])
    assert counts == (0, 10, 1000, "abc123")

    # Resume: nothing finished is redone; an eval whose result is gone and an incomplete training run (its
    # folder without a checkpoint) are. The DP evaluations stay: the same command remakes the checkpoint.
    calls.clear()
    assert bench.main(["--out", str(out)]) == 0 and calls == []
    (out / "eval" / "diffusion" / TASK0 / "ood2" / "seed1" / "eval_info.json").unlink()
    assert bench.main(["--out", str(out)]) == 0
    assert calls == ["lerobot-eval"]
    (out / "train" / "diffusion" / TASK0 / CHECKPOINT / "model.safetensors").unlink()
    calls.clear()
    assert bench.main(["--out", str(out)]) == 0
    assert calls == ["lerobot-train"]
    assert "removing" in capsys.readouterr().out


def test_failed_run_blocks_what_needs_it(monkeypatch, tmp_path, capsys):
    calls: list[str] = []
    monkeypatch.setattr(engine, "run_logged", _fake_tools(calls, {}, fail=("lerobot-train",)))
    assert bench.main(["--out", str(tmp_path), "--settings", "id,ood1"]) == 1
    assert calls == ["omnid-record"] * 3 + ["lerobot-train", "lerobot-train"]
    out = capsys.readouterr().out
    # blocked: 2 x 2 evaluations, 2 x 2 open-loop runs, OmniD's 3 calibration files and 3 control
    # evaluations, DP's blind evaluation
    assert "train/omnid/select_apple: FAILED" in out and "2 failed, 15 blocked" in out
    assert (tmp_path / "report.md").is_file()


def test_dry_run_prints_every_command_and_runs_nothing(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(engine, "run_logged", lambda *a, **k: pytest.fail("dry run ran a command"))
    assert bench.main(["--profile", "paper", "--dry-run", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    # One training run per method and task, three ablations, eight few-shot fine-tunes (every method, two
    # tasks); DP, ACT and VQ-BeT start from a copy whose image input is camera A.
    n_train = 4 * len(gym_omnid.constants.TASKS) + 11
    assert out.count("lerobot-train ") == n_train and out.count("checkpoint_cameras --src") == 3
    assert "Plan: " in out
    assert not any(tmp_path.iterdir())


def test_ablations_only_with_omnid(monkeypatch, tmp_path, capsys):
    """OmniD's ablations are compared with OmniD: `--methods` without it plans none."""
    monkeypatch.setattr(engine, "run_logged", lambda *a, **k: pytest.fail("dry run ran a command"))
    argv = ["--profile", "paper", "--dry-run", "--out", str(tmp_path), "--tasks", TASK0]
    assert bench.main([*argv, "--methods", "act,vqbet"]) == 0
    out = capsys.readouterr().out
    assert "train/omnid_" not in out and "camera A, ablations" not in out and "--policy.type=act" in out
    assert bench.main([*argv, "--methods", "omnid"]) == 0
    out = capsys.readouterr().out
    assert all(f"train/{name}/{TASK0}" in out for name in ABLATIONS)


def _write_eval(path: Path, rate: float, n: int) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"overall": {"pc_success": rate, "n_episodes": n}, "per_task": []}))
    return path


def _records(tmp_path, rows) -> list[EvalRecord]:
    """Finished evaluations' records: rows of (key, eval seed, rate %, episodes[, training seed, control])."""
    records = []
    for i, (key, seed, rate, n, *rest) in enumerate(rows):
        train_seed, control = (rest + [TRAIN_SEED, ""][len(rest) :])[:2]
        path = _write_eval(tmp_path / f"{i}" / "eval_info.json", rate, n)
        records.append(record_of(EvalEntry(key, seed, path, train_seed, control)))
    return records


def test_report_tables_pool_seeds_and_match_the_paper_layout(tmp_path):
    records = _records(
        tmp_path,
        [
            (("omnid", TASK0, "id"), 1, 40.0, 5),
            (("omnid", TASK0, "id"), 2, 60.0, 5),
            (("omnid", TASK1, "id"), 1, 100.0, 10),
            (("diffusion", TASK0, "id"), 1, 80.0, 10),
            *((("omnid", TASK0, f"ood{i}"), 1, 10.0 * i, 10) for i in (1, 2, 4)),
            (("omnid", TASK1, "fewshot_a"), 1, 30.0, 10),
            (("omnid_no_ofg", TASK0, "id"), 1, 20.0, 10),
            (("omnid", TASK0, "id"), 1, 0.0, 10, TRAIN_SEED, "blind"),  # not pooled with the trained model
        ],
    )
    results = collect(records)
    assert results[("omnid", TASK0, "id")].episodes == 10 and results[("omnid", TASK0, "id")].rate == 50.0
    assert collect(records, control="blind")[("omnid", TASK0, "id")].successes == 0
    table = id_table(results, ("omnid", "diffusion"), (TASK0, TASK1), LABELS)
    assert table[0] == "| Method | Select Apple | Select Chemistry Tube | Average |"
    # a lone value is not bold; the average pools the tasks' episodes (15/20)
    assert table[2] == "| OmniD | 50.0 (23.7-76.3) | 100.0 (72.2-100.0) | 75.0 (53.1-88.8) |"
    assert (
        table[3] == "| DP | **80.0 (49.0-94.3)** | — | 80.0 (49.0-94.3)* |"
    )  # average of the evaluated tasks
    table = generalisation_table(
        results, ("omnid", "diffusion"), TASK0, TASK1, ("ood1", "ood2", "ood3", "ood4"), LABELS
    )
    assert table[0] == (
        "| Method | Task 0 ID | Position OOD | Background ood1 | Background ood2 | Background ood3 | "
        "Background ood4 | Fine-tune Task 0-A | Fine-tune Task 1-A |"
    )
    assert table[2] == (
        "| OmniD | 50.0 (23.7-76.3) | — | 10.0 (1.8-40.4) | 20.0 (5.7-51.0) | — | 40.0 (16.8-68.7) | — | "
        "30.0 (10.8-60.3) |"
    )
    assert table[3] == "| DP | **80.0 (49.0-94.3)** | — | — | — | — | — | — | — |"
    table = ablation_table(results, TASK0)
    assert table[0] == "|  | ResNet-101 | w/o OFG | Camera A | Base model |"
    assert table[2] == "| ResNet-18 |  | ✓ | ✓ | ✓ |" and table[4] == "| OFG module | ✓ |  | ✓ | ✓ |"
    assert table[-1] == "| **Success rate (%)** | — | 20.0 (5.7-51.0) | — | 50.0 (23.7-76.3) |"
    missing = EvalEntry(("diffusion", TASK1, "id"), 1, tmp_path / "missing.json", TRAIN_SEED)
    raw = "\n".join(raw_table([missing], records, LABELS))
    assert "| DP | select_chemistry_tube | id |  | 1000 | 1 | — |  | not run yet |" in raw
    blind = (
        f"| OmniD | select_apple | id | blind | 1000 | 1 | 0/10 (0.0-27.8 %) | ? | `{records[-1].source}` |"
    )
    assert blind in raw
    png = bar_chart(
        results,
        ("omnid", "diffusion"),
        (TASK0, TASK1),
        TASK0,
        TASK1,
        ("ood1", "ood2", "ood3", "ood4"),
        LABELS,
        tmp_path / "chart" / "b.png",
    )
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_comparison_pools_training_seeds_and_tests_each(tmp_path):
    """OmniD vs DP with Fisher's test on the episodes pooled over training seeds, and per seed."""
    records = _records(
        tmp_path,
        [
            (("omnid", TASK0, "id"), 1, 60.0, 10, 1000),
            (("omnid", TASK0, "id"), 1, 60.0, 10, 1001),
            (("diffusion", TASK0, "id"), 1, 0.0, 10, 1000),
            (("diffusion", TASK0, "id"), 1, 0.0, 10, 1001),
            (("omnid", TASK0, "ood1"), 1, 50.0, 10, 1000),  # DP not evaluated there: no row
        ],
    )
    table = comparison_table(records, "omnid", ["diffusion"], [(TASK0, "id"), (TASK0, "ood1")], LABELS)
    assert table[0].endswith("| Fisher p (pooled) | Fisher p per training seed |")
    assert len(table) == 3  # header, rule, one row
    # 12/20 vs 0/20 pooled; 6/10 vs 0/10 per seed
    p_pooled, p_seed = fisher_exact(12, 20, 0, 20), fisher_exact(6, 10, 0, 10)
    assert p_pooled < 1e-4 and p_seed == pytest.approx(0.0108, abs=1e-4)
    assert table[2] == (
        "| select_apple | id | DP | 12/20 (38.7-78.1 %) | 0/20 (0.0-16.1 %) | +60.0 (+33.3 to +78.1) | "
        f"<0.0001 | 1000: {p_seed:.2g}, 1001: {p_seed:.2g} |"
    )
    single = [r for r in records if r.train_seed == 1000]
    assert (
        "per training seed"
        not in comparison_table(single, "omnid", ["diffusion"], [(TASK0, "id")], LABELS)[0]
    )


def test_controls_table_margins_over_each_control(tmp_path):
    records = _records(
        tmp_path,
        [
            (("omnid", TASK0, "id"), 1, 70.0, 10),
            (("omnid", TASK0, "ood2"), 1, 30.0, 10),
            (("omnid", TASK0, "id"), 1, 0.0, 10, TRAIN_SEED, "blind"),
            (("omnid", TASK0, "id"), 1, 20.0, 10, TRAIN_SEED, "scrambled"),
            (("diffusion", TASK0, "id"), 1, 50.0, 10),
            (("diffusion", TASK0, "id"), 1, 30.0, 10, TRAIN_SEED, "blind"),
        ],
    )
    control_of = {(s, c): control_setting(s, c, ("id",)) for s in SETTINGS for c in CONTROLS}
    assert control_of[("ood2", "blind")] == "id" and control_of[("ood2", "scrambled")] is None
    assert control_of[("position_ood", "blind")] is None
    table = controls_table(
        records, ("omnid", "diffusion"), TASK0, SETTINGS, control_of, LABELS, CONTROL_LABELS
    )
    assert table[0] == "| Method | Control | Setting | As trained | Control | Margin (pp) | Fisher p |"
    assert (
        table[2]
        == "| OmniD | blind | id | 7/10 (39.7-89.2 %) | 0/10 (0.0-27.8 %) | +70.0 (+28.9 to +89.2) | 0.0031 |"
    )
    assert table[3].startswith(
        "| OmniD | blind | ood2 (control of id) | 3/10 (10.8-60.3 %) | 0/10 (0.0-27.8 %) |"
    )
    assert table[4].startswith("| DP | blind | id | 5/10 (23.7-76.3 %) | 3/10 (10.8-60.3 %) | +20.0 (")
    assert table[5].startswith("| OmniD | scrambled geometry | id | 7/10 (39.7-89.2 %) | 2/10 (5.7-51.0 %) |")
    assert len(table) == 6  # DP has no scrambled control, OmniD's scrambled none in ood2


def test_position_curve_table_area_and_chart(tmp_path):
    bands = BANDS_CM
    assert bands == {
        "position_band_1": (0.0, 2.5),
        "position_band_2": (2.5, 5.0),
        "position_band_3": (5.0, 7.5),
        "position_band_4": (7.5, 10.0),
    }
    records = _records(
        tmp_path,
        [
            *(
                (("omnid", TASK0, band), 1, rate, 10)
                for band, rate in zip(BANDS, (80.0, 60.0, 40.0, 20.0), strict=True)
            ),
            *(
                (("diffusion", TASK0, band), 1, rate, 10)
                for band, rate in zip(BANDS, (40.0, 10.0, 0.0, 0.0), strict=True)
            ),
            (("act", TASK0, "position_band_1"), 1, 50.0, 10),
        ],
    )
    results = collect(records)
    area, counts = curve_area(results, "omnid", TASK0, bands)
    assert area == pytest.approx(50.0) and (counts.successes, counts.episodes) == (20, 40)
    assert curve_area(results, "act", TASK0, bands) is None  # bands missing
    table = curve_table(results, ("omnid", "diffusion", "act"), TASK0, bands, LABELS)
    assert table[0] == "| Method | 0-2.5 cm | 2.5-5 cm | 5-7.5 cm | 7.5-10 cm | Area (mean over 0-10 cm) |"
    assert table[2].startswith("| OmniD | **80.0 (49.0-94.3)** | **60.0 (31.3-83.2)** |")
    assert table[2].endswith("| 50.0 (35.2-64.8) |") and table[4].endswith("| — | — | — | — |")
    png = position_curve_chart(
        results, ("omnid", "diffusion", "act"), TASK0, bands, LABELS, tmp_path / "c.png"
    )
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_offline_table_lowest_error_in_bold(tmp_path):
    paths = {}
    for method, error in (("omnid", 2.5), ("diffusion", 7.25)):
        paths[(method, TASK0, "id")] = tmp_path / f"{method}.json"
        hold = {"position_cm": 3.0, "gripper": 0.05}
        paths[(method, TASK0, "id")].write_text(
            json.dumps({"position_cm": error, "gripper": 0.125, "hold": hold})
        )
    paths[("omnid", TASK0, "ood1")] = tmp_path / "not_run.json"
    table = offline_table(paths, ("omnid", "diffusion"), TASK0, ("id", "ood1"), LABELS)
    assert table[0] == "| Method | id | ood1 |"
    assert table[2:] == [
        "| OmniD | **2.5 / 0.12** | — |",
        "| DP | 7.2 / 0.12 | — |",
        "| (holding the measured pose) | 3.0 / 0.05 | — |",
    ]


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--methods", "omnid,pi0"], ["--methods", "pi0", "vqbet"]),
        (["--tasks", "make_tea"], ["--tasks", "make_tea", "select_apple"]),
        (["--settings", "id,ood9"], ["--settings", "ood9", "position_ood"]),
        (["--steps", "0"], ["--steps", ">= 1", "0"]),
        (["--num-workers", "-1"], ["--num-workers", ">= 0", "-1"]),
        (["--eval-seeds", "0,1"], ["--eval-seeds", "positive", "[0, 1]"]),
        (["--eval-seeds", "1,x"], ["--eval-seeds", "1,x"]),
        (["--profile", "huge"], ["--profile", "huge", "mini"]),
        (["--dry-run", "--report-only"], ["--dry-run", "--report-only"]),
    ],
)
def test_bad_arguments_are_named(argv, expected, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        bench.main([*argv, "--out", str(tmp_path / "b")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    for text in expected:
        assert text in err
    assert not (tmp_path / "b").exists()


def test_a_run_is_done_only_when_made_by_the_planned_command(tmp_path):
    runs = build_plan(PROFILES["mini"], tmp_path, (TASK0,))
    named = by_name(runs)
    train, offline = named[f"train/omnid/{TASK0}"], named[f"offline/omnid/{TASK0}/id"]
    assert not any(is_done(r) for r in runs)
    (offline.output).mkdir(parents=True)
    (offline.output / "offline_eval.json").write_text("{}")
    assert engine.state(offline) == "stale"  # products, but no stamp: made by whom?
    engine.write_stamp(offline, "abc", 1.0)
    assert is_done(offline)
    (train.output / CHECKPOINT).mkdir(parents=True)
    engine.write_stamp(train, "abc", 1.0)
    assert engine.state(train) == "to run"  # a checkpoint folder without weights is unfinished
    (train.output / CHECKPOINT / "model.safetensors").write_bytes(b"")
    assert is_done(train)
    # The same run planned with another command, or below another dataset, is not the one stamped.
    other = by_name(build_plan(dataclasses.replace(PROFILES["mini"], steps=3), tmp_path, (TASK0,)))
    assert engine.state(other[train.name]) == "stale" and engine.state(other[offline.name]) == "stale"
    other = by_name(build_plan(dataclasses.replace(PROFILES["mini"], episodes=2), tmp_path, (TASK0,)))
    assert other[train.name].cmd == train.cmd and engine.state(other[train.name]) == "stale"


def test_rerun_with_other_options_reruns_what_they_change_and_reports_only_the_new(monkeypatch, tmp_path):
    """A folder never mixes plans: other training options retrain and re-evaluate (the recordings stay),
    other evaluation options re-evaluate only, other recording options redo everything downstream."""
    calls: list[str] = []
    monkeypatch.setattr(engine, "run_logged", _fake_tools(calls, {"omnid": 60.0, "diffusion": 20.0}))
    out = tmp_path / "bench"
    small = ["--out", str(out), "--settings", "id", "--heldout-episodes", "0"]
    assert bench.main(small) == 0
    first = {t: calls.count(t) for t in ("omnid-record", "lerobot-train", "lerobot-eval")}
    assert first == {"omnid-record": 1, "lerobot-train": 2, "lerobot-eval": 6}

    def rerun(*options: str) -> dict[str, int]:
        calls.clear()
        assert bench.main([*small, *options]) == 0
        return {t: calls.count(t) for t in first}

    assert rerun() == dict.fromkeys(first, 0)
    # Other image size, steps and evaluation episodes: everything is planned anew and reported anew.
    assert rerun("--image-size", "48", "--steps", "3", "--eval-episodes", "3") == first
    evaluations = json.loads((out / "summary.json").read_text())["evaluations"]
    assert {e["episodes"] for e in evaluations} == {3}
    # Other evaluation episodes only: the checkpoints stay.
    assert rerun("--image-size", "48", "--steps", "3", "--eval-episodes", "4") == {
        "omnid-record": 0,
        "lerobot-train": 0,
        "lerobot-eval": 6,
    }
    # Other recordings: retrained and re-evaluated from the new data.
    assert rerun("--image-size", "48", "--steps", "3", "--eval-episodes", "4", "--episodes", "2") == first
    runs_table = (out / "report.md").read_text().split("## Evaluation runs")[1]
    assert "/4 (" in runs_table and "/3 (" not in runs_table and "/10 (" not in runs_table
    evaluations = json.loads((out / "summary.json").read_text())["evaluations"]
    assert len(evaluations) == 6 and {e["episodes"] for e in evaluations} == {4}


TINY = "--episodes 1 --steps 2 --batch-size 2 --image-size 64 --num-workers 0 --eval-episodes 1 "
TINY += "--episode-length 10"
# omnid-benchmark's smallest sizes, shared by the tiny runs so that the few-shot one reuses mini's runs.


def _omnid_benchmark(job: Job, out: Path, *options: str) -> subprocess.CompletedProcess:
    argv = [str(Path(sys.executable).parent / "omnid-benchmark"), "--out", str(out), *TINY.split(), *options]
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    return job.run(argv, timeout=900, env=env)


@job("benchmark", seconds=120)
def _real_tools_tiny(job: Job) -> tuple[Path, subprocess.CompletedProcess]:
    out = job.tmp / "bench"
    return out, _omnid_benchmark(job, out, "--settings", "id", "--heldout-episodes", "1")


@pytest.mark.slow
@pytest.mark.jobs("benchmark")
def test_real_tools_end_to_end_tiny(jobs):
    """The real omnid-record, lerobot-train (OmniD and stock DP) and lerobot-eval, controls included, at the
    smallest sizes."""
    out, proc = jobs.result("benchmark")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    summary = json.loads((out / "results.json").read_text())
    cells = {(c["model"], c["setting"]): c for c in summary["cells"]}
    assert set(cells) == {("omnid", "id"), ("diffusion", "id")}
    assert all(c["episodes"] == 1 for c in cells.values())
    # The controls ran through the real tools: OmniD with the calibration files written from its checkpoint
    # (lerobot-eval --policy.calibration_path), DP with black images (--env.blackout_cameras).
    controls = {(c["model"], c["control"]): c["episodes"] for c in summary["controls"]}
    assert controls == {("omnid", c): 1 for c in ("blind", "scrambled", "perturbed")} | {
        ("diffusion", "blind"): 1
    }
    for control in ("blind", "scrambled", "perturbed"):
        calibrations = load_calibration_file(out / "controls" / "omnid" / TASK0 / f"{control}.json")
        assert sorted(calibrations) == [f"observation.images.cam_{c}" for c in "bcde"]
    stamp = json.loads(
        (out / "stamps" / "eval_blind" / "diffusion" / TASK0 / "id" / "seed1.json").read_text()
    )
    assert "--env.blackout_cameras=[cam_b,cam_c,cam_d,cam_e]" in stamp["command"]
    assert len(json.loads((out / "summary.json").read_text())["evaluations"]) == 6
    report = (out / "report.md").read_text()
    assert "| Method | Select Apple | Average |" in report
    for method in ("omnid", "diffusion"):  # the open-loop diagnostic ran with the real checkpoints
        result = json.loads((out / "offline" / method / TASK0 / "id" / "offline_eval.json").read_text())
        assert result["episodes"] == 1 and result["frames"] > 10 and result["position_cm"] >= 0.0
    assert "open-loop action error" in report


@job("benchmark_fewshot", seconds=150)
def _real_tools_fewshot_tiny(job: Job) -> tuple[Path, subprocess.CompletedProcess]:
    """``--profile mini-fewshot`` on the tiny mini run's folder: its task-0 models fine-tuned on camera A."""
    mini, first = job.result("benchmark")
    if first.returncode != 0:
        return mini, first
    out = job.tmp / "bench"  # a copy: the mini test reads its own folder's results
    shutil.copytree(mini, out)
    options = ("--profile", "mini-fewshot", "--fewshot-episodes", "1", "--finetune-steps", "2")
    return out, _omnid_benchmark(job, out, *options)


@pytest.mark.slow
@pytest.mark.jobs("benchmark", "benchmark_fewshot")
def test_real_tools_fewshot_tiny(jobs):
    """Both task-0 models fine-tuned on camera A of both tasks through the real lerobot-train, DP from its
    one-camera copy, and evaluated with camera A beside its blind control; mini's trainings are reused."""
    out, proc = jobs.result("benchmark_fewshot")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    results = json.loads((out / "results.json").read_text())
    cells = {(c["model"], c["task"], c["setting"]) for c in results["cells"]}
    for model in ("omnid", "diffusion"):
        for task in (TASK0, TASK1):
            assert (model, task, "fewshot_a") in cells
    controls = {(c["model"], c["task"], c["setting"], c["control"]) for c in results["controls"]}
    assert {(m, t, "fewshot_a", "blind") for m in ("omnid", "diffusion") for t in (TASK0, TASK1)} <= controls
    report = (out / "report.md").read_text()
    assert "Few-shot on camera A, select_chemistry_tube: each fine-tuned model" in report
    copy = json.loads((out / "finetune" / "diffusion" / "start_cam_a" / "config.json").read_text())
    assert [k for k in copy["input_features"] if k.startswith("observation.images.")] == [
        "observation.images.cam_a"
    ]
    assert "train/omnid/select_apple: done" not in proc.stdout + proc.stderr  # reused, not retrained


def test_checkpoint_copy_with_other_cameras(tmp_path, capsys):
    src = tmp_path / "pretrained_model"
    src.mkdir()
    image = {"type": "VISUAL", "shape": [3, 64, 64]}
    features = {"observation.state": {"type": "STATE", "shape": [16]}}
    features |= {f"observation.images.cam_{c}": image for c in "bcde"}
    (src / "config.json").write_text(
        json.dumps({"type": "act", "input_features": features, "chunk_size": 16})
    )
    (src / "model.safetensors").write_bytes(b"weights")
    dst = tmp_path / "copy"
    assert checkpoint_cameras.main(["--src", str(src), "--dst", str(dst), "--cameras", "cam_a"]) == 0
    config = json.loads((dst / "config.json").read_text())
    assert config["input_features"] == {
        "observation.state": features["observation.state"],
        "observation.images.cam_a": image,
    }
    assert config["chunk_size"] == 16 and (dst / "model.safetensors").read_bytes() == b"weights"
    assert json.loads((src / "config.json").read_text())["input_features"] == features  # source untouched
    with pytest.raises(SystemExit):
        checkpoint_cameras.main(["--src", str(tmp_path / "nowhere"), "--dst", str(dst), "--cameras", "cam_a"])
    assert "--src" in capsys.readouterr().err


def test_fold_camera_columns_sums_each_steps_camera_blocks():
    # E=1, 2 obs steps of [state 1, 2 cameras x F=2, env 1]: columns e | s0 a0 a1 b0 b1 v0 | s1 ...
    weight = torch.arange(13.0).reshape(1, 13)
    folded = checkpoint_cameras.fold_camera_columns(weight, 1, 2, before=1, after=1, n_cameras=2)
    assert folded.tolist() == [[0.0, 1.0, 2 + 4, 3 + 5, 6.0, 7.0, 8 + 10, 9 + 11, 12.0]]
    with pytest.raises(ValueError, match="columns, got 13"):
        checkpoint_cameras.fold_camera_columns(weight, 1, 2, before=1, after=1, n_cameras=3)


def test_diffusion_copy_with_one_camera_acts_as_the_camera_in_every_slot(tmp_path):
    """LeRobot's DP with a shared encoder, copied from two cameras to camera A: the copy's noise prediction
    on camera A's images equals the original's given those images from both cameras."""
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy
    from lerobot.utils.constants import OBS_IMAGES, OBS_STATE

    torch.manual_seed(0)
    DiffusionPolicy(tiny_diffusion_config()).save_pretrained(tmp_path / "two")
    checkpoint_cameras.retarget_cameras(tmp_path / "two", tmp_path / "one", ["cam_a"])
    two = DiffusionPolicy.from_pretrained(tmp_path / "two").eval()
    one = DiffusionPolicy.from_pretrained(tmp_path / "one").eval()
    assert list(one.config.image_features) == ["observation.images.cam_a"]
    state, images = torch.randn(3, 2, 5), torch.rand(3, 2, 1, 3, 32, 32)
    noisy, t = torch.randn(3, 8, 4), torch.tensor([3, 50, 99])
    with torch.no_grad():
        cond_two = two.diffusion._prepare_global_conditioning(
            {OBS_STATE: state, OBS_IMAGES: images.expand(-1, -1, 2, -1, -1, -1)}
        )
        cond_one = one.diffusion._prepare_global_conditioning({OBS_STATE: state, OBS_IMAGES: images})
        expected = two.diffusion.unet(noisy, t, global_cond=cond_two)
        actual = one.diffusion.unet(noisy, t, global_cond=cond_one)
    assert cond_one.shape[1] < cond_two.shape[1]
    torch.testing.assert_close(actual, expected, rtol=1e-4, atol=1e-5)
    with pytest.raises(ValueError, match="with one, got 3"):
        checkpoint_cameras.retarget_cameras(tmp_path / "two", tmp_path / "x", ["cam_a", "cam_d", "cam_e"])


def test_ctrl_c_keeps_finished_runs_and_writes_the_report(monkeypatch, tmp_path, capsys):
    calls: list[str] = []
    fake = _fake_tools(calls, {"omnid": 50.0})

    def interrupt_second_eval(cmd, log_path, on_line=None):
        if calls.count("lerobot-eval") == 1 and Path(cmd[0]).name == "lerobot-eval":
            raise KeyboardInterrupt
        return fake(cmd, log_path, on_line)

    monkeypatch.setattr(engine, "run_logged", interrupt_second_eval)
    assert bench.main(["--out", str(tmp_path)]) == 130
    assert "Interrupted" in capsys.readouterr().out
    assert "| OmniD | 50.0 (23.7-76.3) |" in (tmp_path / "report.md").read_text()
    calls.clear()
    monkeypatch.setattr(engine, "run_logged", fake)
    assert bench.main(["--out", str(tmp_path)]) == 0
    assert (
        calls.count("lerobot-train") == 1
        and calls.count("lerobot-eval") == 23
        and "omnid-record" not in calls
    )


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


def test_seed_and_control_options(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(engine, "run_logged", lambda *a, **k: pytest.fail("dry run ran a command"))
    argv = ["--dry-run", "--out", str(tmp_path), "--train-seeds", "1000,7", "--control-settings", "none"]
    assert bench.main(argv) == 0
    out = capsys.readouterr().out
    assert "train_seed7/train/omnid/select_apple" in out and "--seed=7" in out
    assert "eval_blind" not in out and "control_calibration" not in out
    assert bench.main(["--dry-run", "--out", str(tmp_path), "--control-settings", "id,position_ood"]) == 0
    assert "eval_blind/diffusion/select_apple/position_ood/seed1" in capsys.readouterr().out
    for bad, expected in (
        (["--train-seeds", "-1"], "non-negative"),
        (["--control-settings", "id,far"], "far"),
    ):
        with pytest.raises(SystemExit):
            bench.main([*bad, "--out", str(tmp_path / "b")])
        assert expected in capsys.readouterr().err


def test_report_only_aggregates_folders_from_two_machines(monkeypatch, tmp_path, capsys):
    """Machine A runs training seed 1000, machine B seed 1001 (its summary copied as a file); the report of
    A with B's results pools both seeds and tests each; the same evaluation twice counts once."""
    calls: list[str] = []
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")
    monkeypatch.setattr(engine, "run_logged", _fake_tools(calls, {"omnid": 60.0, "diffusion": 20.0}))
    small = ["--settings", "id,ood1", "--heldout-episodes", "0"]
    a, b = tmp_path / "a", tmp_path / "b"
    assert bench.main(["--out", str(a), *small]) == 0
    assert bench.main(["--out", str(b), *small, "--train-seeds", "1001"]) == 0
    copied = tmp_path / "docs" / "results" / "mini_seed1001.json"
    copied.parent.mkdir(parents=True)
    copied.write_text((b / "summary.json").read_text())
    shutil.rmtree(b)  # the other machine's folder is not here: its summary is enough
    calls.clear()
    assert bench.main(["--report-only", "--out", str(a), *small, "--also", str(copied), str(a)]) == 0
    assert calls == []
    report = (a / "report.md").read_text()
    assert "Merged with 8 evaluations of:" in report  # 2 x 2 settings + 4 controls: B's, not A's again
    # OmniD 12/20 vs DP 4/20 pooled over the two seeds, and each seed's 6/10 vs 2/10 (p = 0.17)
    assert "| select_apple | id | DP | 12/20 (38.7-78.1 %) | 4/20 (8.1-41.6 %) |" in report
    assert "| 1000: 0.17, 1001: 0.17 |" in report
    assert f"`{copied}`" in report and "| OmniD | select_apple | id |  | 1001 | 1 | 6/10" in report
    assert json.loads((a / "results.json").read_text())["train_seeds"] == [1000, 1001]
    assert len(json.loads((a / "summary.json").read_text())["evaluations"]) == 8  # only A's own
    # A result that contradicts another of the same evaluation, and results of another experiment
    data = json.loads(copied.read_text())
    data["evaluations"][0]["train_seed"] = TRAIN_SEED
    data["evaluations"][0]["successes"] = 1
    conflict = tmp_path / "conflict.json"
    conflict.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"expected one result, got 6/10 in .* and 1/10 in .*conflict.json"):
        bench.main(["--report-only", "--out", str(a), *small, "--also", str(conflict)])
    for bad, expected in (
        (["--steps", "5"], "steps: expected 5 as in this"),
        ([], "expected a benchmark summary"),
    ):
        also = str(copied) if bad else str(tmp_path / "nowhere")
        with pytest.raises(SystemExit):
            bench.main(["--report-only", "--out", str(a), *small, *bad, "--also", also])
        assert expected in capsys.readouterr().err


def test_gpu8_profile_compares_both_methods_in_three_settings(monkeypatch, tmp_path):
    """The GPU profile end to end with the tools stood in (its real run needs a GPU): both methods trained
    once, ID / one unseen table / one position band evaluated with 30 episodes and 10 envs at once, the
    controls in ID, no held-out recordings; then its report."""
    calls: list[str] = []
    monkeypatch.setattr(engine, "run_logged", _fake_tools(calls, {"omnid": 60.0, "diffusion": 20.0}))
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")
    runs = by_name(build_plan(PROFILES["gpu8"], tmp_path, (TASK0,)))
    evals = sorted(n for n in runs if n.startswith("eval/"))
    assert evals == [
        f"eval/{m}/select_apple/{s}/seed1"
        for m in ("diffusion", "omnid")
        for s in ("id", "ood2", "position_band_2")
    ]
    cmd = runs["eval/omnid/select_apple/ood2/seed1"].cmd
    assert flag(cmd, "eval.n_episodes") == "30" and flag(cmd, "eval.batch_size") == "10"
    assert flag(runs["train/omnid/select_apple"].cmd, "policy.device") == "cuda"
    assert flag(runs["train/omnid/select_apple"].cmd, "policy.fuse_last_step_only") == "true"
    mini = by_name(build_plan(PROFILES["mini"], tmp_path / "m", (TASK0,)))
    assert flag(mini["train/omnid/select_apple"].cmd, "policy.fuse_last_step_only") is None
    assert bench.main(["--profile", "gpu8", "--device", "cpu", "--out", str(tmp_path / "b")]) == 0
    assert calls.count("lerobot-train") == 2 and calls.count("omnid-record") == 1
    assert "position_band_2" in (tmp_path / "b" / "report.md").read_text()


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
