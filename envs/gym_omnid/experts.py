"""Scripted experts as data: a list of named TCP waypoints per task plus one pure interpolation function.

Usage::

    obs, info = env.reset(seed=0)
    expert = make_expert(env.unwrapped)
    while True:
        obs, reward, terminated, truncated, info = env.step(expert.act())

The plan is computed once, right after ``reset``, from privileged simulator state (object poses); the
gripper stays top-down, so each waypoint holds a TCP position, a yaw and a gripper command.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING

import gymnasium as gym
import numpy as np

from gym_omnid.constants import MAX_EPISODE_STEPS
from gym_omnid.robot import FINGER_TIP_BEYOND_TCP
from gym_omnid.rotations import rot6d_from_matrix, topdown_rotation
from gym_omnid.tasks.select_apple import APPLE_RADIUS, BOWL_BASE_THICKNESS
from gym_omnid.tasks.select_chemistry_tube import HOLDER_BASE_TOP, TUBE_LENGTH

if TYPE_CHECKING:
    from gym_omnid.env import OmniDEnv

TRAVEL_SPEED = 0.03  # m per env step (0.3 m/s) for moves in free space
APPROACH_SPEED = 0.015  # m per env step for moves near objects (descend, lift, lower)
MIN_MOVE_STEPS = 3  # env steps: shortest move
GRIPPER_STEPS = 4  # env steps to close or open the gripper
HOLD_STEPS = 2  # env steps of waiting for a grasp to settle
OPEN, CLOSED = 0.0, 1.0  # gripper commands
GRASP_YAW = 0.0  # rad: fingers close along world x (across the rack, away from neighbouring tubes)

# select_apple
APPLE_HOVER_Z = 0.20  # m: TCP height above the apple before descending
APPLE_CARRY_Z = 0.23  # m: TCP height while carrying the apple
APPLE_RELEASE_CLEARANCE = 0.015  # m: apple bottom above the bowl's base when released
# select_chemistry_tube
TUBE_GRASP_BELOW_TOP = 0.02  # m: TCP this far below the tube's top when grasping
TUBE_HOVER_ABOVE_TOP = 0.08  # m: TCP this far above the tube's top before descending
TUBE_CARRY_LIFT = 0.17  # m: how far the tube is lifted out of the rack
TUBE_RELEASE_CLEARANCE = 0.012  # m: tube bottom above the holder's base when released
RETREAT_Z = 0.28  # m: TCP height after releasing


@dataclass(frozen=True)
class Waypoint:
    """One named TCP target of a plan.

    Args:
        name: phase name (for debugging and tests).
        xyz: TCP position, world frame, metres.
        yaw: rotation of the top-down gripper about world z, rad (see ``topdown_rotation``).
        gripper: gripper command at the end of the phase, 0 open .. 1 closed.
        steps: env steps taken to reach this waypoint from the previous one (>= 1).
    """

    name: str
    xyz: tuple[float, float, float]
    yaw: float
    gripper: float
    steps: int


def waypoint_action(xyz: np.ndarray, yaw: float, gripper: float) -> np.ndarray:
    """(ACTION_DIM,) float32 action for a top-down TCP target."""
    action = np.concatenate([xyz, rot6d_from_matrix(topdown_rotation(yaw)), [gripper]])
    return action.astype(np.float32)


def interpolate(start: Waypoint, waypoints: Sequence[Waypoint], step: int) -> np.ndarray:
    """Action at env step ``step`` (0-based) of a plan: linear in position, yaw and gripper between
    consecutive waypoints, each reached after its ``steps``; the last waypoint is held afterwards."""
    previous = start
    remaining = step + 1
    for waypoint in waypoints:
        if remaining <= waypoint.steps:
            t = remaining / waypoint.steps
            xyz = (1 - t) * np.asarray(previous.xyz) + t * np.asarray(waypoint.xyz)
            yaw = (1 - t) * previous.yaw + t * waypoint.yaw
            gripper = (1 - t) * previous.gripper + t * waypoint.gripper
            return waypoint_action(xyz, yaw, gripper)
        remaining -= waypoint.steps
        previous = waypoint
    return waypoint_action(np.asarray(previous.xyz), previous.yaw, previous.gripper)


def plan_length(waypoints: Sequence[Waypoint]) -> int:
    """Env steps until the last waypoint is reached."""
    return sum(w.steps for w in waypoints)


def _steps(a: Sequence[float], b: Sequence[float], speed: float) -> int:
    return max(MIN_MOVE_STEPS, math.ceil(float(np.linalg.norm(np.subtract(b, a))) / speed))


def _chain(
    start: Waypoint, moves: Sequence[tuple[str, Sequence[float], float, float | None]]
) -> list[Waypoint]:
    """Waypoints from (name, xyz, gripper, speed) moves; speed None = a gripper-only phase."""
    plan: list[Waypoint] = []
    previous = start
    for name, xyz, gripper, speed in moves:
        if speed is None:
            steps = GRIPPER_STEPS if gripper != previous.gripper else HOLD_STEPS
        else:
            steps = _steps(previous.xyz, xyz, speed)
        previous = Waypoint(name, tuple(float(v) for v in xyz), GRASP_YAW, gripper, steps)
        plan.append(previous)
    return plan


def pick_and_place_apple(env: OmniDEnv, start: Waypoint) -> list[Waypoint]:
    """select_apple: hover, descend around the apple, close, lift, carry over the bowl, lower, open."""
    positions = env.object_positions()
    ax, ay, az = positions["apple"]
    bx, by, bz = positions["bowl"]
    release_z = bz + BOWL_BASE_THICKNESS + APPLE_RELEASE_CLEARANCE + APPLE_RADIUS
    return _chain(
        start,
        [
            ("hover_apple", (ax, ay, APPLE_HOVER_Z), OPEN, TRAVEL_SPEED),
            ("descend", (ax, ay, az), OPEN, APPROACH_SPEED),
            ("close", (ax, ay, az), CLOSED, None),
            ("hold", (ax, ay, az), CLOSED, None),
            ("lift", (ax, ay, APPLE_CARRY_Z), CLOSED, APPROACH_SPEED),
            ("carry", (bx, by, APPLE_CARRY_Z), CLOSED, TRAVEL_SPEED),
            ("lower", (bx, by, release_z), CLOSED, APPROACH_SPEED),
            ("open", (bx, by, release_z), OPEN, None),
            ("retreat", (bx, by, RETREAT_Z), OPEN, TRAVEL_SPEED),
        ],
    )


def pick_and_place_tube(env: OmniDEnv, start: Waypoint) -> list[Waypoint]:
    """select_chemistry_tube: grasp the named tube near its top, pull it out, carry, lower into the holder."""
    positions = env.object_positions()
    tx, ty, tz = positions["target_tube"]
    hx, hy, hz = positions["holder"]
    grasp_z = tz + TUBE_LENGTH / 2 - TUBE_GRASP_BELOW_TOP
    carry_z = grasp_z + TUBE_CARRY_LIFT
    tcp_above_bottom = TUBE_LENGTH - TUBE_GRASP_BELOW_TOP
    release_z = hz + HOLDER_BASE_TOP + TUBE_RELEASE_CLEARANCE + tcp_above_bottom
    hover_z = tz + TUBE_LENGTH / 2 + TUBE_HOVER_ABOVE_TOP + FINGER_TIP_BEYOND_TCP
    return _chain(
        start,
        [
            ("hover_tube", (tx, ty, hover_z), OPEN, TRAVEL_SPEED),
            ("descend", (tx, ty, grasp_z), OPEN, APPROACH_SPEED),
            ("close", (tx, ty, grasp_z), CLOSED, None),
            ("hold", (tx, ty, grasp_z), CLOSED, None),
            ("lift", (tx, ty, carry_z), CLOSED, APPROACH_SPEED),
            ("carry", (hx, hy, carry_z), CLOSED, TRAVEL_SPEED),
            ("lower", (hx, hy, release_z), CLOSED, APPROACH_SPEED),
            ("open", (hx, hy, release_z), OPEN, None),
            ("retreat", (hx, hy, RETREAT_Z), OPEN, TRAVEL_SPEED),
        ],
    )


PLANNERS: MappingProxyType[str, Callable[[OmniDEnv, Waypoint], list[Waypoint]]] = MappingProxyType(
    {"select_apple": pick_and_place_apple, "select_chemistry_tube": pick_and_place_tube}
)


class ScriptedExpert:
    """Replays a waypoint plan: ``act()`` returns the interpolated action of the next env step."""

    def __init__(self, start: Waypoint, waypoints: Sequence[Waypoint]) -> None:
        self.start = start
        self.waypoints = tuple(waypoints)
        self._step = 0

    def act(self) -> np.ndarray:
        """(ACTION_DIM,) float32 action for the next env step."""
        action = interpolate(self.start, self.waypoints, self._step)
        self._step += 1
        return action

    def __len__(self) -> int:
        return plan_length(self.waypoints)


def make_expert(env: OmniDEnv) -> ScriptedExpert:
    """Plan an expert for the episode just reset in ``env`` (the unwrapped :class:`OmniDEnv`)."""
    tcp_xyz, _ = env.tcp_pose()
    start = Waypoint("start", tuple(float(v) for v in tcp_xyz), GRASP_YAW, OPEN, 1)
    plan = PLANNERS[env.task](env, start)
    return ScriptedExpert(start, plan)


def run_expert_episode(env: gym.Env, seed: int, max_steps: int = MAX_EPISODE_STEPS) -> tuple[bool, int]:
    """Reset ``env`` (a gymnasium env, wrapped or not) with ``seed`` and run the expert until the episode
    ends; returns (success, env steps taken)."""
    env.reset(seed=seed)
    expert = make_expert(env.unwrapped)
    for step in range(1, max_steps + 1):
        _, _, terminated, truncated, info = env.step(expert.act())
        if terminated or truncated:
            return bool(info["is_success"]), step
    return False, max_steps
