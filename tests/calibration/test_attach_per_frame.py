"""``omnid-attach-calibration --per-frame-columns``: an existing dataset with a static calibration becomes a
copy with constant per-frame columns that merges with a dataset of another rig recorded with
``omnid-record --per-frame-calibration``; the source is untouched and bad input is refused by name."""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.scripts.lerobot_edit_dataset import edit_dataset
from omnid_testing import record_rig

from lerobot_omnid.calibration.attach_calibration import main
from lerobot_omnid.calibration.frame_columns import (
    extrinsics_column,
    extrinsics_from_column,
    extrinsics_key,
    intrinsics_column,
    intrinsics_key,
)
from lerobot_omnid.calibration.rig_file import save_calibration_file
from lerobot_omnid.calibration.schema import (
    CALIBRATION_INFO_KEY,
    CameraCalibration,
    calibration_from_feature_info,
)
from lerobot_omnid.env_config import OmniDEnvConfig

SIZE = 32
CAMERAS = ["cam_b", "cam_d"]


def _record(root: Path, rig: str, per_frame_calibration: bool) -> Path:
    return record_rig(root, rig, per_frame_calibration, CAMERAS, SIZE)


def _tree_digest(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in root.rglob("*")
        if p.is_file()
    }


@pytest.fixture(scope="module")
def static_root(tmp_path_factory) -> Path:
    """A dataset of the default rig with its calibration in the feature info, as recorded until now."""
    return _record(tmp_path_factory.mktemp("attach_per_frame") / "static", "default", False)


def test_columns_from_the_info_calibration_and_merge_with_another_rig(
    static_root, tmp_path, monkeypatch, capsys
):
    before = _tree_digest(static_root)
    copy_root = tmp_path / "static_columns"
    assert main(["--root", str(static_root), "--per-frame-columns", str(copy_root)]) == 0
    assert "copy with per-frame columns" in capsys.readouterr().out
    assert _tree_digest(static_root) == before  # the source is untouched

    source_meta = LeRobotDatasetMetadata("local/static", root=static_root)
    meta = LeRobotDatasetMetadata("local/static_columns", root=copy_root)
    data = pd.read_parquet(sorted((copy_root / "data").rglob("*.parquet"))[0])
    assert len(data) == source_meta.total_frames
    for cam in CAMERAS:
        key = f"observation.images.{cam}"
        calib = calibration_from_feature_info(key, source_meta.features[key])
        assert CALIBRATION_INFO_KEY not in meta.features[key].get("info", {})
        np.testing.assert_array_equal(
            np.stack(data[extrinsics_key(cam)]), [extrinsics_column(calib.T_cam_world)] * len(data)
        )
        np.testing.assert_array_equal(
            np.stack(data[intrinsics_key(cam)]), [intrinsics_column(calib.K)] * len(data)
        )
        stats = meta.stats[extrinsics_key(cam)]  # computed, as a recorded dataset's
        np.testing.assert_allclose(stats["mean"], extrinsics_column(calib.T_cam_world), atol=1e-6)
        assert int(np.asarray(stats["count"]).item()) == len(data)
    item = LeRobotDataset("local/static_columns", root=copy_root, video_backend="pyav")[3]
    assert item[extrinsics_key("cam_d")].shape == (16,)

    recorded = _record(tmp_path / "bumped", "bumped", True)
    roots = [copy_root, recorded]
    argv = ["lerobot-edit-dataset", "--new_repo_id=local/merged", f"--new_root={tmp_path / 'merged'}"]
    argv += ["--operation.type=merge", f"--operation.repo_ids={[f'local/{r.name}' for r in roots]}"]
    argv += [f"--operation.roots={[str(r) for r in roots]}"]
    monkeypatch.setattr(sys, "argv", argv)
    edit_dataset()
    merged = LeRobotDataset("local/merged", root=tmp_path / "merged", video_backend="pyav")
    assert merged.num_episodes == 2
    first, last = merged[0][extrinsics_key("cam_b")], merged[len(merged) - 1][extrinsics_key("cam_b")]
    assert not np.array_equal(first, last)  # the default rig's cam_b, then the bumped rig's


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["--overwrite"], "--overwrite: --per-frame-columns writes a new dataset"),
        (["--no-backup"], "--no-backup: --per-frame-columns writes a new dataset"),
    ],
)
def test_flags_of_the_in_place_mode_are_refused(static_root, tmp_path, capsys, extra, expected):
    with pytest.raises(SystemExit):
        main(["--root", str(static_root), "--per-frame-columns", str(tmp_path / "out"), *extra])
    assert expected in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_bad_input_is_refused_and_nothing_written(static_root, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["--root", str(static_root)])
    assert "--calibration: expected a calibration file" in capsys.readouterr().err

    occupied = tmp_path / "occupied"
    occupied.mkdir()
    (occupied / "keep.txt").write_text("mine")
    assert main(["--root", str(static_root), "--per-frame-columns", str(occupied)]) == 2
    assert "refusing to overwrite" in capsys.readouterr().err
    assert sorted(p.name for p in occupied.iterdir()) == ["keep.txt"]

    with_columns = _record(tmp_path / "with_columns", "default", True)
    assert main(["--root", str(with_columns), "--per-frame-columns", str(tmp_path / "again")]) == 2
    assert "expected a dataset without per-frame columns" in capsys.readouterr().err
    assert not (tmp_path / "again").exists()


def test_columns_from_a_calibration_file(static_root, tmp_path, capsys):
    """A file's calibration (here the cameras re-measured after a move to the "closer" rig) is checked and
    written instead of the info's; a file missing a camera writes nothing."""
    closer = OmniDEnvConfig(cameras=CAMERAS, image_size=SIZE, rig="closer").camera_calibrations()
    calibrations = {key: CameraCalibration.from_dict(data, camera=key) for key, data in closer.items()}
    rig_file = save_calibration_file(tmp_path / "closer.yaml", calibrations)
    copy_root = tmp_path / "closer_columns"
    argv = ["--root", str(static_root), "--calibration", str(rig_file), "--per-frame-columns", str(copy_root)]
    assert main(argv) == 0
    data = pd.read_parquet(sorted((copy_root / "data").rglob("*.parquet"))[0])
    expected = np.array(calibrations["observation.images.cam_d"].T_cam_world)
    np.testing.assert_allclose(
        extrinsics_from_column(data[extrinsics_key("cam_d")].iloc[-1]), expected, atol=1e-6
    )

    partial = save_calibration_file(
        tmp_path / "partial.yaml", {"cam_b": calibrations["observation.images.cam_b"]}
    )
    argv = [
        "--root",
        str(static_root),
        "--calibration",
        str(partial),
        "--per-frame-columns",
        str(tmp_path / "no"),
    ]
    assert main(argv) == 2
    assert "observation.images.cam_d: no calibration in the file" in capsys.readouterr().err
    assert not (tmp_path / "no").exists()
