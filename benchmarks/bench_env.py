"""gym_omnid env benchmark: step time, and scripted-expert success rates per task and layout.

    python benchmarks/bench_env.py                      # 100 episodes per task and layout
    python benchmarks/bench_env.py --episodes 10 --timing-steps 100

Step time: ``env.step`` (IK + 1 / CONTROL_FPS s of physics + rendering every observed camera) timed
over expert rollouts with the default observation (five cameras at 128x128), median and p90.
Success: seeds ``--seed0 .. --seed0 + episodes - 1`` per task and layout; an episode succeeds when the
env reports ``info["is_success"]`` before ``MAX_EPISODE_STEPS``. Rendering does not influence the
physics or the expert, so the success runs observe one 32x32 camera by default (``--full-obs`` to
render all five cameras at ``--image-size`` there too).
"""

from __future__ import annotations

import argparse
import statistics
import time

import gym_omnid
import gymnasium as gym
import numpy as np
from gym_omnid.experts import make_expert, run_expert_episode
from tqdm import tqdm

CHEAP_OBS = {"cameras": ["cam_a"], "image_size": 32}


def time_steps(task: str, steps: int, image_size: int, seed: int) -> list[float]:
    """Wall-clock seconds of ``steps`` env steps (five cameras at ``image_size``) along expert rollouts."""
    env = gym.make(f"gym_omnid/{task}", image_size=image_size)
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
    task: str, layout: str, episodes: int, seed0: int, obs_kwargs: dict
) -> tuple[float, float, float]:
    """(success rate, mean steps of successful episodes, mean steps of all episodes)."""
    env = gym.make(f"gym_omnid/{task}", layout=layout, **obs_kwargs)
    try:
        results = [
            run_expert_episode(env, seed)
            for seed in tqdm(range(seed0, seed0 + episodes), desc=f"{task}/{layout}", leave=False)
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
    parser.add_argument("--tasks", nargs="+", default=list(gym_omnid.TASKS), choices=gym_omnid.TASKS)
    parser.add_argument("--layouts", nargs="+", default=list(gym_omnid.LAYOUTS), choices=gym_omnid.LAYOUTS)
    parser.add_argument("--seed0", type=int, default=0, help="first seed of the success runs")
    parser.add_argument("--full-obs", action="store_true", help="render five cameras in the success runs too")
    args = parser.parse_args()
    if args.episodes < 0 or args.timing_steps < 0:
        parser.error(f"--episodes and --timing-steps must be >= 0, got {args.episodes}, {args.timing_steps}")

    rows = []
    if args.timing_steps:
        for task in args.tasks:
            durations_ms = np.array(time_steps(task, args.timing_steps, args.image_size, args.seed0)) * 1e3
            median, p90 = statistics.median(durations_ms), np.percentile(durations_ms, 90)
            rows.append(
                f"step time {task:<22} 5 cams {args.image_size}x{args.image_size}: "
                f"median {median:6.2f} ms  p90 {p90:6.2f} ms  ({len(durations_ms)} steps)"
            )
    obs_kwargs = {"image_size": args.image_size} if args.full_obs else CHEAP_OBS
    if args.episodes:
        for task in args.tasks:
            for layout in args.layouts:
                rate, len_success, len_all = success_rate(task, layout, args.episodes, args.seed0, obs_kwargs)
                rows.append(
                    f"expert    {task:<22} {layout:<13} success {100 * rate:5.1f} % of {args.episodes}"
                    f"  mean length {len_success:5.1f} steps (successes), {len_all:5.1f} (all)"
                )
    print(
        f"\n== gym_omnid benchmark (max {gym_omnid.MAX_EPISODE_STEPS} steps at {gym_omnid.CONTROL_FPS} Hz;"
        f" success runs observe {obs_kwargs}) =="
    )
    print("\n".join(rows))


if __name__ == "__main__":
    main()
