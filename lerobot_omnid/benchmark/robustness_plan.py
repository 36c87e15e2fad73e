"""What ``omnid-robustness`` runs: the perturbations, each checkpoint's cells and their ``lerobot-eval`` runs.

Pure: builds offsets, calibrations, command lines and paths; reads and runs nothing. A perturbation of
level ``L`` moves every camera's optical centre by exactly ``L`` cm in a random direction and turns it by
exactly ``L`` degrees about a random axis, as ``T_cam_world' = [R | t] @ T_cam_world`` (camera frame; the
convention of :func:`lerobot_omnid.geometry.perturb_extrinsics` and of the env option ``camera_offsets``).
Draw ``d`` has the same directions at every level (seeded by the perturbation seed and ``d``) and for every
checkpoint, so the curves are paired. The same offsets serve two conditions that mirror each other:

- ``calibration``: the scene unchanged, the policy given the perturbed calibration
  (``--policy.calibration_path``; OmniD only, other policies have no calibration);
- ``bumped``: the cameras of the scene moved by the offsets (``--env.camera_offsets``), the policy keeps
  its calibration.

A dead camera (``dead_*``) delivers black frames from the first step (``dead_black``) or from the middle of
the episode (``dead_black_mid``), or, for OmniD, is removed from the inputs (``dead_removed``:
``--policy.cameras`` and ``--env.cameras`` without it). Controls: ``blind`` (OmniD with every camera turned
away in its calibration, other policies with black images) and OmniD's ``scrambled`` geometry.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch
from gym_omnid.constants import CAMERAS

from lerobot_omnid.benchmark.commands import eval_command, json_list
from lerobot_omnid.benchmark.methods import control_flags
from lerobot_omnid.benchmark.plan import EVAL_SEED_STRIDE
from lerobot_omnid.calibration.schema import CameraCalibration
from lerobot_omnid.geometry import axis_angle_to_matrix, perturb_extrinsics, random_unit_vectors
from lerobot_omnid.keys import image_key
from lerobot_omnid.measure.engine import Run, plan
from lerobot_omnid.measure.results import tags_of

LEVELS = (0.0, 0.5, 1.0, 2.0, 4.0)
"""Perturbation levels: cm of translation and degrees of rotation together."""
CM = 0.01  # metres per centimetre
DRAW_SEED_STRIDE = 1000  # generator seed of draw d: perturbation seed * stride + d (so draws < stride)
OFFSET_DECIMALS = (
    9  # offsets are rounded once, so the env option and the calibration file get the same numbers
)
GROUPS = ("calibration", "bumped", "dead", "controls")
"""Condition groups a run may select (``--conditions``); the unperturbed ``nominal`` cell is always run."""
DEAD = ("dead_removed", "dead_black", "dead_black_mid")
CONTROLS = ("blind", "scrambled")
OMNID_ONLY = ("calibration", "dead_removed", "scrambled")
LABELS = {
    "nominal": "as trained",
    "calibration": "calibration error (scene unchanged)",
    "bumped": "bumped cameras (calibration unchanged)",
    "dead_removed": "dead camera, removed from the inputs",
    "dead_black": "dead camera, black from the first step",
    "dead_black_mid": "dead camera, black from mid-episode",
    "blind": "blind control",
    "scrambled": "scrambled-geometry control",
}


@dataclass(frozen=True)
class Checkpoint:
    """A LeRobot checkpoint to evaluate: ``label`` (unique, names its folders), its ``pretrained_model``
    folder, policy type, image cameras (fixed env cameras), square image side, its cameras' calibrations
    by camera name (OmniD; empty for other policies) and its training seed (if known)."""

    label: str
    path: Path
    policy_type: str
    cameras: tuple[str, ...]
    image_size: int
    calibrations: Mapping[str, CameraCalibration]
    train_seed: int | None = None

    @property
    def is_omnid(self) -> bool:
        return self.policy_type == "omnid"


def checkpoint_from_config(
    label: str, path: Path, config: Mapping[str, Any], train_config: Mapping[str, Any] | None = None
) -> Checkpoint:
    """The :class:`Checkpoint` of a ``config.json`` (and ``train_config.json``) content; ValueErrors name the
    checkpoint and the field."""
    where = f"--checkpoint {label}={path}"
    features = config.get("input_features") or {}
    images = {k: v for k, v in features.items() if v.get("type") == "VISUAL"}
    cameras = tuple(k.removeprefix(image_key("")) for k in images)
    if not cameras or not set(cameras) <= set(CAMERAS):
        raise ValueError(
            f"{where}: input_features: expected images of fixed cameras from {list(CAMERAS)}, got "
            f"{list(images)}"
        )
    sizes = {tuple(v.get("shape", ())) for v in images.values()}
    if len(sizes) != 1 or len(shape := next(iter(sizes))) != 3 or shape[1] != shape[2]:
        raise ValueError(f"{where}: input_features: expected square images of one size, got shapes {sizes}")
    calibrations: dict[str, CameraCalibration] = {}
    if config.get("type") == "omnid":
        if config.get("frame_calibration"):
            raise ValueError(
                f"{where}: frame_calibration: expected a static calibration (perturbed per file), got "
                f"per-frame calibration of {config['frame_calibration']}"
            )
        raw = config.get("camera_calibration") or {}
        missing = [image_key(c) for c in cameras if image_key(c) not in raw]
        if missing:
            raise ValueError(f"{where}: camera_calibration: expected every image input, missing {missing}")
        calibrations = {c: CameraCalibration.from_dict(raw[image_key(c)], image_key(c)) for c in cameras}
    seed = (train_config or {}).get("seed")
    return Checkpoint(label, path, str(config.get("type")), cameras, int(shape[1]), calibrations, seed)


@dataclass(frozen=True)
class Cell:
    """One condition of a checkpoint: ``condition`` (a key of ``LABELS``), the ``level`` (cm and degrees)
    and ``draw`` (from 1) of a perturbation, the dead ``camera``."""

    condition: str
    level: float = 0.0
    draw: int = 0
    camera: str = ""

    @property
    def name(self) -> str:
        """Relative folder name, unique per checkpoint: ``nominal``, ``calibration/1cm_1deg/draw2``, ..."""
        if self.condition in ("calibration", "bumped"):
            return f"{self.condition}/{self.level:g}cm_{self.level:g}deg/draw{self.draw}"
        if self.condition in DEAD:
            return f"{self.condition}/{self.camera}"
        return self.condition


@dataclass(frozen=True)
class RobustnessSettings:
    """Sizes and choices of one run of ``omnid-robustness``."""

    task: str
    levels: tuple[float, ...] = LEVELS
    draws: int = 3
    perturbation_seed: int = 0
    eval_seeds: tuple[int, ...] = (1,)
    episodes: int = 10
    episode_length: int = 200
    groups: tuple[str, ...] = GROUPS
    dead_cameras: tuple[str, ...] | None = None  # None: every camera of each checkpoint
    device: str = "cpu"
    batch_size: int = 5  # envs run at once by each lerobot-eval (episode i still has env seed seed + i)
    draw_ids: tuple[int, ...] = ()  # only these draws of each level (e.g. the worst ones); empty: 1 .. draws

    @property
    def draw_numbers(self) -> tuple[int, ...]:
        """The draws of each level that run: ``draw_ids`` if given, else 1 .. ``draws``."""
        return self.draw_ids or tuple(range(1, self.draws + 1))

    @property
    def mid_episode_step(self) -> int:
        """First black step of ``dead_black_mid``."""
        return self.episode_length // 2


def camera_offsets(level: float, draw: int, seed: int) -> dict[str, tuple[float, ...]]:
    """Per fixed camera (all of ``CAMERAS``, so a camera's offset does not depend on which others a checkpoint
    uses): ``(rx, ry, rz, tx, ty, tz)``, the rotation vector (degrees) of a turn by ``level`` degrees about a
    random axis and a translation of ``level`` cm in a random direction, camera frame, rounded to
    ``OFFSET_DECIMALS``. The directions depend only on ``seed`` and ``draw``."""
    if not 1 <= draw < DRAW_SEED_STRIDE:
        raise ValueError(f"draw: expected an int in [1, {DRAW_SEED_STRIDE - 1}], got {draw!r}")
    generator = torch.Generator().manual_seed(seed * DRAW_SEED_STRIDE + draw)
    directions = random_unit_vectors((len(CAMERAS), 2), generator=generator, dtype=torch.float64)
    rotation_deg, translation_m = directions[:, 0] * level, directions[:, 1] * level * CM  # cameras, 3
    offsets = torch.cat([rotation_deg, translation_m], dim=-1).round(decimals=OFFSET_DECIMALS)
    return {cam: tuple(offsets[i].tolist()) for i, cam in enumerate(CAMERAS)}


def offset_parts(offset: Sequence[float]) -> tuple[torch.Tensor, torch.Tensor]:
    """(rotation (3, 3), translation (3,) m), float64, of an offset ``(rx, ry, rz (deg), tx, ty, tz (m))``."""
    rotvec_deg = torch.tensor(offset[:3], dtype=torch.float64)
    angle_deg = rotvec_deg.norm()
    axis = rotvec_deg / angle_deg if angle_deg > 0 else rotvec_deg  # any axis turns by a zero angle
    return axis_angle_to_matrix(axis, torch.deg2rad(angle_deg)), torch.tensor(offset[3:], dtype=torch.float64)


def perturbed_calibrations(
    calibrations: Mapping[str, CameraCalibration], offsets: Mapping[str, Sequence[float]]
) -> dict[str, CameraCalibration]:
    """Each camera's calibration with ``T_cam_world`` replaced by ``[R | t] @ T_cam_world`` of its offset
    (:func:`lerobot_omnid.geometry.perturb_extrinsics`; intrinsics and image size kept), keyed like
    ``calibrations``."""
    out = {}
    for cam, calib in calibrations.items():
        rotation, translation_m = offset_parts(offsets[cam])
        cam_T_world = torch.tensor(calib.T_cam_world, dtype=torch.float64)
        moved = perturb_extrinsics(cam_T_world, rotation, translation_m)
        out[cam] = CameraCalibration(calib.K, tuple(map(tuple, moved.tolist())), calib.image_size)
    return out


def dead_cameras(checkpoint: Checkpoint, settings: RobustnessSettings) -> tuple[str, ...]:
    """The cameras of ``checkpoint`` killed in turn; a ValueError names one that is not among its inputs."""
    if settings.dead_cameras is None:
        return checkpoint.cameras
    missing = [c for c in settings.dead_cameras if c not in checkpoint.cameras]
    if missing:
        raise ValueError(
            f"--dead-cameras: expected inputs of checkpoint {checkpoint.label} {list(checkpoint.cameras)}, "
            f"got {missing}"
        )
    return settings.dead_cameras


def plan_cells(checkpoint: Checkpoint, settings: RobustnessSettings) -> list[Cell]:
    """Every cell of ``checkpoint``, in report order; conditions a policy has no use for are left out (see
    the module): OmniD-only ones for other policies, removal for a single camera."""
    cells = [Cell("nominal")]
    levels = [level for level in settings.levels if level > 0]  # level 0 is the nominal cell
    for condition in ("calibration", "bumped"):
        if condition in settings.groups and (checkpoint.is_omnid or condition not in OMNID_ONLY):
            cells += [Cell(condition, lv, d) for lv in levels for d in settings.draw_numbers]
    if "dead" in settings.groups:
        for condition in DEAD:
            if condition == "dead_removed" and (not checkpoint.is_omnid or len(checkpoint.cameras) < 2):
                continue
            cells += [Cell(condition, camera=cam) for cam in dead_cameras(checkpoint, settings)]
    if "controls" in settings.groups:
        cells += [Cell(c) for c in CONTROLS if checkpoint.is_omnid or c not in OMNID_ONLY]
    return cells


def calibration_file(out: Path, checkpoint: Checkpoint, cell: Cell) -> Path | None:
    """Where ``cell``'s calibration file is written, or None if it has none."""
    if not checkpoint.is_omnid or cell.condition not in ("calibration", *CONTROLS):
        return None
    return out / "calibration" / checkpoint.label / f"{cell.name}.json"


def eval_dir(out: Path, checkpoint: Checkpoint, cell: Cell, eval_seed: int) -> Path:
    return out / "eval" / checkpoint.label / cell.name / f"seed{eval_seed}"


def cell_options(
    checkpoint: Checkpoint, cell: Cell, settings: RobustnessSettings, out: Path
) -> tuple[tuple[str, ...], list[str]]:
    """(env cameras, extra ``lerobot-eval`` options) of ``cell``."""
    cameras = checkpoint.cameras
    options = [f"--env.episode_length={settings.episode_length}"]
    if cell.condition == "calibration":
        options.append(f"--policy.calibration_path={calibration_file(out, checkpoint, cell)}")
    elif cell.condition == "bumped":
        offsets = camera_offsets(cell.level, cell.draw, settings.perturbation_seed)
        offsets = {cam: list(offsets[cam]) for cam in cameras}
        options.append("--env.camera_offsets=" + json.dumps(offsets, separators=(",", ":")))
    elif cell.condition == "dead_removed":
        cameras = tuple(c for c in cameras if c != cell.camera)
        options.append("--policy.cameras=" + json_list(cameras))
    elif cell.condition in ("dead_black", "dead_black_mid"):
        options.append(f"--env.blackout_cameras=[{cell.camera}]")
        if cell.condition == "dead_black_mid":
            options.append(f"--env.blackout_from_step={settings.mid_episode_step}")
    elif cell.condition in CONTROLS:
        method = "omnid" if checkpoint.is_omnid else checkpoint.policy_type
        file = calibration_file(out, checkpoint, cell) or ""
        options += [flag for flag, _ in control_flags(method, cell.condition, cameras, file)]
    return cameras, options


def build_runs(checkpoints: Sequence[Checkpoint], settings: RobustnessSettings, out: Path) -> list[Run]:
    """One ``lerobot-eval`` run per checkpoint, cell and eval seed (seed k: env seeds k*1000, k*1000+1, ...,
    disjoint from the training recordings' 0, 1, ...)."""
    runs = []
    for checkpoint in checkpoints:
        for cell in plan_cells(checkpoint, settings):
            cameras, options = cell_options(checkpoint, cell, settings, out)
            for k in settings.eval_seeds:
                output = eval_dir(out, checkpoint, cell, k)
                cmd = eval_command(
                    checkpoint.path,
                    output,
                    settings.task,
                    "id",
                    cameras,
                    checkpoint.image_size,
                    settings.episodes,
                    settings.device,
                    seed=k * EVAL_SEED_STRIDE,
                    extra=options,
                    batch_size=min(settings.batch_size, settings.episodes),
                )
                result = (checkpoint.label, settings.task, cell.name)
                name = f"{checkpoint.label}/{cell.name}/seed{k}"
                calibration = calibration_file(out, checkpoint, cell)
                inputs = (
                    checkpoint.path / "model.safetensors",
                    checkpoint.path / "config.json",
                    *((calibration,) if calibration else ()),
                )
                runs.append(
                    Run(
                        name,
                        "eval",
                        tuple(cmd),
                        output,
                        inputs=inputs,
                        result=result,
                        seed=k,
                        train_seed=checkpoint.train_seed,
                        tags=tags_of(asdict(cell)),
                    )
                )
    return plan(runs, out)
