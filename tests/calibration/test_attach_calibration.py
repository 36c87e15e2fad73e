"""Calibration files (JSON/YAML, T_world_cam, distortion) and ``omnid-attach-calibration``: a bad file leaves
the dataset untouched with an error naming camera and field; distortion modes, re-attaching, skipped
cameras, volume bounds, the Hub. (The console command on an uncalibrated dataset, which then loads in
LeRobot and OmniD with its data and videos unchanged: tests/e2e/test_omnid_attach_calibration.py.)"""

from __future__ import annotations

import copy
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from calibration_testing import CAMS, REPO_ID, SIZE, digests, make_uncalibrated_dataset, sim_calibration
from gym_omnid.scene import CAMERA_POSES
from omnid_testing import tiny_config

import lerobot_omnid.calibration.rig_file as calibration_file
from lerobot_omnid.calibration.attach_calibration import main
from lerobot_omnid.calibration.rig_file import (
    load_calibration_file,
    load_calibration_meta,
    save_calibration_file,
)
from lerobot_omnid.calibration.schema import CalibrationError, CameraCalibration


@pytest.fixture(scope="module")
def pristine(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("pristine") / "dataset"
    make_uncalibrated_dataset(root)
    return root


@pytest.fixture
def dataset(pristine, tmp_path) -> Path:
    root = tmp_path / "dataset"
    shutil.copytree(pristine, root)
    return root


def write(path: Path, data: dict) -> Path:
    path.write_text(json.dumps(data))
    return path


# --- calibration files -------------------------------------------------------------------------------


def test_yaml_and_json_round_trip_with_meta(tmp_path):
    calibs = {f"observation.images.{c}": CameraCalibration.from_dict(sim_calibration(c)) for c in CAMS}
    calibs["observation.images.cam_b"] = CameraCalibration(
        **{**calibs["observation.images.cam_b"].__dict__, "distortion": (0.1, -0.2, 0.001, 0.0, 0.05)}
    )
    meta = {"cam_b": {"intrinsics_rms_px": np.float64(0.2), "views": np.int64(12)}}
    for name in ("rig.yaml", "rig.json"):
        path = save_calibration_file(tmp_path / name, calibs, meta)
        assert load_calibration_file(path) == calibs
        assert load_calibration_meta(path) == {
            "observation.images.cam_b": {"intrinsics_rms_px": 0.2, "views": 12}
        }
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.json", "rig.yaml"]  # no temporary files left


def test_t_world_cam_is_inverted_and_bare_names_accepted(tmp_path):
    data = sim_calibration("cam_b")
    world_T_cam = np.linalg.inv(np.array(data.pop("T_cam_world"))).tolist()
    loaded = load_calibration_file(
        write(tmp_path / "rig.json", {"cam_b": {**data, "T_world_cam": world_T_cam}})
    )
    expected = np.array(sim_calibration("cam_b")["T_cam_world"])
    np.testing.assert_allclose(loaded["observation.images.cam_b"].T_cam_world, expected, atol=1e-12)
    # The camera's optical centre is the translation of T_world_cam.
    np.testing.assert_allclose(np.array(world_T_cam)[:3, 3], CAMERA_POSES["cam_b"][0], atol=1e-12)


def test_module_docstring_example_is_valid():
    pytest.importorskip("yaml")
    import yaml

    example = calibration_file.__doc__.split("Example (YAML)::")[1].split("The same in JSON")[0]
    data = yaml.safe_load(example)
    calib = calibration_file.parse_camera_entry(data["observation.images.front"], "front")
    centre = np.linalg.inv(np.array(calib.T_cam_world))[:3, 3]
    np.testing.assert_allclose(centre, [1.3, 0.0, 0.5], atol=1e-9)
    assert calib.image_size == (480, 640)


@pytest.mark.parametrize(
    ("entry", "match"),
    [
        ({"T_cam_wrld": "x"}, r"rig\.json: cam_b: unknown field\(s\) \['T_cam_wrld'\]"),
        ({"T_world_cam": "both"}, r"cam_b: give exactly one of 'T_cam_world'"),
        ({"distortion": [0.1, 0.2, 0.3]}, r"cam_b\.distortion: expected 4, 5, 8, 12 or 14"),
        ({"image_size": [32.0, 48]}, r"cam_b\.image_size"),
        ({"meta": "notes"}, r"cam_b\.meta"),
    ],
)
def test_bad_file_entries_name_camera_and_field(tmp_path, entry, match):
    path = write(tmp_path / "rig.json", {"cam_b": {**sim_calibration("cam_b"), **entry}})
    with pytest.raises(CalibrationError, match=match):
        load_calibration_file(path)


def test_bad_t_world_cam_is_reported_under_its_own_name(tmp_path):
    data = sim_calibration("cam_b")
    T = np.array(data.pop("T_cam_world"))
    T[0, 0] = 3.0
    path = write(tmp_path / "rig.json", {"cam_b": {**data, "T_world_cam": T.tolist()}})
    with pytest.raises(CalibrationError, match=r"cam_b\.T_world_cam: rotation part is not orthonormal"):
        load_calibration_file(path)


def test_unreadable_files(tmp_path):
    (tmp_path / "cv.yaml").write_text("%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n")
    with pytest.raises(CalibrationError, match="OpenCV FileStorage files are not supported"):
        load_calibration_file(tmp_path / "cv.yaml")
    (tmp_path / "broken.json").write_text("{not: [json")
    with pytest.raises(CalibrationError, match=r"broken\.json: not valid JSON"):
        load_calibration_file(tmp_path / "broken.json")
    twice = {"cam_b": sim_calibration("cam_b"), "observation.images.cam_b": sim_calibration("cam_b")}
    with pytest.raises(CalibrationError, match=r"observation\.images\.cam_b is given twice"):
        load_calibration_file(write(tmp_path / "twice.json", twice))


# --- attaching ---------------------------------------------------------------------------------------


def _inverted(cam: str) -> dict:
    data = sim_calibration(cam)
    data["T_cam_world"] = np.linalg.inv(np.array(data["T_cam_world"])).tolist()
    return data


def _looking_away(cam: str) -> dict:
    data = sim_calibration(cam)
    flip = np.diag([-1.0, 1.0, -1.0, 1.0])  # turn the camera by 180 degrees about its y axis
    data["T_cam_world"] = (flip @ np.array(data["T_cam_world"])).tolist()
    return data


def _in_millimetres(cam: str) -> dict:
    data = sim_calibration(cam)
    T = np.array(data["T_cam_world"])
    T[:3, 3] *= 1000.0
    data["T_cam_world"] = T.tolist()
    return data


def _with(cam: str, **changes) -> dict:
    return {**sim_calibration(cam), **changes}


def _skewed_rotation(cam: str) -> dict:
    data = copy.deepcopy(sim_calibration(cam))
    data["T_cam_world"][0][0] += 0.05
    return data


BAD_FILES = {
    "missing camera": (
        {"cam_b": sim_calibration("cam_b")},
        r"observation\.images\.cam_c: no calibration in the file",
    ),
    "unknown camera": (
        {**{c: sim_calibration(c) for c in CAMS}, "cam_z": sim_calibration("cam_b")},
        r"observation\.images\.cam_z: in the calibration file but not an image feature",
    ),
    "swapped size": (
        {"cam_b": _with("cam_b", image_size=[48, 36]), "cam_c": sim_calibration("cam_c")},
        r"observation\.images\.cam_b\.image_size: \[48, 36\] is the dataset's .* swapped",
    ),
    "cropped size": (
        {"cam_b": _with("cam_b", image_size=[48, 48]), "cam_c": sim_calibration("cam_c")},
        r"observation\.images\.cam_b\.image_size: .*another aspect ratio",
    ),
    "not orthonormal": (
        {"cam_b": _skewed_rotation("cam_b"), "cam_c": sim_calibration("cam_c")},
        r"cam_b\.T_cam_world: rotation part is not orthonormal",
    ),
    "looking away": (
        {"cam_b": sim_calibration("cam_b"), "cam_c": _looking_away("cam_c")},
        r"observation\.images\.cam_c\.T_cam_world: the workspace volume's centre is behind the camera",
    ),
    "inverted": (
        {"cam_b": _inverted("cam_b"), "cam_c": sim_calibration("cam_c")},
        r"observation\.images\.cam_b\.T_cam_world: only .* of the workspace volume is in the image",
    ),
    "millimetres": (
        {"cam_b": _in_millimetres("cam_b"), "cam_c": sim_calibration("cam_c")},
        r"observation\.images\.cam_b\.T_cam_world: .*is the translation in metres\?",
    ),
    "distortion": (
        {"cam_b": _with("cam_b", distortion=[0.1, -0.05, 0.0, 0.0, 0.0]), "cam_c": sim_calibration("cam_c")},
        r"observation\.images\.cam_b\.distortion: non-zero \(moves pixels by up to [0-9.]+ px\)",
    ),
}


def test_bad_files_leave_the_dataset_untouched(pristine, tmp_path, capsys):
    """Every problem is reported (camera and field), nothing is written: one dataset serves all cases."""
    before = digests(pristine)
    for name, (data, match) in BAD_FILES.items():
        path = write(tmp_path / f"{name.replace(' ', '_')}.json", data)
        assert main(["--root", str(pristine), "--calibration", str(path)]) == 2, name
        err = capsys.readouterr().err
        assert re.search(match, err), f"{name}: {err}"
        assert digests(pristine) == before, f"{name}: the dataset changed"
    # Several problems at once are all listed.
    both = write(tmp_path / "both.json", {"cam_b": _inverted("cam_b"), "cam_c": _looking_away("cam_c")})
    assert main(["--root", str(pristine), "--calibration", str(both)]) == 2
    err = capsys.readouterr().err
    assert "nothing was written" in err and "cam_b.T_cam_world" in err and "cam_c.T_cam_world" in err


def test_distortion_modes(dataset, tmp_path):
    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata

    distortion = [0.1, -0.05, 0.001, 0.0, 0.0]
    rig = write(tmp_path / "rig.json", {c: _with(c, distortion=distortion) for c in CAMS})
    assert main(["--root", str(dataset), "--calibration", str(rig), "--distortion", "ignore"]) == 0
    info = LeRobotDatasetMetadata(REPO_ID, root=dataset).features["observation.images.cam_b"]["info"]
    assert info["calibration"]["distortion"] == distortion  # describes the raw frames
    assert info["calibration_source"]["distortion"] == "ignore"
    # Re-attaching the same file with another meaning of the distortion needs --overwrite.
    args = ["--root", str(dataset), "--calibration", str(rig), "--distortion", "undistorted"]
    assert main(args) == 2
    assert main([*args, "--overwrite"]) == 0
    info = LeRobotDatasetMetadata(REPO_ID, root=dataset).features["observation.images.cam_b"]["info"]
    assert "distortion" not in info["calibration"]
    assert info["calibration_source"]["notes"] == [
        "frames already undistorted: distortion dropped",
        "replaces the previous calibration",
    ]


def test_reattach_identical_is_allowed_and_dry_run_writes_nothing(dataset, tmp_path, capsys):
    rig = write(tmp_path / "rig.json", {c: sim_calibration(c) for c in CAMS})
    before = digests(dataset)
    assert main(["--root", str(dataset), "--calibration", str(rig), "--dry-run"]) == 0
    assert "nothing written" in capsys.readouterr().out
    assert digests(dataset) == before
    assert main(["--root", str(dataset), "--calibration", str(rig), "--no-backup"]) == 0
    assert main(["--root", str(dataset), "--calibration", str(rig), "--no-backup"]) == 0
    assert not (dataset / "meta" / "info.json.bak").exists()
    assert sorted(p.name for p in (dataset / "meta").iterdir()) == sorted(
        p.name for p in (dataset / "meta").iterdir() if not p.name.startswith(".")
    ), "no temporary files left in meta/"


def test_skip_camera_then_train_on_the_others(dataset, tmp_path):
    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata

    rig = write(tmp_path / "rig.json", {"cam_b": sim_calibration("cam_b")})
    assert main(["--root", str(dataset), "--calibration", str(rig), "--skip-camera", "cam_c"]) == 0
    features = LeRobotDatasetMetadata(REPO_ID, root=dataset).features
    assert "calibration" not in (features["observation.images.cam_c"].get("info") or {})
    config = tiny_config(cams=CAMS, size=SIZE[0], cameras=["cam_b"])
    config.set_dataset_feature_metadata(features)
    assert list(config.camera_calibration) == ["observation.images.cam_b"]
    with pytest.raises(CalibrationError, match=r"observation\.images\.cam_c: no camera calibration"):
        tiny_config(cams=CAMS, size=SIZE[0]).set_dataset_feature_metadata(features)


def test_volume_bounds_options(pristine, tmp_path, capsys):
    rig = write(tmp_path / "rig.json", {c: sim_calibration(c) for c in CAMS})
    far = ["--volume-bounds", "5", "6", "5", "6", "0", "1"]
    assert main(["--root", str(pristine), "--calibration", str(rig), "--dry-run", *far]) == 2
    assert "volume bounds [[5.0, 6.0], [5.0, 6.0], [0.0, 1.0]]" in capsys.readouterr().err
    config = write(
        tmp_path / "config.json", {"type": "omnid", "volume_bounds": [[0.3, 0.8], [-0.3, 0.3], [0, 0.3]]}
    )
    assert (
        main(
            ["--root", str(pristine), "--calibration", str(rig), "--dry-run", "--policy-config", str(config)]
        )
        == 0
    )
    bad = write(tmp_path / "bad.json", {"policy": {"volume_bounds": [[1, 0], [0, 1], [0, 1]]}})
    assert main(["--root", str(pristine), "--calibration", str(rig), "--policy-config", str(bad)]) == 2
    assert "min < max" in capsys.readouterr().err


def test_hub_repo_id(monkeypatch, tmp_path, pristine, capsys):
    """Without --root the dataset comes from LeRobot's cache, else from the Hub; offline is a clear error."""
    import huggingface_hub
    import lerobot.utils.constants

    monkeypatch.setattr(lerobot.utils.constants, "HF_LEROBOT_HOME", tmp_path / "cache")

    def offline(*args, **kwargs):
        raise huggingface_hub.errors.LocalEntryNotFoundError("no connection")

    monkeypatch.setattr(huggingface_hub, "snapshot_download", offline)
    rig = write(tmp_path / "rig.json", {c: sim_calibration(c) for c in CAMS})
    assert main(["--repo-id", "someone/dataset", "--calibration", str(rig)]) == 2
    err = capsys.readouterr().err
    assert "--repo-id someone/dataset: could not download the dataset from the Hub" in err
    assert "pass --root" in err
    shutil.copytree(pristine, tmp_path / "cache" / "someone" / "dataset")
    assert main(["--repo-id", "someone/dataset", "--calibration", str(rig), "--dry-run"]) == 0
    assert main(["--calibration", str(rig)]) == 2
    assert "give --root" in capsys.readouterr().err
