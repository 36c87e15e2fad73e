"""The calibrations of OmniD's controls: the same checkpoint evaluated with a calibration that lies.

- ``blind``: every camera turned away from the feature volume about its own optical centre (optical axis
  pointing from the volume's centre through the camera, every corner of the volume behind it): no anchor
  projects into any image, the images contribute nothing and only the state can drive the policy;
- ``scrambled``: the cameras' calibrations permuted (each camera gets the next one's, a cycle that leaves
  none in place): the images are real but the geometry that lifts them into the volume is wrong;
- ``perturbed``: every camera moved by ``PERTURBED_LEVEL`` cm and turned by as many degrees, in random
  directions drawn from a fixed seed (``omnid-robustness``'s first draw at that level): a rig measured
  with an error.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence

import torch

from lerobot_omnid.benchmark.methods import CONTROLS, PERTURBED_LEVEL
from lerobot_omnid.benchmark.robustness_plan import camera_offsets, perturbed_calibrations
from lerobot_omnid.calibration.schema import CameraCalibration
from lerobot_omnid.geometry import apply_transform, camera_centers_world, look_at
from lerobot_omnid.keys import IMAGE_KEY_PREFIX

NEAR_VERTICAL = (
    0.99  # |cos| of the angle between the turned camera's axis and world z above which world x is up
)


def volume_corners_world(bounds: Sequence[Sequence[float]]) -> torch.Tensor:
    """(8, 3) corners of the box ``bounds`` ((min, max) per world axis x, y, z), float64."""
    return torch.tensor(list(itertools.product(*bounds)), dtype=torch.float64)


def turned_away(
    calib: CameraCalibration, bounds: Sequence[Sequence[float]], camera: str
) -> CameraCalibration:
    """``calib`` rotated about its optical centre to look directly away from the centre of ``bounds``.

    The intrinsics are kept. Raises ValueError naming ``camera`` if a corner of the volume would still be
    in front of it (a camera inside the volume or too close to it to turn its back on all of it).
    """
    cam_T_world = torch.tensor(calib.T_cam_world, dtype=torch.float64)
    eye_world = camera_centers_world(cam_T_world)
    corners_world = volume_corners_world(bounds)
    centre_world = corners_world.mean(dim=0)
    away_world = eye_world - centre_world
    up_world = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)  # world x for a camera above the centre
    if abs(float(away_world @ up_world)) > NEAR_VERTICAL * float(away_world.norm()):
        up_world = torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)
    away_T_world = look_at(eye_world, eye_world + away_world, up_world)
    depth = apply_transform(away_T_world, corners_world)[:, 2]  # 8 corners, camera z
    if (depth >= 0).any():
        raise ValueError(
            f"{camera}: expected every corner of the volume {list(map(list, bounds))} behind the turned-away "
            f"camera at {eye_world.tolist()}, got depths {depth.tolist()} m"
        )
    return CameraCalibration(calib.K, tuple(map(tuple, away_T_world.tolist())), calib.image_size)


def permuted(calibrations: Mapping[str, CameraCalibration]) -> dict[str, CameraCalibration]:
    """Each camera gets the next camera's calibration (in the given order; the last gets the first's)."""
    keys = list(calibrations)
    if len(keys) < 2:
        raise ValueError(f"cameras: expected at least 2 calibrated cameras to permute, got {keys}")
    return {key: calibrations[keys[(i + 1) % len(keys)]] for i, key in enumerate(keys)}


def perturbed(calibrations: Mapping[str, CameraCalibration]) -> dict[str, CameraCalibration]:
    """Each camera (keyed by image feature key) moved and turned by ``PERTURBED_LEVEL`` in its calibration."""
    offsets = camera_offsets(PERTURBED_LEVEL, draw=1, seed=0)
    names = {key: key.removeprefix(IMAGE_KEY_PREFIX) for key in calibrations}
    unknown = [key for key, name in names.items() if name not in offsets]
    if unknown:
        raise ValueError(f"cameras: expected the benchmark's cameras {list(offsets)}, got {unknown}")
    moved = perturbed_calibrations({names[k]: c for k, c in calibrations.items()}, offsets)
    return {key: moved[name] for key, name in names.items()}


def control_calibrations(config: Mapping, control: str) -> dict[str, CameraCalibration]:
    """The calibrations of ``control`` for an OmniD checkpoint's ``config.json`` content."""
    if control not in CONTROLS:
        raise ValueError(f"control: expected one of {list(CONTROLS)}, got {control!r}")
    if config.get("frame_calibration"):
        raise ValueError(
            f"frame_calibration: expected a checkpoint with static calibration (a calibration file replaces "
            f"only that; train on a dataset recorded with omnid-record --static-calibration), got per-frame "
            f"calibration of {config['frame_calibration']}"
        )
    raw = config.get("camera_calibration") or {}
    if not raw:
        raise ValueError(
            f"camera_calibration: expected the calibrated cameras of an OmniD config, got {raw!r}"
        )
    calibrations = {key: CameraCalibration.from_dict(value, camera=key) for key, value in raw.items()}
    if control == "scrambled":
        return permuted(calibrations)
    if control == "perturbed":
        return perturbed(calibrations)
    return {key: turned_away(calib, config["volume_bounds"], key) for key, calib in calibrations.items()}
