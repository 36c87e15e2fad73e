"""Can the diffusion head command what a layout needs? The expert's actions against the generable range.

OmniD's head, like LeRobot's DP, predicts MIN_MAX-normalised actions and, with ``clip_sample=True``, clips
each denoising step's clean estimate to ``[-clip_sample_range, clip_sample_range]``: it can only ever
command an action inside the training actions' range widened by ``clip_sample_range - 1`` half-ranges on
each side (:func:`generable_range`). An object beyond the training square may need a TCP target outside
that range, which no representation of the scene can make the head produce. This counts, per layout, the
episodes whose scripted expert plan (the actions it would command, planned at reset; no rendering of a
policy, no training) leaves the range, and by how far.

    MUJOCO_GL=egl python -m lerobot_omnid.diagnostics.action_reach --out outputs/action_reach \\
        --dataset outputs/six_tasks/data/select_apple_bcde --task select_apple

Layouts from env seed ``REACH_SEED``, disjoint from every other seed set of the benchmark. Writes
``<out>/summary.json`` (the run summary every protocol writes; the counts under ``results``, the commit) and
``<out>/report.md``; ``--report-only SUMMARY...`` rebuilds the report from such files alone.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
from gym_omnid import ACTION_NAMES, LAYOUTS
from gym_omnid.experts import interpolate, make_expert
from tqdm import tqdm

from lerobot_omnid.diagnostics import summary
from lerobot_omnid.measure.engine import code_commit
from lerobot_omnid.measure.results import RunSummary
from lerobot_omnid.measure.stats import wilson_interval

REACH_SEED = 500_000  # first env seed of the layouts examined
PROTOCOL = "action_reach"
MODULE = "lerobot_omnid.diagnostics.action_reach"
POSITION_DIMS = 3  # the action's first entries are the TCP position (m); excess reported in cm for them


def generable_range(low: np.ndarray, high: np.ndarray, clip_range: float) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) of the actions a MIN_MAX-normalised head clipped to ``[-clip_range, clip_range]`` can
    produce, from the training actions' ``low``, ``high`` (D,): normalised ``2 (a - low) / (high - low) - 1``,
    so the clip widens the range by ``(clip_range - 1) / 2`` of its width on each side."""
    margin = (clip_range - 1) / 2 * (high - low)
    return low - margin, high + margin


def excess(actions: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """(D,) how far (>= 0) the plan's ``actions`` (N, D) reach beyond ``[low, high]`` in each dimension."""
    return np.maximum(np.maximum(low - actions, actions - high), 0).max(axis=0)


def expert_plan(env: gym.Env, seed: int) -> np.ndarray:
    """(N, D) the actions the scripted expert plans for the episode of env seed ``seed``."""
    env.reset(seed=seed)
    expert = make_expert(env.unwrapped)
    return np.stack([interpolate(expert.start, expert.waypoints, step) for step in range(len(expert))])


def reach(task: str, layout: str, episodes: int, low: np.ndarray, high: np.ndarray) -> dict:
    """Per layout: the episodes whose expert plan leaves ``[low, high]``, which action dims do, and the
    largest position excess (cm)."""
    env = gym.make(f"gym_omnid/{task}", layout=layout, cameras=["cam_b"], image_size=32)
    try:
        excesses = np.stack(
            [
                excess(expert_plan(env, REACH_SEED + i), low, high)
                for i in tqdm(range(episodes), desc=f"{task} {layout}", unit="ep")
            ]
        )
    finally:
        env.close()
    beyond = excesses > 1e-6  # episodes, D
    position_cm = 100 * excesses[:, :POSITION_DIMS].max(axis=1)
    return {
        "episodes": episodes,
        "beyond": int(beyond.any(axis=1).sum()),
        "beyond_by_dim": {
            name: int(n) for name, n in zip(ACTION_NAMES, beyond.sum(axis=0), strict=True) if n
        },
        "max_position_excess_cm": float(position_cm.max()),
        "median_position_excess_cm": float(np.median(position_cm[position_cm > 0]))
        if position_cm.any()
        else 0.0,
    }


def report_lines(run: RunSummary) -> list[str]:
    """The table of one summary (a clip range, a dataset)."""
    s = run.settings
    lines = [
        f"# Action reach: {s['task']}, training actions of {s['dataset']}, "
        f"clip_sample_range {s['clip_range']} ({run.commit})",
        "",
        "| layout | expert plans leaving the generable range (Wilson 95 %) | dims "
        "| position excess, median / max (cm) |",
        "|---|---|---|---|",
    ]
    for layout, r in run.results["layouts"].items():
        est = wilson_interval(r["beyond"], r["episodes"])
        dims = ", ".join(f"{name} {n}" for name, n in r["beyond_by_dim"].items()) or "-"
        lines.append(
            f"| {layout} | {r['beyond']}/{r['episodes']} = {100 * est.value:.1f} % ({100 * est.low:.1f}-"
            f"{100 * est.high:.1f}) | {dims} | {r['median_position_excess_cm']:.1f} / "
            f"{r['max_position_excess_cm']:.1f} |"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    summary.add_options(parser)
    parser.add_argument("--dataset", type=Path, help="the training dataset (its meta/stats.json)")
    parser.add_argument("--task", default="select_apple")
    parser.add_argument("--layouts", default=",".join(LAYOUTS[:1] + LAYOUTS[2:]))
    parser.add_argument("--episodes", type=int, default=200, help="layouts examined per layout kind")
    parser.add_argument("--clip-range", type=float, default=1.0, help="the policy's clip_sample_range")
    args = parser.parse_args(argv)
    if summary.rebuild(parser, args, PROTOCOL, report_lines):
        return 0
    stats_path = args.dataset / "meta" / "stats.json" if args.dataset else None
    if stats_path is None or not stats_path.is_file():
        parser.error(f"--dataset: expected a LeRobot dataset folder with meta/stats.json, got {args.dataset}")
    layouts = [layout for layout in args.layouts.split(",") if layout]
    for layout in layouts:
        if layout not in LAYOUTS:
            parser.error(f"--layouts: expected names from {list(LAYOUTS)}, got {layout!r}")
    if args.clip_range < 1:
        parser.error(f"--clip-range: expected >= 1 (the training range itself), got {args.clip_range}")
    stats = json.loads(stats_path.read_text())["action"]
    low, high = generable_range(np.array(stats["min"]), np.array(stats["max"]), args.clip_range)
    results = {layout: reach(args.task, layout, args.episodes, low, high) for layout in layouts}
    settings = {
        "task": args.task,
        "dataset": args.dataset.name,
        "clip_range": args.clip_range,
        "reach_seed": REACH_SEED,
        "generable_low": low.tolist(),
        "generable_high": high.tolist(),
    }
    summary.finish(args, PROTOCOL, MODULE, argv, settings, {"layouts": results}, code_commit(), report_lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
