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

``--per-frame-columns NEW_ROOT`` instead writes a copy of the dataset (data rewritten with the new
columns, videos copied as they are) in which every checked camera's calibration is a constant per-frame
column (``observation.extrinsics.<cam>``, ``observation.intrinsics.<cam>``:
:mod:`lerobot_omnid.calibration.frame_columns`) and the image features' ``info`` holds no calibration:
the feature schema of datasets recorded by ``omnid-record`` (its default form), so that the copy
merges with them and with copies of datasets from other rigs. The calibration is the file's or, without
``--calibration``, the one already in the dataset's feature ``info``; the same checks run first. The
source dataset is not touched.

Example::

    omnid-attach-calibration --root ~/.cache/huggingface/lerobot/me/so100_pick --calibration rig.yaml
    omnid-attach-calibration --repo-id me/so100_pick --calibration rig.yaml   # downloads it first
    omnid-attach-calibration --root data/apple --per-frame-columns data/apple_columns  # info -> columns
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
from pathlib import Path
from typing import Any

import numpy as np

from lerobot_omnid.calibration.checks import (
    DEFAULT_MIN_VISIBLE,
    DEFAULT_VOLUME_BOUNDS,
    DISTORTION_MODES,
    SOURCE_INFO_KEY,
    CameraReport,
    plan_attachment,
)
from lerobot_omnid.calibration.frame_columns import (
    calibration_column_features,
    extrinsics_column,
    extrinsics_key,
    intrinsics_column,
    intrinsics_key,
    is_calibration_key,
)
from lerobot_omnid.calibration.rig_file import load_calibration_file
from lerobot_omnid.calibration.schema import (
    CALIBRATION_INFO_KEY,
    CalibrationError,
    CameraCalibration,
    calibration_from_feature_info,
)
from lerobot_omnid.keys import image_key

INFO_PATH = Path("meta") / "info.json"
BACKUP_SUFFIX = ".bak"


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


def _info_calibrations(info: Mapping[str, Any], skip: Sequence[str]) -> dict[str, CameraCalibration]:
    """The calibration in the feature ``info`` of every image feature not skipped (errors name the key)."""
    skip_keys = {image_key(c) for c in skip}
    return {
        key: calibration_from_feature_info(key, feature)
        for key, feature in info.get("features", {}).items()
        if feature.get("dtype") in ("video", "image") and key not in skip_keys
    }


def write_per_frame_columns(
    root: str | Path,
    new_root: str | Path,
    calibration_path: str | Path | None = None,
    new_repo_id: str | None = None,
    volume_bounds=DEFAULT_VOLUME_BOUNDS,
    min_visible: float = DEFAULT_MIN_VISIBLE,
    distortion: str = "refuse",
    skip: Sequence[str] = (),
    dry_run: bool = False,
) -> list[CameraReport]:
    """Copy the dataset at ``root`` to ``new_root`` with each camera's calibration as constant per-frame
    columns and none in the image features' ``info`` (see the module docstring).

    The calibration is the file's, or with ``calibration_path=None`` the dataset's own feature ``info``;
    it is checked as :func:`attach_calibration` checks it. ``new_repo_id`` defaults to
    ``local/<new_root's name>``.
    """
    from lerobot.datasets.dataset_tools import modify_features, recompute_stats
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root, new_root = Path(root), Path(new_root)
    info_path = root / INFO_PATH
    if not info_path.is_file():
        raise CalibrationError(f"--root {root}: no {INFO_PATH} there, not a LeRobot dataset")
    info = json.loads(info_path.read_text(encoding="utf-8"))
    existing = sorted(key for key in info.get("features", {}) if is_calibration_key(key))
    if existing:
        raise CalibrationError(
            f"--root {root}: expected a dataset without per-frame columns, it has {existing}"
        )
    if new_root.exists() and (not new_root.is_dir() or any(new_root.iterdir())):
        raise CalibrationError(
            f"--per-frame-columns: {new_root} already exists and is not an empty directory; refusing to "
            f"overwrite it"
        )
    if calibration_path is None:
        calibrations = _info_calibrations(info, skip)
    else:
        calibrations = load_calibration_file(calibration_path)
    _, reports = plan_attachment(info, calibrations, volume_bounds, min_visible, distortion, skip, True)
    if dry_run:
        return reports

    dataset = LeRobotDataset(f"local/{root.name}", root=root, video_backend="pyav")
    frames = dataset.meta.total_frames
    specs = calibration_column_features(report.key for report in reports)
    columns: dict[str, tuple[np.ndarray, dict[str, Any]]] = {}
    for report in reports:
        for key, value in (
            (extrinsics_key(report.key), extrinsics_column(report.calibration.T_cam_world)),
            (intrinsics_key(report.key), intrinsics_column(report.calibration.K)),
        ):
            columns[key] = (np.tile(value, (frames, 1)), specs[key])
    if new_root.exists():
        new_root.rmdir()  # LeRobot creates it itself and refuses an existing one
    try:
        copy_dataset = modify_features(
            dataset,
            add_features=columns,
            output_dir=new_root,
            repo_id=new_repo_id or f"local/{new_root.name}",
        )
        recompute_stats(copy_dataset)  # the new columns' statistics, like a recorded dataset's
        new_info_path = new_root / INFO_PATH
        new_info = json.loads(new_info_path.read_text(encoding="utf-8"))
        for feature in new_info["features"].values():
            for key in (CALIBRATION_INFO_KEY, SOURCE_INFO_KEY):
                (feature.get("info") or {}).pop(key, None)
        _write_json_atomically(new_info, new_info_path)
    except BaseException:
        shutil.rmtree(new_root, ignore_errors=True)  # nothing half-written
        raise
    return reports


def _check_readable(new_info: Mapping[str, Any], reports: Sequence[CameraReport]) -> None:
    """The new info must parse with LeRobot's own metadata class and give back every calibration."""
    from lerobot.datasets.utils import DatasetInfo

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
        "dataset's image features (meta/info.json only; data and videos are not touched), or write a copy of "
        "the dataset with the calibration as per-frame columns (--per-frame-columns).",
    )
    parser.add_argument(
        "--calibration",
        type=Path,
        help="calibration file (JSON or YAML); required unless --per-frame-columns, which then uses the "
        "dataset's own",
    )
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
    parser.add_argument(
        "--per-frame-columns",
        type=Path,
        metavar="NEW_ROOT",
        help="write a copy of the dataset here with every camera's calibration as constant per-frame columns "
        "(observation.extrinsics.<cam>, observation.intrinsics.<cam>) and none in the feature info, so that "
        "it merges with datasets of other rigs; the source is not touched",
    )
    parser.add_argument(
        "--new-repo-id", help="repo id of the --per-frame-columns copy (default: local/<NEW_ROOT's name>)"
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.per_frame_columns is None:
        if args.calibration is None:
            parser.error(
                "--calibration: expected a calibration file (or --per-frame-columns NEW_ROOT), got none"
            )
        if args.new_repo_id is not None:
            parser.error(f"--new-repo-id: expected only with --per-frame-columns, got {args.new_repo_id!r}")
    else:
        for flag, given in (("--overwrite", args.overwrite), ("--no-backup", args.no_backup)):
            if given:
                parser.error(
                    f"{flag}: --per-frame-columns writes a new dataset and never changes the source; "
                    f"expected {flag} only without it"
                )
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
        if args.per_frame_columns is not None:
            reports = write_per_frame_columns(
                root,
                args.per_frame_columns,
                args.calibration,
                args.new_repo_id,
                volume_bounds=volume_bounds,
                min_visible=args.min_visible,
                distortion=args.distortion,
                skip=args.skip_camera,
                dry_run=args.dry_run,
            )
        else:
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
    if args.per_frame_columns is not None:
        written = (
            "nothing written (dry run)"
            if args.dry_run
            else f"copy with per-frame columns: {args.per_frame_columns}"
        )
        print(f"checked the calibration of {len(reports)} camera(s) of {root}; {written}")
        return 0
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
