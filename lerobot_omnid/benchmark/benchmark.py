"""``omnid-benchmark``: the paper's comparison (section 4) on the OmniD benchmark envs, in one command.

OmniD and LeRobot's stock Diffusion Policy (DP), ACT and VQ-BeT are trained with ``lerobot-train`` on the
same datasets recorded by ``omnid-record`` (cameras B-E), for the same steps with the same seed, and
evaluated with ``lerobot-eval``: ID success on every task; on task 0 (select_apple) position OOD, the graded
position bands, four background OODs, each method's controls (blind; OmniD's scrambled geometry) and few-shot
fine-tuning on the unseen camera A (task 0 and task 1); OmniD's ablations. Writes ``<out>/report.md`` (tables
with Wilson intervals and Fisher tests), ``<out>/benchmark.png`` and ``<out>/position_curve.png`` (charts),
``<out>/results.json`` and ``<out>/summary.json`` (this folder's evaluations, to combine with others':
``--report-only --also <folder or summary.json> ...``).

    omnid-benchmark --dry-run          # the plan: settings, every command, what is already done
    omnid-benchmark                    # profile mini: select_apple, OmniD vs DP, CPU (1 h on 2 quiet cores)
    omnid-benchmark --profile paper    # every method, task and setting at the paper's sizes (GPU, days)

Resumable: a run is done when its output is complete and its stamp says it was made by the very command and
inputs planned now (:mod:`lerobot_omnid.measure.engine`); anything else is deleted and rerun when a result
needs it, with everything downstream of it, so a report never shows results made for another plan. Each run
logs to <out>/logs/.

    omnid-benchmark --report-only --out A --also B docs/results/mini_seed1002_eval30_cpu2.json  # 3 folders

A campaign longer than one machine's session continues in a fresh folder from its committed summary:
``--resume-from docs/results/<campaign>.json`` keeps the planned evaluations and few-shot probes it holds
(matched by fingerprint, so a summary of another plan keeps nothing) and records and trains only what the
missing ones need, each dataset and model just before its first use; the new ``summary.json`` holds both.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from lerobot_omnid.benchmark.methods import METHODS
from lerobot_omnid.benchmark.outputs import settings_markdown, summary_probes, write_outputs, write_summary
from lerobot_omnid.benchmark.plan import (
    PROFILES,
    RIG_SETTINGS,
    SETTINGS,
    BenchmarkProfile,
    available_tasks,
    build_plan,
)
from lerobot_omnid.cli import csv_of, int_at_least
from lerobot_omnid.measure import results
from lerobot_omnid.measure.engine import Run, code_commit, describe_plan, execute, schedule, state

OVERRIDES = {  # option: (profile field, minimum)
    "episodes": ("episodes", 1),
    "fewshot_episodes": ("fewshot_episodes", 1),
    "steps": ("steps", 1),
    "finetune_steps": ("finetune_steps", 1),
    "batch_size": ("batch_size", 1),
    "eval_episodes": ("eval_episodes", 1),
    "eval_batch_size": ("eval_batch_size", 1),
    "heldout_episodes": ("heldout_episodes", 0),
    "episode_length": ("episode_length", 1),
    "image_size": ("image_size", 16),
    "num_workers": ("num_workers", 0),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="omnid-benchmark", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--profile", choices=sorted(PROFILES), default="mini", help="sizes (default: mini)")
    parser.add_argument("--out", type=Path, help="output folder (default: outputs/benchmark_<profile>)")
    parser.add_argument(
        "--device", help="torch device (default: the profile's, cpu for mini, cuda for paper)"
    )
    parser.add_argument("--methods", type=csv_of(str, METHODS), help=f"subset of {','.join(METHODS)}")
    parser.add_argument(
        "--tasks", type=csv_of(str, available_tasks()), help="subset of the benchmark's tasks"
    )
    every = (*SETTINGS, *RIG_SETTINGS)
    parser.add_argument("--settings", type=csv_of(str, every), help=f"task-0 settings, of {','.join(every)}")
    parser.add_argument(
        "--eval-seeds", type=csv_of(int, None), help="comma-separated eval seeds, e.g. 1,2,3,4"
    )
    parser.add_argument(
        "--train-seeds",
        type=csv_of(int, None),
        help="comma-separated lerobot-train seeds, e.g. 1000,1001 (default: 1000; other seeds' runs go "
        "to <out>/train_seed<seed>/)",
    )
    parser.add_argument(
        "--control-settings",
        type=csv_of(str, SETTINGS, none=True),
        help="task-0 settings in which the controls are evaluated, or none (mini: id; paper: "
        "id,position_ood)",
    )
    for option, (name, minimum) in OVERRIDES.items():
        values = ", ".join(f"{k} {getattr(v, name)}" for k, v in PROFILES.items())
        parser.add_argument(
            f"--{option.replace('_', '-')}",
            type=int_at_least(minimum),
            help=f"override the profile's ({values})",
        )
    parser.add_argument(
        "--dry-run", action="store_true", help="print the plan and every command, run nothing"
    )
    parser.add_argument("--report-only", action="store_true", help="only rebuild the report from results")
    parser.add_argument(
        "--also",
        type=Path,
        nargs="+",
        default=[],
        metavar="PATH",
        help="other benchmark folders or summary files (their summary.json, e.g. copied under docs/results/) "
        "whose evaluations the report combines with this folder's",
    )
    parser.add_argument(
        "--resume-from",
        type=Path,
        metavar="SUMMARY",
        help="an earlier campaign's summary.json (e.g. committed under docs/results/): the planned "
        "evaluations it holds (same command and inputs, by fingerprint) are not run again, nor the "
        "datasets and models only they need; this folder's summary.json keeps them. Open-loop runs "
        "(--heldout-episodes) are not in a summary: they run again, with the models they need",
    )
    parser.add_argument(
        "--task-steps",
        type=Path,
        metavar="SIZING",
        help="training steps per task: a task sizing's sizing.json (python -m lerobot_omnid.benchmark."
        "task_sizing), naming every planned task",
    )
    parser.add_argument("--verbose", action="store_true", help="show the output of every command")
    return parser


def resolve_profile(parser: argparse.ArgumentParser, args: argparse.Namespace) -> BenchmarkProfile:
    p = PROFILES[args.profile]
    changes = {}
    for option, (name, _) in OVERRIDES.items():
        value = getattr(args, option)
        if value is not None:
            changes[name] = value
    if args.eval_seeds and min(args.eval_seeds) < 1:
        parser.error(f"--eval-seeds: expected positive integers, got {list(args.eval_seeds)}")
    if args.train_seeds and min(args.train_seeds) < 0:
        parser.error(f"--train-seeds: expected non-negative integers, got {list(args.train_seeds)}")
    for name in ("device", "methods", "tasks", "settings", "eval_seeds", "train_seeds", "control_settings"):
        if getattr(args, name) is not None:
            changes[name] = getattr(args, name)
    if args.task_steps:
        sizing = json.loads(args.task_steps.read_text())
        unsized = {task: steps for task, steps in sizing.items() if not isinstance(steps, int) or steps < 1}
        if unsized:
            parser.error(
                f"--task-steps: expected positive step counts per task, got {unsized} in {args.task_steps}"
            )
        changes["task_steps"] = tuple(sizing.items())
    methods = changes.get("methods", p.methods)
    if "omnid" not in methods:
        changes["ablations"] = False  # OmniD's ablations are compared with OmniD itself
    changes["variants"] = tuple(v for v in p.variants if v.method in methods)  # of the methods kept
    return dataclasses.replace(p, **changes)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.dry_run and args.report_only:
        parser.error("--dry-run and --report-only: expected at most one of them, got both")
    p = resolve_profile(parser, args)
    tasks = p.tasks or available_tasks()
    if args.task_steps and (unsized := [t for t in tasks if t not in dict(p.task_steps)]):
        parser.error(
            f"--task-steps: expected a step count for every planned task, got none for {unsized} in "
            f"{args.task_steps} (a task still being sized: plan the others with --tasks)"
        )
    out = (args.out or Path(f"outputs/benchmark_{p.name}")).resolve()

    def comparable_summary(path: Path, option: str) -> results.RunSummary:
        """A summary of this same experiment; otherwise an error naming ``option``."""
        try:
            summary = results.read_run_summary(path, results.BENCHMARK)
            results.check_comparable(dataclasses.asdict(p), summary.settings["profile"], str(path))
        except ValueError as e:
            parser.error(f"{option}: {e}")
        return summary

    for path in args.also:  # before running anything: a summary that cannot be combined is an error now
        comparable_summary(path, "--also")
    resumed = comparable_summary(args.resume_from, "--resume-from") if args.resume_from else None
    commit = code_commit()
    command = ["omnid-benchmark", *(sys.argv[1:] if argv is None else argv)]
    runs = build_plan(p, out, tasks)
    recorded = set()
    if resumed is not None:
        recorded = {r.fingerprint for r in resumed.evaluations if r.fingerprint}
        recorded |= {e["fingerprint"] for e in summary_probes(resumed)}
    print("\n".join(settings_markdown(p, tasks)))
    kinds = ("record", "merge", "prepare", "train", "calibration", "eval", "offline")
    kinds = {k: sum(r.kind == k for r in runs) for k in kinds}
    per_kind = ", ".join(f"{n} {k}" for k, n in kinds.items() if n)
    to_run = schedule(runs, recorded)
    todo = len(to_run)
    stale = sum(state(r) == "stale" for r in to_run)
    redo = f" ({stale} made for another plan: rerun)" if stale else ""
    n_kept = sum(r.kind in ("eval", "probe") and r.fingerprint in recorded for r in runs)
    unplanned = len(recorded - {r.fingerprint for r in runs})
    kept = f", {n_kept} results kept from {args.resume_from}" if args.resume_from else ""
    if unplanned:  # e.g. other tasks: not in this folder's summary.json, keep the file they are in
        kept += f" ({unplanned} of its results are not in this plan and not in this folder's summary)"
    print(f"\nPlan: {len(runs)} runs ({per_kind}), {todo} to run{redo}{kept}; {out}")
    if args.dry_run:
        print("\n".join(describe_plan(runs, recorded)))
        return 0

    def write() -> dict:
        return write_outputs(p, tasks, runs, out, args.also, commit, command, resumed)

    def keep(run: Run) -> None:  # summary.json after every finished result: a kill loses nothing done
        if run.kind in ("eval", "probe"):
            write_summary(p, tasks, runs, out, commit, command, resumed)

    try:
        status, seconds = (
            ({}, {})
            if args.report_only
            else execute(runs, out, args.verbose, commit, "benchmark", on_done=keep, recorded=recorded)
        )
    except KeyboardInterrupt:
        write()
        print(f"\nInterrupted: finished runs are kept, the one in progress is redone next time; {out}")
        return 130
    summary = write()
    states = ("reused", "recorded", "not needed", "ran", "failed", "blocked")
    counts = {s: list(status.values()).count(s) for s in states}
    print(f"\n{len(runs)} runs: " + ", ".join(f"{n} {s}" for s, n in counts.items() if n or s == "ran"))
    print(f"time: {sum(seconds.values()) / 60:.1f} min; report: {out / 'report.md'}, {out / 'benchmark.png'}")
    print(f"this folder's evaluations (copy under docs/results/ to combine): {out / results.SUMMARY}")
    for cell in [*summary["cells"], *summary["controls"]]:
        low, high = cell["wilson_95"]
        print(
            f"  {p.labels.get(cell['model'], cell['model'])} {cell['task']} {cell['setting']}"
            f"{' ' + cell['control'] if cell['control'] else ''}: {cell['successes']}/{cell['episodes']} "
            f"= {cell['success_rate']:.1f}% ({low:.1f}-{high:.1f})"
        )
    return 1 if counts["failed"] or counts["blocked"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
