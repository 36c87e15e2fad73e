"""Named constants of the MetaWorld suite, with units.

Frames: the world frame is MetaWorld's own: the Sawyer's base at the origin, x to the robot's right,
y forward (away from the robot, over the table), z up, metres; z = 0 is the table top. Calibration
(``T_cam_world``), the hand position in the state and the action's position deltas are all in it.
"""

from __future__ import annotations

GYM_NAMESPACE = "gym_omnid_metaworld"  # gym ids are f"{GYM_NAMESPACE}/{task}"
# The v3 tasks of metaworld 3.0.0 (``metaworld.env_dict.ALL_V3_ENVIRONMENTS``), listed here so that
# registering the gym ids and validating configs never imports metaworld (tests check the two agree).
TASKS = (
    "assembly-v3",
    "basketball-v3",
    "bin-picking-v3",
    "box-close-v3",
    "button-press-topdown-v3",
    "button-press-topdown-wall-v3",
    "button-press-v3",
    "button-press-wall-v3",
    "coffee-button-v3",
    "coffee-pull-v3",
    "coffee-push-v3",
    "dial-turn-v3",
    "disassemble-v3",
    "door-close-v3",
    "door-lock-v3",
    "door-open-v3",
    "door-unlock-v3",
    "hand-insert-v3",
    "drawer-close-v3",
    "drawer-open-v3",
    "faucet-open-v3",
    "faucet-close-v3",
    "hammer-v3",
    "handle-press-side-v3",
    "handle-press-v3",
    "handle-pull-side-v3",
    "handle-pull-v3",
    "lever-pull-v3",
    "pick-place-wall-v3",
    "pick-out-of-hole-v3",
    "pick-place-v3",
    "plate-slide-v3",
    "plate-slide-side-v3",
    "plate-slide-back-v3",
    "plate-slide-back-side-v3",
    "peg-insert-side-v3",
    "peg-unplug-side-v3",
    "soccer-v3",
    "stick-push-v3",
    "stick-pull-v3",
    "push-v3",
    "push-wall-v3",
    "push-back-v3",
    "reach-v3",
    "reach-wall-v3",
    "shelf-place-v3",
    "sweep-into-v3",
    "sweep-v3",
    "window-open-v3",
    "window-close-v3",
)

# --- timing ------------------------------------------------------------------------------------------
CONTROL_FPS = 80  # Hz: one env step = MetaWorld's 5 physics steps of 2.5 ms
MAX_EPISODE_STEPS = 500  # env steps: MetaWorld's own horizon (``max_path_length``)

# --- cameras -----------------------------------------------------------------------------------------
# The scene's three fixed cameras; MetaWorld defines them upside down, the env turns them 180 degrees
# about their optical axis (same viewpoint, upright images, calibration of the turned camera).
FIXED_CAMERAS = ("corner", "corner2", "corner3")
# Cameras on the hand, calibrated per frame. behindGripper (60 deg fovy) looks down past the gripper from
# 0.5 m behind it and sees the fingers, the object in hand and the target together; gripperPOV (90 deg)
# sits beside the fingers and, once an object is grasped, sees little but that object.
HAND_CAMERAS = ("behindGripper", "gripperPOV")
HAND_CAMERA = "behindGripper"  # the hand camera of the default set
ALL_CAMERAS = (*FIXED_CAMERAS, *HAND_CAMERAS)  # every camera an env can observe
DEFAULT_CAMERAS = (*FIXED_CAMERAS, HAND_CAMERA)
DEFAULT_IMAGE_SIZE = 128  # px, square images unless (height, width) is given
MAX_IMAGE_SIDE = 2048  # px: upper bound accepted for one image side
RENDER_MOSAIC_COLUMNS = 2  # images per row in render()'s mosaic of the observed cameras

# --- state and action --------------------------------------------------------------------------------
# State: MetaWorld's proprioception, the first four entries of its flat observation.
STATE_NAMES = ("hand_x", "hand_y", "hand_z", "gripper_opening")  # m, m, m, finger gap / 10 cm in [0, 1]
STATE_LOW = (-0.525, 0.348, -0.0525, 0.0)  # MetaWorld's hand space (m) and the gripper's range
STATE_HIGH = (0.525, 1.025, 0.7, 1.0)
# Action: MetaWorld's, each in [-1, 1]: a hand position delta of up to 1 cm per axis per step (it moves
# the mocap target) and the gripper effort (-1 open, 1 close).
ACTION_NAMES = ("delta_x", "delta_y", "delta_z", "grab_effort")
ACTION_DIM = len(ACTION_NAMES)
STATE_DIM = len(STATE_NAMES)
