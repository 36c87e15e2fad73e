"""gym_omnid env benchmark: step time, and scripted-expert success rates per task and layout.

    python benchmarks/bench_env.py                      # 100 episodes per task and layout
    python benchmarks/bench_env.py --episodes 10 --timing-steps 100
    python benchmarks/bench_env.py --suite metaworld --tasks assembly-v3 push-v3 --episodes 10

``--suite metaworld`` measures the MetaWorld suite (extra ``[metaworld]``) the same way: its four default
cameras, MetaWorld's scripted policies, no layouts.

Step time: ``env.step`` (IK + 1 / CONTROL_FPS s of physics + rendering every observed camera) timed
over expert rollouts with the default observation (gym_omnid: five cameras at 128x128), median and p90.
Success: seeds ``--seed0 .. --seed0 + episodes - 1`` per task and layout; an episode succeeds when the
env reports ``info["is_success"]`` before ``MAX_EPISODE_STEPS``. Rendering does not influence the
physics or the expert, so the success runs observe one 32x32 camera by default (``--full-obs`` to
render the default cameras at ``--image-size`` there too).
"""

from __future__ import annotations

import argparse
import importlib
import statistics
import time
from dataclasses import dataclass
from types import ModuleType

import gym_omnid
import gym_omnid.metaworld_suite
import gymnasium as gym
import numpy as np
from tqdm import tqdm


@dataclass(frozen=True)
class Suite:
    namespace: str  # gym ids are f"{namespace}/{task}"
    tasks: tuple[str, ...]
    layouts: tuple[str, ...]  # () where the suite has none
    cheap_camera: str  # the one camera the success runs observe
    max_steps: int
    control_fps: int
    experts: str  # module with make_expert(env) and run_expert_episode(env, seed, max_steps)


SUITES = {
    "gym_omnid": Suite(
        "gym_omnid",
        gym_omnid.TASKS,
        gym_omnid.LAYOUTS,
        "cam_a",
        gym_omnid.MAX_EPISODE_STEPS,
        gym_omnid.CONTROL_FPS,
        "gym_omnid.experts",
    ),
    "metaworld": Suite(
        gym_omnid.metaworld_suite.GYM_NAMESPACE,
        gym_omnid.metaworld_suite.TASKS,
        (),
        "corner2",
        gym_omnid.metaworld_suite.MAX_EPISODE_STEPS,
        gym_omnid.metaworld_suite.CONTROL_FPS,
        "gym_omnid.metaworld_suite.experts",
    ),
}


def experts_of(suite: Suite) -> ModuleType:
    """The suite's experts module (MetaWorld's imports metaworld, so only when that suite is measured)."""
    return importlib.import_module(suite.experts)


def time_steps(suite: Suite, task: str, steps: int, image_size: int, seed: int) -> list[float]:
    """Wall-clock seconds of ``steps`` env steps (the default cameras at ``image_size``) along expert
    rollouts."""
    make_expert = experts_of(suite).make_expert
    env = gym.make(f"{suite.namespace}/{task}", image_size=image_size)
    durations: list[float] = []
    try:
        with tqdm(total=steps, desc=f"timing {task}", leave=False) as bar:
            while len(durations) < steps:
                env.reset(seed=seed + len(durations))
                expert = make_expert(env.unwrapped)
                done = False
                while not done and len(durations) < steps:
                    action = expert.act()
                    start = time.perf_counter()
                    _, _, terminated, truncated, _ = env.step(action)
                    durations.append(time.perf_counter() - start)
                    done = terminated or truncated
                    bar.update()
    finally:
        env.close()
    return durations


def success_rate(
    suite: Suite, task: str, layout: str | None, episodes: int, seed0: int, obs_kwargs: dict
) -> tuple[float, float, float]:
    """(success rate, mean steps of successful episodes, mean steps of all episodes)."""
    layout_kwargs = {"layout": layout} if layout else {}
    env = gym.make(f"{suite.namespace}/{task}", **layout_kwargs, **obs_kwargs)
    run_expert_episode = experts_of(suite).run_expert_episode
    try:
        results = [
            run_expert_episode(env, seed, suite.max_steps)
            for seed in tqdm(range(seed0, seed0 + episodes), desc=f"{task}/{layout or '-'}", leave=False)
        ]
    finally:
        env.close()
    success_lengths = [steps for success, steps in results if success]
    mean_success_len = float(np.mean(success_lengths)) if success_lengths else float("nan")
    return len(success_lengths) / episodes, mean_success_len, float(np.mean([steps for _, steps in results]))


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes", type=int, default=100, help="expert episodes per task and layout")
    parser.add_argument("--timing-steps", type=int, default=300, help="timed env steps per task")
    parser.add_argument("--image-size", type=int, default=128, help="image side for the step timing")
    parser.add_argument("--suite", choices=sorted(SUITES), default="gym_omnid")
    parser.add_argument("--tasks", nargs="+", help="default: every task of the suite")
    parser.add_argument("--layouts", nargs="+", help="gym_omnid only; default: every layout")
    parser.add_argument("--seed0", type=int, default=0, help="first seed of the success runs")
    parser.add_argument(
        "--full-obs", action="store_true", help="render the default cameras in the success runs too"
    )
    args = parser.parse_args()
    if args.episodes < 0 or args.timing_steps < 0:
        parser.error(f"--episodes and --timing-steps must be >= 0, got {args.episodes}, {args.timing_steps}")
    suite = SUITES[args.suite]
    tasks = args.tasks or list(suite.tasks)
    if unknown := [t for t in tasks if t not in suite.tasks]:
        parser.error(f"--tasks: expected tasks of the {args.suite} suite, got {unknown}")
    if args.layouts and not suite.layouts:
        parser.error(f"--layouts: the {args.suite} suite has no layouts, got {args.layouts}")
    layouts = args.layouts or list(suite.layouts) or [None]
    if unknown := [lay for lay in layouts if lay is not None and lay not in suite.layouts]:
        parser.error(f"--layouts: expected names from {list(suite.layouts)}, got {unknown}")

    rows = []
    if args.timing_steps:
        for task in tasks:
            durations_ms = (
                np.array(time_steps(suite, task, args.timing_steps, args.image_size, args.seed0)) * 1e3
            )
            median, p90 = statistics.median(durations_ms), np.percentile(durations_ms, 90)
            rows.append(
                f"step time {task:<22} default cameras {args.image_size}x{args.image_size}: "
                f"median {median:6.2f} ms  p90 {p90:6.2f} ms  ({len(durations_ms)} steps)"
            )
    cheap = {"cameras": [suite.cheap_camera], "image_size": 32}
    obs_kwargs = {"image_size": args.image_size} if args.full_obs else cheap
    if args.episodes:
        for task in tasks:
            for layout in layouts:
                rate, len_success, len_all = success_rate(
                    suite, task, layout, args.episodes, args.seed0, obs_kwargs
                )
                rows.append(
                    f"expert    {task:<22} {layout or '-':<13} success {100 * rate:5.1f} % of {args.episodes}"
                    f"  mean length {len_success:5.1f} steps (successes), {len_all:5.1f} (all)"
                )
    print(
        f"\n== {args.suite} benchmark (max {suite.max_steps} steps at {suite.control_fps} Hz;"
        f" success runs observe {obs_kwargs}) =="
    )
    print("\n".join(rows))


if __name__ == "__main__":
    main()
