"""Calibration: pure conversion round trips, and projection checked against segmentation renders."""

from __future__ import annotations

import math

import gym_omnid
import mujoco
import numpy as np
import pytest
from gym_omnid.calibration import (
    cam_T_world_from_mujoco,
    intrinsics_from_fovy,
    invert_rigid,
    mujoco_camera_calibration,
    project,
    unproject,
)
from gym_omnid.scene import look_at_xyaxes

FOVY = 50.0
HIDDEN_GROUP = 5  # geom group the render test hides everything but the apple in
NEAR_IMAGE_EDGE = {("texas_holdem", "position_band_3"), ("texas_holdem", "position_band_4")}
EDGE_MARGIN_PX = 4.0  # at 64 px: how far past the image edge a card of NEAR_IMAGE_EDGE may project


def _mujoco_camera(position: tuple[float, float, float], target: tuple[float, float, float]) -> np.ndarray:
    """``cam_xmat`` (3, 3) of a MuJoCo camera at ``position`` looking at ``target``."""
    xyaxes = look_at_xyaxes(position, target)
    x_axis, y_axis = xyaxes[:3], xyaxes[3:]
    return np.stack([x_axis, y_axis, np.cross(x_axis, y_axis)], axis=1)


@pytest.mark.parametrize("size", [(128, 128), (96, 160), (480, 480)])
def test_intrinsics_principal_point_and_focal(size: tuple[int, int]) -> None:
    height, width = size
    K = intrinsics_from_fovy(FOVY, height, width)
    assert K.shape == (3, 3) and K.dtype == np.float64
    assert K[0, 2] == pytest.approx((width - 1) / 2) and K[1, 2] == pytest.approx((height - 1) / 2)
    assert K[0, 0] == pytest.approx(K[1, 1])
    assert K[1, 1] == pytest.approx((height / 2) / math.tan(math.radians(FOVY) / 2))


def test_fov_edges_land_on_pixel_borders() -> None:
    """A ray at +-fovy/2 hits the outer border of the first/last pixel row (v = -0.5, H - 0.5)."""
    height, width = 96, 160
    K = intrinsics_from_fovy(FOVY, height, width)
    half = math.tan(math.radians(FOVY) / 2)
    xyz_cam = np.array([[0.0, -half, 1.0], [0.0, half, 1.0], [0.0, 0.0, 2.0]])
    uv_pix, depth = project(K, np.eye(4), xyz_cam)
    np.testing.assert_allclose(uv_pix[:, 1], [-0.5, height - 0.5, (height - 1) / 2], atol=1e-9)
    np.testing.assert_allclose(depth, [1.0, 1.0, 2.0])


def test_mujoco_to_opencv_axes() -> None:
    """The camera sits at the origin of its frame, looks along +z, image up is -y (OpenCV)."""
    position, target = (1.0, 0.5, 0.8), (0.4, 0.0, 0.1)
    cam_xmat = _mujoco_camera(position, target)
    cam_T_world = cam_T_world_from_mujoco(np.array(position), cam_xmat)
    np.testing.assert_allclose(cam_T_world[:3, :3] @ cam_T_world[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(cam_T_world[:3, :3]) == pytest.approx(1.0)
    origin_cam = cam_T_world @ np.array([*position, 1.0])
    np.testing.assert_allclose(origin_cam[:3], 0.0, atol=1e-12)
    target_cam = (cam_T_world @ np.array([*target, 1.0]))[:3]
    np.testing.assert_allclose(target_cam[:2], 0.0, atol=1e-12)
    assert target_cam[2] == pytest.approx(np.linalg.norm(np.subtract(target, position)))
    up_cam = (cam_T_world @ np.array([*(np.array(position) + cam_xmat[:, 1]), 1.0]))[:3]
    np.testing.assert_allclose(up_cam, [0.0, -1.0, 0.0], atol=1e-12)
    right_cam = (cam_T_world @ np.array([*(np.array(position) + cam_xmat[:, 0]), 1.0]))[:3]
    np.testing.assert_allclose(right_cam, [1.0, 0.0, 0.0], atol=1e-12)


def test_project_unproject_round_trip() -> None:
    rng = np.random.default_rng(0)
    K = intrinsics_from_fovy(FOVY, 96, 160)
    cam_T_world = cam_T_world_from_mujoco(
        np.array([1.2, -0.4, 0.7]), _mujoco_camera((1.2, -0.4, 0.7), (0.5, 0, 0))
    )
    xyz_world = rng.uniform([0.3, -0.3, 0.0], [0.8, 0.3, 0.3], size=(50, 3))
    uv_pix, depth = project(K, cam_T_world, xyz_world)
    assert (depth > 0).all()
    np.testing.assert_allclose(unproject(K, cam_T_world, uv_pix, depth), xyz_world, atol=1e-12)
    np.testing.assert_allclose(invert_rigid(invert_rigid(cam_T_world)), cam_T_world, atol=1e-12)
    np.testing.assert_allclose(invert_rigid(cam_T_world) @ cam_T_world, np.eye(4), atol=1e-12)


def test_points_behind_camera_are_nan() -> None:
    uv_pix, depth = project(intrinsics_from_fovy(FOVY, 64, 64), np.eye(4), np.array([[0.0, 0.0, -1.0]]))
    assert np.isnan(uv_pix).all() and depth[0] < 0


@pytest.mark.parametrize("size", [128, (96, 160)])
def test_env_calibration_schema(make_env, size) -> None:
    env = make_env("select_apple", image_size=size)
    height, width = env.image_size
    for cam in gym_omnid.CAMERAS:
        calib = env.camera_calibration(cam)
        assert set(calib) == {"K", "T_cam_world", "image_size"}
        assert calib["K"].shape == (3, 3) and calib["K"].dtype == np.float64
        assert calib["T_cam_world"].shape == (4, 4) and calib["T_cam_world"].dtype == np.float64
        assert calib["image_size"] == (height, width)
        np.testing.assert_allclose(calib["T_cam_world"][3], [0, 0, 0, 1])
    with pytest.raises(ValueError, match="cam"):
        env.camera_calibration("cam_z")


def _apple_mask(env, renderer: mujoco.Renderer, cam: str, apple_geom: int) -> np.ndarray:
    """Boolean (H, W) mask of the apple's pixels in a segmentation render of ``cam``."""
    option = mujoco.MjvOption()
    option.geomgroup[:] = 1
    option.geomgroup[HIDDEN_GROUP] = 0
    renderer.update_scene(env.data, camera=cam, scene_option=option)
    seg = renderer.render()  # H, W, 2: object id, object type
    return (seg[..., 0] == apple_geom) & (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM)


@pytest.mark.parametrize("size", [128, (96, 160)])
def test_projection_matches_rendered_pixels(make_env, size) -> None:
    """The apple's centre projected with the calibration lands on the centroid of its rendered pixels.

    Everything but the apple's sphere is moved to a hidden geom group, so occluders cannot bias the
    centroid; the sphere is placed at several workspace points, rendered from every camera.
    """
    env = make_env("select_apple", image_size=size)
    env.reset(seed=0)
    apple_geom = env.model.geom("apple").id
    env.model.geom_group[:] = HIDDEN_GROUP
    env.model.geom_group[apple_geom] = 0
    apple_body = env.model.body("apple").id
    qpos_adr = env.model.jnt_qposadr[env.model.body_jntadr[apple_body]]
    points = np.array([[0.35, -0.25, 0.04], [0.55, 0.0, 0.04], [0.75, 0.25, 0.12], [0.6, -0.1, 0.3]])
    renderer = mujoco.Renderer(env.model, *env.image_size)
    renderer.enable_segmentation_rendering()
    errors = []
    try:
        for xyz_world in points:
            env.data.qpos[qpos_adr : qpos_adr + 3] = xyz_world
            mujoco.mj_forward(env.model, env.data)
            for cam in gym_omnid.CAMERAS:
                mask = _apple_mask(env, renderer, cam, apple_geom)
                assert mask.sum() > 20, f"{cam}: apple at {xyz_world} not visible"
                rows, cols = np.nonzero(mask)
                calib = env.camera_calibration(cam)
                uv_pix, _ = project(calib["K"], calib["T_cam_world"], env.data.xpos[apple_body][None])
                error = np.hypot(uv_pix[0, 0] - cols.mean(), uv_pix[0, 1] - rows.mean())
                assert error < 1.0, f"{cam} at {xyz_world}: projected {uv_pix[0]} vs centroid"
                errors.append(error)
    finally:
        renderer.close()
    # A half-pixel convention slip shifts every point by ~0.5 px: the mean error stays far below.
    assert np.mean(errors) < 0.3


@pytest.mark.parametrize("task", gym_omnid.TASKS)
def test_task_objects_project_into_every_camera(make_env, task: str) -> None:
    """Every key object, in every layout, lies in front of and inside every camera's image; texas_holdem's
    cards in the two farthest graded bands (up to y 0.43 m) within a few pixels of cam_b's edge."""
    envs = [make_env(task, cameras=["cam_a"], image_size=64, layout=layout) for layout in gym_omnid.LAYOUTS]
    for env in envs:
        margin = EDGE_MARGIN_PX if (task, env.layout) in NEAR_IMAGE_EDGE else 0.0
        for seed in range(5):
            env.reset(seed=seed)
            xyz_world = np.array(list(env.object_positions().values()))
            for cam in gym_omnid.CAMERAS:
                calib = env.camera_calibration(cam)
                uv_pix, depth = project(calib["K"], calib["T_cam_world"], xyz_world)
                assert (depth > 0).all(), (env.layout, seed, cam)
                inside = (uv_pix >= -margin) & (uv_pix <= 63 + margin)
                assert inside.all(), (env.layout, seed, cam, uv_pix)


def test_calibration_helper_matches_env(make_env) -> None:
    env = make_env("select_chemistry_tube", image_size=(96, 160))
    cam_id = env.model.camera("cam_c").id
    expected = mujoco_camera_calibration(
        float(env.model.cam_fovy[cam_id]), env.data.cam_xpos[cam_id], env.data.cam_xmat[cam_id], (96, 160)
    )
    calib = env.camera_calibration("cam_c")
    np.testing.assert_allclose(calib["K"], expected["K"])
    np.testing.assert_allclose(calib["T_cam_world"], expected["T_cam_world"])
