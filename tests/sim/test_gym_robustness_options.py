"""Env options of the robustness evaluation: ``camera_offsets`` (a bumped camera, checked against segmentation
renders) and ``blackout_from_step`` (a camera dying mid-episode)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from gym_omnid.calibration import project
from gym_omnid.camera_offsets import check_camera_offsets, rotation_from_vector_deg

HIDDEN_GROUP = 5  # geom group that hides everything but the apple in the segmentation renders
OFFSETS = {  # 4 degrees about a tilted axis and 4 cm, as the robustness sweep's largest level
    "cam_b": (*(4.0 * np.array([0.6, 0.0, 0.8])), *(0.04 * np.array([0.0, -0.6, 0.8]))),
    "cam_d": (*(4.0 * np.array([0.6, 0.8, 0.0])), *(0.04 * np.array([0.8, 0.0, 0.6]))),
}
APPLE_POINTS = np.array([[0.45, -0.15, 0.04], [0.6, 0.1, 0.1]])


def delta(offset) -> np.ndarray:
    """``[R(r) | t]`` (4, 4) of an offset."""
    out = np.eye(4)
    out[:3, :3] = rotation_from_vector_deg(offset[:3])
    out[:3, 3] = offset[3:]
    return out


def apple_centroids(env, cams) -> dict[str, list[np.ndarray]]:
    """Per camera, the centroid (u, v) of the apple's rendered pixels at each of ``APPLE_POINTS``."""
    apple_geom = env.model.geom("apple").id
    env.model.geom_group[:] = HIDDEN_GROUP
    env.model.geom_group[apple_geom] = 0
    qpos_adr = env.model.jnt_qposadr[env.model.body_jntadr[env.model.body("apple").id]]
    option = mujoco.MjvOption()
    option.geomgroup[:] = 1
    option.geomgroup[HIDDEN_GROUP] = 0
    renderer = mujoco.Renderer(env.model, *env.image_size)
    renderer.enable_segmentation_rendering()
    out: dict[str, list[np.ndarray]] = {cam: [] for cam in cams}
    try:
        for xyz_world in APPLE_POINTS:
            env.data.qpos[qpos_adr : qpos_adr + 3] = xyz_world
            mujoco.mj_forward(env.model, env.data)
            for cam in cams:
                renderer.update_scene(env.data, camera=cam, scene_option=option)
                seg = renderer.render()
                mask = (seg[..., 0] == apple_geom) & (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM)
                assert mask.sum() > 20, f"{cam}: apple at {xyz_world} not visible"
                rows, cols = np.nonzero(mask)
                out[cam].append(np.array([cols.mean(), rows.mean()]))
    finally:
        renderer.close()
    return out


def test_bumped_camera_renders_move_by_the_requested_amount(make_env) -> None:
    """The moved camera's calibration is ``[R | t] @`` the old one (its centre 4 cm away, turned 4 degrees),
    the apple projected with it lands on its rendered pixels, and the render moved as the calibrations
    predict."""
    default = make_env("select_apple", image_size=128)
    bumped = make_env("select_apple", image_size=128, camera_offsets=OFFSETS)
    for env in (default, bumped):
        env.reset(seed=0)
    seen = {"default": apple_centroids(default, OFFSETS), "bumped": apple_centroids(bumped, OFFSETS)}
    for cam, offset in OFFSETS.items():
        old, new = default.camera_calibration(cam), bumped.camera_calibration(cam)
        np.testing.assert_allclose(new["T_cam_world"], delta(offset) @ old["T_cam_world"], atol=1e-9)
        np.testing.assert_allclose(new["K"], old["K"])
        centre_old = -old["T_cam_world"][:3, :3].T @ old["T_cam_world"][:3, 3]
        centre_new = -new["T_cam_world"][:3, :3].T @ new["T_cam_world"][:3, 3]
        assert np.linalg.norm(centre_new - centre_old) == pytest.approx(0.04, abs=1e-9)
        turn = new["T_cam_world"][:3, :3] @ old["T_cam_world"][:3, :3].T
        angle = math.degrees(math.acos(np.clip((np.trace(turn) - 1) / 2, -1, 1)))
        assert angle == pytest.approx(4.0, abs=1e-6)
        for i, xyz_world in enumerate(APPLE_POINTS):
            uv_new, _ = project(new["K"], new["T_cam_world"], xyz_world[None])
            uv_old, _ = project(old["K"], old["T_cam_world"], xyz_world[None])
            rendered_new, rendered_old = seen["bumped"][cam][i], seen["default"][cam][i]
            assert np.linalg.norm(uv_new[0] - rendered_new) < 1.0, (cam, xyz_world)
            # The render moved by what the two calibrations predict, several pixels at this size.
            predicted, moved = uv_new[0] - uv_old[0], rendered_new - rendered_old
            assert np.linalg.norm(predicted) > 5.0, (cam, predicted)
            assert np.linalg.norm(moved - predicted) < 1.0, (cam, moved, predicted)
    # Cameras without an offset are where they were.
    np.testing.assert_array_equal(
        bumped.camera_calibration("cam_c")["T_cam_world"], default.camera_calibration("cam_c")["T_cam_world"]
    )


def test_zero_offset_changes_nothing(make_env) -> None:
    default = make_env("select_apple", image_size=64)
    zero = make_env("select_apple", image_size=64, camera_offsets={"cam_b": [0, 0, 0, 0, 0, 0]})
    obs_default, _ = default.reset(seed=3)
    obs_zero, _ = zero.reset(seed=3)
    np.testing.assert_allclose(
        zero.camera_calibration("cam_b")["T_cam_world"],
        default.camera_calibration("cam_b")["T_cam_world"],
        atol=1e-12,
    )
    np.testing.assert_array_equal(obs_zero["pixels"]["cam_b"], obs_default["pixels"]["cam_b"])


def test_blackout_from_step_blacks_from_that_step(make_env) -> None:
    env = make_env("select_apple", image_size=32, blackout_cameras=["cam_b"], blackout_from_step=3)
    action = np.concatenate([env.tcp_pose()[0], [1, 0, 0, 0, -1, 0], [0]]).astype(np.float32)
    for _ in range(2):  # every episode: seen until step 3, black from it
        obs, _ = env.reset(seed=0)
        black = [not obs["pixels"]["cam_b"].any()]
        others = [obs["pixels"]["cam_c"].any()]
        for _ in range(5):
            obs, *_ = env.step(action)
            black.append(not obs["pixels"]["cam_b"].any())
            others.append(obs["pixels"]["cam_c"].any())
        assert black == [False, False, False, True, True, True]
        assert all(others)
    assert env.render().any()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"camera_offsets": {"cam_z": [0] * 6}}, "camera_offsets: expected cameras from"),
        ({"camera_offsets": {"cam_b": [0] * 5}}, r"camera_offsets\[cam_b\]: expected 6 finite numbers"),
        ({"camera_offsets": {"cam_b": [0, 0, 0, 0, 0, math.inf]}}, "finite"),
        ({"camera_offsets": [0] * 6}, "camera_offsets: expected a mapping"),
        ({"blackout_from_step": -1, "blackout_cameras": ["cam_b"]}, "blackout_from_step: expected an int"),
        ({"blackout_from_step": 2}, "blackout_from_step: expected 0 without blackout_cameras"),
    ],
)
def test_bad_options_are_named(make_env, kwargs, match) -> None:
    with pytest.raises(ValueError, match=match):
        make_env("select_apple", image_size=32, **kwargs)


def test_check_camera_offsets_normalises() -> None:
    assert check_camera_offsets(None) == {}
    assert check_camera_offsets({"cam_wrist": [1, 0, 0, 0, 0, 0.01]}) == {
        "cam_wrist": (1.0, 0.0, 0.0, 0.0, 0.0, 0.01)
    }
