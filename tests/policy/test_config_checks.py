"""OmniDConfig refuses what would silently do nothing: a calibration file that matches none of the dataset's
cameras or overrides a camera calibrated per frame, augmentations without the OFG; and its errors are
logged, so that a user of ``lerobot-train`` (whose parser drops their message) reads them."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from omnid_testing import STATE_DIM, synthetic_calibration, tiny_config

from lerobot_omnid.calibration.frame_columns import calibration_column_features
from lerobot_omnid.calibration.rig_file import save_calibration_file
from lerobot_omnid.calibration.schema import CalibrationError, CameraCalibration
from lerobot_omnid.policy.configuration_omnid import OmniDConfig
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy

SIZE = 32
CAMS_B = {"cam_b": "cam_b"}
CAMS_BC = {"cam_b": "cam_b", "cam_c": "cam_c"}
OFG_AUGMENTATIONS = {  # each set to a value that is on
    "random_crop_min_scale": 0.5,
    "camera_rotation_deg": 5.0,
    "calibration_noise_rotation_deg": 2.0,
    "calibration_noise_translation_mm": 20.0,
    "calibration_noise_focal_pct": 2.0,
    "calibration_noise_principal_px": 1.0,
    "camera_dropout": 0.5,
    "single_camera_rate": 0.5,
}


def dataset_features(cams: dict[str, str], per_frame: tuple[str, ...] = ()) -> dict[str, dict]:
    """Features of a dataset with image features ``observation.images.<name>``, calibrated as the synthetic
    camera ``cams[name]`` in their info or, for the names in ``per_frame``, by calibration columns."""
    return {
        "observation.state": {"dtype": "float32", "shape": (STATE_DIM,), "names": None},
        "action": {"dtype": "float32", "shape": (10,), "names": None},
        **{
            f"observation.images.{name}": {
                "dtype": "video",
                "shape": (SIZE, SIZE, 3),
                "names": ["height", "width", "channels"],
                "info": {} if name in per_frame else {"calibration": synthetic_calibration(cam, SIZE)},
            }
            for name, cam in cams.items()
        },
        **calibration_column_features(per_frame),
    }


def moved(cam: str) -> dict:
    """The synthetic calibration of ``cam`` with the camera 10 cm along its own x axis: a file's calibration
    told apart from the dataset's."""
    calib = synthetic_calibration(cam, SIZE)
    calib["T_cam_world"][0][3] -= 0.1
    return calib


def rig_file(path: Path, cams: dict[str, str]) -> str:
    """A calibration file keyed by the names in ``cams``, each the moved synthetic camera ``cams[name]``."""
    calibrations = {name: CameraCalibration.from_dict(moved(cam), camera=name) for name, cam in cams.items()}
    return str(save_calibration_file(path, calibrations))


def assert_taken_from_file(config: OmniDConfig, key: str, cam: str) -> None:
    """``key``'s calibration in ``config`` is the file's (moved) one of the synthetic camera ``cam``."""
    taken = config.camera_calibration[key]["T_cam_world"]
    expected = moved(cam)["T_cam_world"]
    assert [v for row in taken for v in row] == pytest.approx([v for row in expected for v in row])


def config_with_file(path: str) -> OmniDConfig:
    return tiny_config(("cam_b",), size=SIZE, calibration_path=path)


def test_a_file_none_of_whose_cameras_is_in_the_dataset_is_refused_naming_both(tmp_path):
    config = config_with_file(rig_file(tmp_path / "rig.yaml", {"front": "cam_b"}))
    with pytest.raises(CalibrationError) as error:
        config.set_dataset_feature_metadata(dataset_features({"cam_front": "cam_b"}))
    message = str(error.value)
    assert "`calibration_path`" in message
    assert "['observation.images.front']" in message and "['observation.images.cam_front']" in message


@pytest.mark.parametrize("file_key", ["cam_front", "observation.images.cam_front"])
def test_a_file_keyed_by_camera_name_or_feature_key_is_taken(tmp_path, file_key):
    path = rig_file(tmp_path / "rig.json", {file_key: "cam_b", "spare": "cam_c"})
    config = config_with_file(path)
    config.set_dataset_feature_metadata(dataset_features({"cam_front": "cam_b"}))
    assert_taken_from_file(config, "observation.images.cam_front", "cam_b")


def test_a_file_matching_only_cameras_the_policy_does_not_use_is_refused(tmp_path):
    config = tiny_config(
        ("cam_b",),
        size=SIZE,
        cameras=["cam_b"],
        calibration_path=rig_file(tmp_path / "r.yaml", {"cam_c": "cam_c"}),
    )
    with pytest.raises(
        CalibrationError, match=r"none of the file's cameras \['observation\.images\.cam_c'\]"
    ):
        config.set_dataset_feature_metadata(dataset_features({"cam_b": "cam_b", "cam_c": "cam_c"}))


def test_a_file_entry_for_a_camera_calibrated_per_frame_is_refused_naming_it(tmp_path):
    features = dataset_features({"cam_b": "cam_b", "cam_c": "cam_c"}, per_frame=("cam_c",))
    both = tiny_config(("cam_b",), size=SIZE, calibration_path=rig_file(tmp_path / "both.yaml", CAMS_BC))
    with pytest.raises(
        CalibrationError, match=r"the file calibrates \['observation\.images\.cam_c'\].* every frame"
    ):
        both.set_dataset_feature_metadata(features)

    # An entry for the camera calibrated statically is taken, the per-frame camera keeps its columns.
    static_only = tiny_config(("cam_b",), size=SIZE, calibration_path=rig_file(tmp_path / "b.yaml", CAMS_B))
    static_only.set_dataset_feature_metadata(features)
    assert static_only.frame_calibration == ["observation.images.cam_c"]
    assert list(static_only.camera_calibration) == ["observation.images.cam_b"]
    assert_taken_from_file(static_only, "observation.images.cam_b", "cam_b")


def test_a_checkpoint_calibrated_per_frame_refuses_a_file_entry_for_that_camera(tmp_path):
    """The same without a dataset (``lerobot-eval --policy.path=... --policy.calibration_path=...``): the
    checkpoint's ``frame_calibration`` decides."""
    keys = ["observation.images.cam_b", "observation.images.cam_c"]
    config = tiny_config(
        ("cam_b", "cam_c"),
        size=SIZE,
        camera_calibration={},
        frame_calibration=keys,
        calibration_path=rig_file(tmp_path / "rig.yaml", CAMS_B),
    )
    with pytest.raises(CalibrationError, match=r"the file calibrates \['observation\.images\.cam_b'\]"):
        OmniDPolicy(config)


@pytest.mark.parametrize(("name", "value"), OFG_AUGMENTATIONS.items())
def test_ofg_augmentations_are_refused_without_the_ofg(name, value):
    with pytest.raises(ValueError, match=rf"`{name}`: expected .* with use_ofg=false, got {value}: "):
        tiny_config(use_ofg=False, **{name: value})
    assert getattr(tiny_config(**{name: value}), name) == value  # with the OFG they act


def test_no_ofg_with_the_augmentations_off_is_accepted():
    assert not tiny_config(use_ofg=False).use_ofg


def test_an_invalid_config_is_logged_before_it_is_raised(caplog):
    """lerobot-train's parser (draccus) reports only "Couldn't instantiate class OmniDConfig": the log is
    where its user reads what is wrong."""
    with caplog.at_level(logging.ERROR), pytest.raises(ValueError) as error:
        OmniDConfig(volume_shape=(0, 4, 2))
    assert str(error.value) in caplog.text and "`volume_bounds` / `volume_shape`" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.ERROR), pytest.raises(CalibrationError):
        OmniDConfig(calibration_path="missing.json")
    assert "`calibration_path`: calibration file missing.json does not exist" in caplog.text
