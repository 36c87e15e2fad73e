"""The main job: record a select_apple dataset with the scripted expert, train OmniD with `lerobot-train`,
evaluate it with `lerobot-eval` in the ID and position-OOD layouts and, as its blind control, in the ID
layout with every camera turned away in its calibration (the same checkpoint and env seeds, so only the
state can drive it), and write a markdown report: each success rate with its Wilson 95 % interval and the
margin over the blind control with Newcombe's interval and a two-sided Fisher test.

Every stage is a real console command (`omnid-record`, `lerobot-train`, `lerobot-eval`), run by the
experiment engine (:mod:`lerobot_omnid.measure.engine`) as a subprocess whose output goes to the terminal
and to ``<out>/logs/<stage>.log``; the commands are written into the report so that each can be rerun by
hand. A stage made by the same command from the same inputs is not redone; one made with other options is.

    omnid-demo                       # CPU budget: about 30 minutes on 2 cores
    omnid-demo --profile gpu --device cuda
"""

from __future__ import annotations

import argparse
import shlex
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from gym_omnid import TRAIN_CAMERAS

from lerobot_omnid.benchmark import commands
from lerobot_omnid.benchmark.commands import (
    SIM_VOLUME_BOUNDS,
    control_calibration_command,
    env_cameras,
    eval_command,
    json_list,
    record_command,
)
from lerobot_omnid.benchmark.commands import train_command as train_command_base
from lerobot_omnid.benchmark.methods import control_flags, method_flags
from lerobot_omnid.benchmark.plan import MINI, BenchmarkProfile
from lerobot_omnid.cli import positive_int
from lerobot_omnid.measure.engine import (
    CHECKPOINT,
    Run,
    code_commit,
    describe_plan,
    evaluations,
    execute,
    plan,
    read_stamp,
)
from lerobot_omnid.measure.report import short_commit
from lerobot_omnid.measure.results import (
    EvalRecord,
    RunSummary,
    read_run_summary,
    write_run_summary,
)
from lerobot_omnid.measure.stats import fisher_exact, rate_difference, wilson_interval

EVAL_BATCH_SIZE = 5  # envs each lerobot-eval runs at once: faster than one, the same env seeds
BLIND = "id_blind"  # the ID evaluation under the blind control
PROTOCOL = "omnid-demo"
TASK = "select_apple"
SUMMARY = "summary.json"  # the run's counts, commits, commands and timings; the report is rebuilt from it


@dataclass(frozen=True)
class Profile:
    """Sizes of one run of the main job."""

    episodes: int
    image_size: int
    steps: int
    batch_size: int
    eval_episodes: int
    policy_flags: tuple[str, ...]


def benchmark_omnid_flags(profile: BenchmarkProfile) -> tuple[str, ...]:
    """The benchmark profile's OmniD options (sizes, readout, diffusion head) but its cameras, which the
    main job names itself."""
    return tuple(
        flag for flag, _ in method_flags("omnid", profile) if not flag.startswith("--policy.cameras=")
    )


# The CPU profile is the benchmark's `mini` OmniD (the same data size, images, steps and options): the
# smallest run measured above its blind control (docs/results.md#main-job-omnid-demo).
PROFILES = {
    "cpu": Profile(
        episodes=MINI.episodes,
        image_size=MINI.image_size,
        steps=MINI.steps,
        batch_size=MINI.batch_size,
        eval_episodes=10,
        policy_flags=benchmark_omnid_flags(MINI),
    ),
    "gpu": Profile(
        episodes=50,
        image_size=128,
        steps=30000,
        batch_size=16,
        eval_episodes=50,
        policy_flags=(
            f"--policy.volume_bounds={SIM_VOLUME_BOUNDS}",
            "--policy.volume_shape=[32,40,16]",
            "--policy.backbone_layer=3",
            "--policy.noise_scheduler_type=DDIM",
            "--policy.num_inference_steps=10",
        ),
    ),
}


def train_command(
    dataset_root: Path,
    output_dir: Path,
    profile: Profile,
    device: str,
    task: str,
    cameras: tuple[str, ...],
    extra: tuple[str, ...] = (),
) -> list[str]:
    """`lerobot-train` of OmniD, evaluating in the env halfway and at the end of training."""
    policy_flags = [
        "--policy.type=omnid",
        f"--policy.device={device}",
        "--policy.push_to_hub=false",
        "--policy.cameras=" + json_list(cameras),
        *profile.policy_flags,
    ]
    env_eval = [
        "--env.type=omnid",
        f"--env.task={task}",
        env_cameras(cameras),
        f"--env.image_size={profile.image_size}",
        f"--env_eval_freq={max(profile.steps // 2, 1)}",
        "--eval.n_episodes=2",
        "--eval.batch_size=1",
    ]
    return train_command_base(
        dataset_root, output_dir, policy_flags, profile.steps, profile.batch_size, extra=(*env_eval, *extra)
    )


def blind_margin(id_counts: tuple[int, int], blind_counts: tuple[int, int]) -> str:
    """One sentence: the ID success rate's margin over the blind control, its interval, the Fisher p-value,
    and whether the policy is significantly above the control (p < 0.05), i.e. uses its cameras."""
    margin = rate_difference(*id_counts, *blind_counts)
    p = fisher_exact(*id_counts, *blind_counts)
    verdict = (
        "significantly above its blind control: it uses its cameras"
        if p < 0.05 and margin.value > 0
        else "not distinguishable from its blind control at this number of episodes"
    )
    return (
        f"Margin over the blind control in ID: {100 * margin.value:+.1f} points (Newcombe 95 % "
        f"{100 * margin.low:+.1f} to {100 * margin.high:+.1f}), two-sided Fisher p = {p:.3g}: {verdict}."
    )


def summarise(runs: list[Run], out: Path, profile_name: str, commit: str | None = None) -> RunSummary:
    """The run's summary: per evaluation its counts and the commit that made it, per stage its command
    (paths relative to ``out``, so the file says nothing about the machine) and seconds, from the stamps."""
    stamps = {run.name: read_stamp(run) or {} for run in runs}

    def relative(cmd: Sequence[str]) -> str:
        return shlex.join(cmd).replace(f"{out}/", "").replace(str(commands.BIN) + "/", "")

    stages = [
        {"name": run.name, "seconds": stamps[run.name].get("seconds"), "command": relative(run.cmd)}
        for run in runs
    ]
    return RunSummary(PROTOCOL, {"profile": profile_name}, evaluations(runs), {"stages": stages}, commit)


def evaluation_name(record: EvalRecord) -> str:
    """``id``, ``position_ood`` or ``id_blind``: the evaluation's folder is ``eval_<name>``."""
    return BLIND if record.control == "blind" else record.key[2]


def write_report(summary: RunSummary, path: Path) -> str:
    """Write the report from a run's summary (this run's or a committed one); returns its sentence on the
    margin over the blind control."""
    lines = [
        "# OmniD main job: select_apple, cameras B-E",
        "",
        f"Profile `{summary.settings['profile']}`; paths are relative to the output folder. The `{BLIND}` "
        "row is the blind control: the same checkpoint and env seeds as `id`, every camera turned away from "
        "the volume in its calibration (no anchor is visible), so only the state drives it.",
        "",
        "| evaluation | successes | success rate (%) | Wilson 95 % | code commit | videos |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for row in summary.evaluations:
        est = wilson_interval(row.successes, row.episodes)
        name = evaluation_name(row)
        lines.append(
            f"| {name} | {row.successes}/{row.episodes} | {100 * est.value:.1f} | "
            f"{100 * est.low:.1f}-{100 * est.high:.1f} | {short_commit(row.commit)} | `eval_{name}/videos` |"
        )
    counts = {evaluation_name(row): (row.successes, row.episodes) for row in summary.evaluations}
    margin = blind_margin(counts["id"], counts[BLIND])
    lines += ["", margin]
    lines += ["", "## Stages", "", "| stage | seconds | command |", "| --- | --- | --- |"]
    for stage in summary.results["stages"]:
        seconds = "-" if stage["seconds"] is None else f"{stage['seconds']:.0f}"
        lines.append(f"| {stage['name']} | {seconds} | `{stage['command']}` |")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return margin


def plan_runs(
    profile: Profile, out: Path, device: str = "cpu", episode_length: int | None = None
) -> list[Run]:
    """The main job as runs: record, train, the blind control's calibration, the evaluations."""
    dataset = out / "data" / f"{TASK}_bcde"
    train_dir = out / "train"
    checkpoint = train_dir / CHECKPOINT
    env_flags = (f"--env.episode_length={episode_length}",) if episode_length else ()
    blind_file = out / "controls" / "blind.json"
    blind_flags = tuple(f for f, _ in control_flags("omnid", "blind", TRAIN_CAMERAS, blind_file))
    record = record_command(TASK, profile.episodes, TRAIN_CAMERAS, profile.image_size, dataset)
    train = train_command(dataset, train_dir, profile, device, TASK, TRAIN_CAMERAS, env_flags)
    runs = [
        Run("record", "record", tuple(record), dataset),
        Run("train", "train", tuple(train), train_dir, ("record",)),
        Run(
            "blind_calibration",
            "calibration",
            tuple(control_calibration_command(checkpoint, "blind", blind_file)),
            blind_file,
            ("train",),
        ),
    ]
    evaluations = {layout: (layout, env_flags) for layout in ("id", "position_ood")}
    evaluations[BLIND] = ("id", (*env_flags, *blind_flags))
    for name, (layout, extra) in evaluations.items():
        cmd = eval_command(
            checkpoint,
            out / f"eval_{name}",
            TASK,
            layout,
            TRAIN_CAMERAS,
            profile.image_size,
            profile.eval_episodes,
            device,
            extra=extra,
            batch_size=min(EVAL_BATCH_SIZE, profile.eval_episodes),
        )
        needs = ("train", "blind_calibration") if name == BLIND else ("train",)
        cell = {"result": ("omnid", TASK, layout), "control": "blind" if name == BLIND else ""}
        runs.append(Run(f"eval_{name}", "eval", tuple(cmd), out / f"eval_{name}", needs, **cell))
    return plan(runs, out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--profile", choices=sorted(PROFILES), default="cpu", help="budget (default: cpu)")
    parser.add_argument("--device", default="cpu", help="torch device for training and evaluation")
    parser.add_argument("--out", type=Path, default=Path("outputs/demo"), help="output folder")
    parser.add_argument(
        "--episodes", type=positive_int, help="override the profile's number of expert episodes"
    )
    parser.add_argument("--steps", type=positive_int, help="override the profile's training steps")
    parser.add_argument(
        "--eval-episodes", type=positive_int, help="override the profile's evaluation episodes"
    )
    parser.add_argument(
        "--episode-length", type=positive_int, help="time limit of evaluation episodes, env steps"
    )
    parser.add_argument("--dry-run", action="store_true", help="print every planned command, run nothing")
    parser.add_argument(
        "--report-only",
        action="store_true",
        help="run nothing: rebuild <out>/report.md from <out>/summary.json or --summary",
    )
    parser.add_argument("--summary", type=Path, help="with --report-only: the summary.json to report")
    args = parser.parse_args(argv)
    out = args.out.resolve()
    if args.summary and not args.report_only:
        parser.error("--summary: expected with --report-only, got it without")
    if args.report_only:
        source = args.summary or out / SUMMARY
        if not source.is_file():
            parser.error(f"--report-only: expected a summary file, got none at {source}")
        margin = write_report(read_run_summary(source, PROTOCOL), out / "report.md")
        print(f"{margin} Report: {out / 'report.md'}")
        return 0
    base = PROFILES[args.profile]
    profile = Profile(
        episodes=args.episodes or base.episodes,
        image_size=base.image_size,
        steps=args.steps or base.steps,
        batch_size=base.batch_size,
        eval_episodes=args.eval_episodes or base.eval_episodes,
        policy_flags=base.policy_flags,
    )
    runs = plan_runs(profile, out, args.device, args.episode_length)
    if args.dry_run:
        print("\n".join(describe_plan(runs)))
        return 0
    status, timings = execute(
        runs, out, verbose=True, commit=code_commit(), desc="OmniD main job", stop_on_failure=True
    )
    for name in (n for n, s in status.items() if s == "reused"):
        print(f"[{name}] already done (same command and inputs), reusing its result")
    summary = summarise(runs, out, args.profile, code_commit())
    write_run_summary(out / SUMMARY, summary)
    report = out / "report.md"
    margin = write_report(summary, report)
    counts = ", ".join(f"{evaluation_name(r)} {r.successes}/{r.episodes}" for r in summary.evaluations)
    print(f"Done in {sum(timings.values()):.0f} s: success {counts}. {margin} Report: {report}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
