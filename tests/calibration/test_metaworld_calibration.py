"""The MetaWorld suite's calibration against MuJoCo's segmentation renders: a ray cast through a random
pixel with the calibration (``K``, ``T_cam_world``) hits the geom the renderer shows at that pixel, for every
camera, the hand cameras at two frames of an expert episode."""

from __future__ import annotations

from collections.abc import Iterator

import gymnasium as gym
import mujoco
import numpy as np
import pytest

pytest.importorskip("metaworld")

from gym_omnid.calibration import invert_rigid
from gym_omnid.metaworld_suite import ALL_CAMERAS, FIXED_CAMERAS, GYM_NAMESPACE, HAND_CAMERAS
from gym_omnid.metaworld_suite.experts import make_expert

SIZE = (96, 128)  # (height, width): not square, so swapped sizes are caught
N_PIXELS = 300  # random pixels per camera and frame
MIN_MATCH = 0.99  # share of pixels whose ray hits the rendered geom (misses: edges between two geoms)
MAX_BACK_FACES = 8  # back faces a ray may pass through (it starts inside a link) before its hit
STEP_EPS = 1e-6  # m: how far past a back face a ray restarts
HAND_FRAMES = (0, 40)  # env steps of the expert episode at which the hand cameras are checked
TASKS = ("assembly-v3", "stick-push-v3")


@pytest.fixture(scope="module", params=TASKS)
def env(request) -> Iterator:
    env = gym.make(f"{GYM_NAMESPACE}/{request.param}", cameras=list(ALL_CAMERAS), image_size=SIZE)
    env.unwrapped.reset(seed=3)
    yield env.unwrapped
    env.close()


@pytest.fixture(scope="module")
def segmenter(env) -> Iterator:
    renderer = mujoco.Renderer(env.model, *SIZE)
    renderer.enable_segmentation_rendering()
    yield renderer
    renderer.close()


def _rendered_geoms(env, renderer: mujoco.Renderer, cam: str) -> np.ndarray:
    """(H, W) geom id per pixel of a segmentation render of ``cam`` (-1: no geom), sites hidden."""
    option = mujoco.MjvOption()
    option.sitegroup[:] = 0
    renderer.update_scene(env.data, camera=cam, scene_option=option)
    seg = renderer.render()  # H, W, 2: object id, object type
    return np.where(seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM, seg[..., 0], -1)


def _ray_geom(env, origin: np.ndarray, direction: np.ndarray, near: float) -> int:
    """First geom a ray hits on a front face, from depth ``near`` on (``direction`` has unit depth along
    the optical axis, so distances are depths), as the rasteriser sees it: it clips at the near plane and
    culls back faces (a camera inside a link sees through it); -1 when it hits nothing."""
    group = np.array(mujoco.MjvOption().geomgroup, dtype=np.uint8)
    geom_id = np.zeros(1, np.int32)
    normal = np.zeros(3)
    start = origin + near * direction
    for _ in range(MAX_BACK_FACES):
        dist = mujoco.mj_ray(env.model, env.data, start, direction, group, 1, -1, geom_id, normal)
        if dist < 0 or normal @ direction < 0:
            return int(geom_id[0]) if dist >= 0 else -1
        start = start + (dist + STEP_EPS) * direction
    return int(geom_id[0])


def match_share(env, renderer: mujoco.Renderer, cam: str, calib: dict, rng: np.random.Generator) -> float:
    """Share of random pixels where the ray cast with ``calib`` hits the geom rendered there."""
    rendered = _rendered_geoms(env, renderer, cam)
    height, width = SIZE
    uv_pix = np.stack([rng.integers(0, width, N_PIXELS), rng.integers(0, height, N_PIXELS)], axis=1)
    uv1 = np.concatenate([uv_pix, np.ones((N_PIXELS, 1))], axis=1)
    world_T_cam = invert_rigid(calib["T_cam_world"])
    # pixels -> rays in the camera frame with unit depth -> world directions
    dirs_world = (uv1 @ np.linalg.inv(calib["K"]).T) @ world_T_cam[:3, :3].T
    near = env.model.vis.map.znear * env.model.stat.extent
    hits = [_ray_geom(env, world_T_cam[:3, 3], d, near) for d in dirs_world]
    return float(np.mean(np.array(hits) == rendered[uv_pix[:, 1], uv_pix[:, 0]]))


def test_fixed_cameras_match_segmentation(env, segmenter) -> None:
    rng = np.random.default_rng(0)
    for cam in FIXED_CAMERAS:
        share = match_share(env, segmenter, cam, env.camera_calibration(cam), rng)
        assert share >= MIN_MATCH, (env.task, cam, share)


def test_hand_cameras_match_segmentation_at_two_frames(env, segmenter) -> None:
    """The hand cameras move with the hand: their calibration at each frame matches that frame's render."""
    rng = np.random.default_rng(1)
    env.reset(seed=3)
    expert = make_expert(env)
    poses = {cam: [] for cam in HAND_CAMERAS}
    for step in range(max(HAND_FRAMES) + 1):
        if step in HAND_FRAMES:
            for cam in HAND_CAMERAS:
                calib = env.camera_calibration(cam)
                poses[cam].append(calib["T_cam_world"])
                share = match_share(env, segmenter, cam, calib, rng)
                assert share >= MIN_MATCH, (env.task, cam, step, share)
        env.step(expert.act())
    for cam, (first, last) in poses.items():
        assert np.linalg.norm(invert_rigid(first)[:3, 3] - invert_rigid(last)[:3, 3]) > 0.05, cam


def test_broken_calibration_fails_the_check(env, segmenter) -> None:
    """The check can fail: MuJoCo's camera axes taken as OpenCV's (no y/z flip), or the image turned
    upside down (the camera before the env turned it upright), match far fewer pixels."""
    rng = np.random.default_rng(2)
    cam = FIXED_CAMERAS[0]
    cam_id = env.model.camera(cam).id
    calib = env.camera_calibration(cam)
    mjcam_R_world = env.data.cam_xmat[cam_id].reshape(3, 3).T
    unflipped = np.eye(4)
    unflipped[:3, :3], unflipped[:3, 3] = mjcam_R_world, -mjcam_R_world @ env.data.cam_xpos[cam_id]
    upside_down = np.diag([-1.0, -1.0, 1.0, 1.0]) @ calib["T_cam_world"]
    for broken in (unflipped, upside_down):
        share = match_share(env, segmenter, cam, {**calib, "T_cam_world": broken}, rng)
        assert share < 0.9, share
