"""Per-frame calibration, measured: one OmniD on two rigs against one rig, and B-E plus the wrist camera.

Two pairs of OmniD models at the benchmark's ``mini`` sizes (``omnid-benchmark``'s OmniD options, 64 px,
1000 steps, batch 8, ``lerobot-train --seed=1000``) on ``select_apple``; each pair has the same steps and
seed:

(a) *rigs*: ``one_rig`` (50 episodes of the default rig) against ``two_rigs`` (25 episodes of the default
    rig and 25 of ``closer``, merged with ``lerobot-edit-dataset``), evaluated on the default rig and on
    ``higher`` and ``bumped``, which neither saw; every model is given the evaluated rig's true calibration
    (``--env.per_frame_calibration=true``).
(b) *wrist*: ``one_rig`` (cameras B-E) against ``wrist`` (B-E plus ``cam_wrist``, the same 50 scenes), in
    distribution and on the position-shift bands 1-4.

Every model also gets a blind control in distribution: every camera black (``--env.blackout_cameras``), so
only the state drives it. ``--one-rig-checkpoint`` takes an OmniD trained by ``omnid-benchmark`` (the same
50 scenes and options, calibration in the feature info) instead of training ``one_rig`` here; it is then
told to read the env's per-frame calibration (``--policy.frame_calibration``). Runs on the experiment
engine (resumable, ``--dry-run`` prints every command); writes ``<out>/report.md`` (Wilson 95 % intervals,
Fisher tests of each pair, the code commit of each evaluation, from its stamp) and ``<out>/summary.json``;
``--report-only --summary FILE`` rebuilds the report from such a summary alone.

    MUJOCO_GL=egl python -m lerobot_omnid.benchmark.rigs_and_wrist --out outputs/rigs_and_wrist \\
        --one-rig-checkpoint outputs/bench_mini/train/omnid/select_apple/checkpoints/last/pretrained_model
"""

from __future__ import annotations

import argparse
from pathlib import Path

from gym_omnid import TRAIN_CAMERAS, WRIST_CAMERA

from lerobot_omnid.benchmark import commands
from lerobot_omnid.benchmark.methods import method_flags
from lerobot_omnid.benchmark.plan import BANDS, PROFILES, TRAIN_SEED
from lerobot_omnid.cli import add_protocol_options
from lerobot_omnid.keys import image_key
from lerobot_omnid.measure.engine import (
    CHECKPOINT,
    Run,
    code_commit,
    describe_plan,
    evaluations,
    execute,
    plan,
    report_from_summary,
)
from lerobot_omnid.measure.report import write_markdown
from lerobot_omnid.measure.results import (
    SUMMARY,
    RunSummary,
    tags_of,
    write_run_summary,
)
from lerobot_omnid.measure.stats import fisher_exact, rate_difference, wilson_interval

TASK = "select_apple"
PROTOCOL = "rigs_and_wrist"
PROFILE = PROFILES["mini"]
EVAL_SEED = 1000  # env seeds 1000 ... : the benchmark's eval seed 1, disjoint from the recordings' 0 ... 600
WRIST_CAMERAS = (*TRAIN_CAMERAS, WRIST_CAMERA)
DATASETS = {  # name: (rig, cameras, episodes, first env seed)
    "default_bcde": ("default", TRAIN_CAMERAS, PROFILE.episodes, 0),
    "default_bcde_half": ("default", TRAIN_CAMERAS, PROFILE.episodes // 2, 0),
    "closer_bcde_half": ("closer", TRAIN_CAMERAS, PROFILE.episodes // 2, 500),
    "default_wrist": ("default", WRIST_CAMERAS, PROFILE.episodes, 0),
}
MODELS = {  # name: (training dataset, cameras)
    "one_rig": ("default_bcde", TRAIN_CAMERAS),
    "two_rigs": ("two_rigs", TRAIN_CAMERAS),
    "wrist": ("default_wrist", WRIST_CAMERAS),
}
EVALS = {  # model: (rig, layout) cells
    "one_rig": [("default", "id"), ("higher", "id"), ("bumped", "id"), *(("default", b) for b in BANDS)],
    "two_rigs": [("default", "id"), ("higher", "id"), ("bumped", "id")],
    "wrist": [("default", "id"), *(("default", b) for b in BANDS)],
}
PAIRS = {"rigs": ("two_rigs", "one_rig"), "wrist": ("wrist", "one_rig")}
UNSEEN_RIGS = ("higher", "bumped")  # rigs neither model was trained on: the rigs pair is pooled over them


def record(out: Path, name: str) -> list[str]:
    rig, cameras, episodes, seed = DATASETS[name]
    root = out / "data" / name
    cmd = commands.record_command(
        TASK, episodes, cameras, PROFILE.image_size, root, seed=seed, static_calibration=False
    )
    return [*cmd, "--rig", rig, "--per-frame-calibration"]


def merge(out: Path) -> list[str]:
    parts = [out / "data" / "default_bcde_half", out / "data" / "closer_bcde_half"]
    return commands.merge_command(parts, out / "data" / "two_rigs")


def train(out: Path, model: str) -> list[str]:
    dataset, cameras = MODELS[model]
    flags = [f for f, _ in method_flags("omnid", PROFILE) if not f.startswith("--policy.cameras=")]
    flags = ["--policy.type=omnid", "--policy.device=cpu", "--policy.push_to_hub=false", *flags]
    flags.append("--policy.cameras=" + commands.json_list(cameras))
    return commands.train_command(
        out / "data" / dataset,
        out / "train" / model,
        flags,
        PROFILE.steps,
        PROFILE.batch_size,
        seed=TRAIN_SEED,
    )


def evaluate(
    out: Path, model: str, checkpoint: Path, rig: str, layout: str, episodes: int, blind: bool
) -> list[str]:
    cameras = MODELS[model][1]
    extra = [
        f"--env.rig={rig}",
        "--env.per_frame_calibration=true",
        f"--env.episode_length={PROFILE.episode_length}",
    ]
    extra.append("--policy.frame_calibration=" + commands.json_list([image_key(c) for c in cameras]))
    if blind:
        extra.append(f"--env.blackout_cameras=[{','.join(cameras)}]")
    return commands.eval_command(
        checkpoint,
        eval_dir(out, model, rig, layout, blind),
        TASK,
        layout,
        cameras,
        PROFILE.image_size,
        episodes,
        "cpu",
        seed=EVAL_SEED,
        extra=extra,
        batch_size=PROFILE.eval_batch_size,
    )


def eval_dir(out: Path, model: str, rig: str, layout: str, blind: bool) -> Path:
    return out / "eval" / model / f"{rig}_{layout}{'_blind' if blind else ''}"


def cells() -> list[tuple[str, str, str, bool]]:
    """(model, rig, layout, blind) of every evaluation."""
    return [(m, r, lay, False) for m, ev in EVALS.items() for r, lay in ev] + [
        (m, "default", "id", True) for m in MODELS
    ]


def report(
    out: Path, episodes: int, given: dict[str, Path], runs: list[Run], commit: str | None = None
) -> None:
    """``report.md`` and ``summary.json`` from the evaluations of ``runs`` done for this plan; ``given``:
    the models whose checkpoints were given, not trained here."""
    settings = {
        "task": TASK,
        "episodes_per_cell": episodes,
        "eval_seed": EVAL_SEED,
        "train_seed": TRAIN_SEED,
        "steps": PROFILE.steps,
        "checkpoints": {m: "given" if m in given else "trained here" for m in MODELS},
    }
    summary = RunSummary(PROTOCOL, settings, evaluations(runs), {}, commit)
    write_run_summary(out / SUMMARY, summary)
    write_report(summary, out / "report.md")


def write_report(summary: RunSummary, path: Path) -> None:
    """``report.md`` (every cell with its Wilson interval, a Fisher test per pair) from a ``summary.json``,
    this run's or a committed one."""
    counts = {
        (r.key[0], r.tag("rig"), r.key[2], r.control == "blind"): (r.successes, r.episodes)
        for r in summary.evaluations
    }
    commits = ", ".join(sorted({str(r.commit) for r in summary.evaluations})) or "none"
    lines = [f"# Per-frame calibration: rigs and wrist camera ({summary.settings['task']}, mini sizes)", ""]
    lines += [f"Commits: {commits}.", ""]
    lines += ["| model | rig | layout | control | success | Wilson 95 % |", "|---|---|---|---|---|---|"]
    for (model, rig, layout, blind), (s, n) in counts.items():
        est = wilson_interval(s, n)
        lines.append(
            f"| {model} | {rig} | {layout} | {'blind' if blind else '-'} | "
            f"{s}/{n} | {100 * est.low:.0f}-{100 * est.high:.0f} % |"
        )
    lines += ["", "| pair | rig | layout | A | B | Fisher p |", "|---|---|---|---|---|---|"]
    for pair, (a, b) in PAIRS.items():
        for rig, layout in EVALS[a]:
            if (a, rig, layout, False) in counts and (b, rig, layout, False) in counts:
                (sa, na), (sb, nb) = counts[a, rig, layout, False], counts[b, rig, layout, False]
                p = fisher_exact(sa, na, sb, nb)
                lines.append(f"| {pair}: {a} vs {b} | {rig} | {layout} | {sa}/{na} | {sb}/{nb} | {p:.3g} |")
    a, b = PAIRS["rigs"]
    unseen = [(a, r, "id", False) for r in UNSEEN_RIGS] + [(b, r, "id", False) for r in UNSEEN_RIGS]
    if all(cell in counts for cell in unseen):
        (sa, na), (sb, nb) = (
            [sum(counts[m, r, "id", False][i] for r in UNSEEN_RIGS) for i in (0, 1)] for m in (a, b)
        )
        d = rate_difference(sa, na, sb, nb)
        difference = f"{100 * d.value:+.1f} pp, {100 * d.low:+.1f} to {100 * d.high:+.1f}"
        p = fisher_exact(sa, na, sb, nb)
        rigs = " + ".join(UNSEEN_RIGS)
        counted = f"{sa}/{na} | {sb}/{nb} | {p:.3g}"
        lines.append(f"| rigs: {a} vs {b}, pooled ({difference}) | {rigs} | id | {counted} |")
    write_markdown(lines, path)


def protocol(out: Path, checkpoints: dict[str, Path], given: dict[str, Path], episodes: int) -> list[Run]:
    """Record, merge, train (what is not given), evaluate every cell."""
    recorded = [d for d in DATASETS if d != "default_bcde" or "one_rig" not in given]
    runs = [Run(f"record/{d}", "record", tuple(record(out, d)), out / "data" / d) for d in recorded]
    halves = ("record/default_bcde_half", "record/closer_bcde_half")
    runs.append(Run("merge/two_rigs", "merge", tuple(merge(out)), out / "data" / "two_rigs", halves))
    data_run = {"default_bcde": "record/default_bcde", "two_rigs": "merge/two_rigs"}
    data_run["default_wrist"] = "record/default_wrist"
    for m in MODELS:
        if m not in given:
            runs.append(
                Run(f"train/{m}", "train", tuple(train(out, m)), out / "train" / m, (data_run[MODELS[m][0]],))
            )
    for m, r, lay, b in cells():
        folder = eval_dir(out, m, r, lay, b)
        cmd = evaluate(out, m, checkpoints[m], r, lay, episodes, b)
        needs = () if m in given else (f"train/{m}",)
        inputs = (given[m] / "model.safetensors", given[m] / "config.json") if m in given else ()
        cell = {"result": (m, TASK, lay), "seed": EVAL_SEED, "train_seed": TRAIN_SEED}
        cell |= {"control": "blind" if b else "", "tags": tags_of({"rig": r})}
        runs.append(Run(f"eval/{m}/{folder.name}", "eval", tuple(cmd), folder, needs, inputs=inputs, **cell))
    return plan(runs, out)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("outputs/rigs_and_wrist"))
    parser.add_argument("--one-rig-checkpoint", type=Path, help="a mini OmniD pretrained_model folder")
    parser.add_argument("--eval-episodes", type=int, default=30, help="episodes per cell (default 30)")
    add_protocol_options(parser)
    args = parser.parse_args(argv)
    out = args.out.resolve()
    if report_from_summary(parser, args, out, PROTOCOL, write_report):
        return
    given = {"one_rig": args.one_rig_checkpoint.resolve()} if args.one_rig_checkpoint else {}
    for path in given.values():
        if not (path / "config.json").is_file():
            parser.error(f"--one-rig-checkpoint: expected a folder with a config.json, got {path}")
    checkpoints = {m: given.get(m, out / "train" / m / CHECKPOINT) for m in MODELS}
    runs = protocol(out, checkpoints, given, args.eval_episodes)
    if args.dry_run:
        print("\n".join(describe_plan(runs)))
        return
    commit = code_commit()
    if not args.report_only:
        execute(runs, out, commit=commit, desc="rigs_and_wrist", stop_on_failure=True)
    report(out, args.eval_episodes, given, runs, commit)


if __name__ == "__main__":
    main()
