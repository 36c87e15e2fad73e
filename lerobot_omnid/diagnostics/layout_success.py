"""Where were the objects when a policy succeeded? Success against the layout, episode by episode.

A success rate pools layouts; two ranges of env seeds can disagree because one range's layouts are harder
for a policy (its objects nearer the robot, farther from the training square's centre). This replays each
evaluated episode's layout (``reset(seed)`` of the same env: objects only, no policy) and sets the task's
object positions (``object_positions``) against the episode's success from ``lerobot-eval``'s
``eval_info.json``: per model and object axis the mean position in successes and in failures, and a
two-sided permutation test of their difference; per range of env seeds, the mean layout. A diagnostic to
read beside a table, not a claim: many tests, none corrected.

    MUJOCO_GL=egl python -m lerobot_omnid.diagnostics.layout_success --out outputs/layouts_add_condiment \\
        --summary outputs/six_tasks/summary.json --task add_condiment

Reads the evaluations of ``--summary`` (an ``omnid-benchmark`` folder's, whose ``eval_info.json`` files
must still be there; run from where the benchmark ran) for the task and setting, controls left out. Writes
``<out>/summary.json`` (the counts and means under ``results``) and ``<out>/report.md``; ``--report-only
SUMMARY...`` rebuilds the report from such files alone.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from lerobot_omnid.benchmark.plan import setting_env
from lerobot_omnid.diagnostics import summary
from lerobot_omnid.measure.engine import code_commit
from lerobot_omnid.measure.results import (
    RunSummary,
    read_summary,
)

PROTOCOL = "layout_success"
MODULE = "lerobot_omnid.diagnostics.layout_success"
PERMUTATIONS = 10_000
AXES = ("x", "y")


def episode_successes(eval_info: Path) -> list[bool]:
    """Each episode's success, in ``lerobot-eval``'s episode order (episode i: env seed first + i)."""
    tasks = json.loads(eval_info.read_text())["per_task"]
    return [bool(s) for task in tasks for s in task["metrics"]["successes"]]


def option(command: tuple[str, ...], name: str) -> str:
    """The value of ``--name=`` in a ``lerobot-eval`` command line (``seed``: its first episode's env seed;
    ``output_dir``: where its ``eval_info.json`` is, relative to where it ran)."""
    values = [arg.split("=", 1)[1] for arg in command if arg.startswith(f"--{name}=")]
    if len(values) != 1:
        raise ValueError(
            f"expected one --{name}= in the evaluation's command, got {values}: {' '.join(command)}"
        )
    return values[0]


def layouts(task: str, setting: str, seeds: list[int]) -> dict[int, dict[str, list[float]]]:
    """{env seed: {key object: (x, y) m}} of ``task``'s episodes in ``setting``."""
    layout, background = setting_env(setting)
    env = gym.make(
        f"gym_omnid/{task}", layout=layout, background=background, cameras=["cam_b"], image_size=32
    )
    found = {}
    try:
        for seed in tqdm(seeds, desc=f"{task} {setting} layouts", unit="ep"):
            env.reset(seed=seed)
            found[seed] = {name: xyz[:2].tolist() for name, xyz in env.unwrapped.object_positions().items()}
    finally:
        env.close()
    return found


def permutation_p(values: np.ndarray, success: np.ndarray, rng: np.random.Generator) -> float:
    """Two-sided permutation p of the difference of means between successes and failures."""
    observed = abs(values[success].mean() - values[~success].mean())
    hits = 0
    for _ in range(PERMUTATIONS):
        shuffled = rng.permutation(success)
        hits += abs(values[shuffled].mean() - values[~shuffled].mean()) >= observed - 1e-12
    return (hits + 1) / (PERMUTATIONS + 1)


def compare(episodes: list[dict]) -> dict[str, dict]:
    """Per object axis: the means (cm) in successes and failures, their difference and its p-value; empty
    when either group is empty."""
    success = np.array([e["success"] for e in episodes])
    if success.all() or not success.any():
        return {}
    rng = np.random.default_rng(0)
    result = {}
    for name in episodes[0]["objects"]:
        for i, axis in enumerate(AXES):
            values = 100 * np.array([e["objects"][name][i] for e in episodes])
            result[f"{name}.{axis}"] = {
                "success_cm": float(values[success].mean()),
                "failure_cm": float(values[~success].mean()),
                "p": permutation_p(values, success, rng),
            }
    return result


def report_lines(run: RunSummary) -> list[str]:
    s, results = run.settings, run.results
    lines = [
        f"# Success against the layout: {s['task']}, {s['setting']} ({run.commit})",
        "",
        "Mean key-object position (cm, world frame) in the episodes each model solved and in those it did "
        f"not; two-sided permutation p ({PERMUTATIONS} permutations), uncorrected.",
        "",
        "| model | successes | object axis | solved (cm) | failed (cm) | solved - failed | p |",
        "|---|---|---|---|---|---|---|",
    ]
    for model, r in results["models"].items():
        counts = f"{r['successes']}/{r['episodes']}"
        if not r["axes"]:
            lines.append(f"| {model} | {counts} | (all solved or none) | | | | |")
        for axis, a in r["axes"].items():
            difference = a["success_cm"] - a["failure_cm"]
            lines.append(
                f"| {model} | {counts} | {axis} | {a['success_cm']:.1f} | {a['failure_cm']:.1f} | "
                f"{difference:+.1f} | {a['p']:.3g} |"
            )
    lines += ["", "| env seeds | episodes | " + " | ".join(results["range_means"][0]["means"]) + " |"]
    lines.append("|---|---|" + "---|" * len(results["range_means"][0]["means"]))
    for r in results["range_means"]:
        means = " | ".join(f"{v:.1f}" for v in r["means"].values())
        lines.append(f"| {r['first']}-{r['first'] + r['episodes'] - 1} | {r['episodes']} | {means} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    summary.add_options(parser)
    parser.add_argument("--summary", type=Path, help="an omnid-benchmark folder's summary.json")
    parser.add_argument("--task")
    parser.add_argument("--setting", default="id")
    args = parser.parse_args(argv)
    if summary.rebuild(parser, args, PROTOCOL, report_lines):
        return 0
    if args.summary is None or args.task is None:
        parser.error("--summary and --task: expected both (or --report-only)")
    try:
        _, records = read_summary(args.summary)
    except ValueError as e:
        parser.error(f"--summary: {e}")
    chosen = [r for r in records if r.key[1:] == (args.task, args.setting) and not r.control]
    if not chosen:
        parser.error(f"--task/--setting: no evaluation of {args.task} in {args.setting} in {args.summary}")
    episodes_of: dict[str, list[dict]] = defaultdict(list)
    ranges = {}
    for r in chosen:
        eval_info = Path(option(r.command, "output_dir")) / "eval_info.json"
        if not eval_info.is_file():
            where = "/".join(map(str, r.key))
            parser.error(
                f"--summary: {where}: expected {eval_info} (run from where it ran), got no such file"
            )
        first = int(option(r.command, "seed"))
        successes = episode_successes(eval_info)
        ranges[first] = len(successes)
        episodes_of[r.key[0]] += [{"seed": first + i, "success": s} for i, s in enumerate(successes)]
    positions = layouts(
        args.task, args.setting, sorted({e["seed"] for es in episodes_of.values() for e in es})
    )
    models = {}
    for model, episodes in episodes_of.items():
        for e in episodes:
            e["objects"] = positions[e["seed"]]
        solved = sum(e["success"] for e in episodes)
        models[model] = {"successes": solved, "episodes": len(episodes), "axes": compare(episodes)}
    range_means = []
    for first, n in sorted(ranges.items()):
        objects = [positions[first + i] for i in range(n)]
        means = {
            f"{name}.{axis}": 100 * float(np.mean([o[name][i] for o in objects]))
            for name in objects[0]
            for i, axis in enumerate(AXES)
        }
        range_means.append({"first": first, "episodes": n, "means": means})
    settings = {"task": args.task, "setting": args.setting, "summary": str(args.summary)}
    results = {"models": models, "range_means": range_means}
    summary.finish(args, PROTOCOL, MODULE, argv, settings, results, code_commit(), report_lines)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
