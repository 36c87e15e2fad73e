"""texas_holdem: among a row of cards, put the one the instruction names (e.g. the leftmost) on the mat."""

from __future__ import annotations

import math
from types import MappingProxyType

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

CARD_SUITS = MappingProxyType(
    {  # card name -> RGBA of the mark printed on its face
        "hearts": (0.85, 0.08, 0.1, 1.0),
        "spades": (0.05, 0.05, 0.05, 1.0),
        "diamonds": (0.95, 0.55, 0.05, 1.0),
        "clubs": (0.1, 0.45, 0.85, 1.0),
    }
)
# Card positions in the row, named from the robot's point of view: left = world +y (the robot looks
# along world +x); ordered from left to right.
ROW_POSITIONS = ("leftmost", "second from the left", "second from the right", "rightmost")
CARD_HALF = (0.035, 0.025, 0.005)  # m: half sizes (length along x, width along y, thickness: 1 cm, pinchable)
CARD_DENSITY = 500.0  # kg / m^3
CARD_SPACING = 0.09  # m: between neighbouring card centres along y (4 cm free between them)
CARD_MAX_YAW = 0.15  # rad: each card's yaw is drawn within +- this
MARK_RADIUS = 0.011  # m: the suit mark, a disc printed on the face
MAT_HALF = (0.06, 0.07, 0.0015)  # m: the felt mat (half sizes)
ON_MAT_MARGIN = 0.01  # m: the card's centre lies this far inside the mat's edges
CARD_MAX_TILT = math.radians(20.0)  # rad: the card lies flat
CARD_MAX_LIFT = 0.006  # m: card bottom at most this far above the mat (it lies on it)
DROP_GAP = 0.001  # m
# scripted expert
CARD_PREGRASP = 0.25  # gripper command while approaching a card: fingers 6.75 cm apart, clear of
# the neighbouring cards 9 cm away
CARD_GRASP_TIP_Z = 0.002  # m: fingertip height above the table when grasping a card
CARD_HOVER_Z = 0.15  # m: TCP height above the card before descending
CARD_CARRY_Z = 0.15  # m: TCP height while carrying the card
CARD_RELEASE_CLEARANCE = 0.004  # m: card bottom above the mat when released

PLACEMENTS = (
    Placement("cards", (0.55, 0.15), keepout=0.17),
    Placement("mat", (0.5, -0.18), keepout=0.09),
)


def _slot_y(slot: int) -> float:
    """y offset (m) of row position ``slot`` (0 = leftmost, i.e. largest y) from the row's centre."""
    return (1.5 - slot) * CARD_SPACING


class TexasHoldem(Task):
    """Put the card at the named row position (leftmost, second from the left, ...) on the mat.

    Key objects (following ``layout``): the row of cards (its centre) and the mat. The suits' order
    along the row and the named position are drawn per episode, so the target is found by its position
    in the row, not its look. Left and right are the robot's (left = world +y). Success: the named card
    lies flat on the mat (centre inside its edges), resting and released.
    """

    name = "texas_holdem"

    def __init__(self) -> None:
        self._slot = 0
        self._order: tuple[str, ...] = tuple(CARD_SUITS)

    def mjcf_assets(self) -> str:
        marks = "\n    ".join(
            f'<material name="mark_{suit}" rgba="{r} {g} {b} {a}"/>'
            for suit, (r, g, b, a) in CARD_SUITS.items()
        )
        return f"""
    {marks}
    <material name="card" rgba="0.97 0.97 0.95 1"/>
    <material name="mat" rgba="0.1 0.45 0.22 1"/>"""

    def mjcf_bodies(self) -> str:
        cx, cy, cz = CARD_HALF
        cards = "\n    ".join(
            f"""<body name="card_{suit}" pos="0.55 {0.15 + _slot_y(slot)} {cz}">
      <freejoint name="card_{suit}"/>
      <geom class="object" type="box" size="{cx} {cy} {cz}" material="card" density="{CARD_DENSITY}"/>
      <geom class="decor" type="cylinder" size="{MARK_RADIUS} 0.0005" pos="0 0 {cz}" material="mark_{suit}"/>
      <geom class="decor" type="box" size="0.004 0.004 0.0005" pos="{cx - 0.008} {cy - 0.007} {cz}"
            material="mark_{suit}"/>
      <geom class="decor" type="box" size="0.004 0.004 0.0005" pos="{-cx + 0.008} {-cy + 0.007} {cz}"
            material="mark_{suit}"/>
    </body>"""
            for slot, suit in enumerate(CARD_SUITS)
        )
        return f"""
    {cards}
    <body name="mat" mocap="true" pos="0.5 -0.18 0">
      <geom class="fixture" type="box" material="mat" size="{MAT_HALF[0]} {MAT_HALF[1]} {MAT_HALF[2]}"
            pos="0 0 {MAT_HALF[2]}"/>
    </body>"""

    def bind(self, model: mujoco.MjModel) -> None:
        super().bind(model)
        self._cards = {suit: self._body_id(f"card_{suit}") for suit in CARD_SUITS}
        self._mat = self._body_id("mat")

    @property
    def target(self) -> str:
        """Suit of this episode's target card (the card at the named row position)."""
        return self._order[self._slot]

    def reset(self, data: mujoco.MjData, rng: np.random.Generator, layout: str) -> None:
        xy = sample_layout(rng, PLACEMENTS, layout)
        suits = list(CARD_SUITS)
        self._order = tuple(suits[i] for i in rng.permutation(len(suits)))
        self._slot = int(rng.integers(len(ROW_POSITIONS)))
        for slot, suit in enumerate(self._order):
            card_xyz = np.array([xy["cards"][0], xy["cards"][1] + _slot_y(slot), CARD_HALF[2] + DROP_GAP])
            self._set_free_pose(
                data, f"card_{suit}", card_xyz, yaw_quat(rng.uniform(-CARD_MAX_YAW, CARD_MAX_YAW))
            )
        self._set_mocap_xy(data, "mat", xy["mat"])

    @property
    def description(self) -> str:
        return f"put the {ROW_POSITIONS[self._slot]} card on the mat"

    def is_success(self, data: mujoco.MjData) -> bool:
        card = self._cards[self.target]
        offset = data.xpos[card] - data.xpos[self._mat]
        inside = abs(offset[0]) < MAT_HALF[0] - ON_MAT_MARGIN and abs(offset[1]) < MAT_HALF[1] - ON_MAT_MARGIN
        bottom = data.xpos[card][2] - CARD_HALF[2]
        return bool(
            inside
            and bottom < 2 * MAT_HALF[2] + CARD_MAX_LIFT
            and self._tilt(data, f"card_{self.target}") < CARD_MAX_TILT
            and self._is_resting(data, f"card_{self.target}")
            and not self._touches_gripper(data, f"card_{self.target}")
        )

    def object_positions(self, data: mujoco.MjData) -> dict[str, np.ndarray]:
        cards = {f"card_{suit}": data.xpos[body].copy() for suit, body in self._cards.items()}
        return {
            "target_card": cards[f"card_{self.target}"],
            "cards": np.mean(list(cards.values()), axis=0),
            "mat": data.xpos[self._mat].copy(),
            **cards,
        }

    def plan_expert(self, data: mujoco.MjData, start: Waypoint) -> list[Waypoint]:
        """Approach the named card with the fingers partly open (clear of its neighbours), pinch it across
        its width just above the table, carry it over the mat, lower, open."""
        positions = self.object_positions(data)
        cx, cy, cz = positions["target_card"]
        mx, my, mz = positions["mat"]
        card_yaw = self.body_yaw(data, f"card_{self.target}") + math.pi / 2
        grasp_z = cz - CARD_HALF[2] + CARD_GRASP_TIP_Z + FINGER_TIP_BEYOND_TCP
        release_z = mz + 2 * MAT_HALF[2] + CARD_RELEASE_CLEARANCE + CARD_GRASP_TIP_Z + FINGER_TIP_BEYOND_TCP
        return chain(
            start,
            [
                ("hover_card", (cx, cy, CARD_HOVER_Z), CARD_PREGRASP, TRAVEL_SPEED),
                ("descend", (cx, cy, grasp_z), CARD_PREGRASP, APPROACH_SPEED),
                ("close", (cx, cy, grasp_z), CLOSED, None),
                ("hold", (cx, cy, grasp_z), CLOSED, None),
                ("lift", (cx, cy, CARD_CARRY_Z), CLOSED, APPROACH_SPEED),
                ("carry", (mx, my, CARD_CARRY_Z), CLOSED, TRAVEL_SPEED),
                ("lower", (mx, my, release_z), CLOSED, APPROACH_SPEED),
                ("open", (mx, my, release_z), OPEN, None),
                ("retreat", (mx, my, RETREAT_Z), OPEN, TRAVEL_SPEED),
            ],
            card_yaw,
        )
