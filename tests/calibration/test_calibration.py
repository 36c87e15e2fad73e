"""The calibration schema: parsing, validation errors naming camera and field, resizing, the tensors."""

import copy

import pytest
import torch
from omnid_testing import synthetic_calibration

from lerobot_omnid.calibration.schema import (
    CalibrationError,
    CameraCalibration,
    calibration_from_feature_info,
    camera_matrices,
)
from lerobot_omnid.geometry import apply_transform, project_to_pixels


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


def test_resized_keeps_pixel_centres_and_returns_self_at_its_size():
    calib = CameraCalibration.from_dict(
        {
            "K": [[120.0, 0.5, 49.0], [0.0, 118.0, 41.0], [0.0, 0.0, 1.0]],
            "T_cam_world": torch.eye(4).tolist(),
            "image_size": [80, 100],
            "distortion": [0.1, -0.05, 0.0, 0.0],
        }
    )
    assert calib.resized((80, 100)) is calib
    half = calib.resized((40, 25))
    assert half.image_size == (40, 25) and half.distortion == calib.distortion
    xyz_cam = torch.tensor([[0.3, -0.2, 1.5]], dtype=torch.float64)
    uv, _ = project_to_pixels(torch.tensor(calib.K, dtype=torch.float64), xyz_cam)
    uv_half, _ = project_to_pixels(torch.tensor(half.K, dtype=torch.float64), xyz_cam)
    # The same scene point lands where the resize puts its pixel: u' = (u + 0.5) * sx - 0.5.
    expected = (uv + 0.5) * torch.tensor([25 / 100, 40 / 80], dtype=torch.float64) - 0.5
    assert torch.allclose(uv_half, expected, atol=1e-9)
    with pytest.raises(CalibrationError, match="positive"):
        calib.resized((0, 10))


def test_camera_matrices_of_a_calibration_stored_at_another_size():
    """A camera calibrated at 480x640 and fed at 96x128 projects with K scaled to 96x128, per camera."""
    stored = CameraCalibration.from_dict(synthetic_calibration("cam_b", 64)).resized((480, 640))
    other = CameraCalibration.from_dict(synthetic_calibration("cam_c", 64))
    pix_T_cam, cam_T_world = camera_matrices([stored, other], [(96, 128), (64, 64)])
    assert pix_T_cam.shape == (2, 3, 3) and cam_T_world.shape == (2, 4, 4)
    assert pix_T_cam.dtype == torch.float32
    assert torch.allclose(pix_T_cam[0], torch.tensor(stored.resized((96, 128)).K, dtype=torch.float32))
    assert not torch.allclose(pix_T_cam[0], torch.tensor(stored.K, dtype=torch.float32))
    assert torch.allclose(pix_T_cam[1], torch.tensor(other.K, dtype=torch.float32))
    assert torch.allclose(cam_T_world[0], torch.tensor(stored.T_cam_world, dtype=torch.float32))
    # A world point projects to the pixel the downscaled image shows it at.
    xyz_world = torch.tensor([[0.45, 0.05, 0.02]])
    uv_small, _ = project_to_pixels(pix_T_cam[0], apply_transform(cam_T_world[0], xyz_world))
    K_big = torch.tensor(stored.K, dtype=torch.float32)
    uv_big, _ = project_to_pixels(K_big, apply_transform(cam_T_world[0], xyz_world))
    assert torch.allclose(uv_small, (uv_big + 0.5) * torch.tensor([128 / 640, 96 / 480]) - 0.5, atol=1e-3)
    with pytest.raises(ValueError, match="2 calibrations for 1 image sizes"):
        camera_matrices([stored, other], [(96, 128)])
