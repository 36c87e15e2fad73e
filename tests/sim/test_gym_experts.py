"""Scripted experts: the pure interpolation, and success in ID, position-OOD and graded-band episodes."""

from __future__ import annotations

import gym_omnid
import gymnasium as gym
import numpy as np
import pytest
from gym_omnid.experts import Waypoint, interpolate, make_expert, plan_length, run_expert_episode
from gym_omnid.rotations import matrix_from_rot6d, topdown_rotation

FAST_SEEDS = (0, 1, 2)
BAND_SEEDS = (0,)  # one episode per graded position band and task in the fast test (4 bands)
SLOW_EPISODES = 100
MIN_SUCCESS_RATE = 0.95
# The longest expert episodes (set_study_table, position-OOD) take about 100 of the 200 steps: a
# policy at 10 Hz gets at least 5/3 of the expert's time.
EXPERT_MAX_STEPS = 3 * gym_omnid.MAX_EPISODE_STEPS // 5


def test_interpolate_is_piecewise_linear_and_holds_the_end() -> None:
    start = Waypoint("start", (0.0, 0.0, 0.0), 0.0, 0.0, 1)
    plan = [Waypoint("a", (1.0, 0.0, 0.0), 0.0, 0.0, 4), Waypoint("b", (1.0, 2.0, 0.0), 1.0, 1.0, 2)]
    assert plan_length(plan) == 6
    np.testing.assert_allclose(interpolate(start, plan, 0)[:3], [0.25, 0, 0])
    np.testing.assert_allclose(interpolate(start, plan, 3)[:3], [1.0, 0, 0])
    mid = interpolate(start, plan, 4)
    np.testing.assert_allclose(mid[:3], [1.0, 1.0, 0])
    assert mid[9] == pytest.approx(0.5)
    np.testing.assert_allclose(matrix_from_rot6d(mid[3:9]), topdown_rotation(0.5), atol=1e-6)
    np.testing.assert_array_equal(interpolate(start, plan, 5), interpolate(start, plan, 50))
    assert interpolate(start, plan, 0).dtype == np.float32


@pytest.mark.parametrize("layout", gym_omnid.LAYOUTS)
@pytest.mark.parametrize("task", gym_omnid.TASKS)
def test_expert_succeeds_fast(task: str, layout: str) -> None:
    env = gym.make(f"gym_omnid/{task}", layout=layout, cameras=["cam_a"], image_size=32)
    try:
        for seed in BAND_SEEDS if layout in gym_omnid.constants.POSITION_BANDS else FAST_SEEDS:
            success, steps = run_expert_episode(env, seed)
            assert success, f"{task}/{layout} seed {seed} failed"
            assert steps <= EXPERT_MAX_STEPS
    finally:
        env.close()


def test_expert_plan_names(make_env) -> None:
    env = make_env("select_apple", cameras=["cam_a"], image_size=32)
    env.reset(seed=0)
    expert = make_expert(env)
    names = [w.name for w in expert.waypoints]
    assert names.index("close") < names.index("lift") < names.index("carry") < names.index("open")
    assert len(expert) == plan_length(expert.waypoints)


@pytest.mark.slow
@pytest.mark.parametrize("task", gym_omnid.TASKS)
def test_expert_success_rate(task: str) -> None:
    """>= 95 % over 100 seeded ID episodes (seeds 1000..1099, disjoint from the fast test's).

    ID only, to keep the whole suite within its time budget; the position-OOD rates over the same
    number of episodes come from ``benchmarks/bench_env.py`` (envs/README.md), and every layout keeps
    the fast test above."""
    env = gym.make(f"gym_omnid/{task}", layout="id", cameras=["cam_a"], image_size=32)
    try:
        successes = sum(run_expert_episode(env, 1000 + i)[0] for i in range(SLOW_EPISODES))
    finally:
        env.close()
    assert successes / SLOW_EPISODES >= MIN_SUCCESS_RATE
