"""The calibration schema: parsing, validation errors naming camera and field."""

import copy

import pytest
from omnid_testing import synthetic_calibration

from lerobot_omnid.calibration.schema import (
    CalibrationError,
    CameraCalibration,
    calibration_from_feature_info,
)


def test_round_trip():
    data = synthetic_calibration("cam_b", 64)
    calib = CameraCalibration.from_dict(data, camera="cam_b")
    assert calib.image_size == (64, 64)
    again = CameraCalibration.from_dict(calib.to_dict())
    assert again == calib


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda d: d.pop("K"), "'K' is missing"),
        (lambda d: d.update(K=[[1, 0], [0, 1]]), r"cam_x\.K: expected a 3x3"),
        (lambda d: d.update(image_size=[64]), r"cam_x\.image_size"),
        (lambda d: d["K"].__setitem__(1, [0.5, 32, 31.5]), r"cam_x\.K: expected \[\[fx"),
        (lambda d: d["T_cam_world"][0].__setitem__(0, 3.0), "not orthonormal"),
        (lambda d: d["T_cam_world"][3].__setitem__(0, 1.0), "last row"),
        (lambda d: d["T_cam_world"][0].__setitem__(1, float("nan")), "finite"),
    ],
)
def test_bad_calibration_names_camera_and_field(mutate, match):
    data = copy.deepcopy(synthetic_calibration("cam_b", 64))
    mutate(data)
    with pytest.raises(CalibrationError, match=match):
        CameraCalibration.from_dict(data, camera="cam_x")


def test_reflection_rejected():
    data = synthetic_calibration("cam_b", 64)
    data["T_cam_world"][0] = [-v for v in data["T_cam_world"][0][:3]] + [data["T_cam_world"][0][3]]
    with pytest.raises(CalibrationError, match="reflection"):
        CameraCalibration.from_dict(data)


def test_missing_in_feature_info_names_the_feature():
    with pytest.raises(CalibrationError, match=r"observation\.images\.cam_b: no camera calibration"):
        calibration_from_feature_info(
            "observation.images.cam_b", {"dtype": "video", "info": {"video.fps": 10}}
        )
