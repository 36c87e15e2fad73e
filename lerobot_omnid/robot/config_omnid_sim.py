"""``--robot.type=omnid_sim``: the ``gym_omnid`` scene as a LeRobot robot, for ``lerobot-record`` and
``lerobot-rollout``.

LeRobot finds the robot class by naming convention: ``OmniDSimConfig`` here, ``OmniDSim`` in the sibling
module ``omnid_sim`` (``make_device_from_device_class``).

Example::

    lerobot-record --robot.type=omnid_sim --robot.task=select_apple --robot.seed=0 \\
        --robot.cameras='{front: {source: cam_b, width: 64, height: 64}, left: {source: cam_c, ...}}' \\
        --teleop.type=omnid_expert --teleop.task=select_apple --teleop.seed=0 --dataset.fps=10 ...
"""

from __future__ import annotations

from dataclasses import dataclass, field

from gym_omnid.constants import (
    BACKGROUNDS,
    CAMERAS,
    CONTROL_FPS,
    DEFAULT_IMAGE_SIZE,
    DEFAULT_RIG,
    LAYOUTS,
    MAX_IMAGE_SIDE,
    RIGS,
    TASKS,
    TRAIN_CAMERAS,
)
from lerobot.robots.config import RobotConfig

from lerobot_omnid.cli import check_choice

ROBOT_TYPE = "omnid_sim"
"""The ``--robot.type`` of the sim robot, also its ``Robot.name`` and the datasets' ``robot_type``."""


def check_seed(field_name: str, value: object) -> None:
    """Raise ``ValueError`` naming the field unless ``value`` is an int >= 0 (a gymnasium reset seed)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"`{field_name}`: expected an integer >= 0, got {value!r}")


@dataclass
class OmniDSimCameraConfig:
    """One camera of the sim robot: which ``gym_omnid`` camera it renders, at what size and rate.

    Args:
        source: The fixed ``gym_omnid`` camera (``cam_a`` ... ``cam_e``); None: the robot camera's own
            name, which must then be one of them. The env's wrist camera is not offered: its pose moves
            with the arm and needs per-frame calibration (docs/real_robot.md).
        width: Image width, pixels.
        height: Image height, pixels. Every camera of one robot has the same size (the env renders all
            its cameras at one size).
        fps: Frames per second; the sim steps at a fixed ``gym_omnid.CONTROL_FPS`` (10 Hz), so this
            must be 10, and so must ``--dataset.fps`` / ``--fps`` of the LeRobot command.
    """

    source: str | None = None
    width: int = DEFAULT_IMAGE_SIZE
    height: int = DEFAULT_IMAGE_SIZE
    fps: int = CONTROL_FPS


def _default_cameras() -> dict[str, OmniDSimCameraConfig]:
    return {cam: OmniDSimCameraConfig() for cam in TRAIN_CAMERAS}


@RobotConfig.register_subclass(ROBOT_TYPE)
@dataclass(kw_only=True)
class OmniDSimConfig(RobotConfig):
    """The simulated 6-DoF arm of ``gym_omnid`` on its table, with fixed calibrated cameras.

    The arm is commanded like the env (``gym_omnid`` README): an absolute tool-centre-point target in the
    robot base frame (position, 6D orientation) and a gripper command, applied by IK; each
    ``send_action`` advances the physics by one 0.1 s control step. ``connect`` builds the scene and
    resets it with ``seed``; one connection is one scene (a real robot's scene is reset by a person
    between episodes, and LeRobot tells a robot nothing about episodes: record one episode per
    ``lerobot-record`` run and merge the datasets, see docs/real_robot.md).

    The fields a user changes are ``task``, ``layout``, ``background``, ``seed``, ``rig`` and ``cameras``.

    Args:
        task: Benchmark task, one of ``gym_omnid.TASKS``.
        layout: Object placement, ``"id"`` or ``"position_ood"``.
        background: Table texture, ``"id"`` or ``"ood1"`` ... ``"ood4"``.
        seed: Reset seed of the scene (the object layout). Give the expert teleoperator the same one.
        rig: Placement of the fixed cameras, one of ``gym_omnid.RIGS`` (``"default"``, or the same
            cameras moved by 8-17 cm and turned by 5-14 degrees).
        cameras: Robot camera name (the dataset key ``observation.images.<name>``) -> camera.
            Default: the benchmark's training cameras B-E under their own names at 128x128. On the
            command line: ``--robot.cameras='{front: {source: cam_b, width: 64, height: 64}}'``.
    """

    task: str = "select_apple"
    layout: str = "id"
    background: str = "id"
    seed: int = 0
    rig: str = DEFAULT_RIG
    cameras: dict[str, OmniDSimCameraConfig] = field(default_factory=_default_cameras)

    def __post_init__(self) -> None:
        super().__post_init__()
        check_choice("task", self.task, TASKS)
        check_choice("layout", self.layout, LAYOUTS)
        check_choice("background", self.background, BACKGROUNDS)
        check_seed("seed", self.seed)
        check_choice("rig", self.rig, RIGS)
        if not isinstance(self.cameras, dict) or not self.cameras:
            raise ValueError(
                f"`cameras`: expected a non-empty mapping of camera name -> {{source, width, height, fps}}, "
                f"got {self.cameras!r}"
            )
        for name, cam in self.cameras.items():
            if cam.source is None:
                cam.source = name
            check_choice(f"cameras.{name}.source", cam.source, CAMERAS)
            for side in ("width", "height"):
                value = getattr(cam, side)
                if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_IMAGE_SIDE:
                    raise ValueError(
                        f"`cameras.{name}.{side}`: expected an int number of pixels in "
                        f"[1, {MAX_IMAGE_SIDE}], got {value!r}"
                    )
            if cam.fps != CONTROL_FPS:
                raise ValueError(
                    f"`cameras.{name}.fps`: the sim steps at a fixed {CONTROL_FPS} Hz; expected "
                    f"{CONTROL_FPS}, got {cam.fps!r}"
                )
        sources = [cam.source for cam in self.cameras.values()]
        if len(set(sources)) != len(sources):
            raise ValueError(f"`cameras`: expected distinct sources, got {sources}")
        sizes = {(cam.height, cam.width) for cam in self.cameras.values()}
        if len(sizes) > 1:
            raise ValueError(
                f"`cameras`: expected one image size for every camera (the env renders all at one size), "
                f"got (height, width) {sorted(sizes)}"
            )

    @property
    def image_size(self) -> tuple[int, int]:
        """(height, width) of every camera's images."""
        cam = next(iter(self.cameras.values()))
        return cam.height, cam.width
