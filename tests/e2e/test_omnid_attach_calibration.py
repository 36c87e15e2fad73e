"""``omnid-attach-calibration`` as a console command: a dataset recorded without calibration gets one, is
loadable by LeRobot and accepted by OmniD, and keeps its data and videos byte for byte. (The files, the
checks and the other options: tests/calibration/test_attach_calibration.py.)"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from calibration_testing import CAMS, REPO_ID, SIZE, digests, make_uncalibrated_dataset, sim_calibration
from omnid_testing import tiny_config

from lerobot_omnid.calibration.schema import calibration_from_feature_info

BIN = Path(sys.executable).parent


@pytest.fixture
def dataset(tmp_path) -> Path:
    root = tmp_path / "dataset"
    make_uncalibrated_dataset(root)
    return root


def test_attach_to_uncalibrated_dataset(dataset, tmp_path):
    """The console script attaches a 2x-resolution calibration (K rescaled; one camera given by its
    pose T_world_cam); LeRobot loads the dataset, OmniD takes the calibration, nothing else changed."""
    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    before = digests(dataset)
    original_info = (dataset / "meta" / "info.json").read_bytes()
    original_mode = (dataset / "meta" / "info.json").stat().st_mode
    high_res = (SIZE[0] * 2, SIZE[1] * 2)
    cam_c = sim_calibration("cam_c", high_res)
    cam_c["T_world_cam"] = np.linalg.inv(np.array(cam_c.pop("T_cam_world"))).tolist()
    rig = tmp_path / "rig.yaml"
    rig.write_text(json.dumps({"cam_b": sim_calibration("cam_b", high_res), "cam_c": cam_c}))  # JSON is YAML

    result = subprocess.run(
        [BIN / "omnid-attach-calibration", "--root", dataset, "--calibration", rig],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert "K rescaled from 96x72 to 48x36 px" in result.stdout
    assert "attached the calibration of 2 camera(s)" in result.stdout

    after = digests(dataset)
    changed = {k for k in after if before.get(k) != after[k]}
    assert changed == {"meta/info.json", "meta/info.json.bak"}, "only the metadata may change"
    assert (dataset / "meta" / "info.json.bak").read_bytes() == original_info
    assert (dataset / "meta" / "info.json").stat().st_mode == original_mode

    meta = LeRobotDatasetMetadata(REPO_ID, root=dataset)
    for cam in CAMS:
        key = f"observation.images.{cam}"
        calib = calibration_from_feature_info(key, meta.features[key])
        expected = sim_calibration(cam)
        assert calib.image_size == SIZE
        np.testing.assert_allclose(calib.K, expected["K"], atol=1e-9)
        np.testing.assert_allclose(calib.T_cam_world, expected["T_cam_world"], atol=1e-9)
        assert meta.features[key]["info"]["video.height"] == SIZE[0]  # LeRobot's own entries kept
        assert meta.features[key]["info"]["calibration_source"]["file"] == "rig.yaml"

    item = LeRobotDataset(REPO_ID, root=dataset, video_backend="pyav")[0]
    assert item["observation.images.cam_b"].shape == (3, *SIZE)

    config = tiny_config(cams=CAMS, size=SIZE[0])
    config.set_dataset_feature_metadata(meta.features)
    config.validate_features()
    assert sorted(config.camera_calibration) == [f"observation.images.{c}" for c in CAMS]
    np.testing.assert_allclose(
        config.camera_calibration["observation.images.cam_c"]["K"], sim_calibration("cam_c")["K"], atol=1e-9
    )
