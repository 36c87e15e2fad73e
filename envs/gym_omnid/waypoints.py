"""Waypoint plans of the scripted experts: the data type, plan building, and one pure interpolation.

Each waypoint holds a TCP position, a yaw of the top-down gripper, a tilt about world x (pouring) and
a gripper command; the action between two waypoints is linear in all of them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gym_omnid.rotations import rot6d_from_matrix, tilted_rotation

TRAVEL_SPEED = 0.03  # m per env step (0.3 m/s) for moves in free space
APPROACH_SPEED = 0.015  # m per env step for moves near objects (descend, lift, lower)
TILT_SPEED = 0.16  # rad per env step for tilting a held object
MIN_MOVE_STEPS = 3  # env steps: shortest move
GRIPPER_STEPS = 4  # env steps to close or open the gripper
HOLD_STEPS = 2  # env steps of waiting for a grasp to settle
OPEN, CLOSED = 0.0, 1.0  # gripper commands
GRASP_YAW = 0.0  # rad: yaw of every plan's start and of plain top-down grasps: fingers close along world x
RETREAT_Z = 0.28  # m: TCP height after releasing

# One move of a plan: (name, TCP xyz, gripper command, speed in m per env step); speed None makes a
# gripper-only phase that stays in place (GRIPPER_STEPS when the command changes, else HOLD_STEPS).
Move = tuple[str, Sequence[float], float, float | None]


@dataclass(frozen=True)
class Waypoint:
    """One named TCP target of a plan.

    Args:
        name: phase name (for debugging and tests).
        xyz: TCP position, world frame, metres.
        yaw: rotation of the top-down gripper about world z, rad (see ``topdown_rotation``).
        gripper: gripper command at the end of the phase, 0 open .. 1 closed.
        steps: env steps taken to reach this waypoint from the previous one (>= 1).
        tilt: rotation of the gripper about world x after the yaw, rad (see ``tilted_rotation``).
    """

    name: str
    xyz: tuple[float, float, float]
    yaw: float
    gripper: float
    steps: int
    tilt: float = 0.0


def waypoint_action(xyz: np.ndarray, yaw: float, gripper: float, tilt: float = 0.0) -> np.ndarray:
    """(ACTION_DIM,) float32 action for a TCP target, top-down with ``yaw``, tilted by ``tilt``."""
    action = np.concatenate([xyz, rot6d_from_matrix(tilted_rotation(yaw, tilt)), [gripper]])
    return action.astype(np.float32)


def interpolate(start: Waypoint, waypoints: Sequence[Waypoint], step: int) -> np.ndarray:
    """Action at env step ``step`` (0-based) of a plan: linear in position, yaw, tilt and gripper between
    consecutive waypoints, each reached after its ``steps``; the last waypoint is held afterwards."""
    previous = start
    remaining = step + 1
    for waypoint in waypoints:
        if remaining <= waypoint.steps:
            t = remaining / waypoint.steps
            xyz = (1 - t) * np.asarray(previous.xyz) + t * np.asarray(waypoint.xyz)
            yaw = (1 - t) * previous.yaw + t * waypoint.yaw
            tilt = (1 - t) * previous.tilt + t * waypoint.tilt
            gripper = (1 - t) * previous.gripper + t * waypoint.gripper
            return waypoint_action(xyz, yaw, gripper, tilt)
        remaining -= waypoint.steps
        previous = waypoint
    return waypoint_action(np.asarray(previous.xyz), previous.yaw, previous.gripper, previous.tilt)


def plan_length(waypoints: Sequence[Waypoint]) -> int:
    """Env steps until the last waypoint is reached."""
    return sum(w.steps for w in waypoints)


def move_steps(a: Sequence[float], b: Sequence[float], speed: float) -> int:
    """Env steps of a straight move from ``a`` to ``b`` at ``speed`` (m per step), >= MIN_MOVE_STEPS."""
    return max(MIN_MOVE_STEPS, math.ceil(float(np.linalg.norm(np.subtract(b, a))) / speed))


def chain(start: Waypoint, moves: Sequence[Move], yaw: float, tilt: float = 0.0) -> list[Waypoint]:
    """Waypoints of ``moves`` after ``start``, all at ``yaw`` and ``tilt`` (the first move turns the
    gripper from the start's orientation)."""
    plan: list[Waypoint] = []
    previous = start
    for name, xyz, gripper, speed in moves:
        if speed is None:
            steps = GRIPPER_STEPS if gripper != previous.gripper else HOLD_STEPS
        else:
            steps = move_steps(previous.xyz, xyz, speed)
        previous = Waypoint(name, (float(xyz[0]), float(xyz[1]), float(xyz[2])), yaw, gripper, steps, tilt)
        plan.append(previous)
    return plan


def pick_and_place(
    start: Waypoint,
    pick_xy: tuple[float, float],
    hover_z: float,
    grasp_z: float,
    carry_z: float,
    place_xy: tuple[float, float],
    release_z: float,
    hover_name: str,
) -> list[Waypoint]:
    """The plan of a top-down grasp carried to a place: hover over the object, descend, close and hold,
    lift to ``carry_z``, carry, lower to ``release_z``, open and retreat (heights in metres, TCP)."""
    (px, py), (qx, qy) = pick_xy, place_xy
    return chain(
        start,
        [
            (hover_name, (px, py, hover_z), OPEN, TRAVEL_SPEED),
            ("descend", (px, py, grasp_z), OPEN, APPROACH_SPEED),
            ("close", (px, py, grasp_z), CLOSED, None),
            ("hold", (px, py, grasp_z), CLOSED, None),
            ("lift", (px, py, carry_z), CLOSED, APPROACH_SPEED),
            ("carry", (qx, qy, carry_z), CLOSED, TRAVEL_SPEED),
            ("lower", (qx, qy, release_z), CLOSED, APPROACH_SPEED),
            ("open", (qx, qy, release_z), OPEN, None),
            ("retreat", (qx, qy, RETREAT_Z), OPEN, TRAVEL_SPEED),
        ],
        GRASP_YAW,
    )
