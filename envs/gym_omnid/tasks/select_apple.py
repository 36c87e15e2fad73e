"""select_apple: put the apple (among distractor fruits) into the bowl."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from gym_omnid.tasks.base import Placement, Task, ring_wall_geoms, sample_layout, yaw_quat
from gym_omnid.waypoints import Waypoint, pick_and_place

APPLE_RADIUS = 0.035  # m
ORANGE_RADIUS = 0.037  # m
LEMON_HALF = (0.042, 0.03, 0.03)  # m: ellipsoid semi-axes
BANANA_RADIUS = 0.017  # m
BANANA_SEGMENT = 0.065  # m: length of each of the banana's two capsule segments
BANANA_BEND = 0.35  # rad: angle of each segment away from the banana's axis
BOWL_INNER_RADIUS = 0.085  # m
BOWL_WALL_THICKNESS = 0.008  # m
BOWL_RIM_HEIGHT = 0.055  # m: top of the wall above the table
BOWL_BASE_THICKNESS = 0.008  # m
BOWL_WALL_SEGMENTS = 16
DROP_GAP = 0.002  # m: objects are placed this far above their support and settle at reset
FRUIT_DENSITY = 700.0  # kg / m^3
# scripted expert
APPLE_HOVER_Z = 0.20  # m: TCP height above the apple before descending
APPLE_CARRY_Z = 0.23  # m: TCP height while carrying the apple
APPLE_RELEASE_CLEARANCE = 0.015  # m: apple bottom above the bowl's base when released

PLACEMENTS = (
    Placement("apple", (0.55, 0.12), keepout=0.07),
    Placement("bowl", (0.50, -0.17), keepout=0.105),
    Placement("orange", (0.68, -0.02), keepout=0.045, key=False),
    Placement("lemon", (0.40, 0.02), keepout=0.05, key=False),
    Placement("banana", (0.68, 0.25), keepout=0.08, key=False),
)
DISTRACTORS = ("orange", "lemon", "banana")


class SelectApple(Task):
    """Pick the apple among an orange, a lemon and a banana and place it in the bowl.

    Key objects (following ``layout``): the apple and the bowl. Success: the apple's centre lies
    within the bowl's inner radius, below the rim, resting, and released by the gripper.
    """

    name = "select_apple"

    def mjcf_assets(self) -> str:
        return """
    <material name="apple" rgba="0.78 0.06 0.06 1" specular="0.4" shininess="0.6"/>
    <material name="orange" rgba="1.0 0.55 0.05 1" specular="0.2"/>
    <material name="lemon" rgba="0.98 0.92 0.25 1" specular="0.3"/>
    <material name="banana" rgba="0.93 0.82 0.35 1"/>
    <material name="bowl" rgba="0.82 0.88 0.95 1" specular="0.5" shininess="0.8"/>"""

    def mjcf_bodies(self) -> str:
        seg_dx = BANANA_SEGMENT * math.cos(BANANA_BEND)
        seg_dy = BANANA_SEGMENT * math.sin(BANANA_BEND)
        walls = ring_wall_geoms(
            BOWL_INNER_RADIUS,
            BOWL_WALL_THICKNESS,
            (BOWL_BASE_THICKNESS, BOWL_RIM_HEIGHT),
            BOWL_WALL_SEGMENTS,
            "bowl",
        )
        return f"""
    <body name="apple" pos="0.55 0.12 {APPLE_RADIUS}">
      <freejoint name="apple"/>
      <geom name="apple" class="object" type="sphere" size="{APPLE_RADIUS}" material="apple"
            density="{FRUIT_DENSITY}"/>
      <geom class="decor" type="capsule" size="0.003 0.008" pos="0 0 {APPLE_RADIUS + 0.004}"
            euler="0.2 0 0" rgba="0.35 0.2 0.08 1"/>
      <geom class="decor" type="ellipsoid" size="0.012 0.005 0.002" pos="0.01 0 {APPLE_RADIUS + 0.006}"
            euler="0 -0.35 0" rgba="0.2 0.55 0.15 1"/>
    </body>
    <body name="orange" pos="0.68 -0.02 {ORANGE_RADIUS}">
      <freejoint name="orange"/>
      <geom class="object" type="sphere" size="{ORANGE_RADIUS}" material="orange" density="{FRUIT_DENSITY}"/>
    </body>
    <body name="lemon" pos="0.4 0.02 {LEMON_HALF[2]}">
      <freejoint name="lemon"/>
      <geom class="object" type="ellipsoid" size="{LEMON_HALF[0]} {LEMON_HALF[1]} {LEMON_HALF[2]}"
            material="lemon" density="{FRUIT_DENSITY}"/>
    </body>
    <body name="banana" pos="0.68 0.25 {BANANA_RADIUS}">
      <freejoint name="banana"/>
      <geom class="object" type="capsule" size="{BANANA_RADIUS}" material="banana" density="{FRUIT_DENSITY}"
            fromto="{-seg_dx:.4f} {seg_dy:.4f} 0 0 0 0"/>
      <geom class="object" type="capsule" size="{BANANA_RADIUS}" material="banana" density="{FRUIT_DENSITY}"
            fromto="0 0 0 {seg_dx:.4f} {seg_dy:.4f} 0"/>
    </body>
    <body name="bowl" mocap="true" pos="0.5 -0.17 0">
      <geom class="fixture" type="cylinder" material="bowl"
            size="{BOWL_INNER_RADIUS + BOWL_WALL_THICKNESS} {BOWL_BASE_THICKNESS / 2}"
            pos="0 0 {BOWL_BASE_THICKNESS / 2}"/>
        {walls}
    </body>"""

    def bind(self, model: mujoco.MjModel) -> None:
        super().bind(model)
        self._apple = self._body_id("apple")
        self._bowl = self._body_id("bowl")

    def reset(self, data: mujoco.MjData, rng: np.random.Generator, layout: str) -> None:
        xy = sample_layout(rng, PLACEMENTS, layout)
        rest_height = {
            "apple": APPLE_RADIUS,
            "orange": ORANGE_RADIUS,
            "lemon": LEMON_HALF[2],
            "banana": BANANA_RADIUS,
        }
        for name, height in rest_height.items():
            yaw = rng.uniform(-math.pi, math.pi)
            self._set_free_pose(data, name, np.array([*xy[name], height + DROP_GAP]), yaw_quat(yaw))
        self._set_mocap_xy(data, "bowl", xy["bowl"])

    @property
    def description(self) -> str:
        return "put the apple in the bowl"

    def is_success(self, data: mujoco.MjData) -> bool:
        apple_xyz = data.xpos[self._apple]
        bowl_xyz = data.xpos[self._bowl]
        inside = np.linalg.norm(apple_xyz[:2] - bowl_xyz[:2]) < BOWL_INNER_RADIUS
        below_rim = apple_xyz[2] < BOWL_RIM_HEIGHT
        return bool(
            inside
            and below_rim
            and self._is_resting(data, "apple")
            and not self._touches_gripper(data, "apple")
        )

    def object_positions(self, data: mujoco.MjData) -> dict[str, np.ndarray]:
        return {name: data.xpos[self._body_id(name)].copy() for name in ("apple", "bowl", *DISTRACTORS)}

    def plan_expert(self, data: mujoco.MjData, start: Waypoint) -> list[Waypoint]:
        """Hover, descend around the apple, close, lift, carry over the bowl, lower, open."""
        positions = self.object_positions(data)
        ax, ay, az = positions["apple"]
        bx, by, bz = positions["bowl"]
        release_z = bz + BOWL_BASE_THICKNESS + APPLE_RELEASE_CLEARANCE + APPLE_RADIUS
        return pick_and_place(
            start, (ax, ay), APPLE_HOVER_Z, az, APPLE_CARRY_Z, (bx, by), release_z, hover_name="hover_apple"
        )
