"""select_chemistry_tube: take the tube of the named colour from the rack and put it into the holder."""

from __future__ import annotations

import math
from types import MappingProxyType

import mujoco
import numpy as np

from gym_omnid.robot import FINGER_TIP_BEYOND_TCP
from gym_omnid.tasks.base import Placement, Task, sample_layout
from gym_omnid.waypoints import Waypoint, pick_and_place

TUBE_COLOURS = MappingProxyType(
    {  # name -> RGBA of the tube's liquid
        "red": (0.85, 0.1, 0.1, 1.0),
        "green": (0.1, 0.7, 0.2, 1.0),
        "blue": (0.1, 0.3, 0.9, 1.0),
        "yellow": (0.95, 0.85, 0.1, 1.0),
    }
)
TUBE_RADIUS = 0.011  # m
TUBE_LENGTH = 0.11  # m: end to end, round bottom included
TUBE_DENSITY = 600.0  # kg / m^3
RACK_SLOT_Y = (-0.075, -0.025, 0.025, 0.075)  # m: slot centres along the rack (rack frame y)
RACK_HALF_LENGTH = 0.11  # m: rack half extent along y
RACK_SLOT_HALF_X = 0.015  # m: half inner width of a slot along x
RACK_BAR = 0.005  # m: half thickness of the rack's bars
RACK_BASE_TOP = 0.01  # m: height of the rack's base plate top (tubes stand on it)
RACK_TOP = 0.05  # m: height of the rack's upper plate top
HOLDER_INNER_HALF = 0.018  # m: half inner width of the holder's square hole
HOLDER_WALL = 0.004  # m: half thickness of the holder's walls
HOLDER_BASE_TOP = 0.01  # m
HOLDER_TOP = 0.07  # m: top of the holder's walls
PLACED_XY_TOL = 0.02  # m: tube axis within this distance of the holder centre
PLACED_MAX_TILT = math.radians(25.0)  # rad: tube axis from vertical
PLACED_MAX_BOTTOM = 0.04  # m: tube bottom below this height (i.e. inside the holder)
DROP_GAP = 0.002  # m
# scripted expert
TUBE_GRASP_BELOW_TOP = 0.02  # m: TCP this far below the tube's top when grasping
TUBE_HOVER_ABOVE_TOP = 0.08  # m: TCP this far above the tube's top before descending
TUBE_CARRY_LIFT = 0.17  # m: how far the tube is lifted out of the rack
TUBE_RELEASE_CLEARANCE = 0.012  # m: tube bottom above the holder's base when released

PLACEMENTS = (
    Placement("rack", (0.55, 0.17), keepout=0.125),
    Placement("holder", (0.50, -0.17), keepout=0.06),
)


def _box(size: tuple[float, float, float], pos: tuple[float, float, float], material: str) -> str:
    return (
        f'<geom class="fixture" type="box" material="{material}" size="{size[0]} {size[1]} {size[2]}" '
        f'pos="{pos[0]} {pos[1]} {pos[2]}"/>'
    )


def _rack_geoms() -> str:
    """Base plate, end posts, and an upper plate made of bars around the slots."""
    half_upper = (RACK_TOP - RACK_BASE_TOP) / 2
    bar_z = RACK_TOP - RACK_BAR
    outer_x = RACK_SLOT_HALF_X + 2 * RACK_BAR
    geoms = [
        _box((outer_x, RACK_HALF_LENGTH, RACK_BASE_TOP / 2), (0, 0, RACK_BASE_TOP / 2), "rack"),
        _box(
            (outer_x, RACK_BAR, half_upper),
            (0, RACK_HALF_LENGTH - RACK_BAR, RACK_BASE_TOP + half_upper),
            "rack",
        ),
        _box(
            (outer_x, RACK_BAR, half_upper),
            (0, -RACK_HALF_LENGTH + RACK_BAR, RACK_BASE_TOP + half_upper),
            "rack",
        ),
    ]
    for sign in (-1, 1):  # long bars in front of and behind the slots
        geoms.append(
            _box(
                (RACK_BAR, RACK_HALF_LENGTH, RACK_BAR),
                (sign * (RACK_SLOT_HALF_X + RACK_BAR), 0, bar_z),
                "rack",
            )
        )
    for y in (-0.05, 0.0, 0.05):  # separators between slots
        geoms.append(_box((RACK_SLOT_HALF_X, RACK_BAR, RACK_BAR), (0, y, bar_z), "rack"))
    return "\n      ".join(geoms)


def _holder_geoms() -> str:
    """Base plate and four walls around a square hole."""
    half_wall = (HOLDER_TOP - HOLDER_BASE_TOP) / 2
    wall_z = HOLDER_BASE_TOP + half_wall
    offset = HOLDER_INNER_HALF + HOLDER_WALL
    outer = HOLDER_INNER_HALF + 2 * HOLDER_WALL
    geoms = [_box((outer, outer, HOLDER_BASE_TOP / 2), (0, 0, HOLDER_BASE_TOP / 2), "holder")]
    for sign in (-1, 1):
        geoms.append(_box((HOLDER_WALL, outer, half_wall), (sign * offset, 0, wall_z), "holder"))
        geoms.append(_box((HOLDER_INNER_HALF, HOLDER_WALL, half_wall), (0, sign * offset, wall_z), "holder"))
    return "\n      ".join(geoms)


class SelectChemistryTube(Task):
    """Take the tube of the named colour out of a 4-slot rack and stand it in the holder.

    Key objects (following ``layout``): the rack (with its tubes) and the holder. The target colour
    and the colours' slot order are drawn per episode. Success: the named tube stands in the holder's
    hole (axis within ``PLACED_XY_TOL`` of its centre, tilt below ``PLACED_MAX_TILT``, bottom inside),
    resting and released.
    """

    name = "select_chemistry_tube"

    def __init__(self) -> None:
        self._target = "red"

    def mjcf_assets(self) -> str:
        tubes = "\n    ".join(
            f'<material name="tube_{c}" rgba="{r} {g} {b} {a}" specular="0.6" shininess="0.9"/>'
            for c, (r, g, b, a) in TUBE_COLOURS.items()
        )
        return f"""
    {tubes}
    <material name="rack" rgba="0.93 0.93 0.9 1"/>
    <material name="holder" rgba="0.35 0.45 0.55 1"/>"""

    def mjcf_bodies(self) -> str:
        half_cyl = TUBE_LENGTH / 2 - TUBE_RADIUS
        tubes = "\n    ".join(
            f"""<body name="tube_{c}" pos="0.55 {0.17 + y} {RACK_BASE_TOP + TUBE_LENGTH / 2}">
      <freejoint name="tube_{c}"/>
      <geom class="object" type="capsule" size="{TUBE_RADIUS} {half_cyl}" material="tube_{c}"
            density="{TUBE_DENSITY}" condim="4"/>
      <geom class="decor" type="cylinder" size="{TUBE_RADIUS + 0.001} 0.006" pos="0 0 {half_cyl}"
            rgba="0.95 0.95 0.95 1"/>
    </body>"""
            for c, y in zip(TUBE_COLOURS, RACK_SLOT_Y, strict=True)
        )
        return f"""
    <body name="rack" mocap="true" pos="0.55 0.17 0">
      {_rack_geoms()}
    </body>
    <body name="holder" mocap="true" pos="0.5 -0.17 0">
      {_holder_geoms()}
    </body>
    {tubes}"""

    def bind(self, model: mujoco.MjModel) -> None:
        super().bind(model)
        self._holder = self._body_id("holder")
        self._tubes = {c: self._body_id(f"tube_{c}") for c in TUBE_COLOURS}

    @property
    def target(self) -> str:
        """Colour name of this episode's target tube."""
        return self._target

    def reset(self, data: mujoco.MjData, rng: np.random.Generator, layout: str) -> None:
        xy = sample_layout(rng, PLACEMENTS, layout)
        colours = list(TUBE_COLOURS)
        self._target = colours[int(rng.integers(len(colours)))]
        slot_of = rng.permutation(len(colours))
        for colour, slot in zip(colours, slot_of, strict=True):
            tube_xyz = np.array(
                [xy["rack"][0], xy["rack"][1] + RACK_SLOT_Y[slot], RACK_BASE_TOP + TUBE_LENGTH / 2 + DROP_GAP]
            )
            self._set_free_pose(data, f"tube_{colour}", tube_xyz, np.array([1.0, 0.0, 0.0, 0.0]))
        self._set_mocap_xy(data, "rack", xy["rack"])
        self._set_mocap_xy(data, "holder", xy["holder"])

    @property
    def description(self) -> str:
        return f"put the {self._target} tube in the holder"

    def is_success(self, data: mujoco.MjData) -> bool:
        tube = self._tubes[self._target]
        tube_xyz = data.xpos[tube]
        axis_world = data.xmat[tube].reshape(3, 3)[:, 2]
        tilt = math.acos(min(1.0, abs(float(axis_world[2]))))
        bottom_z = tube_xyz[2] - abs(axis_world[2]) * TUBE_LENGTH / 2
        centred = np.linalg.norm(tube_xyz[:2] - data.xpos[self._holder][:2]) < PLACED_XY_TOL
        return bool(
            centred
            and tilt < PLACED_MAX_TILT
            and bottom_z < PLACED_MAX_BOTTOM
            and self._is_resting(data, f"tube_{self._target}")
            and not self._touches_gripper(data, f"tube_{self._target}")
        )

    def object_positions(self, data: mujoco.MjData) -> dict[str, np.ndarray]:
        positions = {"target_tube": data.xpos[self._tubes[self._target]].copy()}
        positions["holder"] = data.xpos[self._holder].copy()
        positions["rack"] = data.xpos[self._body_id("rack")].copy()
        positions.update({f"tube_{c}": data.xpos[b].copy() for c, b in self._tubes.items()})
        return positions

    def plan_expert(self, data: mujoco.MjData, start: Waypoint) -> list[Waypoint]:
        """Grasp the named tube near its top, pull it out, carry, lower into the holder. The fingers close
        along world x (``GRASP_YAW``): across the rack, away from the neighbouring tubes."""
        positions = self.object_positions(data)
        tx, ty, tz = positions["target_tube"]
        hx, hy, hz = positions["holder"]
        grasp_z = tz + TUBE_LENGTH / 2 - TUBE_GRASP_BELOW_TOP
        carry_z = grasp_z + TUBE_CARRY_LIFT
        tcp_above_bottom = TUBE_LENGTH - TUBE_GRASP_BELOW_TOP
        release_z = hz + HOLDER_BASE_TOP + TUBE_RELEASE_CLEARANCE + tcp_above_bottom
        hover_z = tz + TUBE_LENGTH / 2 + TUBE_HOVER_ABOVE_TOP + FINGER_TIP_BEYOND_TCP
        return pick_and_place(
            start, (tx, ty), hover_z, grasp_z, carry_z, (hx, hy), release_z, hover_name="hover_tube"
        )
