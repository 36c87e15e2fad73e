"""add_condiment: pick up the condiment bottle and pour it over the pot."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from gym_omnid.tasks.base import Placement, Task, ring_wall_geoms, sample_layout, yaw_quat
from gym_omnid.waypoints import (
    APPROACH_SPEED,
    CLOSED,
    HOLD_STEPS,
    OPEN,
    TILT_SPEED,
    TRAVEL_SPEED,
    Waypoint,
    chain,
)

BOTTLE_RADIUS = 0.024  # m: radius of the bottle's body
BOTTLE_HALF_HEIGHT = 0.05  # m: half height of the body; the body frame sits at its centre
NECK_RADIUS = 0.011  # m
NECK_HALF_HEIGHT = 0.015  # m
CAP_RADIUS = 0.013  # m
CAP_HALF_HEIGHT = 0.008  # m
BOTTLE_MOUTH = BOTTLE_HALF_HEIGHT + 2 * NECK_HALF_HEIGHT + 2 * CAP_HALF_HEIGHT  # m: centre to cap top
BOTTLE_DENSITY = 400.0  # kg / m^3 (about 80 g: light enough to pour from a friction grasp)
POT_INNER_RADIUS = 0.09  # m
POT_WALL_THICKNESS = 0.008  # m
POT_BASE_THICKNESS = 0.008  # m
POT_RIM_HEIGHT = 0.09  # m: top of the wall above the table
POT_WALL_SEGMENTS = 16
POT_HANDLE_HALF = (0.02, 0.012, 0.006)  # m: half sizes of the two side handles
POUR_MIN_TILT = math.radians(75.0)  # rad: bottle axis from vertical that counts as pouring
POUR_STEPS = 5  # env steps (0.5 s) of sustained pouring that solve the task
DROP_GAP = 0.002  # m
# scripted expert
BOTTLE_GRASP_YAW = math.pi / 2  # rad: fingers close along world y, so the pouring tilt (about world x)
# turns the bottle against the pads' faces rather than about them
BOTTLE_HOVER_Z = 0.20  # m: TCP height above the bottle's centre before descending
POUR_TCP_Z = 0.22  # m: TCP height while carrying and pouring (bottle well above the pot's rim)
POUR_TILT = math.radians(110.0)  # rad: tilt of the gripper (and bottle) while pouring
POUR_EXTRA_STEPS = 3  # env steps held beyond POUR_STEPS

PLACEMENTS = (
    Placement("bottle", (0.45, 0.15), keepout=0.07),
    Placement("pot", (0.56, -0.14), keepout=0.12),
)


class AddCondiment(Task):
    """Pick up the condiment bottle and pour it over the pot.

    Key objects (following ``layout``): the bottle and the pot. Success: for ``POUR_STEPS`` consecutive
    env steps the bottle is held by the gripper (not dropped), tilted at least ``POUR_MIN_TILT`` from
    upright, with its mouth above the pot's rim and inside its inner radius. The count of consecutive
    pouring steps is the task's only per-episode state, reset with the episode.
    """

    name = "add_condiment"

    def __init__(self) -> None:
        self._pour_steps = 0

    def mjcf_assets(self) -> str:
        return """
    <material name="bottle" rgba="0.9 0.75 0.2 1" specular="0.5" shininess="0.7"/>
    <material name="bottle_cap" rgba="0.8 0.1 0.08 1"/>
    <material name="pot" rgba="0.3 0.32 0.35 1" specular="0.6" shininess="0.8"/>"""

    def mjcf_bodies(self) -> str:
        neck_z = BOTTLE_HALF_HEIGHT + NECK_HALF_HEIGHT
        cap_z = BOTTLE_HALF_HEIGHT + 2 * NECK_HALF_HEIGHT + CAP_HALF_HEIGHT
        walls = ring_wall_geoms(
            POT_INNER_RADIUS,
            POT_WALL_THICKNESS,
            (POT_BASE_THICKNESS, POT_RIM_HEIGHT),
            POT_WALL_SEGMENTS,
            "pot",
        )
        handle_y = POT_INNER_RADIUS + POT_WALL_THICKNESS + POT_HANDLE_HALF[1]
        handle_z = POT_RIM_HEIGHT - 2 * POT_HANDLE_HALF[2]
        hx, hy, hz = POT_HANDLE_HALF
        return f"""
    <body name="bottle" pos="0.45 0.15 {BOTTLE_HALF_HEIGHT}">
      <freejoint name="bottle"/>
      <geom class="object" type="cylinder" size="{BOTTLE_RADIUS} {BOTTLE_HALF_HEIGHT}" material="bottle"
            density="{BOTTLE_DENSITY}" condim="4"/>
      <geom class="object" type="cylinder" size="{NECK_RADIUS} {NECK_HALF_HEIGHT}" pos="0 0 {neck_z}"
            material="bottle" density="{BOTTLE_DENSITY}"/>
      <geom class="object" type="cylinder" size="{CAP_RADIUS} {CAP_HALF_HEIGHT}" pos="0 0 {cap_z}"
            material="bottle_cap" density="{BOTTLE_DENSITY}"/>
      <geom class="decor" type="cylinder" size="{BOTTLE_RADIUS + 0.0008} 0.02" pos="0 0 -0.005"
            rgba="0.95 0.95 0.9 1"/>
    </body>
    <body name="pot" mocap="true" pos="0.56 -0.14 0">
      <geom class="fixture" type="cylinder" material="pot"
            size="{POT_INNER_RADIUS + POT_WALL_THICKNESS} {POT_BASE_THICKNESS / 2}"
            pos="0 0 {POT_BASE_THICKNESS / 2}"/>
        {walls}
      <geom class="fixture" type="box" material="pot" size="{hx} {hy} {hz}" pos="0 {handle_y} {handle_z}"/>
      <geom class="fixture" type="box" material="pot" size="{hx} {hy} {hz}" pos="0 {-handle_y} {handle_z}"/>
      <geom class="decor" type="cylinder" size="{POT_INNER_RADIUS} 0.001" pos="0 0 0.04"
            rgba="0.75 0.45 0.2 1"/>
    </body>"""

    def bind(self, model: mujoco.MjModel) -> None:
        super().bind(model)
        self._bottle = self._body_id("bottle")
        self._pot = self._body_id("pot")

    def reset(self, data: mujoco.MjData, rng: np.random.Generator, layout: str) -> None:
        xy = sample_layout(rng, PLACEMENTS, layout)
        yaw = rng.uniform(-math.pi, math.pi)
        self._set_free_pose(
            data, "bottle", np.array([*xy["bottle"], BOTTLE_HALF_HEIGHT + DROP_GAP]), yaw_quat(yaw)
        )
        self._set_mocap_xy(data, "pot", xy["pot"])
        self._pour_steps = 0

    @property
    def description(self) -> str:
        return "pour the condiment into the pot"

    def mouth_xyz(self, data: mujoco.MjData) -> np.ndarray:
        """World xyz (3,) of the centre of the bottle's cap top (its mouth), metres."""
        return data.xpos[self._bottle] + data.xmat[self._bottle].reshape(3, 3)[:, 2] * BOTTLE_MOUTH

    def is_pouring(self, data: mujoco.MjData) -> bool:
        """Held, tilted past ``POUR_MIN_TILT``, mouth above the rim and within the pot's inner radius."""
        mouth = self.mouth_xyz(data)
        over_pot = np.linalg.norm(mouth[:2] - data.xpos[self._pot][:2]) < POT_INNER_RADIUS
        return bool(
            over_pot
            and mouth[2] > POT_RIM_HEIGHT
            and self._tilt(data, "bottle") > POUR_MIN_TILT
            and self._touches_gripper(data, "bottle")
        )

    def after_step(self, data: mujoco.MjData) -> None:
        self._pour_steps = self._pour_steps + 1 if self.is_pouring(data) else 0

    def is_success(self, data: mujoco.MjData) -> bool:
        return self._pour_steps >= POUR_STEPS

    def object_positions(self, data: mujoco.MjData) -> dict[str, np.ndarray]:
        return {"bottle": data.xpos[self._bottle].copy(), "pot": data.xpos[self._pot].copy()}

    def plan_expert(self, data: mujoco.MjData, start: Waypoint) -> list[Waypoint]:
        """Grasp the bottle's body, lift, carry beside the pot's centre, tilt so the mouth comes over the
        centre, hold the pour, tilt back."""
        positions = self.object_positions(data)
        bx, by, bz = positions["bottle"]
        px, py, _ = positions["pot"]
        # The mouth lies BOTTLE_MOUTH from the grasp point (the bottle's centre) along the bottle's axis,
        # which the tilt turns toward world -y: hold the TCP that far on the +y side of the pot's centre.
        pour_xyz = (px, py + BOTTLE_MOUTH * math.sin(POUR_TILT), POUR_TCP_Z)
        plan = chain(
            start,
            [
                ("hover_bottle", (bx, by, BOTTLE_HOVER_Z), OPEN, TRAVEL_SPEED),
                ("descend", (bx, by, bz), OPEN, APPROACH_SPEED),
                ("close", (bx, by, bz), CLOSED, None),
                ("hold", (bx, by, bz), CLOSED, None),
                ("lift", (bx, by, POUR_TCP_Z), CLOSED, APPROACH_SPEED),
                ("carry", pour_xyz, CLOSED, TRAVEL_SPEED),
            ],
            BOTTLE_GRASP_YAW,
        )
        tilt_steps = math.ceil(POUR_TILT / TILT_SPEED)
        return [
            *plan,
            Waypoint("tilt", pour_xyz, BOTTLE_GRASP_YAW, CLOSED, tilt_steps, POUR_TILT),
            Waypoint("pour", pour_xyz, BOTTLE_GRASP_YAW, CLOSED, POUR_STEPS + POUR_EXTRA_STEPS, POUR_TILT),
            Waypoint("untilt", pour_xyz, BOTTLE_GRASP_YAW, CLOSED, tilt_steps + HOLD_STEPS),
        ]
