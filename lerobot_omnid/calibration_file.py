"""Calibration files: one camera calibration per image feature key, in the schema of ``calibration.py``.

JSON, keyed by image feature key (``observation.images.<cam>``; a bare camera name is accepted too)::

    {"observation.images.cam_b": {"K": [[...]], "T_cam_world": [[...]], "image_size": [h, w]}, ...}
"""

from __future__ import annotations

import json
from pathlib import Path

from lerobot_omnid.calibration import CalibrationError, CameraCalibration


def image_key(camera: str) -> str:
    """``cam_b`` -> ``observation.images.cam_b``; full feature keys are returned unchanged."""
    return camera if camera.startswith("observation.image") else f"observation.images.{camera}"


def load_calibration_file(path: str | Path) -> dict[str, CameraCalibration]:
    """Read and validate a calibration file; errors name the file, the camera and the field."""
    path = Path(path)
    if not path.is_file():
        raise CalibrationError(f"calibration file {path} does not exist")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise CalibrationError(f"calibration file {path}: not valid JSON ({e})") from e
    if not isinstance(data, dict) or not data:
        raise CalibrationError(f"calibration file {path}: expected a non-empty object keyed by camera")
    return {
        image_key(cam): CameraCalibration.from_dict(calib, camera=f"{path.name}: {cam}")
        for cam, calib in data.items()
    }
