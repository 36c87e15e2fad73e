"""Camera calibration: the one schema shared by datasets, configs and checkpoints.

Convention (docs/calibration.md):
- world frame = robot base frame: x forward, y left, z up, metres; z = 0 is the table top;
- ``K`` (3x3, pixels) is for an image of ``image_size = (height, width)``; OpenCV pinhole, pixel
  centres at integer coordinates, u right, v down;
- ``T_cam_world`` (4x4) maps world points into the OpenCV camera frame (x right, y down, z forward):
  ``uv = K @ (T_cam_world @ X)[:3]`` divided by its third component.

In a LeRobot dataset the calibration of camera ``observation.images.<cam>`` lives in
``features["observation.images.<cam>"]["info"]["calibration"]`` as the JSON dict produced by
:meth:`CameraCalibration.to_dict`. Per-feature ``info`` survives video encoding and is copied into
``OmniDConfig.camera_calibration`` when the policy is made, so every checkpoint carries it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from lerobot_omnid.geometry import resize_intrinsics

CALIBRATION_INFO_KEY = "calibration"
"""Key of the calibration dict inside a dataset feature's ``info``."""

ASPECT_TOLERANCE = 0.01
"""Relative difference of the x and y scale factors of two image sizes still treated as a resize."""
_ROTATION_TOLERANCE = 1e-4


class CalibrationError(ValueError):
    """A calibration is missing or malformed; the message names the camera and the field."""


def _matrix(value: Any, rows: int, cols: int, where: str) -> tuple[tuple[float, ...], ...]:
    """Validate a nested sequence as a finite ``rows x cols`` matrix of floats."""
    shape_msg = f"{where}: expected a {rows}x{cols} matrix (list of {rows} lists of {cols} numbers)"
    if not isinstance(value, list | tuple) or len(value) != rows:
        raise CalibrationError(f"{shape_msg}, got {value!r}")
    out = []
    for row in value:
        if not isinstance(row, list | tuple) or len(row) != cols:
            raise CalibrationError(f"{shape_msg}, got row {row!r}")
        try:
            floats = tuple(float(x) for x in row)
        except (TypeError, ValueError) as e:
            raise CalibrationError(f"{shape_msg}, got non-numeric row {row!r}") from e
        if not all(math.isfinite(x) for x in floats):
            raise CalibrationError(f"{where}: expected finite numbers, got row {row!r}")
        out.append(floats)
    return tuple(out)


@dataclass(frozen=True)
class CameraCalibration:
    """Pinhole calibration of one camera for one image size.

    Args:
        K: 3x3 intrinsics in pixels for an image of ``image_size``.
        T_cam_world: 4x4 rigid transform from the world (robot base) frame to the OpenCV camera frame.
        image_size: (height, width) in pixels that ``K`` refers to.
        distortion: OpenCV distortion coefficients (k1, k2, p1, p2[, k3...]) of the raw images. OmniD
            assumes undistorted images; the sim cameras have none.
    """

    K: tuple[tuple[float, ...], ...]
    T_cam_world: tuple[tuple[float, ...], ...]
    image_size: tuple[int, int]
    distortion: tuple[float, ...] = ()

    @classmethod
    def from_dict(cls, data: Any, camera: str = "camera") -> CameraCalibration:
        """Parse and validate the JSON dict form; errors name ``camera`` and the field."""
        if not isinstance(data, Mapping):
            raise CalibrationError(f"{camera}: expected a calibration dict, got {type(data).__name__}")
        for field_name in ("K", "T_cam_world", "image_size"):
            if field_name not in data:
                raise CalibrationError(
                    f"{camera}: calibration field '{field_name}' is missing (got keys {sorted(data)})"
                )
        K = _matrix(data["K"], 3, 3, f"{camera}.K")
        T = _matrix(data["T_cam_world"], 4, 4, f"{camera}.T_cam_world")
        size = data["image_size"]
        if (
            not isinstance(size, list | tuple)
            or len(size) != 2
            or not all(isinstance(s, int) and not isinstance(s, bool) and s > 0 for s in size)
        ):
            raise CalibrationError(
                f"{camera}.image_size: expected [height, width] as two positive ints, got {size!r}"
            )
        distortion = data.get("distortion") or ()
        try:
            distortion = tuple(float(d) for d in distortion)
        except (TypeError, ValueError) as e:
            raise CalibrationError(
                f"{camera}.distortion: expected a list of numbers, got {distortion!r}"
            ) from e
        calib = cls(K=K, T_cam_world=T, image_size=(size[0], size[1]), distortion=distortion)
        calib.validate(camera)
        return calib

    def validate(self, camera: str = "camera") -> None:
        """Check that K is an upper-triangular pinhole matrix and T_cam_world a rigid transform."""
        (fx, _, _), (z0, fy, _), bottom = self.K
        if fx <= 0 or fy <= 0 or z0 != 0 or bottom != (0.0, 0.0, 1.0):
            raise CalibrationError(
                f"{camera}.K: expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got {self.K}"
            )
        if self.T_cam_world[3] != (0.0, 0.0, 0.0, 1.0):
            raise CalibrationError(
                f"{camera}.T_cam_world: expected last row [0, 0, 0, 1], got {list(self.T_cam_world[3])}"
            )
        R = [row[:3] for row in self.T_cam_world[:3]]
        for i in range(3):
            for j in range(3):
                dot = sum(R[i][k] * R[j][k] for k in range(3))
                if abs(dot - (1.0 if i == j else 0.0)) > _ROTATION_TOLERANCE:
                    raise CalibrationError(
                        f"{camera}.T_cam_world: rotation part is not orthonormal "
                        f"(row {i} . row {j} = {dot:.6f}, expected {float(i == j)})"
                    )
        det = (
            R[0][0] * (R[1][1] * R[2][2] - R[1][2] * R[2][1])
            - R[0][1] * (R[1][0] * R[2][2] - R[1][2] * R[2][0])
            + R[0][2] * (R[1][0] * R[2][1] - R[1][1] * R[2][0])
        )
        if det < 0:
            raise CalibrationError(f"{camera}.T_cam_world: rotation part is a reflection (det = {det:.4f})")

    def resized(self, image_hw: tuple[int, int]) -> CameraCalibration:
        """The same camera after resizing its whole image to ``image_hw`` = (height, width).

        Pixel centres stay at integer coordinates: ``u' = (u + 0.5) * sx - 0.5``, so the principal point
        moves by ``0.5 * sx - 0.5`` beyond its scaling. Distortion is in normalised coordinates and does
        not change. ``resized(image_size)`` returns ``self``.
        """
        height, width = (int(s) for s in image_hw)
        if (height, width) == self.image_size:
            return self
        if height < 1 or width < 1:
            raise CalibrationError(f"resized: expected a positive (height, width), got {tuple(image_hw)}")
        K = resize_intrinsics(torch.tensor(self.K, dtype=torch.float64), self.image_size, (height, width))
        return CameraCalibration(
            tuple(tuple(row) for row in K.tolist()), self.T_cam_world, (height, width), self.distortion
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable form, the one stored in dataset feature info and in config.json."""
        out: dict[str, Any] = {
            "K": [list(row) for row in self.K],
            "T_cam_world": [list(row) for row in self.T_cam_world],
            "image_size": list(self.image_size),
        }
        if self.distortion:
            out["distortion"] = list(self.distortion)
        return out


def calibration_from_feature_info(feature_key: str, feature: Mapping[str, Any]) -> CameraCalibration:
    """Read the calibration of one dataset image feature, raising a clear error when absent."""
    info = feature.get("info") or {}
    if CALIBRATION_INFO_KEY not in info:
        raise CalibrationError(
            f"{feature_key}: no camera calibration in the dataset feature info "
            f"(expected features['{feature_key}']['info']['{CALIBRATION_INFO_KEY}'] with K, T_cam_world, "
            f"image_size). Record with the omnid recorder or attach one to the dataset."
        )
    return CameraCalibration.from_dict(info[CALIBRATION_INFO_KEY], camera=feature_key)


def camera_matrices(
    calibrations: Sequence[CameraCalibration], image_hw: Sequence[tuple[int, int]]
) -> tuple[Tensor, Tensor]:
    """The tensors the OFG projects with, for images of the given sizes.

    Args:
        calibrations: S cameras.
        image_hw: S (height, width) pairs, the size of the image each camera's features come from.
    Returns:
        pix_T_cam (S, 3, 3) intrinsics for those sizes and cam_T_world (S, 4, 4), float32 on the CPU.
    """
    if len(calibrations) != len(image_hw):
        raise ValueError(f"camera_matrices: {len(calibrations)} calibrations for {len(image_hw)} image sizes")
    resized = [c.resized(hw) for c, hw in zip(calibrations, image_hw, strict=True)]
    pix_T_cam = torch.tensor([c.K for c in resized], dtype=torch.float32).reshape(-1, 3, 3)
    cam_T_world = torch.tensor([c.T_cam_world for c in resized], dtype=torch.float32).reshape(-1, 4, 4)
    return pix_T_cam, cam_T_world
