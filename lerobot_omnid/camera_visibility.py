"""Which recorded cameras an episode is meant to show: the per-frame column ``observation.camera_visible``.

Schema: float32, shape (number of recorded cameras,), ``names`` the recorded cameras' names (``cam_a``) in
the order of their image features; 1.0 for a camera the episode shows, 0.0 for one it hides. The images of
a hidden camera are still recorded as they were rendered: the column, not black pixels, hides them, and
only a policy that reads it (OmniD) leaves the camera out. The spec depends only on the recorded cameras,
never on which are hidden, so that a dataset of new-camera episodes (``omnid-record --hidden-cameras
cam_b,cam_c,cam_d,cam_e``) and one of replayed episodes of the training cameras (``--hidden-cameras cam_a``)
have the same features and merge with ``lerobot-edit-dataset``.

The trap, as for the calibration columns (:mod:`lerobot_omnid.calibration.frame_columns`): LeRobot's
``dataset_to_policy_features`` turns this key into a STATE feature, whose normaliser would rescale a 0/1
column by the min / max of a column that is constant in a dataset of one kind of episodes. A policy must
read it raw and keep it out of its state and its normalised features.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import torch
from lerobot.utils.constants import OBS_STR
from torch import Tensor

from lerobot_omnid.keys import camera_name

CAMERA_VISIBLE_KEY = f"{OBS_STR}.camera_visible"


def camera_visible_feature(cameras: Sequence[str]) -> dict[str, Any]:
    """LeRobot feature spec (for ``LeRobotDataset.create``) of the column over the recorded ``cameras``."""
    return {"dtype": "float32", "shape": (len(cameras),), "names": list(cameras)}


def camera_visible_column(cameras: Sequence[str], hidden: Iterable[str]) -> np.ndarray:
    """(len(cameras),) float32 column value: 0.0 for the cameras in ``hidden``, 1.0 for the others."""
    hidden = set(hidden)
    return np.array([0.0 if cam in hidden else 1.0 for cam in cameras], dtype=np.float32)


def check_hidden_cameras(field_name: str, hidden: Sequence[str], cameras: Sequence[str]) -> list[str]:
    """Check a list of cameras to hide: distinct, among the recorded ``cameras``, and not all of them (an
    episode must show at least one camera); empty is allowed (every camera shown). Returns it as a list."""
    if isinstance(hidden, str) or not isinstance(hidden, list | tuple):
        raise ValueError(f"{field_name}: expected a list of cameras among {list(cameras)}, got {hidden!r}")
    if len(set(hidden)) != len(hidden) or not set(hidden) <= set(cameras):
        raise ValueError(
            f"{field_name}: expected distinct cameras among the recorded ones {list(cameras)}, "
            f"got {list(hidden)}"
        )
    if set(hidden) == set(cameras):
        raise ValueError(
            f"{field_name}: expected a subset of the recorded cameras {list(cameras)} that leaves at least "
            f"one visible, got all of them {list(hidden)}"
        )
    return list(hidden)


def visible_cameras(column: Tensor, names: Sequence[str], cameras: Sequence[str]) -> Tensor:
    """The column of every frame as a mask over a policy's cameras, matched by name.

    Args:
        column: (..., R) values of ``observation.camera_visible`` over the R recorded cameras, 0 or 1.
        names: The R recorded cameras' names, the column feature's ``names``.
        cameras: The policy's cameras (names or image feature keys), any subset of ``names`` in any order.
    Returns:
        (..., S) bool, True where the frame shows the policy's camera.
    """
    if len(column.shape) == 0 or column.shape[-1] != len(names):
        raise ValueError(
            f"`{CAMERA_VISIBLE_KEY}`: expected a last dimension of {len(names)} (one value per recorded "
            f"camera {list(names)}), got shape {tuple(column.shape)}"
        )
    if not ((column == 0) | (column == 1)).all():
        raise ValueError(
            f"`{CAMERA_VISIBLE_KEY}`: expected 0.0 (hidden) or 1.0 (visible), got values "
            f"{sorted(set(column.flatten().tolist()))[:8]}; the column must reach the policy unnormalised"
        )
    wanted = [camera_name(cam) for cam in cameras]
    unknown = [cam for cam in wanted if cam not in names]
    if unknown:
        raise ValueError(
            f"`{CAMERA_VISIBLE_KEY}`: the policy's cameras {unknown} are not among its recorded cameras "
            f"{list(names)}, so whether they are shown is unknown"
        )
    index = torch.tensor([list(names).index(cam) for cam in wanted], device=column.device)
    return column.index_select(-1, index) > 0.5
