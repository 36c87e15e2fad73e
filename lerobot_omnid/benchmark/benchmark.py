"""``omnid-benchmark``: the paper's comparison (section 4) on the OmniD benchmark envs, in one command.

OmniD and LeRobot's stock Diffusion Policy (DP), ACT and VQ-BeT are trained with ``lerobot-train`` on the
same datasets recorded by ``omnid-record`` (cameras B-E), for the same steps with the same seed, and
evaluated with ``lerobot-eval``: ID success on every task; on task 0 (select_apple) position OOD, four
background OODs and few-shot fine-tuning on the unseen camera A (task 0 and task 1); OmniD's ablations.
Writes ``<out>/report.md`` (tables laid out like the paper's), ``<out>/benchmark.png`` (bar chart) and
``<out>/results.json``.

    omnid-benchmark --dry-run          # the plan: settings, every command, what is already done
    omnid-benchmark                    # profile mini: select_apple, OmniD vs DP, CPU (under 2 h on 2 cores)
    omnid-benchmark --profile paper    # every method, task and setting at the paper's sizes (GPU, days)

Resumable: a run whose output is complete (a dataset with all its episodes, a final checkpoint, an
eval_info.json) is not run again; an incomplete one is deleted and rerun. Each run logs to <out>/logs/.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import shutil
import sys
import time
from pathlib import Path

from tqdm import tqdm

from lerobot_omnid.benchmark import report
from lerobot_omnid.benchmark.commands import run_logged
from lerobot_omnid.benchmark.plan import (
    ABLATIONS,
    BACKGROUND_OODS,
    EVAL_SEED_STRIDE,
    FEWSHOT_SEED,
    HELDOUT_SEED,
    LABELS,
    METHODS,
    NOT_FINETUNABLE,
    OFFLINE_OUTPUT,
    PROFILES,
    SETTINGS,
    TASK0,
    TASK1,
    TRAIN_SEED,
    VQBET_CAMERA,
    BenchmarkProfile,
    Run,
    ablation_flags,
    available_tasks,
    build_plan,
    finetune_flags,
    is_done,
    method_flags,
)
from lerobot_omnid.cli import int_at_least

OVERRIDES = {  # option: (profile field, minimum)
    "episodes": ("episodes", 1),
    "fewshot_episodes": ("fewshot_episodes", 1),
    "steps": ("steps", 1),
    "finetune_steps": ("finetune_steps", 1),
    "batch_size": ("batch_size", 1),
    "eval_episodes": ("eval_episodes", 1),
    "heldout_episodes": ("heldout_episodes", 0),
    "episode_length": ("episode_length", 1),
    "image_size": ("image_size", 16),
    "num_workers": ("num_workers", 0),
}


def settings_markdown(p: BenchmarkProfile, tasks: tuple[str, ...]) -> list[str]:
    """What is run and how, with every non-default option and its reason."""
    evals = ", ".join(f"{k} (env seeds {k * EVAL_SEED_STRIDE}+)" for k in p.eval_seeds)
    parts = [f"{TASK0} settings {', '.join(p.settings)}"]
    parts += ["few-shot on camera A"] if p.fewshot else []
    parts += ["ablations"] if p.ablations else []
    lines = [
        f"Profile `{p.name}` on `{p.device}`: methods {', '.join(LABELS[m] for m in p.methods)}; "
        f"tasks {', '.join(tasks)}; {', '.join(parts)}.",
        "",
        f"- Same for every method: datasets of {p.episodes} expert episodes per task (cameras B-E, "
        f"{p.image_size}x{p.image_size} px, env seeds from 0), {p.steps} training steps, "
        f"batch {p.batch_size}, `--seed={TRAIN_SEED}`; evaluation: {p.eval_episodes} episodes per setting "
        f"and eval seed, eval seeds {evals}, at most {p.episode_length} env steps (10 per second).",
        f"- Few-shot: the task-0 model fine-tuned for {p.finetune_steps} steps on {p.fewshot_episodes} "
        f"camera-A episodes (env seeds from {FEWSHOT_SEED}) of {TASK0} and of {TASK1}, evaluated with "
        "camera A."
        if p.fewshot
        else "- Few-shot fine-tuning: not in this profile.",
        "- Cells pool the episodes of all eval seeds; `—`: not run (yet); `n/a`: not applicable.",
        f"- Open-loop diagnostic: {p.heldout_episodes} held-out expert episodes per {TASK0} setting."
        if p.heldout_episodes
        else "- Open-loop diagnostic: off.",
        "",
        "| Method | Option | Why |",
        "| --- | --- | --- |",
    ]
    rows = [(LABELS[m], f, why) for m in p.methods for f, why in method_flags(m, p)]
    if p.ablations:
        base = {f for f, _ in method_flags("omnid", p)}
        rows += [(LABELS[a], f, why) for a in ABLATIONS for f, why in ablation_flags(a, p) if f not in base]
    if p.fewshot:
        for m in p.methods:
            if m in NOT_FINETUNABLE:
                rows.append((f"{LABELS[m]} fine-tune", "(none)", NOT_FINETUNABLE[m]))
            else:
                rows += [(f"{LABELS[m]} fine-tune", f, why) for f, why in finetune_flags(m, p)]
    lines += [f"| {who} | `{flag}` | {why} |" for who, flag, why in rows]
    notes = {
        "act": "ACT: one observation step (the only value LeRobot's ACT supports); without pretrained "
        "weights its frozen BatchNorm layers are identities (it has no GroupNorm option); its own optimiser "
        "(AdamW 1e-5, no schedule) is kept.",
        "vqbet": f"VQ-BeT: evaluated with camera {VQBET_CAMERA[0][-1].upper()} only (its single input); "
        "its own optimiser settings are kept.",
    }
    lines += [""] + [f"- {notes[m]}" for m in p.methods if m in notes]
    return lines


def describe_plan(runs: list[Run]) -> list[str]:
    lines = []
    for i, run in enumerate(runs, 1):
        state = "done" if is_done(run) else "to run"
        lines += [f"[{i}/{len(runs)}] {run.name} ({state})", "  " + shlex.join(run.cmd)]
    return lines


def clear_incomplete(run: Run, out: Path) -> None:
    """Remove what an interrupted record or train run left (the tools refuse an existing folder)."""
    if run.kind in ("record", "train") and run.output.exists():
        run.output.relative_to(out)  # never delete outside the benchmark's folder
        tqdm.write(f"{run.name}: removing the incomplete {run.output}")
        shutil.rmtree(run.output)


def execute(runs: list[Run], out: Path, verbose: bool) -> tuple[dict[str, str], dict[str, float]]:
    """Run what is not done yet, in order; a failed run blocks the runs that need its output.
    Returns each run's status ("reused", "ran", "failed", "blocked") and the seconds of those run."""
    status, seconds = {}, {}
    bar = tqdm(runs, desc="benchmark", unit="run", file=sys.stdout, dynamic_ncols=True)
    for run in bar:
        bar.set_postfix_str(run.name)
        if is_done(run):
            status[run.name] = "reused"
            continue
        blocked = [n for n in run.needs if status.get(n) in ("failed", "blocked")]
        if blocked:
            status[run.name] = "blocked"
            tqdm.write(f"{run.name}: skipped, it needs {', '.join(blocked)}")
            continue
        clear_incomplete(run, out)
        log = out / "logs" / (run.name.replace("/", "__") + ".log")
        last = [0.0]

        def show(line: str, run: Run = run, last: list[float] = last) -> None:
            if verbose:
                tqdm.write(line.rstrip())
            elif time.monotonic() - last[0] > 1.0 and line.strip():
                last[0] = time.monotonic()
                bar.set_postfix_str(f"{run.name}: {line.strip()[-60:]}")

        start = time.perf_counter()
        returncode = run_logged(run.cmd, log, on_line=show)
        seconds[run.name] = time.perf_counter() - start
        if returncode == 0 and is_done(run):
            status[run.name] = "ran"
            tqdm.write(f"{run.name}: done in {seconds[run.name]:.0f} s")
        else:
            status[run.name] = "failed"
            tqdm.write(f"{run.name}: FAILED (exit code {returncode}, output incomplete); log: {log}")
    return status, seconds


def write_outputs(p: BenchmarkProfile, tasks: tuple[str, ...], runs: list[Run], out: Path) -> dict:
    """report.md, benchmark.png and results.json from the eval_info.json files found now."""
    entries = [
        report.EvalEntry(r.result, r.seed, r.output / "eval_info.json") for r in runs if r.kind == "eval"
    ]
    offline = {r.result: r.output / OFFLINE_OUTPUT for r in runs if r.kind == "offline"}
    results = report.collect(entries)
    n_a = {(m, t, "fewshot_a") for m in NOT_FINETUNABLE for t in (TASK0, TASK1)} if p.fewshot else set()
    chart = report.bar_chart(
        results, p.methods, tasks, TASK0, TASK1, BACKGROUND_OODS, LABELS, out / "benchmark.png"
    )
    lines = ["# OmniD benchmark: OmniD vs DP, ACT, VQ-BeT", "", *settings_markdown(p, tasks), ""]
    lines += ["## ID success rate (%) per task, cameras B-E", ""]
    lines += report.id_table(results, p.methods, tasks, LABELS)
    if TASK0 in tasks:
        lines += ["", f"## Task 0 ({TASK0}): generalisation and few-shot on camera A, success rate (%)", ""]
        lines += report.generalisation_table(results, p.methods, TASK0, TASK1, BACKGROUND_OODS, n_a, LABELS)
    if offline:
        lines += [
            "",
            f"## Task 0 ({TASK0}): open-loop action error on held-out expert episodes",
            "",
            f"Diagnostic next to the success rates: {p.heldout_episodes} expert episodes per setting "
            f"(env seeds from {HELDOUT_SEED}, never trained on) replayed through each policy as "
            "`lerobot-eval` runs it (`omnid-offline-eval`); mean TCP position error (cm) / gripper error "
            "(0..1) of its action at every frame against the expert's. Lower is better; informative even "
            "when every success rate is 0. The last row is the error of holding the measured pose and "
            "gripper at every frame: a policy that does not beat it has not learned to act yet.",
            "",
        ]
        lines += report.offline_table(offline, p.methods, TASK0, p.settings, LABELS)
    if p.ablations:
        lines += ["", f"## Ablation: OmniD on task 0 ({TASK0}), ID success rate (%)", ""]
        lines += report.ablation_table(results, TASK0)
    lines += ["", f"![success rates]({chart.name})", "", "## Evaluation runs", ""]
    lines += report.raw_table(entries, LABELS)
    (out / "report.md").write_text("\n".join(lines) + "\n")
    cells = [
        {
            "model": m,
            "task": t,
            "setting": s,
            "success_rate": c.rate,
            "episodes": c.episodes,
            "eval_info": [str(x) for x in c.paths],
        }
        for (m, t, s), c in results.items()
    ]
    summary = {"profile": dataclasses.asdict(p), "tasks": list(tasks), "cells": cells}
    (out / "results.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def _csv(kind, allowed):
    def parse(text: str) -> tuple:
        try:
            items = tuple(kind(x.strip()) for x in text.split(",") if x.strip())
        except ValueError:
            items = ()
        bad = [x for x in items if allowed is not None and x not in allowed]
        if not items or bad or len(set(items)) != len(items):
            expected = f"distinct values from {list(allowed)}" if allowed else "distinct values"
            raise argparse.ArgumentTypeError(f"expected comma-separated {expected}, got {text!r}")
        return items

    return parse


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="omnid-benchmark", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--profile", choices=sorted(PROFILES), default="mini", help="sizes (default: mini)")
    parser.add_argument("--out", type=Path, help="output folder (default: outputs/benchmark_<profile>)")
    parser.add_argument(
        "--device", help="torch device (default: the profile's, cpu for mini, cuda for paper)"
    )
    parser.add_argument("--methods", type=_csv(str, METHODS), help=f"subset of {','.join(METHODS)}")
    parser.add_argument("--tasks", type=_csv(str, available_tasks()), help="subset of the benchmark's tasks")
    parser.add_argument(
        "--settings", type=_csv(str, SETTINGS), help=f"task-0 settings, of {','.join(SETTINGS)}"
    )
    parser.add_argument("--eval-seeds", type=_csv(int, None), help="comma-separated eval seeds, e.g. 1,2,3,4")
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
    for name in ("device", "methods", "tasks", "settings", "eval_seeds"):
        if getattr(args, name) is not None:
            changes[name] = getattr(args, name)
    if "omnid" not in changes.get("methods", p.methods):
        changes["ablations"] = False  # OmniD's ablations are compared with OmniD itself
    return dataclasses.replace(p, **changes)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.dry_run and args.report_only:
        parser.error("--dry-run and --report-only: expected at most one of them, got both")
    p = resolve_profile(parser, args)
    tasks = p.tasks or available_tasks()
    out = (args.out or Path(f"outputs/benchmark_{p.name}")).resolve()
    runs = build_plan(p, out, tasks)
    print("\n".join(settings_markdown(p, tasks)))
    kinds = {k: sum(r.kind == k for r in runs) for k in ("record", "prepare", "train", "eval", "offline")}
    per_kind = ", ".join(f"{n} {k}" for k, n in kinds.items() if n)
    todo = sum(not is_done(r) for r in runs)
    print(f"\nPlan: {len(runs)} runs ({per_kind}), {todo} to run; {out}")
    if args.dry_run:
        print("\n".join(describe_plan(runs)))
        return 0
    try:
        status, seconds = ({}, {}) if args.report_only else execute(runs, out, args.verbose)
    except KeyboardInterrupt:
        write_outputs(p, tasks, runs, out)
        print(f"\nInterrupted: finished runs are kept, the one in progress is redone next time; {out}")
        return 130
    summary = write_outputs(p, tasks, runs, out)
    counts = {s: list(status.values()).count(s) for s in ("reused", "ran", "failed", "blocked")}
    print(f"\n{len(runs)} runs: " + ", ".join(f"{n} {s}" for s, n in counts.items() if n or s == "ran"))
    print(f"time: {sum(seconds.values()) / 60:.1f} min; report: {out / 'report.md'}, {out / 'benchmark.png'}")
    for cell in summary["cells"]:
        print(
            f"  {LABELS.get(cell['model'], cell['model'])} {cell['task']} {cell['setting']}: "
            f"{cell['success_rate']:.1f}% of {cell['episodes']}"
        )
    return 1 if counts["failed"] or counts["blocked"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
