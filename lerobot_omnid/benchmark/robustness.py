"""``omnid-robustness``: success of trained checkpoints under what real rigs do, run with ``lerobot-eval``.

For each checkpoint (OmniD, and stock LeRobot policies such as ``diffusion`` where a perturbation applies),
in one task's ID setting with the same env seeds throughout:

1. calibration error (OmniD): the policy is given a perturbed calibration file, the scene is unchanged;
   levels 0, 0.5, 1, 2, 4: every camera moved by exactly L cm in a random direction and turned by exactly
   L degrees about a random axis, several seeded draws per level (files under ``<out>/calibration/``);
2. bumped cameras: the scene's cameras moved by the same offsets (``--env.camera_offsets``), the policy
   keeps its calibration;
3. a dead camera, each in turn: black from the first step and from mid-episode (``--env.blackout_cameras``,
   ``--env.blackout_from_step``), and for OmniD removed from the inputs (``--policy.cameras``);
4. the controls: blind (OmniD: every camera turned away in its calibration; others: black images) and
   OmniD's scrambled geometry (calibrations permuted).

Writes ``<out>/report.md`` (a table per checkpoint: Wilson intervals, share of the rate as trained, Fisher
tests; a table across checkpoints), ``<out>/robustness_<label>.png`` (success against the perturbation
beside the controls' bands) and ``<out>/summary.json``; ``--report-only --summary FILE`` rebuilds the report
and charts from such a file alone. Resumable: an evaluation made by the same command
from the same checkpoint and calibration file is not run again (:mod:`lerobot_omnid.measure.engine`).

    omnid-robustness --checkpoint omnid=<pretrained_model> --checkpoint dp=<pretrained_model> --dry-run
    MUJOCO_GL=egl omnid-robustness --checkpoint omnid=<pretrained_model> --out outputs/robustness
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import re
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from gym_omnid.constants import CAMERAS, MAX_EPISODE_STEPS, TASKS

from lerobot_omnid.benchmark.controls import control_calibrations
from lerobot_omnid.benchmark.plan import EVAL_SEED_STRIDE, TASK0
from lerobot_omnid.benchmark.robustness_plan import (
    CONTROLS,
    DRAW_SEED_STRIDE,
    GROUPS,
    LABELS,
    LEVELS,
    Cell,
    Checkpoint,
    RobustnessSettings,
    build_runs,
    calibration_file,
    camera_offsets,
    checkpoint_from_config,
    perturbed_calibrations,
    plan_cells,
)
from lerobot_omnid.benchmark.robustness_report import (
    Row,
    between_lines,
    checkpoint_lines,
    comparison_chart,
    comparison_lines,
    pooled_rows,
    robustness_chart,
    rows_from_json,
    rows_json,
    table_rows,
)
from lerobot_omnid.calibration.rig_file import save_calibration_file
from lerobot_omnid.cli import add_protocol_options, csv_of, int_at_least
from lerobot_omnid.measure import engine
from lerobot_omnid.measure.engine import Run, code_commit, describe_plan, evaluations, execute, is_done
from lerobot_omnid.measure.results import (
    SUMMARY,
    EvalRecord,
    RunSummary,
    write_run_summary,
)

COMPARISON_CHART = "robustness_comparison.png"
"""The checkpoints' curves side by side (written when more than one has results)."""
SETTINGS_FILE = "robustness.json"
"""What the finished evaluations of an output folder depend on; a rerun with other values is refused."""
PROTOCOL = "omnid-robustness"
FIXED = {  # settings field: option
    "task": "--task",
    "episodes": "--eval-episodes",
    "episode_length": "--episode-length",
    "perturbation_seed": "--perturbation-seed",
}
LABEL_PATTERN = re.compile(r"[A-Za-z0-9_.-]+")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="omnid-robustness", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--checkpoint",
        action="append",
        default=[],
        metavar="[LABEL=]PATH",
        help="a LeRobot pretrained_model folder, optionally labelled (default label: its policy type); "
        "repeat for several",
    )
    parser.add_argument("--out", type=Path, default=Path("outputs/robustness"), help="output folder")
    parser.add_argument("--task", choices=TASKS, default=TASK0, help=f"task (default {TASK0})")
    parser.add_argument(
        "--levels",
        type=csv_of(float, None),
        default=LEVELS,
        help="perturbation levels, cm and degrees together (default "
        + ",".join(f"{v:g}" for v in LEVELS)
        + ")",
    )
    parser.add_argument("--draws", type=int_at_least(1), default=3, help="random draws per level (default 3)")
    parser.add_argument(
        "--draw-ids",
        type=csv_of(int, None),
        default=(),
        help="only these draws of each level, e.g. the worst ones of an earlier run (default: 1 .. --draws)",
    )
    parser.add_argument(
        "--perturbation-seed",
        type=int_at_least(0),
        default=0,
        help="seed of the draws' directions (default 0)",
    )
    parser.add_argument(
        "--eval-seeds",
        type=csv_of(int, None),
        default=(1,),
        help="eval seeds k, each running env seeds k*1000, k*1000+1, ... (default 1)",
    )
    parser.add_argument(
        "--eval-episodes", type=int_at_least(1), default=10, help="episodes per cell and seed"
    )
    parser.add_argument(
        "--episode-length",
        type=int_at_least(2),
        default=MAX_EPISODE_STEPS,
        help=f"time limit of an episode, env steps (default {MAX_EPISODE_STEPS}); mid-episode is half of it",
    )
    parser.add_argument(
        "--conditions", type=csv_of(str, GROUPS), default=GROUPS, help=f"subset of {','.join(GROUPS)}"
    )
    parser.add_argument(
        "--dead-cameras",
        type=csv_of(str, CAMERAS),
        help="cameras killed in turn (default: each checkpoint's)",
    )
    parser.add_argument("--device", default="cpu", help="torch device of lerobot-eval (default cpu)")
    parser.add_argument(
        "--eval-batch-size",
        type=int_at_least(1),
        default=RobustnessSettings.batch_size,
        help="envs each lerobot-eval runs at once (--eval.batch_size; default "
        f"{RobustnessSettings.batch_size}, as the mini benchmark); the env seeds do not change",
    )
    add_protocol_options(parser)  # --summary needs no --checkpoint
    parser.add_argument("--verbose", action="store_true", help="show the output of every command")
    return parser


def read_json(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text()) if path.is_file() else {}


def load_checkpoints(parser: argparse.ArgumentParser, specs: Sequence[str]) -> list[tuple[Checkpoint, dict]]:
    """Each ``[LABEL=]PATH`` as a :class:`Checkpoint` with its ``config.json`` content; errors name it."""
    loaded: list[tuple[Checkpoint, dict]] = []
    for spec in specs:
        label, sep, path_text = spec.partition("=")
        path = Path(path_text if sep else spec).absolute()
        config = read_json(path / "config.json")
        if not config:
            parser.error(f"--checkpoint: expected a pretrained_model folder with a config.json, got {spec!r}")
        label = label if sep else str(config.get("type"))
        if not LABEL_PATTERN.fullmatch(label) or label in [c.label for c, _ in loaded]:
            parser.error(
                f"--checkpoint: expected a distinct label of letters, digits, '_', '.', '-' per checkpoint, "
                f"got {label!r} in {spec!r} (label several checkpoints of one type: LABEL=PATH)"
            )
        try:
            checkpoint = checkpoint_from_config(label, path, config, read_json(path / "train_config.json"))
        except ValueError as e:
            parser.error(str(e))
        loaded.append((checkpoint, config))
    return loaded


def check_settings(
    parser: argparse.ArgumentParser,
    out: Path,
    settings: RobustnessSettings,
    checkpoints: Sequence[Checkpoint],
) -> dict[str, Any]:
    """Refuse settings that would mix with the folder's finished runs; returns the folder's settings."""
    new = {field: getattr(settings, field) for field in FIXED}
    new["checkpoints"] = {c.label: str(c.path) for c in checkpoints}
    old = read_json(out / SETTINGS_FILE)
    for field, option in FIXED.items():
        if field in old and old[field] != new[field]:
            parser.error(
                f"{option}: expected {old[field]!r} as in the finished runs of {out} ({SETTINGS_FILE}), got "
                f"{new[field]!r}; use another --out"
            )
    for label, path in new["checkpoints"].items():
        if old.get("checkpoints", {}).get(label, path) != path:
            parser.error(
                f"--checkpoint {label}: expected {old['checkpoints'][label]} as in the finished runs of "
                f"{out} ({SETTINGS_FILE}), got {path}; use another label or --out"
            )
    return {**new, "checkpoints": {**old.get("checkpoints", {}), **new["checkpoints"]}}


def write_calibration_files(
    checkpoint: Checkpoint, config: Mapping[str, Any], settings: RobustnessSettings, out: Path
) -> int:
    """Write the calibration file of every cell of ``checkpoint`` that has one; returns how many."""
    written = 0
    for cell in plan_cells(checkpoint, settings):
        path = calibration_file(out, checkpoint, cell)
        if path is None:
            continue
        if cell.condition in CONTROLS:
            calibrations = control_calibrations(config, cell.condition)
        else:
            offsets = camera_offsets(cell.level, cell.draw, settings.perturbation_seed)
            calibrations = perturbed_calibrations(checkpoint.calibrations, offsets)
        save_calibration_file(path, calibrations)
        written += 1
    return written


def cell_counts(
    checkpoint: Checkpoint, settings: RobustnessSettings, records: Sequence[EvalRecord]
) -> dict[Cell, dict[int, tuple[int, int]]]:
    """(successes, episodes) per cell of ``checkpoint`` and eval seed, from the ``records`` of the
    evaluations done for this very plan (:func:`lerobot_omnid.measure.engine.evaluations`)."""
    cells = {cell.name: cell for cell in plan_cells(checkpoint, settings)}
    counts: dict[Cell, dict[int, tuple[int, int]]] = {}
    for r in records:
        if r.key[0] == checkpoint.label:
            counts.setdefault(cells[r.key[2]], {})[r.eval_seed] = (r.successes, r.episodes)
    return counts


def shown_path(path: Path) -> str:
    """``path`` as a report and a committed summary show it: relative to the working folder when inside it,
    so no one machine's absolute path reaches the repository."""
    return str(path.relative_to(Path.cwd())) if path.is_relative_to(Path.cwd()) else str(path)


def describe(checkpoint: Checkpoint, settings: RobustnessSettings) -> str:
    seeds = ", ".join(
        f"{k * EVAL_SEED_STRIDE}-{k * EVAL_SEED_STRIDE + settings.episodes - 1}" for k in settings.eval_seeds
    )
    if len(settings.eval_seeds) > 1:
        seeds += " (each row pools the eval seeds it ran on and is compared with as trained on the same ones)"
    cameras = ", ".join(checkpoint.cameras)
    return (
        f"`{shown_path(checkpoint.path)}` (policy `{checkpoint.policy_type}`, cameras {cameras}, "
        f"{checkpoint.image_size} px, training seed {checkpoint.train_seed}); {settings.task} ID, env seeds "
        f"{seeds}, episodes of at most {settings.episode_length} steps."
    )


def write_outputs(
    checkpoints: Sequence[Checkpoint],
    settings: RobustnessSettings,
    runs: Sequence[Run],
    out: Path,
    commit: str | None,
    command: str,
) -> dict[str, list]:
    """summary.json, report.md and the charts from the ``runs`` done; returns the rows per checkpoint
    label. Every evaluation is a record (model: the checkpoint's label; setting: its cell's folder name,
    tags: condition, level, draw, camera); ``results`` holds each checkpoint's table rows, which the report
    is built from."""
    records = evaluations(runs)
    rows = {c.label: table_rows(cell_counts(c, settings, records)) for c in checkpoints}
    results = {
        "checkpoints": {
            c.label: {
                "path": shown_path(c.path),
                "description": describe(c, settings),
                "rows": rows_json(rows[c.label]),
            }
            for c in checkpoints
        },
    }
    summary = RunSummary(PROTOCOL, dataclasses.asdict(settings), records, results, commit, [command])
    write_run_summary(out / SUMMARY, summary)
    write_report(summary, rows, out)
    return rows


def draws_text(settings: Mapping[str, Any]) -> str:
    """The draws of a run's settings: their number, or which ones where ``--draw-ids`` chose them."""
    ids = settings.get("draw_ids") or ()
    return f"draws {', '.join(map(str, ids))}" if ids else str(settings["draws"])


def write_report(summary: RunSummary, rows: Mapping[str, Sequence[Row]], out: Path) -> None:
    """``<out>/report.md`` and its charts from a run summary (this run's or a committed one) and its rows
    per checkpoint label."""
    settings = summary.settings
    command = " ".join(summary.command)
    lines = [
        "# Robustness: calibration error, bumped cameras, dead cameras",
        "",
        f"Command: `{command}`; code commit {summary.commit}. Perturbation level L: every "
        "camera moved by L cm in a random direction and turned by L degrees about a random axis (seeded "
        f"draws per level: {draws_text(settings)}, perturbation seed {settings['perturbation_seed']}; "
        "level 0 is the checkpoint as trained). "
        "Success % with Wilson 95 % intervals; against as trained: difference with Newcombe's interval, "
        "two-sided Fisher exact test.",
        "",
        *comparison_lines(rows),
        "",
    ]
    evaluated = {label: label_rows for label, label_rows in rows.items() if label_rows}
    between = between_lines(evaluated)
    if between:
        lines += [
            "Between checkpoints, on the same env seeds: the first one's rate minus the second's (pp) with "
            "Newcombe's interval, two-sided Fisher exact test.",
            "",
            *between,
            "",
        ]
    out.mkdir(parents=True, exist_ok=True)
    if len(evaluated) > 1:
        chart = comparison_chart(evaluated, out / COMPARISON_CHART)
        lines += [f"![the checkpoints side by side]({chart.name})", ""]
    for label, checkpoint in summary.results["checkpoints"].items():
        chart = None
        if rows[label]:
            chart = robustness_chart(label, rows[label], out / f"robustness_{label}.png")
        description = checkpoint.get("description", f"`{checkpoint['path']}`")
        lines += checkpoint_lines(label, description, rows[label], chart and chart.name)
    (out / "report.md").write_text("\n".join(lines))


def report_from_summary(summary: RunSummary, path: Path) -> None:
    """Rebuild ``path`` (a ``report.md``) and its charts from a committed run summary alone."""
    rows = {label: rows_from_json(c["rows"]) for label, c in summary.results["checkpoints"].items()}
    write_report(summary, rows, path.parent)
    print(f"report: {path}")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.dry_run and args.report_only:
        parser.error("--dry-run and --report-only: expected at most one of them, got both")
    if engine.report_from_summary(parser, args, args.out.resolve(), PROTOCOL, report_from_summary):
        return 0
    if not args.checkpoint:
        parser.error("--checkpoint: expected at least one [LABEL=]PATH, got none")
    if min(args.levels) < 0:
        parser.error(f"--levels: expected numbers >= 0 (cm and degrees), got {list(args.levels)}")
    if args.draws >= DRAW_SEED_STRIDE:
        parser.error(f"--draws: expected at most {DRAW_SEED_STRIDE - 1}, got {args.draws}")
    if args.draw_ids and not all(1 <= d < DRAW_SEED_STRIDE for d in args.draw_ids):
        parser.error(f"--draw-ids: expected draws in [1, {DRAW_SEED_STRIDE - 1}], got {list(args.draw_ids)}")
    if min(args.eval_seeds) < 1:
        parser.error(f"--eval-seeds: expected positive integers, got {list(args.eval_seeds)}")
    loaded = load_checkpoints(parser, args.checkpoint)
    checkpoints = [c for c, _ in loaded]
    settings = RobustnessSettings(
        args.task,
        tuple(sorted(args.levels)),
        args.draws,
        args.perturbation_seed,
        args.eval_seeds,
        args.eval_episodes,
        args.episode_length,
        args.conditions,
        args.dead_cameras,
        args.device,
        args.eval_batch_size,
        tuple(dict.fromkeys(args.draw_ids)),
    )
    out = args.out.resolve()
    folder_settings = check_settings(parser, out, settings, checkpoints)
    try:
        runs = build_runs(checkpoints, settings, out)
        if not (args.dry_run or args.report_only):  # their contents are the runs' inputs: plan again
            files = sum(write_calibration_files(c, config, settings, out) for c, config in loaded)
            print(f"calibration files: {files} under {out / 'calibration'}")
            runs = build_runs(checkpoints, settings, out)
    except ValueError as e:
        parser.error(str(e))
    command = " ".join(["omnid-robustness", *(sys.argv[1:] if argv is None else argv)])
    todo = sum(not is_done(r) for r in runs)
    print(
        f"omnid-robustness: {len(checkpoints)} checkpoint(s), {len(runs)} evaluations, {todo} to run; {out}"
    )
    for checkpoint in checkpoints:
        cells = [c.condition for c in plan_cells(checkpoint, settings)]
        conditions = "; ".join(f"{LABELS[c]} {cells.count(c)}" for c in dict.fromkeys(cells))
        print(f"  {checkpoint.label}: {len(cells)} cells: {conditions}")
    if args.dry_run:
        print("\n".join(describe_plan(runs)))
        return 0
    out.mkdir(parents=True, exist_ok=True)
    (out / SETTINGS_FILE).write_text(json.dumps(folder_settings, indent=2) + "\n")
    commit = code_commit()
    status: dict[str, str] = {}
    seconds: dict[str, float] = {}
    if not args.report_only:
        try:
            status, seconds = execute(runs, out, args.verbose, commit, "robustness")
        except KeyboardInterrupt:
            write_outputs(checkpoints, settings, runs, out, commit, command)
            print(
                f"\nInterrupted: finished evaluations are kept, the one in progress reruns next time; {out}"
            )
            return 130
    rows = write_outputs(checkpoints, settings, runs, out, commit, command)
    counts = {s: list(status.values()).count(s) for s in ("reused", "ran", "failed", "blocked")}
    print(
        f"\n{len(runs)} evaluations: " + ", ".join(f"{n} {s}" for s, n in counts.items() if n or s == "ran")
    )
    print(f"time: {sum(seconds.values()) / 60:.1f} min; report: {out / 'report.md'}")
    for label, label_rows in rows.items():
        for row in pooled_rows(label_rows):
            r, low, high = row.result, 100 * row.result.interval.low, 100 * row.result.interval.high
            print(
                f"  {label} {LABELS[row.condition]} {row.perturbation}: {r.successes}/{r.episodes} = "
                f"{r.rate:.0f}% ({low:.0f}-{high:.0f})"
            )
    return 1 if counts["failed"] or counts["blocked"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
