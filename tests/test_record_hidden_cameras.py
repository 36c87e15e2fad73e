"""``omnid-record --hidden-cameras``: every camera recorded with its real images, plus the column
``observation.camera_visible`` whose feature does not depend on which cameras are hidden, so that a dataset
of new-camera episodes and one of replayed training-camera episodes merge with LeRobot's own
``lerobot-edit-dataset``. (OmniD reading the column: tests/policy/test_camera_visible.py.)"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata
from lerobot.scripts.lerobot_edit_dataset import edit_dataset
from omnid_testing import load_recording

from lerobot_omnid.camera_visibility import CAMERA_VISIBLE_KEY
from lerobot_omnid.record import main, record_dataset

SIZE = 32
CAMERAS = ["cam_a", "cam_b", "cam_c"]
HIDDEN = {"replay": "cam_a", "new_camera": "cam_b,cam_c", "all_visible": ""}
"""``--hidden-cameras`` of each recording: camera A hidden, B and C hidden, none hidden."""
VISIBLE = {"replay": [0.0, 1.0, 1.0], "new_camera": [1.0, 0.0, 0.0], "all_visible": [1.0, 1.0, 1.0]}


def _column(root: Path) -> pd.DataFrame:
    files = sorted((root / "data").rglob("*.parquet"))
    return pd.concat(
        [pd.read_parquet(f, columns=["episode_index", CAMERA_VISIBLE_KEY]) for f in files], ignore_index=True
    )


@pytest.fixture(scope="module")
def roots(tmp_path_factory) -> dict[str, Path]:
    """One select_apple expert episode (the same seed) per ``--hidden-cameras`` value, by ``main``."""
    parent = tmp_path_factory.mktemp("hidden")
    found = {}
    for name, hidden in HIDDEN.items():
        found[name] = parent / name
        argv = ["--episodes", "1", "--cameras", ",".join(CAMERAS), "--image-size", str(SIZE)]
        argv += ["--hidden-cameras", hidden, "--root", str(found[name]), "--repo-id", f"local/{name}"]
        assert main(argv) == 0
    return found


def test_the_column_has_one_spec_whichever_cameras_are_hidden(roots):
    metas = {name: LeRobotDatasetMetadata(f"local/{name}", root=root) for name, root in roots.items()}
    for meta in metas.values():
        assert meta.features == metas["replay"].features  # info of every feature included
    assert metas["replay"].features[CAMERA_VISIBLE_KEY] == {
        "dtype": "float32",
        "shape": (3,),
        "names": CAMERAS,
    }
    for name, root in roots.items():
        column = np.stack(_column(root)[CAMERA_VISIBLE_KEY])
        assert column.dtype == np.float32 and len(column) > 0
        np.testing.assert_array_equal(column, np.broadcast_to(VISIBLE[name], column.shape))
        # Every camera is recorded, hidden or not.
        assert sorted(metas[name].video_keys) == [f"observation.images.{cam}" for cam in CAMERAS]


def test_hidden_cameras_keep_their_rendered_images(roots):
    """cam_a, hidden in the replay recording and shown in the new-camera one of the same episode, has the
    same (not black) images in both."""
    hidden = load_recording(roots["replay"], "local/replay")
    shown = load_recording(roots["new_camera"], "local/new_camera")
    assert len(hidden) == len(shown)
    for index in (0, len(hidden) - 1):
        image = hidden[index]["observation.images.cam_a"]
        assert image.mean() > 0.1
        np.testing.assert_allclose(
            image.numpy(), shown[index]["observation.images.cam_a"].numpy(), atol=2 / 255
        )


def test_recordings_with_different_hidden_cameras_merge(roots, tmp_path, monkeypatch):
    """LeRobot's own ``lerobot-edit-dataset`` merge (its argument parsing and merge, run in this process):
    one dataset whose episodes each keep their column."""
    merged = tmp_path / "merged"
    argv = [
        "lerobot-edit-dataset",
        "--new_repo_id=local/merged",
        f"--new_root={merged}",
        "--operation.type=merge",
        f"--operation.repo_ids={[f'local/{name}' for name in roots]}",
        f"--operation.roots={[str(root) for root in roots.values()]}",
    ]
    monkeypatch.setattr(sys, "argv", argv)
    edit_dataset()
    data = _column(merged)
    assert sorted(set(data.episode_index)) == [0, 1, 2]
    for episode, name in enumerate(roots):
        column = np.stack(data[data.episode_index == episode][CAMERA_VISIBLE_KEY])
        np.testing.assert_array_equal(column, np.broadcast_to(VISIBLE[name], column.shape))
    item = load_recording(merged, "local/merged")[len(data) - 1]
    np.testing.assert_array_equal(item[CAMERA_VISIBLE_KEY].numpy(), VISIBLE["all_visible"])


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--cameras", "cam_a,cam_b", "--hidden-cameras", "cam_c"], ["--hidden-cameras", "cam_c", "'cam_a'"]),
        (
            ["--cameras", "cam_a,cam_b", "--hidden-cameras", "cam_b,cam_a"],
            ["--hidden-cameras", "at least one"],
        ),
        (["--hidden-cameras", "cam_b,cam_b"], ["--hidden-cameras", "distinct", "['cam_b', 'cam_b']"]),
    ],
)
def test_bad_hidden_cameras_are_named(argv, expected, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, "--root", str(tmp_path / "ds")])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    for text in expected:
        assert text in err
    assert not (tmp_path / "ds").exists()


def test_record_dataset_rejects_bad_hidden_cameras(tmp_path):
    with pytest.raises(ValueError, match=r"hidden_cameras: expected distinct cameras among the recorded"):
        record_dataset(tmp_path / "a", episodes=1, cameras=["cam_b"], hidden_cameras=["cam_a"])
    with pytest.raises(ValueError, match=r"hidden_cameras: expected a list of cameras .*got 'cam_a'"):
        record_dataset(tmp_path / "a", episodes=1, hidden_cameras="cam_a")
    with pytest.raises(ValueError, match=r"hidden_cameras: expected a subset .* at least one visible"):
        record_dataset(tmp_path / "a", episodes=1, cameras=["cam_b"], hidden_cameras=["cam_b"])
    assert not (tmp_path / "a").exists()
