"""Sizing every task for a CPU on validation: how long LeRobot's DP must train before it does the task at all.

The protocol (docs/benchmark.md#sizing-the-six-tasks), fixed before any of its runs:

1. *Data*: per task, the benchmark's ``mini`` training set (50 expert episodes from env seed 0, cameras
   B-E, 64 px), recorded by the same command as ``omnid-benchmark``'s, in the same folder, so that the
   six-task benchmark run with this ``--out`` reuses it.
2. *Candidate*: LeRobot's ``diffusion`` with the benchmark's options (``methods.method_flags``), the
   strongest stock baseline here, trained with ``lerobot-train --seed=1000`` for ``BUDGETS[0]`` steps
   (this run is the benchmark's own ``train/diffusion/<task>``); a task below the threshold is trained
   again for ``BUDGETS[1]`` steps, and so on, never beyond the last budget.
3. *Validation*, never reported as a result: ``lerobot-eval`` in the ID setting on env seeds
   ``VALIDATION_SEED`` ... (``VALIDATION_EPISODES`` episodes), disjoint from the training (0 ...), test
   (1000k), few-shot (100000), held-out (200000), readout-validation (50000, 300000) and probe (400000)
   seeds.
4. *Rule* (:func:`size`): a task's budget is the first whose validation success reaches ``THRESHOLD``; a
   task below it at every budget is "not learned within the last budget" and stays in the table as
   measured. The budgets are written to ``sizing.json``; the six-task benchmark trains every method for
   its task's budget (``omnid-benchmark --task-steps sizing.json``).

Runs on the experiment engine (resumable; ``--dry-run`` prints every command; the next budget of a task is
planned once its validation is done; ``--also`` takes committed summaries of earlier sessions, whose
validated budgets are not run again); writes ``<out>/report.md`` and ``<out>/summary.json``, and
``--report-only --summary FILE`` rebuilds the report from such a summary alone.

    MUJOCO_GL=egl python -m lerobot_omnid.benchmark.task_sizing --out outputs/six_tasks
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterable, Sequence
from pathlib import Path

from gym_omnid import TASKS, TRAIN_CAMERAS

from lerobot_omnid.benchmark import commands
from lerobot_omnid.benchmark.methods import method_flags
from lerobot_omnid.benchmark.plan import PROFILES, TRAIN_SEED, train_folder
from lerobot_omnid.cli import add_protocol_options
from lerobot_omnid.measure.engine import (
    CHECKPOINT,
    Run,
    code_commit,
    describe_plan,
    evaluations,
    execute,
    plan,
    report_from_summary,
    schedule,
)
from lerobot_omnid.measure.report import format_counts, write_markdown
from lerobot_omnid.measure.results import (
    SUMMARY,
    EvalRecord,
    RunSummary,
    read_run_summary,
    tags_of,
    write_run_summary,
)

PROFILE = PROFILES["mini"]
METHOD = "diffusion"
BUDGETS = (1000, 3000)  # training steps tried in turn; the first is mini's (its runs are the benchmark's)
VALIDATION_SEED = 60_000
VALIDATION_EPISODES = 20
THRESHOLD = 6  # validation successes of VALIDATION_EPISODES (30 %): the task is being done, not stumbled on
SIZING_FILE = "sizing.json"
PROTOCOL = "task_sizing"


def train_dir(out: Path, task: str, steps: int) -> Path:
    """The benchmark's own folder of a model trained for ``steps`` (:func:`plan.train_folder`)."""
    return out / train_folder(PROFILE, steps) / METHOD / task


def validation_dir(out: Path, task: str, steps: int) -> Path:
    return out / "validation" / METHOD / task / f"steps{steps}"


def task_runs(out: Path, task: str, budgets: Sequence[int]) -> list[Run]:
    """Record ``task``'s training set; per budget, train and validate."""
    data = out / "data" / f"{task}_bcde"
    record = commands.record_command(task, PROFILE.episodes, TRAIN_CAMERAS, PROFILE.image_size, data, seed=0)
    runs = [Run(f"record/{data.name}", "record", tuple(record), data, episodes=PROFILE.episodes)]
    flags = [f"--policy.type={METHOD}", f"--policy.device={PROFILE.device}", "--policy.push_to_hub=false"]
    flags += [flag for flag, _ in method_flags(METHOD, PROFILE)]
    for steps in budgets:
        trained = train_dir(out, task, steps)
        name = f"{trained.relative_to(out)}"
        cmd = commands.train_command(
            data, trained, flags, steps, PROFILE.batch_size, PROFILE.num_workers, seed=TRAIN_SEED
        )
        runs.append(Run(name, "train", tuple(cmd), trained, (runs[0].name,), train_seed=TRAIN_SEED))
        output = validation_dir(out, task, steps)
        cmd = commands.eval_command(
            trained / CHECKPOINT,
            output,
            task,
            "id",
            TRAIN_CAMERAS,
            PROFILE.image_size,
            VALIDATION_EPISODES,
            PROFILE.device,
            seed=VALIDATION_SEED,
            extra=(f"--env.episode_length={PROFILE.episode_length}",),
            batch_size=min(PROFILE.eval_batch_size, VALIDATION_EPISODES),
        )
        cell = {"result": (METHOD, task, "validation"), "seed": VALIDATION_SEED, "train_seed": TRAIN_SEED}
        tags = tags_of({"steps": steps})
        runs.append(Run(f"{output.relative_to(out)}", "eval", tuple(cmd), output, (name,), tags=tags, **cell))
    return runs


def size(counts: dict[int, tuple[int, int]]) -> int | str | None:
    """The rule: the first budget (in ``BUDGETS`` order) whose validation successes reach ``THRESHOLD``;
    None when every budget is measured and none does; "pending" while a needed budget is unmeasured."""
    for steps in BUDGETS:
        if steps not in counts:
            return "pending"
        if counts[steps][0] >= THRESHOLD:
            return steps
    return None


Known = dict[tuple[str, int], EvalRecord]
"""Validation records already measured, per (task, budget): those of committed summaries (``--also``)."""


def validated(records: Iterable[EvalRecord]) -> dict[tuple[str, int], EvalRecord]:
    """Validation records per (task, budget)."""
    return {(r.key[1], int(r.tag("steps"))): r for r in records}


def budget_counts(found: Known, task: str) -> dict[int, tuple[int, int]]:
    """``task``'s validation (successes, episodes) per budget measured."""
    return {steps: (r.successes, r.episodes) for (t, steps), r in found.items() if t == task}


def protocol(out: Path, tasks: Sequence[str], known: Known | None = None) -> list[Run]:
    """Every task's runs up to the budget the validation so far calls for: a budget is planned when the
    previous one is validated (here or in ``known``) and below the threshold; a known budget is not run."""
    runs: list[Run] = []
    for task in tasks:
        counts = budget_counts(known or {}, task)
        todo: list[int] = []
        for steps in BUDGETS:
            if size(counts) != "pending":
                break
            if steps in counts:
                continue
            todo.append(steps)
            measured = budget_counts(validated(evaluations(plan(task_runs(out, task, todo), out))), task)
            if steps not in measured:
                break
            counts[steps] = measured[steps]
        if todo:
            runs += task_runs(out, task, todo)
    return plan(runs, out)


def summarise(
    runs: Sequence[Run], tasks: Sequence[str], known: Known | None = None, commit: str | None = None
) -> RunSummary:
    """Per task the validation record of every budget done for this plan or ``known`` (tagged with its
    steps, with the commit that measured it), and the rule's budget (``results["budgets"]``)."""
    found = {**(known or {}), **validated(evaluations(runs))}
    records = [found[task, steps] for task in tasks for steps in BUDGETS if (task, steps) in found]
    budgets = {task: size(budget_counts(found, task)) for task in tasks}
    settings = {
        "method": METHOD,
        "budgets": list(BUDGETS),
        "threshold": THRESHOLD,
        "validation_seed": VALIDATION_SEED,
        "validation_episodes": VALIDATION_EPISODES,
        "train_seed": TRAIN_SEED,
        "tasks": list(tasks),
    }
    return RunSummary(PROTOCOL, settings, records, {"budgets": budgets}, commit)


def read_known(paths: Sequence[Path]) -> Known:
    """The validation records of committed summaries; a (task, budget) given twice is an error."""
    known: Known = {}
    for path in paths:
        for record in read_run_summary(path, PROTOCOL).evaluations:
            if record.tag("steps") is None:
                raise ValueError(
                    f"--also: expected every evaluation tagged with its steps, got none in {path}"
                )
            task, steps = record.key[1], int(record.tag("steps"))
            if (task, steps) in known:
                raise ValueError(
                    f"--also: expected each task and budget once, got {task} at {steps} steps again in {path}"
                )
            known[task, steps] = record
    return known


def write_report(summary: RunSummary, path: Path) -> None:
    """``report.md``: per task the validation success at each budget and the budget the rule gives."""
    settings = summary.settings
    budgets = settings["budgets"]
    first = settings["validation_seed"]
    lines = [
        "# Sizing the tasks: DP's validation success per training budget (mini data)",
        "",
        f"`{settings['method']}`, `lerobot-train --seed={settings['train_seed']}`; ID on env seeds {first}-"
        f"{first + settings['validation_episodes'] - 1}; rule: the first budget with at least "
        f"{settings['threshold']}/{settings['validation_episodes']} successes.",
        "",
        "| task | " + " | ".join(f"{b} steps (Wilson 95 %)" for b in budgets) + " | budget |",
        "|---|" + "---|" * (len(budgets) + 1),
    ]
    counts = {(r.key[1], int(r.tag("steps"))): (r.successes, r.episodes) for r in summary.evaluations}
    for task in settings["tasks"]:
        cells = [format_counts(counts.get((task, b))) for b in budgets]
        budget = summary.results["budgets"][task]
        chosen = f"not learned within {budgets[-1]} steps" if budget is None else str(budget)
        lines.append(f"| {task} | " + " | ".join(cells) + f" | {chosen} |")
    write_markdown(lines, path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("outputs/six_tasks"))
    parser.add_argument(
        "--tasks", default=",".join(TASKS), help=f"comma-separated subset of {','.join(TASKS)} (default all)"
    )
    parser.add_argument(
        "--also",
        nargs="+",
        type=Path,
        default=[],
        metavar="SUMMARY",
        help="committed summaries of earlier runs: their validated budgets count as measured, not rerun",
    )
    add_protocol_options(parser)
    args = parser.parse_args(argv)
    out = args.out.resolve()
    if report_from_summary(parser, args, out, PROTOCOL, write_report):
        return 0
    tasks = [t for t in args.tasks.split(",") if t]
    if unknown := [t for t in tasks if t not in TASKS]:
        parser.error(f"--tasks: expected names from {','.join(TASKS)}, got {','.join(unknown)}")
    try:
        known = read_known(args.also)
    except ValueError as e:
        parser.error(str(e))
    runs = protocol(out, tasks, known)
    if args.dry_run:
        print("\n".join(describe_plan(runs)))
        return 0
    commit = code_commit()
    if not args.report_only:
        # Each pass runs what the validation so far calls for (a task below the threshold gets its next
        # budget in the next pass); the summary is rewritten after every finished run.
        while schedule(runs):
            execute(
                runs,
                out,
                commit=commit,
                desc="task sizing",
                on_done=lambda _, runs=runs: write_outputs(out, runs, tasks, known, commit),
                stop_on_failure=True,
            )
            runs = protocol(out, tasks, known)
    write_outputs(out, runs, tasks, known, commit)
    return 0


def write_outputs(
    out: Path, runs: Sequence[Run], tasks: Sequence[str], known: Known, commit: str | None = None
) -> None:
    """``summary.json``, ``sizing.json`` (each decided task's training steps) and ``report.md`` from the
    runs done and the ``known`` counts."""
    summary = summarise(runs, tasks, known, commit)
    out.mkdir(parents=True, exist_ok=True)
    write_run_summary(out / SUMMARY, summary)
    # What the six-task benchmark trains for (`omnid-benchmark --task-steps`): a task not learned within
    # the last budget is measured at that budget; a task still pending has no entry yet.
    steps = {
        task: BUDGETS[-1] if budget is None else budget
        for task, budget in summary.results["budgets"].items()
        if budget != "pending"
    }
    (out / SIZING_FILE).write_text(json.dumps(steps, indent=2) + "\n")
    write_report(summary, out / "report.md")


if __name__ == "__main__":
    raise SystemExit(main())
