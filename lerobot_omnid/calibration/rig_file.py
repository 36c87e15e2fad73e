"""Calibration files: the calibration of a camera rig, one entry per camera, as JSON or YAML.

The file maps each camera (its image feature key ``observation.images.<cam>``, or the bare name
``<cam>``) to one calibration. Conventions are those of :mod:`lerobot_omnid.calibration.schema`: the world
frame is the robot base frame (x forward, y left, z up, metres, z = 0 on the table top); ``K`` is the
OpenCV pinhole matrix for images of ``image_size``, pixel centres at integer coordinates.

Per camera:

- ``image_size``: ``[height, width]`` in pixels that ``K`` refers to (note: OpenCV's ``imageSize``
  is ``(width, height)``; this file uses height first, like image arrays).
- ``K``: 3x3 ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``, pixels.
- exactly one of
    - ``T_cam_world``: 4x4, maps world points into the OpenCV camera frame (x right, y down,
      z forward): ``X_cam = T_cam_world @ X_world``. OpenCV's ``solvePnP`` against world points gives
      this (``rvec``, ``tvec``).
    - ``T_world_cam``: 4x4, the camera's pose in the world: its last column is the camera's optical
      centre in world coordinates, its rotation columns the camera's x (right), y (down) and z (optical
      axis) in world coordinates. Inverted on load.
- ``distortion`` (optional): OpenCV coefficients ``[k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[,
  tx, ty]]]]]`` (4, 5, 8, 12 or 14 numbers) of the images ``K`` describes. OmniD assumes undistorted
  pinhole images; ``omnid-attach-calibration`` refuses non-zero distortion unless told how the dataset's
  images relate to it.
- ``meta`` (optional): free-form notes (reprojection errors, board, date); never used by OmniD.

Any other key is an error, so that a misspelt field is not silently ignored. Example (YAML)::

    observation.images.front:
      image_size: [480, 640]
      K: [[615.2, 0.0, 319.1], [0.0, 615.8, 241.3], [0.0, 0.0, 1.0]]
      distortion: [0.08, -0.17, 0.0004, -0.0002, 0.06]
      T_world_cam:            # camera 1.3 m in front of the robot, 0.5 m above the table, looking back
        - [0.0, 0.3714, -0.9285, 1.30]
        - [1.0, 0.0, 0.0, 0.00]
        - [0.0, -0.9285, -0.3714, 0.50]
        - [0.0, 0.0, 0.0, 1.0]
      meta: {reprojection_rms_px: 0.21, board: charuco 7x5 40 mm}

The same in JSON: ``{"observation.images.front": {"image_size": [480, 640], "K": [[...]], ...}}``.
``.yaml``/``.yml`` files are read as YAML, anything else as JSON (then as YAML when PyYAML is
installed and the text is not JSON). OpenCV ``FileStorage`` files (``%YAML:1.0``) are not supported.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from lerobot_omnid.calibration.schema import CalibrationError, CameraCalibration
from lerobot_omnid.keys import image_key

try:
    import yaml
except ImportError:  # PyYAML is a LeRobot dependency; JSON still works without it.
    yaml = None

YAML_SUFFIXES = (".yaml", ".yml")
FILE_FIELDS = ("image_size", "K", "T_cam_world", "T_world_cam", "distortion", "meta")
DISTORTION_LENGTHS = (0, 4, 5, 8, 12, 14)
"""Numbers of OpenCV distortion coefficients accepted (0: none)."""


def _parse_yaml(text: str, path: Path, also: str = "") -> Any:
    if yaml is None:
        raise CalibrationError(f"calibration file {path}: reading YAML needs PyYAML (pip install pyyaml)")
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise CalibrationError(
            f"calibration file {path}: {also + ', ' if also else ''}not valid YAML ({e})"
        ) from e


def read_mapping_file(path: Path) -> dict[str, Any]:
    """Parse a JSON or YAML file (chosen as for calibration files) into its top-level mapping; errors
    name the file."""
    if not path.is_file():
        raise CalibrationError(f"calibration file {path} does not exist")
    text = path.read_text()
    if text.lstrip().startswith("%YAML:"):
        raise CalibrationError(
            f"calibration file {path}: OpenCV FileStorage files are not supported; write the schema of "
            f"lerobot_omnid.calibration.rig_file (plain JSON or YAML lists of numbers)"
        )
    if path.suffix.lower() in YAML_SUFFIXES:
        data = _parse_yaml(text, path)
    else:
        try:
            data = json.loads(text)
        except json.JSONDecodeError as e:
            if yaml is None:
                raise CalibrationError(f"calibration file {path}: not valid JSON ({e})") from e
            data = _parse_yaml(text, path, also=f"not valid JSON ({e})")
    if not isinstance(data, dict) or not data:
        raise CalibrationError(f"calibration file {path}: expected a non-empty mapping keyed by camera")
    return data


def homogeneous_matrix(value: Any, where: str) -> np.ndarray:
    """A finite 4x4 float64 matrix with last row [0, 0, 0, 1]; errors name ``where``."""
    try:
        T = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise CalibrationError(f"{where}: expected a 4x4 matrix of numbers ({e})") from e
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise CalibrationError(f"{where}: expected a finite 4x4 matrix, got {value!r}")
    if not np.allclose(T[3], (0.0, 0.0, 0.0, 1.0)):
        raise CalibrationError(f"{where}: expected last row [0, 0, 0, 1], got {T[3].tolist()}")
    return T


def _invert_pose(T_world_cam: Any, where: str) -> list[list[float]]:
    """``T_world_cam`` (validated as a rigid 4x4 by the caller's schema) -> ``T_cam_world``."""
    T = homogeneous_matrix(T_world_cam, f"{where}.T_world_cam")
    cam_T_world = np.eye(4)
    cam_T_world[:3, :3] = T[:3, :3].T
    cam_T_world[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return cam_T_world.tolist()


def parse_camera_entry(entry: Any, camera: str) -> CameraCalibration:
    """Validate one camera's entry of a calibration file (see the module docstring).

    Errors name ``camera`` and the field. ``T_world_cam`` is inverted; a rotation that is not
    orthonormal is reported under the field that was given.
    """
    if not isinstance(entry, Mapping):
        raise CalibrationError(f"{camera}: expected a calibration mapping, got {type(entry).__name__}")
    unknown = sorted(k for k in entry if k not in FILE_FIELDS)
    if unknown:
        raise CalibrationError(
            f"{camera}: unknown field(s) {unknown}; allowed fields are {list(FILE_FIELDS)}"
        )
    has_cw, has_wc = "T_cam_world" in entry, "T_world_cam" in entry
    if has_cw == has_wc:
        raise CalibrationError(
            f"{camera}: give exactly one of 'T_cam_world' (world -> camera) and 'T_world_cam' (camera pose "
            f"in the world), got {'both' if has_cw else 'neither'}"
        )
    data = {k: v for k, v in entry.items() if k not in ("meta", "T_world_cam")}
    if has_wc:
        # Validate the given matrix under its own name before inverting it.
        try:
            CameraCalibration.from_dict({**data, "T_cam_world": entry["T_world_cam"]}, camera=camera)
        except CalibrationError as e:
            raise CalibrationError(str(e).replace(".T_cam_world", ".T_world_cam")) from e
        data["T_cam_world"] = _invert_pose(entry["T_world_cam"], camera)
    calib = CameraCalibration.from_dict(data, camera=camera)
    if len(calib.distortion) not in DISTORTION_LENGTHS:
        raise CalibrationError(
            f"{camera}.distortion: expected 4, 5, 8, 12 or 14 OpenCV coefficients (k1, k2, p1, p2[, k3...]), "
            f"got {len(calib.distortion)}"
        )
    meta = entry.get("meta")
    if meta is not None and not isinstance(meta, Mapping):
        raise CalibrationError(f"{camera}.meta: expected a mapping of notes, got {type(meta).__name__}")
    return calib


def load_camera_entries[Entry](
    path: str | Path, parse_entry: Callable[[Any, str], Entry], kind: str = "calibration file"
) -> dict[str, Entry]:
    """Read a file keyed by camera and parse every entry with ``parse_entry(entry, camera)``; errors name
    the ``kind`` of file, the file, the camera and the field. Keys: image feature keys."""
    path = Path(path)
    entries: dict[str, Entry] = {}
    for cam, entry in read_mapping_file(path).items():
        key = image_key(str(cam))
        if key in entries:
            raise CalibrationError(f"{kind} {path}: camera {key} is given twice ('{cam}')")
        entries[key] = parse_entry(entry, f"{path.name}: {cam}")
    return entries


def load_calibration_file(path: str | Path) -> dict[str, CameraCalibration]:
    """Read and validate a calibration file; errors name the file, the camera and the field.

    Returns the calibrations keyed by image feature key (``observation.images.<cam>``).
    """
    return load_camera_entries(path, parse_camera_entry)


def load_calibration_meta(path: str | Path) -> dict[str, dict[str, Any]]:
    """The ``meta`` notes of every camera that has some, keyed by image feature key."""
    data = read_mapping_file(Path(path))
    return {
        image_key(str(cam)): dict(entry["meta"])
        for cam, entry in data.items()
        if isinstance(entry, Mapping) and isinstance(entry.get("meta"), Mapping)
    }


def _plain(value: Any) -> Any:
    """Numpy scalars/arrays and tuples -> JSON/YAML-safe Python values."""
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        raise CalibrationError(f"calibration meta: non-finite number {value}")
    return value


def write_mapping_file(path: str | Path, data: Mapping[str, Any]) -> Path:
    """Write ``data`` (numpy values made plain) as YAML for ``.yaml``/``.yml`` paths, JSON otherwise.

    The text goes to a temporary file moved into place, so an existing file is replaced whole or not at all.
    """
    path = Path(path)
    out = _plain(data)
    if path.suffix.lower() in YAML_SUFFIXES:
        if yaml is None:
            raise CalibrationError(f"writing {path} as YAML needs PyYAML (pip install pyyaml)")
        text = yaml.safe_dump(out, default_flow_style=None, sort_keys=False, width=200)
    else:
        text = json.dumps(out, indent=2) + "\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def save_calibration_file(
    path: str | Path,
    calibrations: Mapping[str, CameraCalibration],
    meta: Mapping[str, Mapping[str, Any]] | None = None,
) -> Path:
    """Write ``calibrations`` (keyed by camera name or feature key) in the schema of this module.

    YAML for ``.yaml``/``.yml`` paths, JSON otherwise; ``T_cam_world`` is written (never
    ``T_world_cam``). ``meta`` adds per-camera notes. Written by :func:`write_mapping_file`, so an
    existing file is replaced whole or not at all.
    """
    meta = {image_key(k): v for k, v in (meta or {}).items()}
    out: dict[str, Any] = {}
    for cam, calib in calibrations.items():
        key = image_key(cam)
        calib.validate(key)
        entry = {"image_size": list(calib.image_size), **calib.to_dict()}
        if meta.get(key):
            entry["meta"] = meta[key]
        out[key] = entry
    return write_mapping_file(path, out)
