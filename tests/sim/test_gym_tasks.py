"""Task-specific rules of add_condiment, get_coffee, set_study_table and texas_holdem: instructions,
sustained pouring, the spring-loaded button, the hinged lid, and success needing every part."""

from __future__ import annotations

import numpy as np
from gym_omnid.experts import make_expert
from gym_omnid.tasks import add_condiment, get_coffee, set_study_table, texas_holdem
from gym_omnid.waypoints import OPEN, interpolate, waypoint_action

SMALL = {"cameras": ["cam_a"], "image_size": 32}
OPEN_LID_STEPS = 8  # env steps before the set_study_table expert reaches the lid


def test_texas_holdem_instruction_names_the_row_position(make_env) -> None:
    """The named position is the target card's rank by world y (left = +y); suits move per episode."""
    env = make_env("texas_holdem", **SMALL)
    named, targets = set(), set()
    for seed in range(16):
        env.reset(seed=seed)
        task = env.task_spec
        position = env.task_description.removeprefix("put the ").removesuffix(" card on the mat")
        cards_by_y = sorted(texas_holdem.CARD_SUITS, key=lambda s: -env.object_positions()[f"card_{s}"][1])
        assert cards_by_y.index(task.target) == texas_holdem.ROW_POSITIONS.index(position), seed
        np.testing.assert_array_equal(
            env.object_positions()["target_card"], env.object_positions()[f"card_{task.target}"]
        )
        named.add(position)
        targets.add(task.target)
    assert named == set(texas_holdem.ROW_POSITIONS) and len(targets) >= 3


def test_add_condiment_needs_a_sustained_pour_while_held(make_env) -> None:
    env = make_env("add_condiment", **SMALL)
    env.reset(seed=0)
    task = env.task_spec
    expert = make_expert(env)
    pouring = []
    for _ in range(len(expert)):
        *_, terminated, _, info = env.step(expert.act())
        pouring.append(task.is_pouring(env.data))
        if terminated:
            break
    # Success exactly when the pour has lasted POUR_STEPS consecutive steps, not before.
    assert info["is_success"] and pouring[-add_condiment.POUR_STEPS :] == [True] * add_condiment.POUR_STEPS
    assert not any(pouring[: -add_condiment.POUR_STEPS])
    _, info = env.reset(seed=0)
    assert not info["is_success"] and not env.task_spec.is_success(env.data)

    # Dropping the bottle as soon as it pours ends the count: no success.
    expert = make_expert(env)
    while not task.is_pouring(env.data):
        env.step(expert.act())
    action = expert.act()
    action[9] = OPEN
    for _ in range(2 * add_condiment.POUR_STEPS):
        *_, info = env.step(action)
        assert not info["is_success"]
    assert not task.is_pouring(env.data)


def test_get_coffee_button_springs_back_and_needs_the_mug_under_the_spout(make_env) -> None:
    env = make_env("get_coffee", **SMALL)
    env.reset(seed=0)
    task = env.task_spec
    plan = make_expert(env)
    press_only = [w for w in plan.waypoints if w.name in ("hover_button", "press", "hold_press")]
    for step in range(sum(w.steps for w in press_only)):
        *_, info = env.step(interpolate(plan.start, press_only, step))
    assert task.button_depth(env.data) >= get_coffee.BUTTON_PRESSED
    assert not info["is_success"]  # pressed, but the mug is still where it started
    lifted = waypoint_action(np.asarray(plan.waypoints[-1].xyz), plan.waypoints[-1].yaw, 1.0)
    for _ in range(5):
        env.step(lifted)
    assert task.button_depth(env.data) < 0.1 * get_coffee.BUTTON_TRAVEL  # the spring pushed it back


def test_set_study_table_lid_rests_open_and_success_needs_both_goals(make_env) -> None:
    env = make_env("set_study_table", **SMALL)
    env.reset(seed=0)
    task = env.task_spec
    expert = make_expert(env)
    closed_before_book = False
    for step in range(len(expert) + 20):
        if step < OPEN_LID_STEPS:  # on its stop, untouched while the arm approaches
            assert abs(task.lid_angle(env.data) - set_study_table.LID_OPEN) < 0.02, step
        *_, terminated, _, info = env.step(expert.act())
        lid_closed = task.lid_angle(env.data) < set_study_table.LID_CLOSED
        closed_before_book |= lid_closed and not task.book_on_shelf(env.data)
        assert info["is_success"] == (lid_closed and task.book_on_shelf(env.data))
        if terminated:
            break
    assert info["is_success"] and closed_before_book
