"""``omnid-attach-calibration``: attach camera calibration to an existing LeRobot dataset.

LeRobot's recording tools store no camera calibration; OmniD needs ``K`` and ``T_cam_world`` for every
camera. This command reads a calibration file (schema: :mod:`lerobot_omnid.calibration.rig_file`, written by
``omnid-calibrate`` or by hand), checks it against the dataset and writes each camera's calibration into
``meta/info.json`` under ``features["observation.images.<cam>"]["info"]["calibration"]``, where LeRobot
keeps it (per-feature ``info`` survives video encoding) and OmniD's ``make_policy`` finds it. Data and
videos are not touched.

Checks, all done before anything is written (every problem is reported, naming camera and field):

- every image feature of the dataset has a calibration (``--skip-camera`` leaves one out, e.g. a wrist
  camera, whose pose moves with the arm; train OmniD with ``--policy.cameras`` excluding it), and every
  camera of the file is an image feature of the dataset;
- ``image_size`` equals the dataset's image size, or has the same aspect ratio, in which case ``K`` is
  rescaled (a full-frame resize); another aspect ratio (a crop) is refused;
- ``K`` is a pinhole matrix and ``T_cam_world`` a rigid transform (orthonormal rotation, no reflection);
- the workspace volume (OmniD's default, ``--volume-bounds`` or ``--policy-config``) is in front of every
  camera: its centre has positive depth and at least ``--min-visible`` of a grid of points in it project
  into the image (an inverted transform, or one in another frame or unit, fails this);
- distortion: OmniD assumes undistorted pinhole images, while LeRobot records raw camera frames. Non-zero
  distortion is refused unless ``--distortion undistorted`` (the dataset's frames were undistorted with
  ``cv2.undistort(frame, K, distortion)``, so the attached calibration has no distortion) or
  ``--distortion ignore`` (raw frames; accept the pinhole approximation; the distortion is kept in the
  attached calibration for the record). The largest pixel shift the distortion causes is printed.

Then ``meta/info.json`` is replaced atomically (a temporary file moved over it), after saving the previous
one to ``meta/info.json.bak`` (delete it before pushing the dataset to the Hub, or pass ``--no-backup``).

Example::

    omnid-attach-calibration --root ~/.cache/huggingface/lerobot/me/so100_pick --calibration rig.yaml
    omnid-attach-calibration --repo-id me/so100_pick --calibration rig.yaml   # downloads it first
"""

from __future__ import annotations

import argparse
import copy
import hashlib
import json
import os
import shutil
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import cv2
import numpy as np
import torch

from lerobot_omnid.calibration.rig_file import image_key, load_calibration_file
from lerobot_omnid.calibration.schema import CALIBRATION_INFO_KEY, CalibrationError, CameraCalibration
from lerobot_omnid.geometry import scale_intrinsics
from lerobot_omnid.policy.configuration_omnid import OmniDConfig

INFO_PATH = Path("meta") / "info.json"
BACKUP_SUFFIX = ".bak"
SOURCE_INFO_KEY = "calibration_source"
"""Key, next to ``calibration`` in a feature's ``info``, recording where the calibration came from."""
DISTORTION_MODES = ("refuse", "undistorted", "ignore")
DEFAULT_VOLUME_BOUNDS = OmniDConfig.__dataclass_fields__["volume_bounds"].default
DEFAULT_MIN_VISIBLE = 0.1  # fraction of the volume's grid points that must project into the image
MIN_EXTENT = 0.1  # the volume's projection must span this fraction of the image diagonal
VOLUME_GRID_POINTS = 9  # grid points per axis of the volume for the visibility check
ASPECT_TOLERANCE = 0.01  # relative difference of the x and y scale factors still treated as a resize
DISTORTION_GRID = 33  # pixels per side of the grid on which the distortion's pixel shift is measured
DEPTH_EPS = 1e-3  # m


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


def rescale_calibration(calib: CameraCalibration, to_hw: tuple[int, int]) -> CameraCalibration:
    """The calibration of the same camera after resizing its whole image to ``to_hw`` (distortion is in
    normalised coordinates and does not change)."""
    K = scale_intrinsics(torch.tensor(calib.K, dtype=torch.float64), calib.image_size, to_hw)
    return CameraCalibration(
        K=tuple(tuple(float(v) for v in row) for row in K.tolist()),
        T_cam_world=calib.T_cam_world,
        image_size=(int(to_hw[0]), int(to_hw[1])),
        distortion=calib.distortion,
    )


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
        calib = rescale_calibration(calib, size)
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


def _write_json_atomically(data: Mapping[str, Any], path: Path) -> None:
    """Write ``path`` whole or not at all: a temporary file beside it (keeping its permissions), then an
    atomic rename over it."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(data, f, indent=4, ensure_ascii=False)
            f.flush()
            os.fsync(f.fileno())
        if path.exists():
            shutil.copymode(path, tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def attach_calibration(
    root: str | Path,
    calibration_path: str | Path,
    volume_bounds=DEFAULT_VOLUME_BOUNDS,
    min_visible: float = DEFAULT_MIN_VISIBLE,
    distortion: str = "refuse",
    skip: Sequence[str] = (),
    overwrite: bool = False,
    backup: bool = True,
    dry_run: bool = False,
) -> list[CameraReport]:
    """Validate and attach a calibration file to the dataset at ``root`` (see the module docstring)."""
    root, calibration_path = Path(root), Path(calibration_path)
    info_path = root / INFO_PATH
    if not info_path.is_file():
        raise CalibrationError(f"--root {root}: no {INFO_PATH} there, not a LeRobot dataset")
    info = json.loads(info_path.read_text(encoding="utf-8"))
    calibrations = load_calibration_file(calibration_path)
    source = {
        "file": calibration_path.name,
        "sha256": hashlib.sha256(calibration_path.read_bytes()).hexdigest(),
        "tool": "omnid-attach-calibration",
    }
    new_info, reports = plan_attachment(
        info, calibrations, volume_bounds, min_visible, distortion, skip, overwrite, source
    )
    _check_readable(new_info, reports)
    if dry_run:
        return reports
    if backup:
        backup_path = info_path.with_name(info_path.name + BACKUP_SUFFIX)
        shutil.copy2(info_path, backup_path.with_name(backup_path.name + ".tmp"))
        os.replace(backup_path.with_name(backup_path.name + ".tmp"), backup_path)
    _write_json_atomically(new_info, info_path)
    return reports


def _check_readable(new_info: Mapping[str, Any], reports: Sequence[CameraReport]) -> None:
    """The new info must parse with LeRobot's own metadata class and give back every calibration."""
    from lerobot.datasets.utils import DatasetInfo

    from lerobot_omnid.calibration.schema import calibration_from_feature_info

    DatasetInfo.from_dict(copy.deepcopy(dict(new_info)))
    for report in reports:
        again = calibration_from_feature_info(report.key, new_info["features"][report.key])
        if again != report.calibration:
            raise CalibrationError(f"{report.key}: the calibration does not survive a round trip")


def resolve_root(root: Path | None, repo_id: str | None, revision: str | None = None) -> Path:
    """The dataset's local root: ``root``, or the Hub dataset ``repo_id`` downloaded to LeRobot's cache."""
    if root is not None:
        return root
    if repo_id is None:
        raise CalibrationError("give --root (a local dataset) or --repo-id (a Hub dataset)")
    from lerobot.utils.constants import HF_LEROBOT_HOME

    local = HF_LEROBOT_HOME / repo_id
    if (local / INFO_PATH).is_file():
        print(f"using the local copy of {repo_id} at {local}")
        return local
    from huggingface_hub import snapshot_download

    print(f"downloading dataset {repo_id} from the Hub to {local}")
    try:
        snapshot_download(repo_id, repo_type="dataset", revision=revision, local_dir=local)
    except Exception as e:  # offline, unknown repo, no access: all end the same way
        raise CalibrationError(
            f"--repo-id {repo_id}: could not download the dataset from the Hub ({type(e).__name__}: {e}). "
            f"Without network access, copy the dataset here and pass --root"
        ) from e
    return local


def volume_bounds_from_policy_config(path: Path) -> tuple[tuple[float, float], ...]:
    """``volume_bounds`` of a policy ``config.json`` (or of the ``policy`` of a ``train_config.json``)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise CalibrationError(f"--policy-config {path}: not a readable JSON file ({e})") from e
    bounds = data.get("volume_bounds", (data.get("policy") or {}).get("volume_bounds"))
    if bounds is None:
        raise CalibrationError(f"--policy-config {path}: no 'volume_bounds' (nor 'policy.volume_bounds')")
    return _check_bounds(bounds, f"--policy-config {path}: volume_bounds")


def _check_bounds(bounds: Any, where: str) -> tuple[tuple[float, float], ...]:
    try:
        out = tuple((float(lo), float(hi)) for lo, hi in bounds)
    except (TypeError, ValueError) as e:
        raise CalibrationError(
            f"{where}: expected [[x_min, x_max], [y_min, y_max], [z_min, z_max]], got {bounds!r}"
        ) from e
    if len(out) != 3 or not all(lo < hi for lo, hi in out):
        raise CalibrationError(f"{where}: expected three (min, max) pairs with min < max, got {bounds!r}")
    return out


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="omnid-attach-calibration",
        description="Validate a camera calibration file against a LeRobot dataset and attach it to the "
        "dataset's image features (meta/info.json only; data and videos are not touched).",
    )
    parser.add_argument("--calibration", type=Path, required=True, help="calibration file (JSON or YAML)")
    parser.add_argument("--root", type=Path, help="local dataset root (the folder holding meta/info.json)")
    parser.add_argument(
        "--repo-id", help="Hub dataset repo id, downloaded to LeRobot's cache when --root is not given"
    )
    parser.add_argument("--revision", help="Hub revision (branch, tag or commit) to download")
    bounds = parser.add_mutually_exclusive_group()
    bounds.add_argument(
        "--volume-bounds",
        nargs=6,
        type=float,
        metavar=("X_MIN", "X_MAX", "Y_MIN", "Y_MAX", "Z_MIN", "Z_MAX"),
        help="workspace volume in the robot base frame, metres (default: OmniD's "
        f"{list(map(list, DEFAULT_VOLUME_BOUNDS))})",
    )
    bounds.add_argument("--policy-config", type=Path, help="take volume_bounds from this OmniD config.json")
    parser.add_argument(
        "--min-visible",
        type=float,
        default=DEFAULT_MIN_VISIBLE,
        help="fraction of the workspace volume every camera must see (default: %(default)s)",
    )
    parser.add_argument(
        "--distortion",
        choices=DISTORTION_MODES,
        default="refuse",
        help="non-zero distortion: refuse (default); undistorted: the frames were already undistorted with K "
        "(distortion dropped); ignore: raw frames, accept the pinhole approximation",
    )
    parser.add_argument(
        "--skip-camera",
        action="append",
        default=[],
        metavar="CAM",
        help="an image feature to leave uncalibrated",
    )
    parser.add_argument(
        "--overwrite", action="store_true", help="replace calibrations the dataset already has"
    )
    parser.add_argument("--no-backup", action="store_true", help="do not keep meta/info.json.bak")
    parser.add_argument("--dry-run", action="store_true", help="validate and report; write nothing")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if not 0.0 <= args.min_visible <= 1.0:
            raise CalibrationError(f"--min-visible must be in [0, 1], got {args.min_visible}")
        if args.policy_config is not None:
            volume_bounds = volume_bounds_from_policy_config(args.policy_config)
        elif args.volume_bounds is not None:
            v = args.volume_bounds
            volume_bounds = _check_bounds([v[0:2], v[2:4], v[4:6]], "--volume-bounds")
        else:
            volume_bounds = DEFAULT_VOLUME_BOUNDS
        root = resolve_root(args.root, args.repo_id, args.revision)
        reports = attach_calibration(
            root,
            args.calibration,
            volume_bounds=volume_bounds,
            min_visible=args.min_visible,
            distortion=args.distortion,
            skip=args.skip_camera,
            overwrite=args.overwrite,
            backup=not args.no_backup,
            dry_run=args.dry_run,
        )
    except CalibrationError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    for report in reports:
        print(report.line())
    info_path = root / INFO_PATH
    if args.dry_run:
        print(f"dry run: the calibration of {len(reports)} camera(s) is valid for {root}; nothing written")
    else:
        print(f"attached the calibration of {len(reports)} camera(s) to {info_path}")
        if not args.no_backup:
            backup = f"{info_path}{BACKUP_SUFFIX}"
            print(f"previous version: {backup} (undo: mv {backup} {info_path})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
