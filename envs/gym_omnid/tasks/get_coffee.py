"""get_coffee: put the mug under the coffee machine's spout, then press the machine's button."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from gym_omnid.robot import FINGER_TIP_BEYOND_TCP
from gym_omnid.tasks.base import Placement, Task, sample_layout, yaw_quat
from gym_omnid.waypoints import APPROACH_SPEED, CLOSED, OPEN, TRAVEL_SPEED, Waypoint, chain

MUG_RADIUS = 0.035  # m
MUG_HALF_HEIGHT = 0.045  # m: the mug's body frame sits at its centre
MUG_DENSITY = 300.0  # kg / m^3 (a solid cylinder standing in for an empty mug)
# Machine frame: origin on the table under the spout's axis, x pointing away from the robot (the
# machine faces the robot), z up.
TRAY_HALF = (0.08, 0.08, 0.01)  # m: drip tray (half sizes); the mug stands on it
TRAY_TOP = 2 * TRAY_HALF[2]  # m
COLUMN_HALF = (0.035, 0.08, 0.14)  # m: back column
COLUMN_FRONT_X = 0.06  # m: front face of the column behind the spout
HEAD_HALF = (0.075, 0.065, 0.03)  # m: head overhanging the tray from the column's top
HEAD_TOP = 2 * COLUMN_HALF[2]  # m: the head's top is flush with the column's
SPOUT_RADIUS = 0.01  # m
SPOUT_HALF_LENGTH = 0.015  # m
BUTTON_X = 0.02  # m: the button sits on the head's top, above and behind the spout
BUTTON_RADIUS = 0.018  # m
BUTTON_HALF_HEIGHT = 0.008  # m
BUTTON_TRAVEL = 0.012  # m: depth from rest to the joint's stop
BUTTON_STIFFNESS = 300.0  # N / m: return spring
BUTTON_DAMPING = 3.0  # N s / m
BUTTON_PRESSED = 0.008  # m: depth that counts as a press
UNDER_SPOUT_TOL = 0.02  # m: mug axis within this distance of the spout's axis
MUG_MAX_TILT = math.radians(15.0)  # rad: the mug stands upright
MUG_MAX_LIFT = 0.01  # m: mug bottom at most this far above the tray (it stands on it)
DROP_GAP = 0.002  # m
# scripted expert
MUG_GRASP_YAW = math.pi / 2  # rad: fingers close along world y, beside the machine's column
MUG_HOVER_Z = 0.20  # m: TCP height above the mug before descending
MUG_CARRY_LIFT = 0.02  # m: mug bottom above the drip tray while carried under the machine's head
MACHINE_FRONT = 0.10  # m: the mug is slid in from this far in front of the spout (robot side)
MUG_RELEASE_CLEARANCE = 0.004  # m: mug bottom above the tray when released
PRESS_HOVER_ABOVE = 0.08  # m: fingertips this far above the button before pressing
PRESS_OVERTRAVEL = 0.004  # m: fingertips aimed this far below the button's stop
PRESS_SPEED = 0.008  # m per env step while pressing

PLACEMENTS = (
    Placement("mug", (0.42, 0.13), keepout=0.075),
    Placement("machine", (0.58, -0.13), keepout=0.13),
)


class GetCoffee(Task):
    """Take the mug, set it on the coffee machine's tray under the spout and press the button on top.

    Key objects (following ``layout``): the mug and the machine. The button is a spring-loaded slide
    joint pressed from above. Success: the button is pressed at least ``BUTTON_PRESSED`` while the mug
    stands upright on the tray with its axis within ``UNDER_SPOUT_TOL`` of the spout's, released.
    """

    name = "get_coffee"

    def mjcf_assets(self) -> str:
        return """
    <material name="mug" rgba="0.92 0.92 0.88 1" specular="0.4" shininess="0.6"/>
    <material name="machine" rgba="0.12 0.12 0.14 1" specular="0.4"/>
    <material name="machine_trim" rgba="0.7 0.72 0.75 1" specular="0.7" shininess="0.9"/>
    <material name="button" rgba="0.1 0.75 0.25 1"/>"""

    def mjcf_bodies(self) -> str:
        column_x = COLUMN_FRONT_X + COLUMN_HALF[0]
        head_x = COLUMN_FRONT_X + 2 * COLUMN_HALF[0] - HEAD_HALF[0]
        head_z = HEAD_TOP - HEAD_HALF[2]
        spout_z = HEAD_TOP - 2 * HEAD_HALF[2] - SPOUT_HALF_LENGTH
        tray_x = COLUMN_FRONT_X - TRAY_HALF[0]
        return f"""
    <body name="mug" pos="0.42 0.13 {MUG_HALF_HEIGHT}">
      <freejoint name="mug"/>
      <geom class="object" type="cylinder" size="{MUG_RADIUS} {MUG_HALF_HEIGHT}" material="mug"
            density="{MUG_DENSITY}" condim="4"/>
      <geom class="decor" type="cylinder" size="{MUG_RADIUS - 0.005} 0.001" pos="0 0 {MUG_HALF_HEIGHT}"
            rgba="0.25 0.15 0.1 1"/>
      <geom class="decor" type="capsule" size="0.006" material="mug"
            fromto="{MUG_RADIUS} 0 0.025 {MUG_RADIUS + 0.02} 0 0.012"/>
      <geom class="decor" type="capsule" size="0.006" material="mug"
            fromto="{MUG_RADIUS + 0.02} 0 0.012 {MUG_RADIUS + 0.02} 0 -0.015"/>
      <geom class="decor" type="capsule" size="0.006" material="mug"
            fromto="{MUG_RADIUS + 0.02} 0 -0.015 {MUG_RADIUS} 0 -0.025"/>
    </body>
    <body name="machine" mocap="true" pos="0.58 -0.13 0">
      <geom class="fixture" type="box" material="machine_trim"
            size="{TRAY_HALF[0]} {TRAY_HALF[1]} {TRAY_HALF[2]}" pos="{tray_x} 0 {TRAY_HALF[2]}"/>
      <geom class="fixture" type="box" material="machine"
            size="{COLUMN_HALF[0]} {COLUMN_HALF[1]} {COLUMN_HALF[2]}" pos="{column_x} 0 {COLUMN_HALF[2]}"/>
      <geom class="fixture" type="box" material="machine" size="{HEAD_HALF[0]} {HEAD_HALF[1]} {HEAD_HALF[2]}"
            pos="{head_x} 0 {head_z}"/>
      <geom class="fixture" type="cylinder" material="machine_trim" size="{SPOUT_RADIUS} {SPOUT_HALF_LENGTH}"
            pos="0 0 {spout_z}"/>
      <body name="button" pos="{BUTTON_X} 0 {HEAD_TOP}">
        <joint name="button" type="slide" axis="0 0 1" range="{-BUTTON_TRAVEL} 0"
               stiffness="{BUTTON_STIFFNESS}" damping="{BUTTON_DAMPING}"/>
        <geom class="fixture" type="cylinder" material="button" size="{BUTTON_RADIUS} {BUTTON_HALF_HEIGHT}"
              pos="0 0 {BUTTON_HALF_HEIGHT}" mass="0.01"/>
      </body>
    </body>"""

    def bind(self, model: mujoco.MjModel) -> None:
        super().bind(model)
        self._mug = self._body_id("mug")
        self._machine = self._body_id("machine")
        self._button = self._body_id("button")
        self._button_qpos = int(model.jnt_qposadr[model.joint("button").id])

    def reset(self, data: mujoco.MjData, rng: np.random.Generator, layout: str) -> None:
        xy = sample_layout(rng, PLACEMENTS, layout)
        yaw = rng.uniform(-math.pi, math.pi)  # the handle is decor: any yaw can be grasped
        self._set_free_pose(data, "mug", np.array([*xy["mug"], MUG_HALF_HEIGHT + DROP_GAP]), yaw_quat(yaw))
        self._set_mocap_xy(data, "machine", xy["machine"])

    @property
    def description(self) -> str:
        return "put the mug under the coffee machine and press its button"

    def button_depth(self, data: mujoco.MjData) -> float:
        """How far the button is pressed in, metres (0 at rest)."""
        return float(-data.qpos[self._button_qpos])

    def is_success(self, data: mujoco.MjData) -> bool:
        mug_xyz = data.xpos[self._mug]
        under_spout = np.linalg.norm(mug_xyz[:2] - data.xpos[self._machine][:2]) < UNDER_SPOUT_TOL
        on_tray = mug_xyz[2] - MUG_HALF_HEIGHT < TRAY_TOP + MUG_MAX_LIFT
        return bool(
            self.button_depth(data) >= BUTTON_PRESSED
            and under_spout
            and on_tray
            and self._tilt(data, "mug") < MUG_MAX_TILT
            and not self._touches_gripper(data, "mug")
        )

    def object_positions(self, data: mujoco.MjData) -> dict[str, np.ndarray]:
        return {
            "mug": data.xpos[self._mug].copy(),
            "machine": data.xpos[self._machine].copy(),
            "button": data.xpos[self._button].copy(),
        }

    def plan_expert(self, data: mujoco.MjData, start: Waypoint) -> list[Waypoint]:
        """Grasp the mug, carry it low to the front of the machine, slide it under the spout, set it down,
        back out, rise over the machine's head and press the button with the closed fingers."""
        positions = self.object_positions(data)
        mx, my, mz = positions["mug"]
        sx, sy, sz = positions["machine"]  # the machine's frame sits on the table under the spout
        bx, by, _ = positions["button"]
        carry_z = mz + MUG_CARRY_LIFT + TRAY_TOP
        release_z = sz + TRAY_TOP + MUG_RELEASE_CLEARANCE + MUG_HALF_HEIGHT
        front = (sx - MACHINE_FRONT, sy)
        button_top = sz + HEAD_TOP + 2 * BUTTON_HALF_HEIGHT
        press_hover_z = button_top + PRESS_HOVER_ABOVE + FINGER_TIP_BEYOND_TCP
        press_z = button_top - BUTTON_TRAVEL - PRESS_OVERTRAVEL + FINGER_TIP_BEYOND_TCP
        plan = chain(
            start,
            [
                ("hover_mug", (mx, my, MUG_HOVER_Z), OPEN, TRAVEL_SPEED),
                ("descend", (mx, my, mz), OPEN, APPROACH_SPEED),
                ("close", (mx, my, mz), CLOSED, None),
                ("hold", (mx, my, mz), CLOSED, None),
                ("lift", (mx, my, carry_z), CLOSED, APPROACH_SPEED),
                ("carry", (*front, carry_z), CLOSED, TRAVEL_SPEED),
                ("slide_in", (sx, sy, carry_z), CLOSED, APPROACH_SPEED),
                ("lower", (sx, sy, release_z), CLOSED, APPROACH_SPEED),
                ("open", (sx, sy, release_z), OPEN, None),
                ("back_out", (*front, release_z), OPEN, APPROACH_SPEED),
                ("rise", (*front, press_hover_z), CLOSED, TRAVEL_SPEED),
                ("hover_button", (bx, by, press_hover_z), CLOSED, TRAVEL_SPEED),
            ],
            MUG_GRASP_YAW,
        )
        return [
            *plan,
            *chain(
                plan[-1],
                [
                    ("press", (bx, by, press_z), CLOSED, PRESS_SPEED),
                    ("hold_press", (bx, by, press_z), CLOSED, None),
                    ("release_button", (bx, by, press_hover_z), CLOSED, TRAVEL_SPEED),
                ],
                MUG_GRASP_YAW,
            ),
        ]
