"""Per-frame calibration columns: key names, feature specs, flat <-> matrix round trips for numpy and torch,
errors naming the field, and the trap they are there for (LeRobot types them as state)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from lerobot.configs import FeatureType
from lerobot.utils.feature_utils import dataset_to_policy_features

from lerobot_omnid.calibration.frame_columns import (
    calibration_column_features,
    extrinsics_column,
    extrinsics_from_column,
    extrinsics_key,
    intrinsics_column,
    intrinsics_from_column,
    intrinsics_key,
    is_calibration_key,
)

T_CAM_WORLD = np.array(
    [[0.0, -1.0, 0.0, 0.1], [0.0, 0.0, -1.0, 0.5], [1.0, 0.0, 0.0, 1.2], [0.0, 0.0, 0.0, 1.0]]
)
K = np.array([[110.0, 0.0, 63.5], [0.0, 110.0, 47.5], [0.0, 0.0, 1.0]])


def test_keys() -> None:
    assert (
        extrinsics_key("cam_b")
        == extrinsics_key("observation.images.cam_b")
        == "observation.extrinsics.cam_b"
    )
    assert intrinsics_key("wrist") == "observation.intrinsics.wrist"
    assert is_calibration_key("observation.extrinsics.cam_b") and is_calibration_key(
        "observation.intrinsics.x"
    )
    assert not is_calibration_key("observation.state") and not is_calibration_key("observation.images.cam_b")
    with pytest.raises(ValueError, match=r"camera: expected a camera name .* got 'observation.state'"):
        extrinsics_key("observation.state")


def test_features_spec() -> None:
    features = calibration_column_features(["cam_b", "observation.images.front"])
    assert list(features) == [
        "observation.extrinsics.cam_b",
        "observation.intrinsics.cam_b",
        "observation.extrinsics.front",
        "observation.intrinsics.front",
    ]
    extrinsics, intrinsics = (
        features["observation.extrinsics.front"],
        features["observation.intrinsics.front"],
    )
    assert (extrinsics["dtype"], extrinsics["shape"], extrinsics["names"][:2]) == (
        "float32",
        (16,),
        ["T_cam_world_00", "T_cam_world_01"],
    )
    assert (intrinsics["dtype"], intrinsics["shape"], intrinsics["names"][-1]) == ("float32", (9,), "K_22")


def test_round_trips_numpy_and_torch() -> None:
    extrinsics, intrinsics = extrinsics_column(T_CAM_WORLD), intrinsics_column(K)
    assert extrinsics.dtype == intrinsics.dtype == np.float32
    assert extrinsics.shape == (16,) and intrinsics.shape == (9,)
    np.testing.assert_array_equal(extrinsics[:4], T_CAM_WORLD[0].astype(np.float32))  # row-major
    np.testing.assert_allclose(extrinsics_from_column(extrinsics), T_CAM_WORLD, atol=1e-7)
    np.testing.assert_allclose(intrinsics_from_column(intrinsics), K)
    # A batch of frames (B, T, 16) from a dataloader -> (B, T, 4, 4), still a tensor.
    batch = torch.from_numpy(np.tile(extrinsics, (2, 3, 1)))
    matrices = extrinsics_from_column(batch)
    assert isinstance(matrices, torch.Tensor) and matrices.shape == (2, 3, 4, 4)
    torch.testing.assert_close(matrices[1, 2], torch.from_numpy(T_CAM_WORLD).float())
    assert intrinsics_from_column(torch.zeros(5, 9)).shape == (5, 3, 3)


def test_bad_shapes_name_the_field() -> None:
    with pytest.raises(ValueError, match=r"T_cam_world: expected a 4x4 matrix, got shape \(3, 4\)"):
        extrinsics_column(T_CAM_WORLD[:3])
    with pytest.raises(ValueError, match=r"K: expected a 3x3 matrix, got shape \(9,\)"):
        intrinsics_column(K.reshape(9))
    with pytest.raises(ValueError, match=r"extrinsics: expected a last dimension of 16, got shape \(2, 12\)"):
        extrinsics_from_column(torch.zeros(2, 12))
    with pytest.raises(ValueError, match=r"intrinsics: expected a last dimension of 9, got shape \(\)"):
        intrinsics_from_column(np.float32(1.0))


def test_lerobot_types_the_columns_as_state() -> None:
    """Why a policy must pick the columns out itself: LeRobot makes them STATE inputs to be normalised."""
    features = {
        "observation.state": {"dtype": "float32", "shape": (16,), "names": None},
        **calibration_column_features(["cam_b"]),
    }
    policy_features = dataset_to_policy_features(features)
    assert policy_features["observation.extrinsics.cam_b"].type is FeatureType.STATE
    assert [key for key in policy_features if not is_calibration_key(key)] == ["observation.state"]
