"""Per-task waypoint planners of the scripted experts, registered in ``PLANNERS`` by task name.

Each planner reads privileged simulator state (object poses) right after ``reset`` and returns the
whole plan; see :mod:`gym_omnid.waypoints` for the waypoint type and :mod:`gym_omnid.experts` for the
entry point.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from types import MappingProxyType
from typing import TYPE_CHECKING

from gym_omnid.robot import FINGER_TIP_BEYOND_TCP
from gym_omnid.tasks.add_condiment import BOTTLE_MOUTH, POUR_STEPS
from gym_omnid.tasks.get_coffee import (
    BUTTON_HALF_HEIGHT,
    BUTTON_TRAVEL,
    HEAD_TOP,
    MUG_HALF_HEIGHT,
    TRAY_TOP,
)
from gym_omnid.tasks.select_apple import APPLE_RADIUS, BOWL_BASE_THICKNESS
from gym_omnid.tasks.select_chemistry_tube import HOLDER_BASE_TOP, TUBE_LENGTH
from gym_omnid.tasks.set_study_table import BOOK_HALF, LAPTOP_BASE_HALF, SHELF_TOP
from gym_omnid.tasks.texas_holdem import CARD_HALF, MAT_HALF
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

if TYPE_CHECKING:
    from gym_omnid.env import OmniDEnv

GRASP_YAW = 0.0  # rad: fingers close along world x (across the rack, away from neighbouring tubes)
RETREAT_Z = 0.28  # m: TCP height after releasing

# select_apple
APPLE_HOVER_Z = 0.20  # m: TCP height above the apple before descending
APPLE_CARRY_Z = 0.23  # m: TCP height while carrying the apple
APPLE_RELEASE_CLEARANCE = 0.015  # m: apple bottom above the bowl's base when released
# select_chemistry_tube
TUBE_GRASP_BELOW_TOP = 0.02  # m: TCP this far below the tube's top when grasping
TUBE_HOVER_ABOVE_TOP = 0.08  # m: TCP this far above the tube's top before descending
TUBE_CARRY_LIFT = 0.17  # m: how far the tube is lifted out of the rack
TUBE_RELEASE_CLEARANCE = 0.012  # m: tube bottom above the holder's base when released
# add_condiment
BOTTLE_GRASP_YAW = math.pi / 2  # rad: fingers close along world y, so the pouring tilt (about world x)
# turns the bottle against the pads' faces rather than about them
BOTTLE_HOVER_Z = 0.20  # m: TCP height above the bottle's centre before descending
POUR_TCP_Z = 0.22  # m: TCP height while carrying and pouring (bottle well above the pot's rim)
POUR_TILT = math.radians(110.0)  # rad: tilt of the gripper (and bottle) while pouring
POUR_EXTRA_STEPS = 3  # env steps held beyond the task's POUR_STEPS
# get_coffee
MUG_GRASP_YAW = math.pi / 2  # rad: fingers close along world y, beside the machine's column
MUG_HOVER_Z = 0.20  # m: TCP height above the mug before descending
MUG_CARRY_LIFT = 0.02  # m: mug bottom above the drip tray while carried under the machine's head
MACHINE_FRONT = 0.10  # m: the mug is slid in from this far in front of the spout (robot side)
MUG_RELEASE_CLEARANCE = 0.004  # m: mug bottom above the tray when released
PRESS_HOVER_ABOVE = 0.08  # m: fingertips this far above the button before pressing
PRESS_OVERTRAVEL = 0.004  # m: fingertips aimed this far below the button's stop
PRESS_SPEED = 0.008  # m per env step while pressing
# set_study_table
PUSHER_YAW = math.pi / 2  # rad: the closed fingers push the lid with their broad side
LID_PUSH_TIP_Z = 0.09  # m: fingertip height while pushing the open lid (below its top edge)
LID_HOVER_CLEARANCE = 0.05  # m: fingertips this far above the open lid's top before descending
LID_PUSH_START = 0.10  # m: fingertips start this far behind the hinge (beyond the open lid)
LID_PUSH_END = 0.03  # m: and push to this far in front of it (lid past upright, it falls shut)
BOOK_GRASP_TIP_Z = 0.004  # m: fingertip height above the table when grasping the book
BOOK_HOVER_Z = 0.18  # m: TCP height above the book before descending
BOOK_CARRY_Z = 0.20  # m: TCP height while carrying the book over the shelf
BOOK_RELEASE_CLEARANCE = 0.006  # m: book bottom above the shelf's board when released
# texas_holdem
CARD_PREGRASP = 0.25  # gripper command while approaching a card: fingers 6.75 cm apart, clear of
# the neighbouring cards 9 cm away
CARD_GRASP_TIP_Z = 0.002  # m: fingertip height above the table when grasping a card
CARD_HOVER_Z = 0.15  # m: TCP height above the card before descending
CARD_CARRY_Z = 0.15  # m: TCP height while carrying the card
CARD_RELEASE_CLEARANCE = 0.004  # m: card bottom above the mat when released


def pick_and_place_apple(env: OmniDEnv, start: Waypoint) -> list[Waypoint]:
    """select_apple: hover, descend around the apple, close, lift, carry over the bowl, lower, open."""
    positions = env.object_positions()
    ax, ay, az = positions["apple"]
    bx, by, bz = positions["bowl"]
    release_z = bz + BOWL_BASE_THICKNESS + APPLE_RELEASE_CLEARANCE + APPLE_RADIUS
    return chain(
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
        GRASP_YAW,
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
    return chain(
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
        GRASP_YAW,
    )


def pour_condiment(env: OmniDEnv, start: Waypoint) -> list[Waypoint]:
    """add_condiment: grasp the bottle's body, lift, carry beside the pot's centre, tilt so the mouth comes
    over the centre, hold the pour, tilt back."""
    positions = env.object_positions()
    bx, by, bz = positions["bottle"]
    px, py, _ = positions["pot"]
    # The mouth lies BOTTLE_MOUTH from the grasp point (the bottle's centre) along the bottle's axis, which
    # the tilt turns toward world -y: hold the TCP that far on the +y side of the pot's centre.
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


def get_coffee(env: OmniDEnv, start: Waypoint) -> list[Waypoint]:
    """get_coffee: grasp the mug, carry it low to the front of the machine, slide it under the spout, set it
    down, back out, rise over the machine's head and press the button with the closed fingers."""
    positions = env.object_positions()
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


def set_study_table(env: OmniDEnv, start: Waypoint) -> list[Waypoint]:
    """set_study_table: push the open lid past upright with the closed fingers (it falls shut, away from
    the fingers, while the arm moves on to the book), then pick the book and lay it on the shelf."""
    positions = env.object_positions()
    hx, hy, hz = positions["lid_hinge"]
    kx, ky, kz = positions["book"]
    fx, fy, fz = positions["shelf"]
    push_z = LID_PUSH_TIP_Z + FINGER_TIP_BEYOND_TCP
    behind = hx + LID_PUSH_START
    hover_z = hz + 2 * LAPTOP_BASE_HALF[0] + LID_HOVER_CLEARANCE + FINGER_TIP_BEYOND_TCP
    grasp_z = kz - BOOK_HALF[2] + BOOK_GRASP_TIP_Z + FINGER_TIP_BEYOND_TCP
    release_z = fz + SHELF_TOP + BOOK_RELEASE_CLEARANCE + (grasp_z - (kz - BOOK_HALF[2]))
    book_yaw = env.task_spec.body_yaw(env.data, "book") + math.pi / 2  # close across the book's width
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


def pick_and_place_card(env: OmniDEnv, start: Waypoint) -> list[Waypoint]:
    """texas_holdem: approach the named card with the fingers partly open (clear of its neighbours), pinch
    it across its width just above the table, carry it over the mat, lower, open."""
    positions = env.object_positions()
    cx, cy, cz = positions["target_card"]
    mx, my, mz = positions["mat"]
    card_yaw = env.task_spec.body_yaw(env.data, f"card_{env.task_spec.target}") + math.pi / 2
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


PLANNERS: MappingProxyType[str, Callable[[OmniDEnv, Waypoint], list[Waypoint]]] = MappingProxyType(
    {
        "select_apple": pick_and_place_apple,
        "select_chemistry_tube": pick_and_place_tube,
        "add_condiment": pour_condiment,
        "get_coffee": get_coffee,
        "set_study_table": set_study_table,
        "texas_holdem": pick_and_place_card,
    }
)
