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
told to read the env's per-frame calibration (``--policy.frame_calibration``). Resumable like the benchmark;
writes ``<out>/report.md`` (Wilson 95 % intervals, Fisher tests of each pair, the code commit of each
evaluation, kept beside it in ``commit.txt``) and ``<out>/summary.json``.

    MUJOCO_GL=egl python benchmarks/rigs_and_wrist.py --out outputs/rigs_and_wrist \\
        --one-rig-checkpoint outputs/bench_mini/train/omnid/select_apple/checkpoints/last/pretrained_model
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from gym_omnid import TRAIN_CAMERAS, WRIST_CAMERA

from lerobot_omnid.benchmark import commands
from lerobot_omnid.benchmark.benchmark import code_commit
from lerobot_omnid.benchmark.plan import BANDS, PROFILES, TRAIN_SEED, method_flags
from lerobot_omnid.benchmark.results import read_eval_info
from lerobot_omnid.benchmark.stats import fisher_exact, wilson_interval
from lerobot_omnid.keys import image_key

TASK = "select_apple"
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


def record(out: Path, name: str) -> list[str]:
    rig, cameras, episodes, seed = DATASETS[name]
    root = out / "data" / name
    cmd = commands.record_command(
        TASK, episodes, cameras, PROFILE.image_size, root, seed=seed, static_calibration=False
    )
    return [*cmd, "--rig", rig, "--per-frame-calibration"]


def merge(out: Path) -> list[str]:
    parts = ["default_bcde_half", "closer_bcde_half"]
    return [
        str(commands.BIN / "lerobot-edit-dataset"),
        "--new_repo_id=local/two_rigs",
        f"--new_root={out / 'data' / 'two_rigs'}",
        "--operation.type=merge",
        f"--operation.repo_ids={json.dumps([f'local/{p}' for p in parts])}",
        f"--operation.roots={json.dumps([str(out / 'data' / p) for p in parts])}",
    ]


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


def is_done(kind: str, target: Path) -> bool:
    """Whether the run of ``kind`` that writes ``target`` finished (a record run: all its episodes)."""
    if kind == "record":
        return commands.recorded_episodes(target) == DATASETS[target.name][2]
    if kind == "merge":
        return (target / "meta" / "info.json").is_file()
    return commands.is_trained(target) if kind == "train" else commands.is_evaluated(target)


def cells() -> list[tuple[str, str, str, bool]]:
    """(model, rig, layout, blind) of every evaluation."""
    return [(m, r, lay, False) for m, ev in EVALS.items() for r, lay in ev] + [
        (m, "default", "id", True) for m in MODELS
    ]


def report(out: Path, episodes: int, checkpoints: dict[str, Path]) -> None:
    counts = {}
    for model, rig, layout, blind in cells():
        info = eval_dir(out, model, rig, layout, blind) / "eval_info.json"
        if info.is_file():
            counts[model, rig, layout, blind] = read_eval_info(info)
    rows = []
    for (model, rig, layout, blind), (s, n) in counts.items():
        est = wilson_interval(s, n)
        commit_file = eval_dir(out, model, rig, layout, blind) / commands.COMMIT_FILE
        rows.append(
            {
                "model": model,
                "rig": rig,
                "layout": layout,
                "control": "blind" if blind else "",
                "successes": s,
                "episodes": n,
                "rate": est.value,
                "low": est.low,
                "high": est.high,
                "commit": commit_file.read_text().strip() if commit_file.is_file() else None,
            }
        )
    commits = ", ".join(sorted({str(r["commit"]) for r in rows})) or "none"
    lines = [
        f"# Per-frame calibration: rigs and wrist camera ({TASK}, mini sizes)",
        "",
        f"Commits: {commits}.",
        "",
    ]
    lines += ["| model | rig | layout | control | success | Wilson 95 % |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['model']} | {r['rig']} | {r['layout']} | {r['control'] or '-'} | "
            f"{r['successes']}/{r['episodes']} | {100 * r['low']:.0f}-{100 * r['high']:.0f} % |"
        )
    lines += ["", "| pair | rig | layout | A | B | Fisher p |", "|---|---|---|---|---|---|"]
    for pair, (a, b) in PAIRS.items():
        for rig, layout in EVALS[a]:
            if (a, rig, layout, False) in counts and (b, rig, layout, False) in counts:
                (sa, na), (sb, nb) = counts[a, rig, layout, False], counts[b, rig, layout, False]
                p = fisher_exact(sa, na, sb, nb)
                lines.append(f"| {pair}: {a} vs {b} | {rig} | {layout} | {sa}/{na} | {sb}/{nb} | {p:.3g} |")
    (out / "report.md").write_text("\n".join(lines) + "\n")
    summary = {
        "task": TASK,
        "episodes_per_cell": episodes,
        "eval_seed": EVAL_SEED,
        "train_seed": TRAIN_SEED,
        "steps": PROFILE.steps,
        "results": rows,
        "checkpoints": {m: "given" if m in checkpoints else "trained here" for m in MODELS},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--out", type=Path, default=Path("outputs/rigs_and_wrist"))
    parser.add_argument("--one-rig-checkpoint", type=Path, help="a mini OmniD pretrained_model folder")
    parser.add_argument("--eval-episodes", type=int, default=30, help="episodes per cell (default 30)")
    parser.add_argument("--report-only", action="store_true")
    args = parser.parse_args()
    out = args.out.resolve()
    given = {"one_rig": args.one_rig_checkpoint.resolve()} if args.one_rig_checkpoint else {}
    for path in given.values():
        if not (path / "config.json").is_file():
            parser.error(f"--one-rig-checkpoint: expected a folder with a config.json, got {path}")
    checkpoints = {m: given.get(m, out / "train" / m / commands.CHECKPOINT) for m in MODELS}
    if not args.report_only:
        steps = [
            (f"record/{d}", record(out, d), out / "data" / d)
            for d in DATASETS
            if d != "default_bcde" or "one_rig" not in given
        ]
        steps.append(("merge/two_rigs", merge(out), out / "data" / "two_rigs"))
        steps += [(f"train/{m}", train(out, m), out / "train" / m) for m in MODELS if m not in given]
        steps += [
            (
                f"eval/{m}/{eval_dir(out, m, r, lay, b).name}",
                evaluate(out, m, checkpoints[m], r, lay, args.eval_episodes, b),
                eval_dir(out, m, r, lay, b),
            )
            for m, r, lay, b in cells()
        ]
        commands.run_steps(steps, out, "rigs_and_wrist", is_done, code_commit())
    report(out, args.eval_episodes, given)


if __name__ == "__main__":
    main()
