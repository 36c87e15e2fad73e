"""The task-sizing protocol: its data and first training are the benchmark's own runs, its validation seeds
touch no other seed set, a longer budget is planned only for a task validated below the threshold, and the
report is rebuilt from a summary alone."""

import dataclasses
import json
from pathlib import Path

import pytest
from gym_omnid import TASKS

from lerobot_omnid.benchmark import task_sizing as ts
from lerobot_omnid.benchmark.plan import EVAL_SEED_STRIDE, FEWSHOT_SEED, HELDOUT_SEED, MINI, build_plan
from lerobot_omnid.benchmark.readout_selection import VALIDATION_HELDOUT_SEED
from lerobot_omnid.benchmark.readout_selection import VALIDATION_SEED as READOUT_VALIDATION_SEED
from lerobot_omnid.diagnostics.position_extrapolation import PROBE_SEED
from lerobot_omnid.measure import engine
from lerobot_omnid.measure.results import EvalRecord, RunSummary, tags_of, write_run_summary


def finish(out: Path, run: engine.Run, successes: int | None = None) -> None:
    """Make ``run`` done as the engine sees it: its products, then its stamp."""
    run.output.mkdir(parents=True, exist_ok=True)
    if run.kind == "eval":
        n = ts.VALIDATION_EPISODES
        overall = {"pc_success": 100 * successes / n, "n_episodes": n}
        (run.output / "eval_info.json").write_text(json.dumps({"overall": overall}))
    elif run.kind == "train":
        model = run.output / engine.CHECKPOINT
        model.mkdir(parents=True)
        (model / "model.safetensors").write_bytes(b"0")
        (model / "config.json").write_text("{}")
    else:
        (run.output / "meta").mkdir()
        (run.output / "meta" / "info.json").write_text(json.dumps({"total_episodes": run.episodes}))
    engine.write_stamp(run, "abc", 1.0)


def test_data_and_first_budget_are_the_six_task_benchmarks_own_runs(tmp_path):
    """The same commands in the same folders as omnid-benchmark's DP on every task, so it reuses them."""
    benchmark = dataclasses.replace(MINI, methods=("diffusion",), tasks=None)
    expected = {
        r.name: r.cmd for r in build_plan(benchmark, tmp_path, TASKS) if r.kind in ("record", "train")
    }
    sized = {r.name: r.cmd for r in ts.protocol(tmp_path, TASKS) if r.kind in ("record", "train")}
    assert len(sized) == 2 * len(TASKS)
    assert {name: expected.get(name) for name in sized} == sized


def test_validation_seeds_touch_no_other_seed_set():
    first, last = ts.VALIDATION_SEED, ts.VALIDATION_SEED + ts.VALIDATION_EPISODES - 1
    used = [
        (0, 999),  # training recordings
        *((k * EVAL_SEED_STRIDE, k * EVAL_SEED_STRIDE + 99) for k in range(1, 50)),  # test seeds
        (FEWSHOT_SEED, FEWSHOT_SEED + 999),
        (HELDOUT_SEED, HELDOUT_SEED + 999),
        (READOUT_VALIDATION_SEED, READOUT_VALIDATION_SEED + 999),
        (VALIDATION_HELDOUT_SEED, VALIDATION_HELDOUT_SEED + 999),
        (PROBE_SEED, PROBE_SEED + 999),
    ]
    assert all(last < low or first > high for low, high in used)


def validation_record(task: str, steps: int, successes: int, commit: str | None = None) -> EvalRecord:
    key = ("diffusion", task, "validation")
    record = EvalRecord(key, "", 1000, ts.VALIDATION_SEED, successes, 20, "x", commit)
    return dataclasses.replace(record, tags=tags_of({"steps": steps}))


def test_a_longer_budget_only_for_a_task_validated_below_the_threshold(tmp_path):
    tasks = ["select_apple", "get_coffee"]
    runs = ts.protocol(tmp_path, tasks)
    assert [r.name for r in runs if r.kind == "train"] == [f"train/diffusion/{t}" for t in tasks]
    for run in runs:
        below = run.kind == "eval" and "get_coffee" in run.name
        finish(tmp_path, run, ts.THRESHOLD - 1 if below else ts.THRESHOLD)
    runs = ts.protocol(tmp_path, tasks)
    longer = [r for r in runs if not engine.is_done(r)]
    assert [r.name for r in longer] == [
        f"train_steps{ts.BUDGETS[1]}/diffusion/get_coffee",
        f"validation/diffusion/get_coffee/steps{ts.BUDGETS[1]}",
    ]
    assert f"--steps={ts.BUDGETS[1]}" in longer[0].cmd
    for run in longer:
        finish(tmp_path, run, 0)
    summary = ts.summarise(ts.protocol(tmp_path, tasks), tasks)
    found = {(r.key[1], r.tag("steps")): (r.successes, r.episodes, r.commit) for r in summary.evaluations}
    assert found[("select_apple", "1000")] == (6, 20, "abc") and ("select_apple", "3000") not in found
    assert summary.results["budgets"]["select_apple"] == 1000
    assert summary.results["budgets"]["get_coffee"] is None  # not learned within the last budget


def test_budgets_of_committed_summaries_are_not_run_again(tmp_path):
    """A later session passes the earlier sessions' summaries with --also: a task decided there plans
    nothing, one validated below the threshold there plans only its next budget."""
    earlier = [
        validation_record("select_apple", 1000, 9, "c1"),
        validation_record("get_coffee", 1000, 2, "c2"),
    ]
    source = write_run_summary(tmp_path / "earlier.json", RunSummary(ts.PROTOCOL, {}, earlier))
    known = ts.read_known([source])
    tasks = ["select_apple", "get_coffee", "texas_holdem"]
    runs = ts.protocol(tmp_path / "out", tasks, known)
    assert [r.name for r in runs if r.kind != "record"] == [
        f"train_steps{ts.BUDGETS[1]}/diffusion/get_coffee",
        f"validation/diffusion/get_coffee/steps{ts.BUDGETS[1]}",
        "train/diffusion/texas_holdem",
        f"validation/diffusion/texas_holdem/steps{ts.BUDGETS[0]}",
    ]
    summary = ts.summarise(runs, tasks, known)
    apple = [r for r in summary.evaluations if r.key[1] == "select_apple"]
    assert [(r.successes, r.commit, r.tag("steps")) for r in apple] == [(9, "c1", "1000")]
    assert summary.results["budgets"] == {
        "select_apple": 1000,
        "get_coffee": "pending",
        "texas_holdem": "pending",
    }
    with pytest.raises(ValueError, match="expected each task and budget once, got select_apple at 1000"):
        ts.read_known([source, source])


@pytest.mark.parametrize(
    ("counts", "budget"),
    [
        ({}, "pending"),
        ({1000: (6, 20)}, 1000),
        ({1000: (5, 20)}, "pending"),
        ({1000: (5, 20), 3000: (6, 20)}, 3000),
        ({1000: (5, 20), 3000: (2, 20)}, None),
    ],
)
def test_rule_takes_the_first_budget_at_the_threshold(counts, budget):
    assert ts.size(counts) == budget


def test_report_only_rebuilds_the_report_from_a_summary(tmp_path, capsys):
    settings = {
        "method": "diffusion",
        "budgets": [1000, 3000],
        "threshold": 6,
        "validation_seed": 60000,
        "validation_episodes": 20,
        "train_seed": 1000,
        "tasks": ["select_apple", "texas_holdem"],
    }
    evaluations = [
        validation_record("select_apple", 1000, 12),
        validation_record("texas_holdem", 1000, 1),
        validation_record("texas_holdem", 3000, 3),
    ]
    budgets = {"budgets": {"select_apple": 1000, "texas_holdem": None}}
    source = write_run_summary(
        tmp_path / "summary.json", RunSummary(ts.PROTOCOL, settings, evaluations, budgets)
    )
    assert ts.main(["--out", str(tmp_path / "out"), "--report-only", "--summary", str(source)]) == 0
    report = (tmp_path / "out" / "report.md").read_text()
    assert "| select_apple | 12/20 (38.7-78.1 %) | — | 1000 |" in report
    assert (
        "| texas_holdem | 1/20 (0.9-23.6 %) | 3/20 (5.2-36.0 %) | not learned within 3000 steps |" in report
    )


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--summary", "s.json"], "--summary: expected with --report-only"),
        (["--tasks", "select_apple,fly"], "--tasks: expected names from select_apple,"),
    ],
)
def test_bad_arguments_name_the_option(argv, message, tmp_path, capsys):
    with pytest.raises(SystemExit):
        ts.main(["--out", str(tmp_path), *argv])
    assert message in capsys.readouterr().err
