"""The MJCF scene built in code: floor, table with a swappable texture, the arm, five cameras, a task.

The five fixed cameras are placed by a rig (:mod:`gym_omnid.rigs`); the wrist camera is part of the
arm (:mod:`gym_omnid.robot`).

Rendering cost is kept low on purpose: primitives only, no shadows, no multisampling, and an offscreen
buffer exactly the size of the observation images.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import NamedTuple

from gym_omnid.calibration import look_at_xyaxes
from gym_omnid.constants import (
    CAMERA_FOVY,
    CAMERAS,
    PHYSICS_TIMESTEP,
    RENDER_NUM_QUADS,
    RENDER_NUM_SLICES,
    RENDER_NUM_STACKS,
    TABLE_HEIGHT,
    TABLE_TEXTURE_SIZE,
    TABLE_THICKNESS,
    TABLE_X_RANGE,
    TABLE_Y_HALF,
)
from gym_omnid.robot import arm_actuators, arm_defaults, arm_worldbody
from gym_omnid.tasks.base import Task

TABLE_TEXTURE = "table"
TABLE_LEG_HALF = 0.03  # m: half side of a table leg
ROOM_HALF = 2.5  # m: half side of the room around the table
WALL_HEIGHT = 3.0  # m: wall height above the floor
WALL_THICKNESS = 0.05  # m: half thickness of the floor and wall boxes
# Camera placements of the default rig: (position, point looked at), world frame, metres. B-E look at
# the workspace from the front, both sides and over the robot's shoulder at similar heights; A is a
# steep top view.
CAMERA_POSES = MappingProxyType(
    {
        "cam_a": ((0.30, -0.28, 1.18), (0.55, 0.0, 0.0)),
        "cam_b": ((1.35, 0.0, 0.55), (0.52, 0.0, 0.05)),
        "cam_c": ((0.55, 0.82, 0.52), (0.54, 0.0, 0.05)),
        "cam_d": ((0.55, -0.82, 0.52), (0.54, 0.0, 0.05)),
        "cam_e": ((-0.12, 0.62, 0.62), (0.55, 0.0, 0.05)),
    }
)


class CameraPlacement(NamedTuple):
    """Where a fixed camera stands and what it looks at, world frame.

    Args:
        position: camera centre (x, y, z), metres.
        target: a point on its optical axis, metres.
        roll_deg: turn about the optical axis from the upright view, degrees (see ``look_at_xyaxes``).
    """

    position: tuple[float, float, float]
    target: tuple[float, float, float]
    roll_deg: float = 0.0


def _cameras(placements: Mapping[str, CameraPlacement]) -> str:
    lines = []
    for name in CAMERAS:
        position, target, roll_deg = placements[name]
        xyaxes = " ".join(f"{v:.6f}" for v in look_at_xyaxes(position, target, roll_deg))
        pos = " ".join(f"{v}" for v in position)
        lines.append(
            f'<camera name="{name}" mode="fixed" pos="{pos}" xyaxes="{xyaxes}" fovy="{CAMERA_FOVY}"/>'
        )
    return "\n    ".join(lines)


def _room() -> str:
    """Floor and four walls. Plain boxes: a plane (drawn as a grid) and a textured skybox cost a
    third of the software-rendering time."""
    walls = "\n    ".join(
        f'<geom class="decor" type="box" size="{sx} {sy} {WALL_HEIGHT / 2}" '
        f'pos="{px} {py} {WALL_HEIGHT / 2 - TABLE_HEIGHT}" material="wall"/>'
        for sx, sy, px, py in (
            (WALL_THICKNESS, ROOM_HALF, ROOM_HALF, 0.0),
            (WALL_THICKNESS, ROOM_HALF, -ROOM_HALF, 0.0),
            (ROOM_HALF, WALL_THICKNESS, 0.0, ROOM_HALF),
            (ROOM_HALF, WALL_THICKNESS, 0.0, -ROOM_HALF),
        )
    )
    return f"""<geom name="floor" class="fixture" type="box" size="{ROOM_HALF} {ROOM_HALF} {WALL_THICKNESS}"
          pos="0 0 {-TABLE_HEIGHT - WALL_THICKNESS}" material="floor"/>
    {walls}"""


def _table() -> str:
    x_lo, x_hi = TABLE_X_RANGE
    cx, half_x = (x_lo + x_hi) / 2, (x_hi - x_lo) / 2
    leg_half_h = (TABLE_HEIGHT - TABLE_THICKNESS) / 2
    legs = "\n    ".join(
        f'<geom class="decor" type="box" size="{TABLE_LEG_HALF} {TABLE_LEG_HALF} {leg_half_h}" '
        f'pos="{x:.3f} {y:.3f} {-TABLE_THICKNESS - leg_half_h}" rgba="0.3 0.25 0.2 1"/>'
        for x in (x_lo + 0.06, x_hi - 0.06)
        for y in (-TABLE_Y_HALF + 0.06, TABLE_Y_HALF - 0.06)
    )
    return f"""
    <geom name="table_top" class="fixture" type="box" material="{TABLE_TEXTURE}"
          size="{half_x} {TABLE_Y_HALF} {TABLE_THICKNESS / 2}" pos="{cx} 0 {-TABLE_THICKNESS / 2}"/>
    {legs}"""


def build_mjcf(task: Task, image_size: tuple[int, int], placements: Mapping[str, CameraPlacement]) -> str:
    """Full MJCF of the scene for ``task``, the fixed cameras at ``placements`` (one per ``CAMERAS``),
    with an offscreen buffer of ``image_size`` = (height, width)."""
    height, width = image_size
    return f"""
<mujoco model="omnid_{task.name}">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{PHYSICS_TIMESTEP}" integrator="implicitfast" cone="elliptic" impratio="10"/>
  <visual>
    <global offwidth="{width}" offheight="{height}"/>
    <quality shadowsize="0" offsamples="0" numslices="{RENDER_NUM_SLICES}" numstacks="{RENDER_NUM_STACKS}"
             numquads="{RENDER_NUM_QUADS}"/>
    <headlight ambient="0.35 0.35 0.35" diffuse="0.35 0.35 0.35" specular="0.05 0.05 0.05"/>
  </visual>
  <default>
    <default class="object">
      <geom contype="1" conaffinity="1" friction="1.0 0.01 0.001"/>
    </default>
    <default class="fixture">
      <geom contype="1" conaffinity="1" friction="0.8 0.01 0.001"/>
    </default>
    <default class="decor">
      <geom contype="0" conaffinity="0" density="0"/>
    </default>
    {arm_defaults()}
  </default>
  <asset>
    <texture name="{TABLE_TEXTURE}" type="2d" builtin="flat" rgb1="0.77 0.63 0.46"
             width="{TABLE_TEXTURE_SIZE}" height="{TABLE_TEXTURE_SIZE}"/>
    <material name="{TABLE_TEXTURE}" texture="{TABLE_TEXTURE}" texrepeat="1 1"/>
    <material name="floor" rgba="0.45 0.45 0.47 1"/>
    <material name="wall" rgba="0.66 0.7 0.74 1"/>
    {task.mjcf_assets()}
  </asset>
  <worldbody>
    <light name="sun" directional="true" pos="0.5 0 3" dir="0.1 0.1 -1" castshadow="false"
           diffuse="0.55 0.55 0.55" specular="0.1 0.1 0.1"/>
    {_room()}
    {_table()}
    {_cameras(placements)}
    {arm_worldbody()}
    {task.mjcf_bodies()}
  </worldbody>
  <actuator>
    {arm_actuators()}
  </actuator>
</mujoco>"""
