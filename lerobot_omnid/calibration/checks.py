"""Checks of a rig's calibration against a LeRobot dataset, before ``omnid-attach-calibration`` writes it.

Pure: from a dataset's ``info.json`` dict and the calibrations, :func:`plan_attachment` returns the new
``info`` dict and a report per camera, or raises :class:`CalibrationError` listing every problem (camera
and field named). Per camera: an image feature with a calibration (unless skipped), an image size equal to
the calibration's or a uniform resize of it, no unhandled lens distortion, and a view of the policy's
feature volume (enough of it in front of the camera and inside the image).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import cv2
import numpy as np

from lerobot_omnid.calibration.schema import (
    ASPECT_TOLERANCE,
    CALIBRATION_INFO_KEY,
    CalibrationError,
    CameraCalibration,
)
from lerobot_omnid.geometry import DEPTH_EPS, PAPER_VOLUME_BOUNDS
from lerobot_omnid.keys import image_key

SOURCE_INFO_KEY = "calibration_source"
"""Key, next to ``calibration`` in a feature's ``info``, recording where the calibration came from."""
DISTORTION_MODES = ("refuse", "undistorted", "ignore")
DEFAULT_VOLUME_BOUNDS = PAPER_VOLUME_BOUNDS  # OmniDConfig's default volume
DEFAULT_MIN_VISIBLE = 0.1  # fraction of the volume's grid points that must project into the image
MIN_EXTENT = 0.1  # the volume's projection must span this fraction of the image diagonal
VOLUME_GRID_POINTS = 9  # grid points per axis of the volume for the visibility check
DISTORTION_GRID = 33  # pixels per side of the grid on which the distortion's pixel shift is measured


@dataclass
class CameraReport:
    """What will be attached for one camera, and the notes printed about it."""

    key: str
    calibration: CameraCalibration
    visible_fraction: float
    notes: list[str] = field(default_factory=list)

    def line(self) -> str:
        world_T_cam = np.linalg.inv(np.asarray(self.calibration.T_cam_world))
        centre = ", ".join(f"{v:+.3f}" for v in world_T_cam[:3, 3])
        notes = "; ".join(self.notes)
        return (
            f"{self.key}: camera at ({centre}) m, sees {self.visible_fraction:.0%} of the workspace volume"
            + (f"; {notes}" if notes else "")
        )


def dataset_image_size(key: str, feature: Mapping[str, Any]) -> tuple[int, int]:
    """(height, width) of an image feature, from its ``shape`` and ``names`` (HWC unless named)."""
    shape = list(feature.get("shape") or [])
    names = list(feature.get("names") or [])
    if len(shape) != 3:
        raise CalibrationError(f"{key}: expected an image feature of 3 dimensions, got shape {shape}")
    if len(names) == 3 and "height" in names and "width" in names:
        return int(shape[names.index("height")]), int(shape[names.index("width")])
    if shape[0] in (1, 3) and shape[2] not in (1, 3):
        return int(shape[1]), int(shape[2])
    return int(shape[0]), int(shape[1])


def max_distortion_shift_px(calib: CameraCalibration) -> float:
    """Largest distance (px) between a raw pixel and its undistorted position, over a grid on the image."""
    if not any(calib.distortion):
        return 0.0
    height, width = calib.image_size
    us, vs = np.meshgrid(
        np.linspace(0, width - 1, DISTORTION_GRID), np.linspace(0, height - 1, DISTORTION_GRID)
    )
    uv = np.stack([us.ravel(), vs.ravel()], axis=1).reshape(-1, 1, 2)
    K = np.asarray(calib.K)
    undistorted = cv2.undistortPoints(uv, K, np.asarray(calib.distortion), P=K)
    return float(np.linalg.norm(undistorted - uv, axis=-1).max())


class VolumeView(NamedTuple):
    """How a camera sees the workspace volume.

    Args:
        centre_depth: depth of the volume's centre along the optical axis, metres (negative: behind).
        visible: fraction of a grid of points in the volume that project into the image.
        extent: diagonal of the bounding box of those projections over the image's diagonal (a volume
            that shrinks to a few pixels, e.g. extrinsics in millimetres, has a tiny extent).
    """

    centre_depth: float
    visible: float
    extent: float


def volume_view(
    K: np.ndarray, cam_T_world: np.ndarray, image_size: tuple[int, int], volume_bounds
) -> VolumeView:
    """Project a grid over the volume (robot base frame) into the camera; see :class:`VolumeView`."""
    axes = [np.linspace(lo, hi, VOLUME_GRID_POINTS) for lo, hi in volume_bounds]
    xyz_world = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    centre_world = np.array([(lo + hi) / 2 for lo, hi in volume_bounds])
    xyz_cam = xyz_world @ cam_T_world[:3, :3].T + cam_T_world[:3, 3]
    depth = xyz_cam[:, 2]
    in_front = depth > DEPTH_EPS
    uv_pix = (xyz_cam @ K.T)[:, :2] / np.where(in_front, depth, 1.0)[:, None]
    height, width = image_size
    inside = in_front & (uv_pix[:, 0] >= -0.5) & (uv_pix[:, 0] <= width - 0.5)
    inside &= (uv_pix[:, 1] >= -0.5) & (uv_pix[:, 1] <= height - 0.5)
    extent = 0.0
    if inside.any():
        span = uv_pix[inside].max(axis=0) - uv_pix[inside].min(axis=0)
        extent = float(np.linalg.norm(span) / np.hypot(width, height))
    centre_depth = float((cam_T_world[:3, :3] @ centre_world + cam_T_world[:3, 3])[2])
    return VolumeView(centre_depth, float(inside.mean()), extent)


def _check_camera(
    key: str,
    calib: CameraCalibration,
    feature: Mapping[str, Any],
    volume_bounds,
    min_visible: float,
    distortion_mode: str,
    problems: list[str],
) -> CameraReport | None:
    """Validate one camera against its dataset feature: append its problems to ``problems``, or return
    the report with the calibration to attach (rescaled, distortion handled)."""
    notes: list[str] = []
    size = dataset_image_size(key, feature)
    if tuple(calib.image_size) != size:
        (fh, fw), (dh, dw) = calib.image_size, size
        sx, sy = dw / fw, dh / fh
        if (fh, fw) == (dw, dh):
            problems.append(
                f"{key}.image_size: {[fh, fw]} is the dataset's [height, width] = {[dh, dw]} swapped; "
                f"image_size is [height, width]"
            )
            return None
        if abs(sx / sy - 1.0) > ASPECT_TOLERANCE:
            problems.append(
                f"{key}.image_size: calibrated for {fw}x{fh} px but the dataset stores {dw}x{dh} px, another "
                f"aspect ratio (cropped images?): calibrate at the dataset's resolution"
            )
            return None
        calib = calib.resized(size)
        notes.append(f"K rescaled from {fw}x{fh} to {dw}x{dh} px")
    if calib.distortion and not any(calib.distortion):
        calib = CameraCalibration(calib.K, calib.T_cam_world, calib.image_size, ())  # all zero: none
    shift = max_distortion_shift_px(calib)
    if shift > 0.0:
        if distortion_mode == "refuse":
            problems.append(
                f"{key}.distortion: non-zero (moves pixels by up to {shift:.1f} px) but OmniD assumes "
                f"undistorted pinhole images. Pass --distortion undistorted if the dataset's frames were "
                f"undistorted with this K, --distortion ignore to accept the pinhole approximation of raw "
                f"frames, or recalibrate with omnid-calibrate camera --pinhole"
            )
            return None
        if distortion_mode == "undistorted":
            calib = CameraCalibration(calib.K, calib.T_cam_world, calib.image_size, ())
            notes.append("frames already undistorted: distortion dropped")
        else:
            notes.append(
                f"distortion ignored (raw frames deviate from the pinhole model by up to {shift:.1f} px)"
            )
    K, cam_T_world = np.asarray(calib.K), np.asarray(calib.T_cam_world)
    view = volume_view(K, cam_T_world, calib.image_size, volume_bounds)
    inverse = volume_view(K, np.linalg.inv(cam_T_world), calib.image_size, volume_bounds)
    if view.centre_depth <= 0:
        problem = f"the workspace volume's centre is behind the camera (depth {view.centre_depth:+.2f} m)"
    elif view.visible < min_visible:
        problem = f"only {view.visible:.1%} of the workspace volume is in the image (need {min_visible:.0%})"
    elif view.extent < MIN_EXTENT:
        problem = (
            f"the workspace volume spans only {view.extent:.1%} of the image diagonal: is the translation "
            f"in metres?"
        )
    else:
        problem = None
    if problem is not None:
        hint = (
            " The inverse transform would see it: was the camera pose (T_world_cam) given as T_cam_world?"
            if inverse.centre_depth > 0 and inverse.visible >= min_visible
            else " Check that the extrinsics are in the robot base frame (metres) and the volume bounds."
        )
        problems.append(
            f"{key}.T_cam_world: {problem}, volume bounds {list(map(list, volume_bounds))}.{hint}"
        )
        return None
    if inverse.visible > view.visible:
        notes.append(
            f"warning: the inverse of T_cam_world would see more of the volume ({inverse.visible:.0%}): "
            f"check that T_cam_world maps world points into the camera frame"
        )
    return CameraReport(key, calib, view.visible, notes)


def plan_attachment(
    info: Mapping[str, Any],
    calibrations: Mapping[str, CameraCalibration],
    volume_bounds=DEFAULT_VOLUME_BOUNDS,
    min_visible: float = DEFAULT_MIN_VISIBLE,
    distortion: str = "refuse",
    skip: Sequence[str] = (),
    overwrite: bool = False,
    source: Mapping[str, Any] | None = None,
) -> tuple[dict[str, Any], list[CameraReport]]:
    """Validate ``calibrations`` against a dataset's ``info.json`` dict; return the new info and reports.

    Raises :class:`CalibrationError` listing every problem (camera and field); ``info`` is not modified.
    """
    if distortion not in DISTORTION_MODES:
        raise CalibrationError(f"--distortion must be one of {list(DISTORTION_MODES)}, got {distortion!r}")
    features = info.get("features")
    if not isinstance(features, Mapping):
        raise CalibrationError("meta/info.json has no 'features': not a LeRobot dataset")
    image_keys = [k for k, ft in features.items() if ft.get("dtype") in ("video", "image")]
    skip_keys = [image_key(c) for c in skip]
    problems = [
        f"--skip-camera {k}: not an image feature of the dataset {image_keys}"
        for k in skip_keys
        if k not in image_keys
    ]
    wanted = [k for k in image_keys if k not in skip_keys]
    problems += [
        f"{k}: no calibration in the file (the dataset's image features are {image_keys}; use --skip-camera "
        f"for a camera OmniD should not use)"
        for k in wanted
        if k not in calibrations
    ]
    problems += [
        f"{k}: in the calibration file but not an image feature of the dataset (image features: {image_keys})"
        for k in calibrations
        if k not in image_keys
    ]
    reports = []
    for key in wanted:
        if key not in calibrations:
            continue
        report = _check_camera(
            key, calibrations[key], features[key], volume_bounds, min_visible, distortion, problems
        )
        if report is None:
            continue
        existing = (features[key].get("info") or {}).get(CALIBRATION_INFO_KEY)
        if existing is not None and existing != report.calibration.to_dict():
            if not overwrite:
                problems.append(
                    f"{key}: the dataset already has a different calibration; pass --overwrite to replace it"
                )
                continue
            report.notes.append("replaces the previous calibration")
        reports.append(report)
    if problems:
        raise CalibrationError("calibration not attached, nothing was written:\n  " + "\n  ".join(problems))
    new_info = copy.deepcopy(dict(info))
    for report in reports:
        feature = new_info["features"][report.key]
        feature["info"] = {
            **(feature.get("info") or {}),
            CALIBRATION_INFO_KEY: report.calibration.to_dict(),
            SOURCE_INFO_KEY: {**(source or {}), "distortion": distortion, "notes": report.notes},
        }
    return new_info, reports
