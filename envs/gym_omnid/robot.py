"""MJCF of the arm: a 6-DoF arm of capsules with a spherical wrist and a two-finger parallel gripper.

Kinematics (all at zero joint angles, the arm pointing straight up):
shoulder_pan (z) at the base, shoulder_lift (y) at ``SHOULDER_HEIGHT``, elbow (y) ``UPPER_ARM_LENGTH``
above it, forearm_roll (z) halfway along the forearm, wrist_pitch (y) and wrist_roll (z) intersecting
at the wrist centre ``FOREARM_LENGTH`` above the elbow. The tool centre point (site ``tcp``) is
``WRIST_TO_TCP`` beyond the wrist centre, between the finger pads; its z axis is the approach
direction and its x axis the finger closing direction.

The wrist camera ``cam_wrist`` is fixed to the hand (body ``link6``) beside the wrist, looking along
the approach direction, so that the fingertips sit at the bottom of its image and the space between
and beyond them fills the rest. It is a camera only, with no housing geom: the arm's
dynamics and the fixed cameras' images are those of the arm without it.

Only the hand and the fingers collide (with objects, fixtures and the table); the links are visual,
which keeps the scripted experts free of arm-object collisions they cannot see.
"""

from __future__ import annotations

from gym_omnid.calibration import look_at_xyaxes
from gym_omnid.constants import (
    ARM_DAMPING,
    ARM_FORCE_LIMIT,
    ARM_JOINT_RANGES,
    ARM_JOINTS,
    ARM_KP,
    FINGER_FORCE_LIMIT,
    FINGER_FRICTION,
    FINGER_KP,
    FINGER_TRAVEL,
    FOREARM_LENGTH,
    SHOULDER_HEIGHT,
    UPPER_ARM_LENGTH,
    WRIST_CAMERA,
    WRIST_CAMERA_FOVY,
    WRIST_TO_TCP,
)

TCP_SITE = "tcp"
FINGER_JOINTS = ("finger_left", "finger_right")
FINGER_GEOMS = ("finger_left_pad", "finger_right_pad")
HAND_GEOM = "palm"

BASE_HEIGHT = 0.06  # m: top of the base disc / shoulder_pan joint
WRIST_HOUSING_LENGTH = 0.05  # m: wrist centre to the palm
PALM_HALF = (0.065, 0.025, 0.015)  # m: palm box half sizes (x along the fingers' travel)
FINGER_HALF = (0.006, 0.012, 0.04)  # m: finger box half sizes (thickness, width, length)
FINGER_TIP_BEYOND_TCP = 0.02  # m: fingertips extend this far past the tcp
FINGER_MASS = 0.03  # kg
FINGER_DAMPING = 8.0  # N s / m
FINGER_LIMIT_SOLREF = "0.004 1"  # stiff travel limits (time constant = 2 physics steps, s; damping ratio)
ARM_ARMATURE = 0.05  # kg m^2: rotor inertia added to each arm joint
FINGER_ARMATURE = 0.01  # kg
ARM_DENSITY = 400.0  # kg / m^3 of the link primitives
# Wrist camera mount in the hand frame (link6: origin at the wrist centre, z along the approach, x along
# the fingers' travel), metres: 8 cm beside the wrist centre, its optical axis parallel to the approach
# direction (a target straight ahead); the image's up is the hand's +y, away from the fingers. Nothing
# of the arm lies within MuJoCo's near clipping distance (0.11 m here) inside its field of view.
WRIST_CAMERA_POS = (0.0, 0.08, 0.0)
WRIST_CAMERA_TARGET = (0.0, 0.08, 1.0)
WRIST_CAMERA_UP = (0.0, 1.0, 0.0)


def _hinge(index: int, axis: str) -> str:
    """``<joint>`` tag of arm joint ``index`` with its range and damping."""
    lo, hi = ARM_JOINT_RANGES[index]
    return (
        f'<joint name="{ARM_JOINTS[index]}" axis="{axis}" range="{lo} {hi}" damping="{ARM_DAMPING[index]}"/>'
    )


def _finger(side: str, sign: int, root_z: float) -> str:
    """One finger body: slides along +-x of the hand; joint 0 = pad at the centre line."""
    hx, hy, hz = FINGER_HALF
    return f"""
        <body name="finger_{side}" pos="0 0 {root_z:.4f}">
          <joint name="finger_{side}" type="slide" axis="{sign} 0 0" range="0 {FINGER_TRAVEL}"
                 damping="{FINGER_DAMPING}" armature="{FINGER_ARMATURE}" solreflimit="{FINGER_LIMIT_SOLREF}"/>
          <geom name="finger_{side}_pad" class="gripper" type="box" size="{hx} {hy} {hz}"
                pos="{sign * hx:.4f} 0 {hz:.4f}" mass="{FINGER_MASS}" rgba="0.2 0.2 0.22 1"
                friction="{FINGER_FRICTION} 0.02 0.002" condim="4"/>
        </body>"""


def _wrist_camera() -> str:
    """``<camera>`` tag of the wrist camera, in the hand's frame."""
    xyaxes = " ".join(
        f"{v:.6f}" for v in look_at_xyaxes(WRIST_CAMERA_POS, WRIST_CAMERA_TARGET, up=WRIST_CAMERA_UP)
    )
    pos = " ".join(f"{v}" for v in WRIST_CAMERA_POS)
    return (
        f'<camera name="{WRIST_CAMERA}" mode="fixed" pos="{pos}" xyaxes="{xyaxes}" '
        f'fovy="{WRIST_CAMERA_FOVY}"/>'
    )


def arm_worldbody() -> str:
    """``<body>`` XML of the whole arm, rooted at the world origin."""
    finger_root = WRIST_TO_TCP + FINGER_TIP_BEYOND_TCP - 2 * FINGER_HALF[2]
    palm_z = finger_root - PALM_HALF[2]
    half_forearm = FOREARM_LENGTH / 2
    return f"""
    <body name="arm_base" pos="0 0 0" childclass="arm">
      <geom type="cylinder" size="0.09 {BASE_HEIGHT / 2}" pos="0 0 {BASE_HEIGHT / 2}"
            rgba="0.25 0.25 0.28 1"/>
      <body name="link1" pos="0 0 {BASE_HEIGHT}" gravcomp="1">
        {_hinge(0, "0 0 1")}
        <geom type="cylinder" size="0.065 {(SHOULDER_HEIGHT - BASE_HEIGHT) / 2}"
              pos="0 0 {(SHOULDER_HEIGHT - BASE_HEIGHT) / 2}" rgba="0.85 0.45 0.1 1"/>
        <body name="link2" pos="0 0 {SHOULDER_HEIGHT - BASE_HEIGHT}" gravcomp="1">
          {_hinge(1, "0 1 0")}
          <geom type="cylinder" size="0.06 0.06" quat="0.7071068 0.7071068 0 0" rgba="0.25 0.25 0.28 1"/>
          <geom type="capsule" fromto="0 0 0 0 0 {UPPER_ARM_LENGTH}" size="0.045" rgba="0.85 0.85 0.87 1"/>
          <body name="link3" pos="0 0 {UPPER_ARM_LENGTH}" gravcomp="1">
            {_hinge(2, "0 1 0")}
            <geom type="cylinder" size="0.05 0.05" quat="0.7071068 0.7071068 0 0" rgba="0.25 0.25 0.28 1"/>
            <geom type="capsule" fromto="0 0 0 0 0 {half_forearm}" size="0.036" rgba="0.85 0.45 0.1 1"/>
            <body name="link4" pos="0 0 {half_forearm}" gravcomp="1">
              {_hinge(3, "0 0 1")}
              <geom type="capsule" fromto="0 0 0 0 0 {half_forearm}" size="0.032" rgba="0.85 0.85 0.87 1"/>
              <body name="link5" pos="0 0 {half_forearm}" gravcomp="1">
                {_hinge(4, "0 1 0")}
                <geom type="cylinder" size="0.035 0.035" quat="0.7071068 0.7071068 0 0"
                      rgba="0.25 0.25 0.28 1"/>
                <body name="link6" pos="0 0 0" gravcomp="1">
                  {_hinge(5, "0 0 1")}
                  <geom type="cylinder" size="0.03 {WRIST_HOUSING_LENGTH / 2}"
                        pos="0 0 {WRIST_HOUSING_LENGTH / 2}" rgba="0.85 0.45 0.1 1"/>
                  <geom name="{HAND_GEOM}" class="gripper" type="box"
                        size="{PALM_HALF[0]} {PALM_HALF[1]} {PALM_HALF[2]}" pos="0 0 {palm_z:.4f}"
                        rgba="0.25 0.25 0.28 1"/>
                  <site name="{TCP_SITE}" pos="0 0 {WRIST_TO_TCP}" euler="0 0 3.14159265" size="0.005"
                        rgba="1 0 1 0"/>
                  {_wrist_camera()}
                  {_finger("left", 1, finger_root)}
                  {_finger("right", -1, finger_root)}
                </body>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>"""


def arm_defaults() -> str:
    """``<default>`` classes used by the arm (``arm``: visual links; ``gripper``: colliding parts)."""
    return f"""
    <default class="arm">
      <joint armature="{ARM_ARMATURE}"/>
      <geom contype="0" conaffinity="0" density="{ARM_DENSITY}" group="0"/>
      <default class="gripper">
        <geom contype="2" conaffinity="1" density="{ARM_DENSITY}"/>
      </default>
    </default>"""


def arm_actuators() -> str:
    """``<actuator>`` entries: one position actuator per arm joint and per finger."""
    lines = []
    for name, (lo, hi), kp, limit in zip(ARM_JOINTS, ARM_JOINT_RANGES, ARM_KP, ARM_FORCE_LIMIT, strict=True):
        lines.append(
            f'<position name="{name}" joint="{name}" kp="{kp}" ctrlrange="{lo} {hi}" '
            f'forcerange="{-limit} {limit}"/>'
        )
    for name in FINGER_JOINTS:
        lines.append(
            f'<position name="{name}" joint="{name}" kp="{FINGER_KP}" ctrlrange="0 {FINGER_TRAVEL}" '
            f'forcerange="{-FINGER_FORCE_LIMIT} {FINGER_FORCE_LIMIT}"/>'
        )
    return "\n    ".join(lines)
