"""omnid-benchmark's command with stand-in tools (the engine's run_logged replaced): runs, reports and
resumes, failures, Ctrl-C, dry runs, options, reruns with other options, aggregation of several folders,
argument errors. (Its plan: test_benchmark_plan.py; the real tools at tiny sizes:
tests/e2e/test_omnid_benchmark.py.)"""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import gym_omnid.constants
import pytest
from omnid_testing import by_name, flag

import lerobot_omnid.benchmark.benchmark as bench
from lerobot_omnid.benchmark import new_camera
from lerobot_omnid.benchmark import plan as plan_module
from lerobot_omnid.benchmark.methods import ABLATIONS, PAPER_RECIPE, FewshotRecipe
from lerobot_omnid.benchmark.plan import PROFILES, TASK0, TASK1, TRAIN_SEED, build_plan
from lerobot_omnid.measure import engine
from lerobot_omnid.measure.engine import CHECKPOINT
from lerobot_omnid.measure.results import RunSummary, write_run_summary

CONTROL_MODULE = "lerobot_omnid.benchmark.control_calibration"
PROBE = "position_extrapolation"
PROBE_MODULE = f"lerobot_omnid.diagnostics.{PROBE}"


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
        elif tool == "lerobot-edit-dataset":
            root = Path(flag(cmd, "new_root"))
            (root / "meta").mkdir(parents=True)
            (root / "meta" / "info.json").write_text("{}")
        elif tool == "omnid-offline-eval":
            out = Path(cmd[cmd.index("--out") + 1])  # .../offline/<model>/<task>/<setting>/offline_eval.json
            out.parent.mkdir(parents=True, exist_ok=True)
            error = 10.0 - rates.get(out.parents[2].name, 0.0) / 10.0
            out.write_text(json.dumps({"position_cm": error, "gripper": 0.25}))
        elif tool == "control_calibration":
            out = Path(cmd[cmd.index("--out") + 1])
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text("{}")
        elif PROBE_MODULE in cmd:  # each model's probe error: 10 cm less a tenth of its success rate
            out = Path(cmd[cmd.index("--out") + 1])
            out.mkdir(parents=True, exist_ok=True)
            models = [a.split("=", 1)[0] for a in cmd[cmd.index("--checkpoint") + 1 :: 2]]
            error = {m: {"probe_cm": 10 - rates.get(m, 0.0) / 10, "mean_cm": 4.47} for m in models}
            found = {m: {"sets": {"validation (id)": e}} for m, e in error.items()}
            write_run_summary(out / "summary.json", RunSummary(PROBE, {}, results={"models": found}))
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
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")  # git runs in a subprocess
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


def test_report_has_a_row_per_recipe_beside_its_blind_control(monkeypatch, tmp_path):
    """End to end with the tools stood in: every recipe's model in the few-shot blind-control table."""
    recipes = (PAPER_RECIPE, new_camera.HYPOTHESES["long_frozen_head"])
    tuned = dataclasses.replace(PROFILES["mini-fewshot"], fewshot_recipes=recipes, fewshot_probe=True)
    monkeypatch.setitem(PROFILES, "mini-fewshot", tuned)
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")
    rates = {"omnid": 60.0, "omnid_long_frozen_head": 80.0, "omnid_long_frozen_head/blind": 10.0}
    monkeypatch.setattr(engine, "run_logged", _fake_tools([], rates))
    assert bench.main(["--profile", "mini-fewshot", "--out", str(tmp_path)]) == 0
    report = (tmp_path / "report.md").read_text()
    section = report.split(f"## Few-shot on camera A, {TASK1}: each fine-tuned model against its blind")[1]
    table = section.split("\n\n")[1].splitlines()
    rows = [line.split(" | ")[:5] for line in table if "| fewshot_a |" in line]
    label = "OmniD 1000 steps, head frozen"
    omnid = [f"| {label}", "blind", "fewshot_a", "8/10 (49.0-94.3 %)", "1/10 (1.8-40.4 %)"]
    dp = ["| DP 1000 steps, head frozen", "blind", "fewshot_a", "0/10 (0.0-27.8 %)", "0/10 (0.0-27.8 %)"]
    assert omnid in rows and dp in rows
    # OmniD's recipe model against DP's by the same recipe; DP's recipe model never against another OmniD.
    comparison = report.split("## OmniD against each method, cell by cell")[1].split("\n## ")[0]
    recipe_table = comparison.split("each method alike:")[1]
    assert f"| {TASK1} | fewshot_a | DP 1000 steps, head frozen | 8/10 (49.0-94.3 %) | 0/10" in recipe_table
    assert comparison.count("| DP 1000 steps, head frozen |") == 2  # one row per few-shot task
    assert f"| {TASK1} | fewshot_a | DP | 6/10" in comparison
    assert '`--policy.frozen_modules=["head"]`' in report  # its options, with their reasons
    probe = report.split(f"## Few-shot on camera A, {TASK0}: where each fine-tuned model places the apple")[1]
    assert "| OmniD 1000 steps, head frozen | 2.00 |" in probe and "| DP | 10.00 |" in probe


def test_zero_shot_models_are_rows_beside_their_blind_controls(monkeypatch, tmp_path):
    recipes = (PAPER_RECIPE, FewshotRecipe("zero_shot", "zero-shot", 0))
    monkeypatch.setitem(
        PROFILES, "mini-fewshot", dataclasses.replace(PROFILES["mini-fewshot"], fewshot_recipes=recipes)
    )
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")
    calls: list[str] = []
    monkeypatch.setattr(engine, "run_logged", _fake_tools(calls, {"omnid_zero_shot": 30.0}))
    assert bench.main(["--profile", "mini-fewshot", "--out", str(tmp_path)]) == 0
    assert calls.count("lerobot-train") == 2 + 4  # B-E models, then the paper's fine-tuning only
    report = (tmp_path / "report.md").read_text()
    section = report.split(f"## Few-shot on camera A, {TASK0}: each fine-tuned model against its blind")[1]
    assert "| OmniD zero-shot | blind | fewshot_a | 3/10 (10.8-60.3 %) | 0/10 (0.0-27.8 %) |" in section
    assert "| DP zero-shot | blind | fewshot_a | 0/10 (0.0-27.8 %) | 0/10 (0.0-27.8 %) |" in section
    assert "| OmniD zero-shot | `--env.per_frame_calibration=true` |" in report
    assert "| DP zero-shot | `no fine-tuning` |" in report


def test_probe_is_kept_in_the_summary_and_resumed_from_it(monkeypatch, tmp_path):
    """The few-shot probe's errors travel in summary.json: a fresh folder resumed from it neither trains
    nor probes again, and a report merged with it (``--also``) shows them."""
    tuned = dataclasses.replace(PROFILES["mini-fewshot"], fewshot_probe=True)
    monkeypatch.setitem(PROFILES, "mini-fewshot", tuned)
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")
    calls: list[str] = []
    monkeypatch.setattr(engine, "run_logged", _fake_tools(calls, {"omnid": 60.0}))
    first, profile = tmp_path / "first", ["--profile", "mini-fewshot"]
    assert bench.main([*profile, "--out", str(first)]) == 0
    done = json.loads((first / "summary.json").read_text())
    [probe] = done["results"]["probes"]
    assert probe["train_seed"] == 1000 and probe["models"]["omnid"] == {"probe_cm": 4.0, "mean_cm": 4.47}
    committed = tmp_path / "committed.json"
    committed.write_text(json.dumps(done))

    calls.clear()
    fresh = tmp_path / "fresh"
    assert bench.main([*profile, "--out", str(fresh), "--resume-from", str(committed)]) == 0
    assert calls == []
    assert json.loads((fresh / "summary.json").read_text())["results"] == done["results"]
    heading = f"## Few-shot on camera A, {TASK0}: where each fine-tuned model places the apple"
    merged = tmp_path / "merged"
    assert bench.main([*profile, "--out", str(merged), "--report-only", "--also", str(committed)]) == 0
    for folder in (fresh, merged):
        probe_table = (folder / "report.md").read_text().split(heading)[1]
        assert "| OmniD | 4.00 |" in probe_table and "| DP | 10.00 |" in probe_table


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

    # Resume: nothing finished is redone; an eval whose result is gone is. A model whose checkpoint is gone
    # is trained again only when an evaluation needs it (the same command remakes it; its done evaluations
    # stay).
    calls.clear()
    assert bench.main(["--out", str(out)]) == 0 and calls == []
    (out / "eval" / "diffusion" / TASK0 / "ood2" / "seed1" / "eval_info.json").unlink()
    assert bench.main(["--out", str(out)]) == 0
    assert calls == ["lerobot-eval"]
    (out / "train" / "diffusion" / TASK0 / CHECKPOINT / "model.safetensors").unlink()
    calls.clear()
    assert bench.main(["--out", str(out)]) == 0 and calls == []
    (out / "eval" / "diffusion" / TASK0 / "ood2" / "seed1" / "eval_info.json").unlink()
    assert bench.main(["--out", str(out)]) == 0
    assert calls == ["lerobot-train", "lerobot-eval"]
    assert "removing" in capsys.readouterr().out


def test_resume_from_a_committed_summary_in_a_fresh_folder(monkeypatch, tmp_path, capsys):
    """A campaign continued on another machine: the evaluations of the summary are kept by fingerprint,
    and only what a missing one needs is recorded and trained again, just before its use."""
    calls: list[str] = []
    monkeypatch.setattr(engine, "run_logged", _fake_tools(calls, {"omnid": 60.0, "diffusion": 20.0}))
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")
    first = tmp_path / "first"
    options = ["--settings", "id,ood2", "--heldout-episodes", "0"]  # evaluations only, no open-loop runs
    assert bench.main(["--out", str(first), *options]) == 0
    done = json.loads((first / "summary.json").read_text())
    assert all(len(e["fingerprint"]) == 16 for e in done["evaluations"])
    committed = tmp_path / "committed.json"
    committed.write_text(json.dumps(done))

    calls.clear()
    fresh = tmp_path / "fresh"
    assert bench.main(["--out", str(fresh), *options, "--resume-from", str(committed)]) == 0
    assert calls == []
    assert bench.main(["--out", str(fresh), *options, "--resume-from", str(committed), "--dry-run"]) == 0
    dry = capsys.readouterr().out
    assert "record/select_apple_bcde (not needed)" in dry
    assert "eval/omnid/select_apple/ood2/seed1 (recorded)" in dry
    again = json.loads((fresh / "summary.json").read_text())
    assert sorted(map(json.dumps, again["evaluations"])) == sorted(map(json.dumps, done["evaluations"]))
    report = (fresh / "report.md").read_text()
    assert "60.0 (31.3-83.2)" in report and "not run yet" not in report

    # One evaluation missing from the summary: its dataset, its model and itself run, in that order.
    missing = next(e for e in done["evaluations"] if e["model"] == "omnid" and e["setting"] == "ood2")
    kept = [e for e in done["evaluations"] if e != missing]
    committed.write_text(json.dumps({**done, "evaluations": kept}))
    calls.clear()
    assert bench.main(["--out", str(tmp_path / "third"), *options, "--resume-from", str(committed)]) == 0
    assert calls == ["omnid-record", "lerobot-train", "lerobot-eval"]
    # the 7 other evaluations kept; DP's training and OmniD's 3 control calibrations not needed
    assert "14 runs: 7 recorded, 4 not needed, 3 ran" in capsys.readouterr().out
    assert len(json.loads((tmp_path / "third" / "summary.json").read_text())["evaluations"]) == len(
        done["evaluations"]
    )

    # Another plan (other evaluation sizes): no fingerprint matches, nothing is kept.
    calls.clear()
    other = [*options, "--eval-episodes", "4", "--resume-from", str(committed)]
    assert bench.main(["--out", str(tmp_path / "other"), *other]) == 0
    assert calls.count("lerobot-eval") == len(done["evaluations"])
    assert "0 results kept from" in capsys.readouterr().out


def test_failed_run_blocks_what_needs_it(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")  # git runs in a subprocess
    calls: list[str] = []
    monkeypatch.setattr(engine, "run_logged", _fake_tools(calls, {}, fail=("lerobot-train",)))
    assert bench.main(["--out", str(tmp_path), "--settings", "id,ood1"]) == 1
    # each dataset is recorded just before its first use (the held-out ones before the open-loop runs)
    assert calls[0] == "omnid-record" and sorted(calls) == ["lerobot-train"] * 2 + ["omnid-record"] * 3
    out = capsys.readouterr().out
    # blocked: 2 x 2 evaluations, 2 x 2 open-loop runs, OmniD's 3 calibration files and 3 control
    # evaluations, DP's blind evaluation
    assert "train/omnid/select_apple: FAILED" in out and "2 failed, 15 blocked" in out
    assert (tmp_path / "report.md").is_file()


def test_dry_run_prints_every_command_and_runs_nothing(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")  # git runs in a subprocess
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
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")  # git runs in a subprocess
    monkeypatch.setattr(engine, "run_logged", lambda *a, **k: pytest.fail("dry run ran a command"))
    argv = ["--profile", "paper", "--dry-run", "--out", str(tmp_path), "--tasks", TASK0]
    assert bench.main([*argv, "--methods", "act,vqbet"]) == 0
    out = capsys.readouterr().out
    assert "train/omnid_" not in out and "camera A, ablations" not in out and "--policy.type=act" in out
    assert bench.main([*argv, "--methods", "omnid"]) == 0
    out = capsys.readouterr().out
    assert all(f"train/{name}/{TASK0}" in out for name in ABLATIONS)


def test_ctrl_c_keeps_finished_runs_and_writes_the_report(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")  # git runs in a subprocess
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
    # the training set was recorded before the interruption, the 6 held-out and few-shot sets were not yet
    assert (
        calls.count("lerobot-train") == 1
        and calls.count("lerobot-eval") == 23
        and calls.count("omnid-record") == 6
    )


def test_rerun_with_other_options_reruns_what_they_change_and_reports_only_the_new(monkeypatch, tmp_path):
    """A folder never mixes plans: other training options retrain and re-evaluate (the recordings stay),
    other evaluation options re-evaluate only, other recording options redo everything downstream."""
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")  # git runs in a subprocess
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


def test_seed_and_control_options(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")  # git runs in a subprocess
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
        ([], "expected a run summary of omnid-benchmark"),
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


def test_six_tasks_profile_reports_every_task_with_controls_and_ranges(monkeypatch, tmp_path):
    """The six-task profile on a benchmark of two tasks with the tools stood in: every method trained and
    evaluated on both, the report's every-task table with its ranges and controls (a method no better than
    its blind control marked) and OmniD against each method pooled over the tasks."""
    monkeypatch.setattr(plan_module, "available_tasks", lambda: ("add_condiment", "get_coffee"))
    calls: list[str] = []
    rates = {"omnid": 60.0, "omnid/blind": 0.0, "diffusion": 20.0, "diffusion/blind": 20.0}
    monkeypatch.setattr(engine, "run_logged", _fake_tools(calls, rates))
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")
    argv = ["--profile", "six-tasks", "--tasks", "add_condiment,get_coffee", "--out", str(tmp_path)]
    rates |= {"omnid_multitask": 40.0, "diffusion_multitask": 20.0}
    assert bench.main([*argv, "--methods", "omnid,diffusion"]) == 0
    assert calls.count("lerobot-train") == 6 and calls.count("lerobot-edit-dataset") == 1
    report = (tmp_path / "report.md").read_text()
    table = report.split("## Every task: each method beside its controls")[1].split("\n## ")[0]
    assert "| range 1 | range 2 | blind | scrambled | ood2 |" in table
    rows = {
        tuple(c.strip() for c in line.split("|")[1:3]): line for line in table.splitlines() if "|" in line
    }
    assert "60.0 (" in rows[("add_condiment", "OmniD")] and "†" not in rows[("add_condiment", "OmniD")]
    assert "20.0 (" in rows[("get_coffee", "DP")] and "†" in rows[("get_coffee", "DP")]
    assert "| 18/30 (42.3-75.4 %) | 18/30 (42.3-75.4 %) |" in rows[("**pooled, 2 tasks**", "OmniD")]
    pooled = report.split("## OmniD against each method over the tasks")[1].split("\n## ")[0]
    assert "| DP | +40.0" in pooled and "| yes |" in pooled
    assert "| add_condiment | 100 | 100 |" in report  # the paper's Table 1 beside, OmniD and DP
    together = report.split("## One model for every task against one model per task")[1]
    assert "| **pooled, 2 tasks** | OmniD multi-task | 40.0 (" in together
    assert "| OmniD | -20.0" in together and "| DP | +0.0" in together


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
        (
            ["--task-steps", "SIZING"],
            ["--task-steps: expected positive step counts", "'get_coffee': 'pending'"],
        ),
    ],
)
def test_bad_arguments_are_named(argv, expected, tmp_path, capsys):
    sizing = tmp_path / "sizing.json"
    sizing.write_text(json.dumps({"select_apple": 1000, "get_coffee": "pending"}))
    argv = [str(sizing) if a == "SIZING" else a for a in argv]
    with pytest.raises(SystemExit) as exit_info:
        bench.main([*argv, "--out", str(tmp_path / "b")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    for text in expected:
        assert text in err
    assert not (tmp_path / "b").exists()


def test_task_steps_come_from_a_sizing_file(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")  # git runs in a subprocess
    sizing = tmp_path / "sizing.json"
    sizing.write_text(json.dumps({"select_apple": 3000}))
    assert bench.main(["--task-steps", str(sizing), "--out", str(tmp_path / "b"), "--dry-run"]) == 0
    assert capsys.readouterr().out.count("--steps=3000 ") == 2  # OmniD and DP on select_apple
    # A task the file does not name (still being sized) is not trained for the profile's steps instead.
    argv = ["--task-steps", str(sizing), "--tasks", "select_apple,get_coffee", "--dry-run"]
    with pytest.raises(SystemExit):
        bench.main([*argv, "--out", str(tmp_path / "c")])
    assert "got none for ['get_coffee']" in capsys.readouterr().err


def test_summary_is_kept_after_every_evaluation(monkeypatch, tmp_path):
    """When an evaluation starts, summary.json already holds every evaluation finished before it: a
    campaign killed mid-run keeps what it measured."""
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")
    calls: list[str] = []
    fake = _fake_tools(calls, {"omnid": 60.0, "diffusion": 20.0})
    seen: list[int] = []

    def run(cmd, log_path, on_line=None):
        if Path(cmd[0]).name == "lerobot-eval":
            summary = tmp_path / "summary.json"
            seen.append(len(json.loads(summary.read_text())["evaluations"]) if summary.is_file() else 0)
        return fake(cmd, log_path, on_line)

    monkeypatch.setattr(engine, "run_logged", run)
    argv = [
        "--out",
        str(tmp_path),
        "--settings",
        "id",
        "--control-settings",
        "none",
        "--heldout-episodes",
        "0",
    ]
    assert bench.main(argv) == 0
    assert seen == list(range(len(seen))) and len(seen) == 2


def test_position_validation_reports_its_variants_and_the_choice(monkeypatch, tmp_path):
    """The position validation end to end with the tools stood in: six models trained, each evaluated in
    ID and the four bands (10 episodes, env seeds 80000 ...); the report's curve has a row per variant and
    the rule's choice per method."""
    calls: list[str] = []
    rates = {"omnid": 30.0, "omnid_clip2": 40.0, "omnid_clip2_shift5": 60.0, "omnid_clip2_shift10": 70.0}
    rates |= {"diffusion": 20.0, "diffusion_clip2": 20.0}
    monkeypatch.setattr(engine, "run_logged", _fake_tools(calls, rates))
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")
    assert bench.main(["--profile", "position-validation", "--out", str(tmp_path / "v")]) == 0
    assert calls.count("lerobot-train") == 6 and calls.count("lerobot-eval") == 30
    report = (tmp_path / "v" / "report.md").read_text()
    curve = "| OmniD clip 2, shift 10 cm |" + " **70.0 (39.7-89.2)** |" * 4 + " 70.0 (54.6-81.9) |"
    assert curve in report  # the curve: a row per variant, its four bands and the area
    chosen = [line.split(" | ")[0] for line in report.splitlines() if "**chosen**" in line]
    assert chosen == ["| OmniD clip 2, shift 10 cm", "| DP"]  # DP's variant only ties it


def test_rigs_validation_reports_the_moved_rigs_and_the_choice(monkeypatch, tmp_path):
    """The moved-rig validation with the tools stood in: three OmniD variants and DP beside OmniD as
    trained, each in ID and on the two unseen rigs; the rig table pools the rigs, the rule picks by them."""
    from lerobot_omnid.measure.report import format_rate
    from lerobot_omnid.measure.results import CellResult

    calls: list[str] = []
    rates = {"omnid": 30.0, "omnid_rot5": 40.0, "omnid_rot10": 60.0, "omnid_single_camera": 50.0}
    monkeypatch.setattr(engine, "run_logged", _fake_tools(calls, rates | {"diffusion": 20.0}))
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")
    assert bench.main(["--profile", "rigs-validation", "--out", str(tmp_path / "r")]) == 0
    assert calls.count("lerobot-train") == 5 and calls.count("lerobot-eval") == 15
    report = (tmp_path / "r" / "report.md").read_text()
    six, pooled = format_rate(CellResult(6, 10, ())), format_rate(CellResult(12, 20, ()))
    row = f"| OmniD cameras turned up to 10 deg | {six} | {six} | {six} | {pooled} |"
    assert row in report
    assert "| Model | ID | rig_higher | rig_bumped | moved rigs pooled |" in report
    chosen = [line.split(" | ")[0] for line in report.splitlines() if "**chosen**" in line]
    assert chosen == ["| OmniD cameras turned up to 10 deg"]
