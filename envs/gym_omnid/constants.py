"""Named constants of the OmniD benchmark envs, with units.

Frames: the world frame is the robot base frame (x forward, y left, z up, metres); z = 0 is the table
top and the arm base sits at the origin, at the table's near edge.
"""

from __future__ import annotations

import math

# --- timing -----------------------------------------------------------------------------------------
CONTROL_FPS = 10  # Hz: one env step = 1 / CONTROL_FPS seconds
PHYSICS_TIMESTEP = 0.002  # s: MuJoCo integration step
N_SUBSTEPS = round(1.0 / (CONTROL_FPS * PHYSICS_TIMESTEP))  # physics steps per env step (50)
SETTLE_STEPS = 25  # physics steps run at reset so that objects come to rest on their supports
MAX_EPISODE_STEPS = 200  # env steps (20 s at 10 Hz); the experts finish in about 55-105

# --- variants ----------------------------------------------------------------------------------------
TASKS = (  # the paper's tasks 0 and 1 first (few-shot and OOD settings use them)
    "select_apple",
    "select_chemistry_tube",
    "add_condiment",
    "get_coffee",
    "set_study_table",
    "texas_holdem",
)
# Task conditioning (the env's ``task_onehot``): the observation entry ENV_STATE_OBS_KEY (LeRobot's
# ``environment_state``, which lerobot-eval passes to a policy as ``observation.environment_state``) is a
# float32 one-hot over TASKS, entry i (named TASK_ONEHOT_NAMES[i]) set for TASKS[i].
ENV_STATE_OBS_KEY = "environment_state"
TASK_ONEHOT_NAMES = TASKS
CAMERAS = ("cam_a", "cam_b", "cam_c", "cam_d", "cam_e")
TRAIN_CAMERAS = ("cam_b", "cam_c", "cam_d", "cam_e")  # cam_a is the unseen view for few-shot
# Graded position layouts (the position-shift curve): key objects at an L-inf distance outside the ID
# square in (low, high], metres; the first two bands together are the position-OOD band.
POSITION_BANDS = {
    "position_band_1": (0.0, 0.025),
    "position_band_2": (0.025, 0.05),
    "position_band_3": (0.05, 0.075),
    "position_band_4": (0.075, 0.10),
}
LAYOUTS = ("id", "position_ood", *POSITION_BANDS)
BACKGROUNDS = ("id", "ood1", "ood2", "ood3", "ood4")
DEFAULT_IMAGE_SIZE = 128  # px, square images unless (height, width) is given
MAX_IMAGE_SIDE = 2048  # px: upper bound accepted for one image side
ID_HALF_EXTENT = 0.05  # m: ID positions are nominal +- 5 cm (a 10 cm x 10 cm square)
OOD_HALF_EXTENT = 0.10  # m: position-OOD positions have |offset|_inf in (5 cm, 10 cm]
LAYOUT_MAX_TRIES = 200  # rejection-sampling attempts before a layout sampler gives up
# Workspace: the box, per world axis (x, y, z) as (min, max) in metres, that holds every object position
# of every task in every layout (across tasks and seeds: x 0.30..0.73, y -0.29..0.39, z 0..0.28, the top
# being the coffee machine's button), with a few cm to spare. It is the benchmark's OmniD volume
# (``--policy.volume_bounds``), so the policy's 3D feature grid covers everything it must reach.
# Exception: texas_holdem's cards in position_band_3 and _4 reach y 0.43 (the graded bands the benchmark
# evaluates are select_apple's, which stay inside: x 0.35..0.73, y -0.32..0.30).
WORKSPACE_BOUNDS = ((0.2, 0.84), (-0.4, 0.4), (0.0, 0.32))

# --- rendering ---------------------------------------------------------------------------------------
CAMERA_FOVY = 50.0  # deg: vertical field of view of every fixed camera
WRIST_CAMERA = "cam_wrist"  # on the gripper, looking along it at the fingers; moves with the arm
WRIST_CAMERA_FOVY = 60.0  # deg: vertical field of view of the wrist camera
ALL_CAMERAS = (*CAMERAS, WRIST_CAMERA)  # every camera an env can observe; the default is CAMERAS
RIGS = ("default", "closer", "higher", "bumped")  # placements of the fixed cameras (gym_omnid.rigs)
DEFAULT_RIG = "default"  # the benchmark's placements
TABLE_TEXTURE_SIZE = 128  # px: side of the square table-top texture (about 1 cm per texel)
RENDER_MOSAIC_COLUMNS = 3  # images per row in render()'s mosaic of the observed cameras
# Tessellation of spheres, capsules and cylinders (MuJoCo's defaults are 28 / 16 / 4): halves the
# software-rendering time at 128 px with no visible loss.
RENDER_NUM_SLICES = 16
RENDER_NUM_STACKS = 8
RENDER_NUM_QUADS = 1

# --- table -------------------------------------------------------------------------------------------
TABLE_X_RANGE = (-0.10, 1.10)  # m: table top extent along x
TABLE_Y_HALF = 0.70  # m: table top half extent along y
TABLE_THICKNESS = 0.04  # m
TABLE_HEIGHT = 0.75  # m: table top above the floor

# --- arm (6-DoF, spherical wrist, joint-position actuators) ------------------------------------------
ARM_JOINTS = ("shoulder_pan", "shoulder_lift", "elbow", "forearm_roll", "wrist_pitch", "wrist_roll")
ARM_JOINT_RANGES = (  # rad
    (-2.6, 2.6),
    (-1.2, 1.9),
    (0.05, 2.9),  # elbow-up branch only: keeps IK away from the elbow flip
    (-2.6, 2.6),
    (-2.4, 2.4),
    (-math.pi, math.pi),
)
# Joint targets of the home pose: gripper about 30 cm above the table at x = 0.35 m, pointing down.
HOME_JOINTS = (0.0, 0.098, 2.175, 0.0, 0.869, 0.0)  # rad
SHOULDER_HEIGHT = 0.25  # m: shoulder axis above the table
UPPER_ARM_LENGTH = 0.45  # m: shoulder axis to elbow axis
FOREARM_LENGTH = 0.40  # m: elbow axis to wrist centre
WRIST_TO_TCP = 0.14  # m: wrist centre to the tool centre point (between the finger pads)
ARM_KP = (900.0, 900.0, 700.0, 250.0, 250.0, 150.0)  # N m / rad: position actuator gains
ARM_DAMPING = (60.0, 60.0, 45.0, 12.0, 12.0, 8.0)  # N m s / rad: joint damping
ARM_FORCE_LIMIT = (60.0, 60.0, 45.0, 15.0, 15.0, 10.0)  # N m: actuator torque limits (expert peaks ~20)

# --- gripper (two coupled slide fingers) -------------------------------------------------------------
FINGER_TRAVEL = 0.045  # m: travel of each finger; gap between the pads = 2 * opening per finger
GRIPPER_MAX_GAP = 2 * FINGER_TRAVEL  # m: pad gap when fully open
FINGER_KP = 1500.0  # N / m: finger position actuator gain
FINGER_FORCE_LIMIT = 20.0  # N: squeezing force limit per finger
FINGER_FRICTION = 1.5  # sliding friction coefficient of the pads

# --- IK (damped least squares) -----------------------------------------------------------------------
IK_DAMPING = 0.05  # damping lambda of the DLS pseudo-inverse (m and rad mixed)
IK_MAX_ITERS = 40
IK_POS_TOL = 2e-4  # m
IK_ROT_TOL = 2e-3  # rad
IK_MAX_STEP = 0.4  # rad: largest joint change per IK iteration
IK_ROT_WEIGHT = 0.3  # m per rad: how much orientation error weighs against position error

# --- action / state layout ---------------------------------------------------------------------------
# Action: absolute TCP target in the world frame.
#   [0:3]  position x, y, z (m)
#   [3:9]  orientation "6D": first two columns of the rotation matrix R_world_tcp, column-major
#          (r00, r10, r20, r01, r11, r21); the env re-orthonormalises it (Gram-Schmidt)
#   [9]    gripper command in [0, 1]: 0 fully open, 1 closed
ACTION_NAMES = (
    "ee_x",
    "ee_y",
    "ee_z",
    "ee_r00",
    "ee_r10",
    "ee_r20",
    "ee_r01",
    "ee_r11",
    "ee_r21",
    "gripper",
)
ACTION_DIM = len(ACTION_NAMES)
ACTION_POS_LOW = (0.0, -0.7, -0.05)  # m: bounds of the position part of the action space
ACTION_POS_HIGH = (1.0, 0.7, 0.8)  # m
# State (agent_pos): measured TCP position (m), its 6D orientation (same encoding as the action),
# gripper closure in [0, 1] (0 open, 1 pads touching; same convention as the action), arm joints (rad).
STATE_NAMES = (
    *ACTION_NAMES,  # the measured counterparts of the commanded pose and gripper
    *(f"{name}_pos" for name in ARM_JOINTS),
)
STATE_DIM = len(STATE_NAMES)
STATE_POS_BOUND = 2.0  # m: |TCP position| bound of the observation space
STATE_ROT_BOUND = 1.001  # bound of the 6D entries (unit vectors, with float32 round-off room)
STATE_GRIPPER_RANGE = (-0.05, 1.05)  # gripper closure bounds (fingers may overshoot slightly)
STATE_JOINT_MARGIN = 0.1  # rad: allowed excursion beyond the joint ranges under contact

# --- success -----------------------------------------------------------------------------------------
REST_SPEED = 0.05  # m/s: an object moving slower than this is resting
