"""set_study_table: put the book onto the shelf and close the laptop's lid."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from gym_omnid.robot import FINGER_TIP_BEYOND_TCP
from gym_omnid.tasks.base import Placement, Task, sample_layout, yaw_quat
from gym_omnid.waypoints import (
    APPROACH_SPEED,
    CLOSED,
    OPEN,
    RETREAT_Z,
    TRAVEL_SPEED,
    Waypoint,
    chain,
)

BOOK_HALF = (0.075, 0.032, 0.02)  # m: half sizes (length along its x, width, thickness)
BOOK_DENSITY = 400.0  # kg / m^3
BOOK_MAX_YAW = 0.3  # rad: the book's yaw is drawn within +- this
SHELF_TOP_HALF = (0.09, 0.075, 0.008)  # m: the shelf's top board
SHELF_TOP = 0.08  # m: height of the board's upper face
SHELF_SIDE_HALF_Y = 0.008  # m: half thickness of the two side boards carrying the top
ON_SHELF_MARGIN = 0.01  # m: the book's centre lies this far inside the board's edges
BOOK_MAX_TILT = math.radians(20.0)  # rad: the book lies flat
BOOK_MAX_LIFT = 0.01  # m: book bottom at most this far above the board (it lies on it)
# Laptop frame: origin on the table under the base's centre, x away from the robot; the lid hinges
# about y at the base's back edge and, closed, lies on the base.
LAPTOP_BASE_HALF = (0.07, 0.1, 0.008)  # m
LID_HALF_THICKNESS = 0.004  # m
LID_OPEN = math.radians(112.0)  # rad: the lid rests open on its stop, just past upright
LID_DENSITY = 600.0  # kg / m^3
LID_DAMPING = 0.03  # N m s / rad: hinge damping (the lid falls shut once pushed past upright)
LID_CLOSED = math.radians(6.0)  # rad: hinge angle below which the laptop counts as closed
DROP_GAP = 0.002  # m
# scripted expert
PUSHER_YAW = math.pi / 2  # rad: the closed fingers push the lid with their broad side
LID_PUSH_TIP_Z = 0.09  # m: fingertip height while pushing the open lid (below its top edge)
LID_HOVER_CLEARANCE = 0.05  # m: fingertips this far above the open lid's top before descending
LID_PUSH_START = 0.10  # m: fingertips start this far behind the hinge (beyond the open lid)
LID_PUSH_END = 0.03  # m: and push to this far in front of it (lid past upright, it falls shut)
BOOK_GRASP_TIP_Z = 0.004  # m: fingertip height above the table when grasping the book
BOOK_HOVER_Z = 0.18  # m: TCP height above the book before descending
BOOK_CARRY_Z = 0.20  # m: TCP height while carrying the book over the shelf
BOOK_RELEASE_CLEARANCE = 0.006  # m: book bottom above the shelf's board when released

PLACEMENTS = (
    Placement("book", (0.4, 0.15), keepout=0.09),
    Placement("shelf", (0.62, 0.2), keepout=0.115),
    Placement("laptop", (0.44, -0.2), keepout=0.13),
)


class SetStudyTable(Task):
    """Put the book onto the shelf and close the laptop.

    Key objects (following ``layout``): the book, the shelf and the laptop. The lid is a hinge joint
    resting open against its stop just past upright, so a push toward the robot makes it fall shut.
    Success: both hold at once: the book lies flat on the shelf's board (centre inside its edges),
    resting and released, and the lid is closed (hinge angle below ``LID_CLOSED``).
    """

    name = "set_study_table"

    def mjcf_assets(self) -> str:
        return """
    <material name="book" rgba="0.15 0.3 0.65 1"/>
    <material name="shelf" rgba="0.55 0.38 0.22 1"/>
    <material name="laptop" rgba="0.62 0.64 0.68 1" specular="0.5" shininess="0.7"/>
    <material name="screen" rgba="0.05 0.07 0.12 1" specular="0.8" shininess="0.9"/>"""

    def mjcf_bodies(self) -> str:
        bx, by, bz = BOOK_HALF
        sx, sy, sz = SHELF_TOP_HALF
        side_half_z = (SHELF_TOP - 2 * sz) / 2
        side_y = sy - SHELF_SIDE_HALF_Y
        lx, ly, lz = LAPTOP_BASE_HALF
        lid_t = LID_HALF_THICKNESS
        return f"""
    <body name="book" pos="0.42 0.16 {bz}">
      <freejoint name="book"/>
      <geom class="object" type="box" size="{bx} {by} {bz}" material="book" density="{BOOK_DENSITY}"/>
      <geom class="decor" type="box" size="{bx - 0.004} {by + 0.0005} {bz - 0.003}" rgba="0.96 0.95 0.9 1"
            pos="0.005 0 0"/>
    </body>
    <body name="shelf" mocap="true" pos="0.65 0.2 0">
      <geom class="fixture" type="box" material="shelf" size="{sx} {sy} {sz}" pos="0 0 {SHELF_TOP - sz}"/>
      <geom class="fixture" type="box" material="shelf" size="{sx} {SHELF_SIDE_HALF_Y} {side_half_z}"
            pos="0 {side_y} {side_half_z}"/>
      <geom class="fixture" type="box" material="shelf" size="{sx} {SHELF_SIDE_HALF_Y} {side_half_z}"
            pos="0 {-side_y} {side_half_z}"/>
    </body>
    <body name="laptop" mocap="true" pos="0.5 -0.2 0">
      <geom class="fixture" type="box" material="laptop" size="{lx} {ly} {lz}" pos="0 0 {lz}"/>
      <geom class="decor" type="box" size="{lx * 0.55} {ly * 0.85} 0.0005" pos="{lx * 0.2} 0 {2 * lz}"
            rgba="0.2 0.2 0.22 1"/>
      <body name="lid" pos="{lx} 0 {2 * lz}">
        <joint name="lid" type="hinge" axis="0 1 0" range="0 {LID_OPEN}" damping="{LID_DAMPING}"/>
        <geom class="fixture" type="box" material="laptop" size="{lx} {ly} {lid_t}" pos="{-lx} 0 {lid_t}"
              density="{LID_DENSITY}"/>
        <geom class="decor" type="box" material="screen" size="{lx * 0.85} {ly * 0.9} 0.0005"
              pos="{-lx} 0 -0.0002"/>
      </body>
    </body>"""

    def bind(self, model: mujoco.MjModel) -> None:
        super().bind(model)
        self._book = self._body_id("book")
        self._shelf = self._body_id("shelf")
        self._laptop = self._body_id("laptop")
        self._lid = self._body_id("lid")
        self._lid_qpos = int(model.jnt_qposadr[model.joint("lid").id])

    def reset(self, data: mujoco.MjData, rng: np.random.Generator, layout: str) -> None:
        xy = sample_layout(rng, PLACEMENTS, layout)
        yaw = rng.uniform(-BOOK_MAX_YAW, BOOK_MAX_YAW)
        self._set_free_pose(data, "book", np.array([*xy["book"], BOOK_HALF[2] + DROP_GAP]), yaw_quat(yaw))
        self._set_mocap_xy(data, "shelf", xy["shelf"])
        self._set_mocap_xy(data, "laptop", xy["laptop"])
        data.qpos[self._lid_qpos] = LID_OPEN

    @property
    def description(self) -> str:
        return "put the book on the shelf and close the laptop"

    def lid_angle(self, data: mujoco.MjData) -> float:
        """Hinge angle of the lid, rad (0 closed)."""
        return float(data.qpos[self._lid_qpos])

    def book_on_shelf(self, data: mujoco.MjData) -> bool:
        """The book lies flat on the shelf's board, resting and released."""
        offset = data.xpos[self._book] - data.xpos[self._shelf]
        inside = (
            abs(offset[0]) < SHELF_TOP_HALF[0] - ON_SHELF_MARGIN
            and abs(offset[1]) < SHELF_TOP_HALF[1] - ON_SHELF_MARGIN
        )
        bottom = data.xpos[self._book][2] - BOOK_HALF[2]
        return bool(
            inside
            and SHELF_TOP - BOOK_MAX_LIFT < bottom < SHELF_TOP + BOOK_MAX_LIFT
            and self._tilt(data, "book") < BOOK_MAX_TILT
            and self._is_resting(data, "book")
            and not self._touches_gripper(data, "book")
        )

    def is_success(self, data: mujoco.MjData) -> bool:
        return self.lid_angle(data) < LID_CLOSED and self.book_on_shelf(data)

    def object_positions(self, data: mujoco.MjData) -> dict[str, np.ndarray]:
        return {
            "book": data.xpos[self._book].copy(),
            "shelf": data.xpos[self._shelf].copy(),
            "laptop": data.xpos[self._laptop].copy(),
            "lid_hinge": data.xpos[self._lid].copy(),
        }

    def plan_expert(self, data: mujoco.MjData, start: Waypoint) -> list[Waypoint]:
        """Push the open lid past upright with the closed fingers (it falls shut, away from the fingers,
        while the arm moves on to the book), then pick the book and lay it on the shelf."""
        positions = self.object_positions(data)
        hx, hy, hz = positions["lid_hinge"]
        kx, ky, kz = positions["book"]
        fx, fy, fz = positions["shelf"]
        push_z = LID_PUSH_TIP_Z + FINGER_TIP_BEYOND_TCP
        behind = hx + LID_PUSH_START
        hover_z = hz + 2 * LAPTOP_BASE_HALF[0] + LID_HOVER_CLEARANCE + FINGER_TIP_BEYOND_TCP
        grasp_z = kz - BOOK_HALF[2] + BOOK_GRASP_TIP_Z + FINGER_TIP_BEYOND_TCP
        release_z = fz + SHELF_TOP + BOOK_RELEASE_CLEARANCE + (grasp_z - (kz - BOOK_HALF[2]))
        book_yaw = self.body_yaw(data, "book") + math.pi / 2  # close across the book's width
        lid = chain(
            start,
            [
                ("hover_lid", (behind, hy, hover_z), CLOSED, TRAVEL_SPEED),
                ("settle", (behind, hy, hover_z), CLOSED, None),  # the arm lags the target after travel
                ("descend_behind", (behind, hy, push_z), CLOSED, APPROACH_SPEED),
                ("push_lid", (hx - LID_PUSH_END, hy, push_z), CLOSED, APPROACH_SPEED),
            ],
            PUSHER_YAW,
        )
        book = chain(
            lid[-1],
            [
                ("hover_book", (kx, ky, BOOK_HOVER_Z), OPEN, TRAVEL_SPEED),
                ("descend", (kx, ky, grasp_z), OPEN, APPROACH_SPEED),
                ("close", (kx, ky, grasp_z), CLOSED, None),
                ("hold", (kx, ky, grasp_z), CLOSED, None),
                ("lift", (kx, ky, BOOK_CARRY_Z), CLOSED, APPROACH_SPEED),
                ("carry", (fx, fy, BOOK_CARRY_Z), CLOSED, TRAVEL_SPEED),
                ("lower", (fx, fy, release_z), CLOSED, APPROACH_SPEED),
                ("open", (fx, fy, release_z), OPEN, None),
                ("retreat", (fx, fy, RETREAT_Z), OPEN, TRAVEL_SPEED),
            ],
            book_yaw,
        )
        return [*lid, *book]
