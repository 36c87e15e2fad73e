"""The image-use check: a prediction from an item's own observation, calibration columns included, and the
same prediction moving when the images are another episode's."""

from __future__ import annotations

import numpy as np
import pytest
from lerobot.policies import make_pre_post_processors
from omnid_testing import static_and_per_frame_twins

from lerobot_omnid.diagnostics.image_use import chunk_action


def test_a_per_frame_policy_is_given_each_items_calibration_columns(tmp_path) -> None:
    """On a copy of a dataset whose columns hold its static calibration, the per-frame policy predicts what
    the same weights calibrated statically predict on the original; other images change the prediction."""
    cams = ("cam_b", "cam_c")
    keys = [f"observation.images.{cam}" for cam in cams]
    static_data, columns_root, static, per_frame = static_and_per_frame_twins(
        tmp_path, cams, episodes=2, frames=5
    )
    columns_data = type(static_data)(static_data.repo_id, root=columns_root)

    actions = {}
    for name, policy, data in (("static", static, static_data), ("per_frame", per_frame, columns_data)):
        policy.eval()
        pre, post = make_pre_post_processors(policy.config, dataset_stats=data.meta.stats)
        item, other = data[1], data[6]  # frame 1 of episodes 0 and 1
        actions[name] = chunk_action(policy, pre, post, {k: item[k] for k in keys}, item, ahead=1)
        actions[name + "_swapped"] = chunk_action(
            policy, pre, post, {k: other[k] for k in keys}, item, ahead=1
        )
    np.testing.assert_allclose(actions["per_frame"], actions["static"], rtol=1e-4, atol=1e-5)
    assert np.abs(actions["per_frame_swapped"] - actions["per_frame"]).max() > 1e-4
    with pytest.raises(ValueError, match="--ahead: expected <"):
        chunk_action(per_frame, pre, post, {k: item[k] for k in keys}, item, ahead=1000)
