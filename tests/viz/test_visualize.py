"""omnid-viz: pure viz functions, dataset and env modes (PNG and mp4), projection against a render, errors."""

from __future__ import annotations

import json
import re
import shutil

import av
import gym_omnid  # noqa: F401  (registers the envs)
import gymnasium as gym
import mujoco
import numpy as np
import pytest
import torch
from omnid_testing import make_tiny_dataset, tiny_config
from PIL import Image

from lerobot_omnid.calibration.schema import CameraCalibration, camera_matrices
from lerobot_omnid.env_config import calibration_dict
from lerobot_omnid.geometry import FeatureVolume, grid_to_pixels, pixels_to_grid
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy
from lerobot_omnid.record import record_dataset
from lerobot_omnid.viz.drawing import (
    PlaneView,
    anchor_lattice,
    attention_share,
    bev_heatmap,
    draw_frame,
    figure_rgb,
    project_points,
    query_index,
)
from lerobot_omnid.viz.viz import (
    DatasetSource,
    VizError,
    main,
    resolve_calibrations,
    visualize,
)

ENV_CAMS = ("cam_b", "cam_c", "cam_d", "cam_e")
ENV_SIZE = 64
DPI = 40  # small figures keep the tests fast
HIDDEN_GROUP = 5  # geom group the segmentation render hides everything but the apple in


@pytest.fixture(scope="module")
def synthetic_checkpoint(tmp_path_factory):
    """An untrained tiny checkpoint whose cameras are the synthetic ones of ``make_tiny_dataset``."""
    path = tmp_path_factory.mktemp("ckpt_synthetic")
    OmniDPolicy(tiny_config()).save_pretrained(path)
    return path


@pytest.fixture(scope="module")
def env_checkpoint(tmp_path_factory):
    """An untrained tiny checkpoint calibrated like the 64 px gym_omnid cameras."""
    env = gym.make("gym_omnid/select_apple", cameras=ENV_CAMS, image_size=ENV_SIZE)
    keys = [f"observation.images.{c}" for c in ENV_CAMS]
    calib = {k: calibration_dict(env.unwrapped, c, k) for k, c in zip(keys, ENV_CAMS, strict=True)}
    env.close()
    path = tmp_path_factory.mktemp("ckpt_env")
    OmniDPolicy(tiny_config(ENV_CAMS, size=ENV_SIZE, camera_calibration=calib)).save_pretrained(path)
    return path


@pytest.fixture(scope="module")
def dataset_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("viz_data") / "tiny"
    make_tiny_dataset(root, episodes=2, frames=5)
    return root


# --- pure functions ---------------------------------------------------------------------------------
def test_grid_to_pixels_inverts_pixels_to_grid() -> None:
    uv_pix = torch.tensor([[0.0, 0.0], [63.0, 31.5], [-0.5, 95.5], [10.25, 7.0]])
    np.testing.assert_allclose(grid_to_pixels(pixels_to_grid(uv_pix, (96, 64)), (96, 64)), uv_pix, atol=1e-5)
    corners = grid_to_pixels(torch.tensor([[-1.0, -1.0], [1.0, 1.0]]), (96, 64))
    np.testing.assert_allclose(corners, [[-0.5, -0.5], [63.5, 95.5]])  # the image's outer borders


def test_attention_share_sums_to_one_and_handles_nothing_visible() -> None:
    weights = torch.rand(3, 10, 2, 4, 1)  # S, Q, heads, A, P
    share = attention_share(weights)
    assert share.shape == (3,) and share.sum().item() == pytest.approx(1.0)
    np.testing.assert_allclose(share, weights.sum(dim=(1, 2, 3, 4)) / weights.sum(), rtol=1e-5)
    assert attention_share(torch.zeros(2, 5, 1, 1, 1)).tolist() == [0.0, 0.0]


def test_bev_heatmap_and_orientation() -> None:
    volume = FeatureVolume(bounds=((0.2, 0.8), (-0.3, 0.3), (0.0, 0.3)), shape=(6, 4, 2))
    condition = torch.zeros(6 * 4, 1)
    condition[2 * 4 + 3] = 1.0  # plane cell (x index 2, y index 3)
    heat = bev_heatmap(condition, volume.plane_shape)
    assert heat.shape == (6, 4) and heat[2, 3] == 1.0 and heat.sum() == 1.0
    two_channels = torch.cat([condition, 2 * condition], dim=-1)
    assert bev_heatmap(two_channels, volume.plane_shape)[2, 3] == pytest.approx(5**0.5)
    # Bird's-eye: x up, y across with +y (the robot's left) drawn on the left.
    view = PlaneView.of(volume)
    assert (view.up, view.across, view.flip_across) == (0, 1, True)
    assert view.image(heat.numpy(), volume).shape == (6, 4)
    assert view.extent(volume) == (-0.3, 0.3, 0.2, 0.8)
    side = FeatureVolume(bounds=volume.bounds, shape=(6, 4, 2), pillar_axis="y")  # x-z plane: z up
    side_view = PlaneView.of(side)
    assert (side_view.up, side_view.across) == (2, 0)
    assert side_view.image(np.zeros(side.plane_shape), side).shape == (2, 6)


def test_query_index_and_anchor_lattice() -> None:
    volume = FeatureVolume(bounds=((0.0, 1.0), (-0.5, 0.5), (0.0, 0.5)), shape=(10, 5, 4))
    assert query_index(volume, np.array([0.55, 0.05, 0.3])) == (5, 2)
    assert query_index(volume, np.array([1.2, 0.0, 0.0])) is None
    assert anchor_lattice(volume, 10_000).all()
    lattice = anchor_lattice(volume, 30)
    assert lattice.shape == (50, 4) and 0 < lattice.sum() <= 30


def test_missing_calibration_is_a_clear_error() -> None:
    class Uncalibrated:
        def calibration(self, cam):
            return None

    config = tiny_config()
    with pytest.raises(
        VizError, match=r"--policy-path: expected a calibration of observation\.images\.cam_a"
    ):
        resolve_calibrations(config, ["cam_a"], Uncalibrated())


# --- dataset mode -----------------------------------------------------------------------------------
def test_dataset_png(synthetic_checkpoint, dataset_root, tmp_path, capsys) -> None:
    argv = ["--policy-path", str(synthetic_checkpoint), "--dataset-root", str(dataset_root), "--episode", "1",
            "--frame", "3", "--out", str(tmp_path), "--dpi", str(DPI)]  # fmt: skip
    assert main(argv) == 0
    png = tmp_path / "tiny_ep001_frame0003.png"
    assert png.is_file() and str(png) in capsys.readouterr().out
    summary = visualize(
        synthetic_checkpoint, tmp_path, dataset_root=dataset_root, episode=1, frame=3, dpi=DPI
    )
    frame = summary.last
    assert summary.cameras == ["cam_b", "cam_c", "cam_d", "cam_e"]  # the checkpoint's cameras
    assert summary.share.sum() == pytest.approx(1.0)
    assert frame.heat.shape == (8, 8) and frame.query == (4, 4)  # no objects: the plane centre
    assert frame.sample_uv.shape == (4, 2 * 4 * 1, 2)  # S, heads * A * P, 2
    assert frame.sample_weight.sum() == pytest.approx(1.0, abs=1e-5)
    assert frame.anchor_uv.shape == (4, 8 * 8 * 4, 2)
    expected = figure_rgb(draw_frame(frame, tiny_config().feature_volume, DPI)).shape
    assert np.asarray(Image.open(png).convert("RGB")).shape == expected


def test_dataset_video_with_a_camera_the_checkpoint_lacks(synthetic_checkpoint, dataset_root, tmp_path):
    # cam_a is not among the checkpoint's cameras: its calibration comes from the dataset.
    summary = visualize(synthetic_checkpoint, tmp_path, dataset_root=dataset_root, episode=0, video=True,
                        stride=2, cameras=["cam_a", "cam_b"], dpi=DPI, show_progress=False)  # fmt: skip
    mp4 = tmp_path / "tiny_ep000.mp4"
    assert summary.files == [mp4] and summary.frames == 3  # frames 0, 2, 4 of 5
    with av.open(str(mp4)) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    assert len(frames) == 3
    h, w, _ = figure_rgb(draw_frame(summary.last, tiny_config().feature_volume, DPI)).shape
    assert frames[0].shape == (h + h % 2, w + w % 2, 3)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--episode", "2"], r"--episode: expected an episode index in \[0, 1\].*got 2"),
        (["--frame", "5"], r"--frame: expected a frame in \[0, 4\].*got 5"),
        (["--cameras", "cam_b,cam_z"], r"--cameras: expected distinct names from \['cam_a'.*cam_z"),
        (["--query", "8,0"], r"--query: expected i,j with 0 <= i < 8 and 0 <= j < 8.*got \(8, 0\)"),
        (["--steps", "3"], r"--steps: only with --env-task"),
    ],
)
def test_bad_input_names_the_option(synthetic_checkpoint, dataset_root, tmp_path, capsys, extra, message):
    argv = [
        "--policy-path",
        str(synthetic_checkpoint),
        "--dataset-root",
        str(dataset_root),
        "--out",
        str(tmp_path),
    ]
    with pytest.raises(SystemExit) as exc:
        main(argv + extra)
    assert exc.value.code == 2
    assert re.search(message, capsys.readouterr().err)
    assert not list(tmp_path.iterdir())  # nothing written


def test_bad_checkpoint_path(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit):
        main(["--policy-path", str(tmp_path), "--env-task", "select_apple", "--out", str(tmp_path / "o")])
    assert "--policy-path: expected a checkpoint folder" in capsys.readouterr().err


# --- env mode ---------------------------------------------------------------------------------------
def _apple_mask(env, renderer: mujoco.Renderer, cam: str) -> np.ndarray:
    """(H, W) bool: the apple's pixels in a segmentation render showing nothing else."""
    option = mujoco.MjvOption()
    option.geomgroup[:] = 1
    option.geomgroup[HIDDEN_GROUP] = 0
    renderer.update_scene(env.data, camera=cam, scene_option=option)
    seg = renderer.render()
    return (seg[..., 0] == env.model.geom("apple").id) & (seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM)


def test_env_png_projects_objects_onto_their_pixels(env_checkpoint, tmp_path) -> None:
    summary = visualize(env_checkpoint, tmp_path, env_task="select_apple", seed=3, dpi=DPI)
    assert summary.files == [tmp_path / "select_apple_seed3_step0000.png"] and summary.files[0].is_file()
    frame = summary.last
    assert next(iter(frame.objects)) == "apple"
    assert frame.query == query_index(tiny_config().feature_volume, frame.objects["apple"])

    # The same reset state, rendered with only the apple visible.
    env = gym.make("gym_omnid/select_apple", cameras=ENV_CAMS, image_size=ENV_SIZE).unwrapped
    env.reset(seed=3)
    np.testing.assert_allclose(env.object_positions()["apple"], frame.objects["apple"])
    env.model.geom_group[:] = HIDDEN_GROUP
    env.model.geom_group[env.model.geom("apple").id] = 0
    calibs = [CameraCalibration.from_dict(calibration_dict(env, c, c)) for c in ENV_CAMS]
    renderer = mujoco.Renderer(env.model, ENV_SIZE, ENV_SIZE)
    renderer.enable_segmentation_rendering()
    try:
        for s, cam in enumerate(ENV_CAMS):
            mask = _apple_mask(env, renderer, cam)
            assert mask.sum() >= 4 and frame.objects_visible[s, 0]
            rows, cols = np.nonzero(mask)
            u, v = frame.objects_uv[s, 0]
            assert mask[round(v), round(u)], f"{cam}: apple projected to ({u:.1f}, {v:.1f}), off its pixels"
            assert np.hypot(u - cols.mean(), v - rows.mean()) < 1.5
    finally:
        renderer.close()
        env.close()

    # The drawn anchors (from the OFG's own projection) agree with the drawing's projection function.
    volume = tiny_config().feature_volume
    pix_T_cam, cam_T_world = camera_matrices(calibs, [(ENV_SIZE, ENV_SIZE)] * len(calibs))
    anchors = volume.anchors_world()[anchor_lattice(volume, 10_000)]
    uv_pix, visible = project_points(pix_T_cam, cam_T_world, anchors, (ENV_SIZE, ENV_SIZE))
    np.testing.assert_array_equal(visible.numpy(), frame.anchor_visible)
    np.testing.assert_allclose(uv_pix[visible].numpy(), frame.anchor_uv[frame.anchor_visible], atol=1e-3)


def test_env_video(env_checkpoint, tmp_path) -> None:
    summary = visualize(env_checkpoint, tmp_path, env_task="select_apple", steps=2, video=True, dpi=DPI,
                        show_progress=False)  # fmt: skip
    mp4 = tmp_path / "select_apple_seed0.mp4"
    assert summary.files == [mp4] and summary.frames == 3  # the reset state and 2 expert steps
    with av.open(str(mp4)) as container:
        assert container.streams.video[0].frames == 3
    assert "step 2" in summary.last.title
    assert summary.share.sum() == pytest.approx(1.0)


def test_per_frame_checkpoint_fuses_with_the_source_calibration(env_checkpoint, tmp_path) -> None:
    """A checkpoint trained on per-frame calibration columns (``omnid-record``'s default) has no
    calibration in its config.json: omnid-viz fuses with the source's, exactly as the static checkpoint."""
    per_frame = tmp_path / "ckpt_per_frame"
    shutil.copytree(env_checkpoint, per_frame)
    config = json.loads((per_frame / "config.json").read_text())
    config["frame_calibration"], config["camera_calibration"] = list(config["camera_calibration"]), {}
    (per_frame / "config.json").write_text(json.dumps(config))
    static, ours = (
        visualize(path, tmp_path / path.name, env_task="select_apple", seed=3, dpi=DPI)
        for path in (env_checkpoint, per_frame)
    )
    np.testing.assert_allclose(ours.last.heat, static.last.heat, atol=1e-6)
    np.testing.assert_allclose(ours.share, static.share, atol=1e-6)


def test_dataset_calibration_from_per_frame_columns(tmp_path) -> None:
    """A dataset recorded with the default per-frame columns: a fixed camera's calibration is its constant
    columns'; a camera whose columns change (the wrist camera) is refused, naming the column."""
    root = tmp_path / "per_frame"
    cams = ["cam_b", "cam_wrist"]
    record_dataset(root, episodes=1, cameras=cams, image_size=ENV_SIZE, repo_id="local/per_frame",
                   show_progress=False)  # fmt: skip
    env = gym.make("gym_omnid/select_apple", cameras=cams, image_size=ENV_SIZE)
    expected = CameraCalibration.from_dict(calibration_dict(env.unwrapped, "cam_b", "cam_b"))
    env.close()
    source = DatasetSource(root, None, 0)
    calib = source.calibration("cam_b")
    np.testing.assert_allclose(calib.K, expected.K, rtol=1e-6)
    np.testing.assert_allclose(calib.T_cam_world, expected.T_cam_world, atol=1e-6)
    assert calib.image_size == (ENV_SIZE, ENV_SIZE)
    with pytest.raises(VizError, match=r"observation\.extrinsics\.cam_wrist: expected a fixed camera"):
        source.calibration("cam_wrist")
