"""The experiment engine's checks of a plan, and when a run counts as done: made by the planned command,
below the planned inputs. (Running plans with tiny Python commands as the tools:
tests/e2e/test_engine_runs.py.)"""

import argparse
import dataclasses
from pathlib import Path

import pytest
from omnid_testing import by_name, evaluation

from lerobot_omnid.benchmark.plan import PROFILES, TASK0, build_plan
from lerobot_omnid.measure import engine
from lerobot_omnid.measure.engine import CHECKPOINT, Run, is_done, plan
from lerobot_omnid.measure.results import RunSummary, read_run_summary


def test_a_plan_is_checked(tmp_path):
    with pytest.raises(ValueError, match="two runs are named 'a'"):
        plan([evaluation(tmp_path, "a"), evaluation(tmp_path, "a")], tmp_path)
    with pytest.raises(ValueError, match=r"b needs \['a'\], which are not planned before it"):
        plan([evaluation(tmp_path, "b", needs=["a"])], tmp_path)
    with pytest.raises(ValueError, match="kind 'bake' is not one of"):
        plan([Run("a", "bake", ("true",), tmp_path)], tmp_path)
    with pytest.raises(RuntimeError, match="not planned"):
        engine.write_stamp(evaluation(tmp_path, "a"), None, 0.0)


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


def test_run_protocol_writes_the_outputs_after_each_run_and_never_on_a_dry_run(tmp_path, monkeypatch, capsys):
    """A protocol command's plan: a dry run prints it and writes nothing; a run writes its summary after
    every finished run and at the end; report-only runs nothing and writes it once."""
    runs = plan(
        [Run(name, "eval", ("tool", str(tmp_path / name)), tmp_path / name) for name in "ab"], tmp_path
    )

    def tool(cmd, log, on_line=None):
        (Path(cmd[1])).mkdir(parents=True)
        (Path(cmd[1]) / "eval_info.json").write_text('{"overall": {"pc_success": 0, "n_episodes": 1}}')
        return 0

    monkeypatch.setattr(engine, "run_logged", tool)
    monkeypatch.setattr(engine, "code_commit", lambda: "abc")  # git runs in a subprocess
    written: list[int] = []

    def write_outputs() -> None:
        written.append(sum(is_done(r) for r in runs))

    engine.run_protocol(runs, tmp_path, "test", write_outputs, dry_run=True)
    assert written == [] and "[1/2] a (to run)" in capsys.readouterr().out
    engine.run_protocol(runs, tmp_path, "test", write_outputs, report_only=True)
    assert written == [0]
    engine.run_protocol(runs, tmp_path, "test", write_outputs)
    assert written == [0, 1, 2, 2]


def test_schedule_makes_each_input_just_before_its_first_use_and_skips_recorded_results(tmp_path):
    data, other = evaluation(tmp_path, "data"), evaluation(tmp_path, "other")
    first, second = (evaluation(tmp_path, n, needs=["data"]) for n in ("first", "second"))
    runs = plan([data, other, first, second], tmp_path)
    assert [r.name for r in engine.schedule(runs)] == ["other", "data", "first", "second"]
    recorded = {r.fingerprint for r in runs if r.name in ("first", "other")}
    assert [r.name for r in engine.schedule(runs, recorded)] == ["data", "second"]
    recorded.add(runs[3].fingerprint)  # every consumer of "data" recorded: "data" is not made at all
    assert engine.schedule(runs, recorded) == []


def test_recorded_commands_name_paths_relative_to_the_working_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    cmd = ("lerobot-eval", f"--output_dir={tmp_path}/outputs/eval", "--seed=1000")
    assert engine.portable_command(cmd) == ("lerobot-eval", "--output_dir=outputs/eval", "--seed=1000")


def test_a_fingerprint_names_the_program_not_where_it_is_installed(tmp_path):
    here, there = (Run("a", "eval", (f"{venv}/bin/lerobot-eval", "--seed=1"), tmp_path) for venv in "xy")
    assert plan([here], tmp_path)[0].fingerprint == plan([there], tmp_path)[0].fingerprint


def test_evaluations_are_the_records_of_the_done_runs_with_their_cells(tmp_path):
    """Each done evaluation gives its cell's record (counts, seeds, control, tags, commit); one not done for
    this plan gives none; an evaluation without its cell is refused by name."""
    cell = {"result": ("omnid", TASK0, "id"), "seed": 1000, "train_seed": 1001, "control": "blind"}
    done = dataclasses.replace(evaluation(tmp_path, "done", "40"), tags=(("rig", "higher"),), **cell)
    pending = dataclasses.replace(evaluation(tmp_path, "pending"), **cell)
    runs = plan([done, pending], tmp_path)
    runs[0].output.mkdir()
    (runs[0].output / "eval_info.json").write_text('{"overall": {"pc_success": 40.0, "n_episodes": 5}}')
    engine.write_stamp(runs[0], "abc", 1.0)
    (record,) = engine.evaluations(runs)
    assert (record.key, record.eval_seed, record.train_seed, record.control) == (*cell.values(),)
    assert (record.successes, record.episodes, record.commit, record.tag("rig")) == (2, 5, "abc", "higher")
    assert record.fingerprint == runs[0].fingerprint
    assert record.command == engine.portable_command(runs[0].cmd)  # as a committed summary writes it
    without_cell = plan([evaluation(tmp_path, "bare")], tmp_path)[0]
    (without_cell.output).mkdir()
    (without_cell.output / "eval_info.json").write_text('{"overall": {"pc_success": 0.0, "n_episodes": 1}}')
    engine.write_stamp(without_cell, "abc", 1.0)
    with pytest.raises(ValueError, match="bare: expected an evaluation run with its table cell"):
        engine.evaluations([without_cell])


def test_protocol_main_writes_the_summary_its_decision_and_report_or_reports_committed_summaries(
    tmp_path, monkeypatch
):
    """A protocol's command: it writes ``summary.json``, what the protocol decides from it and
    ``report.md`` into the protocol's results folder; with ``--summary`` it only reports those."""
    monkeypatch.setattr(engine, "code_commit", lambda: "abc")  # git runs in a subprocess
    planned, decided, reported = [], [], []

    def main(argv: list[str]) -> int:
        parser = argparse.ArgumentParser()
        parser.add_argument("--out", type=Path)
        return engine.protocol_main(
            parser,
            argv,
            "demo",
            lambda args, out: planned.append(out) or plan([evaluation(out, "a")], out),
            lambda runs, commit: RunSummary("demo", {"runs": len(runs)}, [], {"chosen": "a"}, commit),
            lambda summary, path: reported.append((summary.settings, path)),
            results_dir=lambda out: out / "results",
            after_summary=lambda summary, folder: decided.append((summary.commit, folder)),
        )

    out = tmp_path / "out"
    assert main(["--out", str(out), "--report-only"]) == 0
    summary = out / "results" / "summary.json"
    assert read_run_summary(summary, "demo").results == {"chosen": "a"}
    assert planned == [out] and decided == [("abc", out / "results")]
    assert reported == [({"runs": 1}, out / "results" / "report.md")]
    assert main(["--out", str(tmp_path / "again"), "--report-only", "--summary", str(summary)]) == 0
    assert planned == [out] and len(decided) == 1  # nothing planned, nothing decided again
    assert reported[-1] == ({"runs": 1}, tmp_path / "again" / "report.md")
