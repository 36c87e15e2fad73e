"""OmniD's control calibrations: blind (every camera turned away: no anchor visible, the images contribute
nothing to the actions) and scrambled (a permutation that leaves no camera in place); the file a checkpoint
is evaluated with."""

from __future__ import annotations

import json

import gym_omnid
import pytest
import torch
from lerobot.configs.policies import PreTrainedConfig
from omnid_testing import STATE_DIM, tiny_config

from lerobot_omnid.benchmark.control_calibration import main
from lerobot_omnid.benchmark.controls import control_calibrations, permuted, turned_away
from lerobot_omnid.benchmark.methods import PERTURBED_LEVEL
from lerobot_omnid.calibration.rig_file import load_calibration_file
from lerobot_omnid.calibration.schema import CameraCalibration
from lerobot_omnid.env_config import OmniDEnvConfig
from lerobot_omnid.geometry import FeatureVolume, project_to_grid
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy

SIZE = 64


def visible_anchors(calibrations: dict[str, CameraCalibration], volume: FeatureVolume) -> dict[str, int]:
    """Per camera, how many of the volume's anchors project into its image."""
    anchors_world = volume.anchors_world().reshape(-1, 3).double()
    counts = {}
    for key, calib in calibrations.items():
        K = torch.tensor(calib.K, dtype=torch.float64)[None, None]
        cam_T_world = torch.tensor(calib.T_cam_world, dtype=torch.float64)[None, None]
        _, visible = project_to_grid(K, cam_T_world, anchors_world, calib.image_size)
        counts[key] = int(visible.sum())
    return counts


@pytest.fixture(scope="module")
def benchmark_cameras() -> dict[str, CameraCalibration]:
    """The five gym_omnid cameras as the benchmark's checkpoints store them."""
    raw = OmniDEnvConfig(cameras=list(gym_omnid.CAMERAS), image_size=SIZE).camera_calibrations()
    return {key: CameraCalibration.from_dict(value, camera=key) for key, value in raw.items()}


def test_blind_turns_every_benchmark_camera_away_from_the_volume(benchmark_cameras):
    volume = FeatureVolume(bounds=gym_omnid.WORKSPACE_BOUNDS, shape=(16, 20, 8))
    assert min(visible_anchors(benchmark_cameras, volume).values()) > volume.num_queries  # the true views
    config = {
        "camera_calibration": {key: c.to_dict() for key, c in benchmark_cameras.items()},
        "volume_bounds": gym_omnid.WORKSPACE_BOUNDS,
    }
    blind = control_calibrations(config, "blind")
    assert list(blind) == list(benchmark_cameras)
    assert visible_anchors(blind, volume) == dict.fromkeys(benchmark_cameras, 0)
    for key, calib in blind.items():  # same camera, same intrinsics: only its orientation changed
        calib.validate(key)
        assert calib.K == benchmark_cameras[key].K and calib.image_size == (SIZE, SIZE)
        centre = torch.tensor(calib.T_cam_world)[:3, :3].T @ -torch.tensor(calib.T_cam_world)[:3, 3]
        true = torch.tensor(benchmark_cameras[key].T_cam_world)
        assert torch.allclose(centre, true[:3, :3].T @ -true[:3, 3], atol=1e-6)


def test_a_camera_inside_the_volume_cannot_turn_away(benchmark_cameras):
    calib = benchmark_cameras["observation.images.cam_b"]
    with pytest.raises(ValueError, match=r"cam_b: expected every corner of the volume .* behind"):
        turned_away(calib, ((-2.0, 3.0), (-2.0, 2.0), (-1.0, 2.0)), "cam_b")


def test_scrambled_leaves_no_camera_in_place(benchmark_cameras):
    config = {"camera_calibration": {key: c.to_dict() for key, c in benchmark_cameras.items()}}
    scrambled = control_calibrations(config, "scrambled")
    keys = list(benchmark_cameras)
    assert list(scrambled) == keys
    for i, key in enumerate(keys):
        assert scrambled[key] == benchmark_cameras[keys[(i + 1) % len(keys)]] != benchmark_cameras[key]
    with pytest.raises(ValueError, match="cameras: expected at least 2 calibrated cameras"):
        permuted({keys[0]: benchmark_cameras[keys[0]]})
    with pytest.raises(ValueError, match="control: expected one of"):
        control_calibrations(config, "shuffled")


def test_perturbed_moves_and_turns_every_camera_by_the_level(benchmark_cameras):
    config = {"camera_calibration": {key: c.to_dict() for key, c in benchmark_cameras.items()}}
    perturbed = control_calibrations(config, "perturbed")
    assert list(perturbed) == list(benchmark_cameras)
    for key, calib in perturbed.items():
        true, moved = (
            torch.tensor(c.T_cam_world, dtype=torch.float64) for c in (benchmark_cameras[key], calib)
        )
        centre = [-m[:3, :3].T @ m[:3, 3] for m in (true, moved)]
        assert (centre[1] - centre[0]).norm() * 100 == pytest.approx(PERTURBED_LEVEL, abs=1e-3)
        cos = ((moved[:3, :3] @ true[:3, :3].T).trace() - 1) / 2
        assert torch.rad2deg(torch.arccos(cos.clamp(-1, 1))) == pytest.approx(PERTURBED_LEVEL, abs=1e-2)
        assert calib.K == benchmark_cameras[key].K
    assert control_calibrations(config, "perturbed") == perturbed  # a fixed draw
    with pytest.raises(ValueError, match="expected the benchmark's cameras"):
        control_calibrations(
            {
                "camera_calibration": {
                    "observation.images.top": config["camera_calibration"]["observation.images.cam_b"]
                }
            },
            "perturbed",
        )


def _actions(policy: OmniDPolicy, images: dict[str, torch.Tensor], state: torch.Tensor) -> torch.Tensor:
    policy.reset()
    noise = torch.zeros(1, policy.config.horizon, 10)
    return policy.predict_action_chunk({**images, "observation.state": state}, noise=noise)


def test_blind_omnid_actions_do_not_depend_on_its_images(tmp_path):
    """Given as ``--policy.calibration_path`` (as lerobot-eval does), the blind file makes a checkpoint's
    actions independent of its images; with its own calibration the same weights respond to them."""
    config = tiny_config(
        ("cam_b", "cam_c"), size=32, volume_shape=(4, 4, 2), num_layers=1, down_dims=(16, 32)
    )
    policy = OmniDPolicy(config)
    torch.manual_seed(0)  # move the zero-initialised compression (and every weight) off its initialisation
    with torch.no_grad():
        for parameter in policy.parameters():
            parameter.add_(0.05 * torch.randn_like(parameter))
    checkpoint = tmp_path / "pretrained_model"
    policy.save_pretrained(checkpoint)
    blind_file = tmp_path / "blind.json"
    assert main(["--checkpoint", str(checkpoint), "--control", "blind", "--out", str(blind_file)]) == 0
    assert sorted(load_calibration_file(blind_file)) == [
        "observation.images.cam_b",
        "observation.images.cam_c",
    ]
    generator = torch.Generator().manual_seed(0)
    shape = (1, config.n_obs_steps, 3, 32, 32)
    views = [{key: torch.rand(shape, generator=generator) for key in config.image_features} for _ in range(2)]
    state = torch.randn(1, config.n_obs_steps, STATE_DIM, generator=generator)
    for overrides, responds in (([], True), ([f"--calibration_path={blind_file}"], False)):
        loaded_config = PreTrainedConfig.from_pretrained(checkpoint, cli_overrides=overrides)
        loaded = OmniDPolicy.from_pretrained(checkpoint, config=loaded_config).eval()
        first, second = (_actions(loaded, images, state) for images in views)
        assert (not torch.allclose(first, second)) == responds, overrides


def test_main_names_a_missing_checkpoint(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["--checkpoint", str(tmp_path), "--control", "blind", "--out", str(tmp_path / "x.json")])
    assert "--checkpoint: expected a checkpoint folder with config.json" in capsys.readouterr().err
    (tmp_path / "config.json").write_text(json.dumps({"type": "diffusion"}))
    with pytest.raises(SystemExit):
        main(["--checkpoint", str(tmp_path), "--control", "scrambled", "--out", str(tmp_path / "x.json")])
    assert "camera_calibration: expected the calibrated cameras of an OmniD config" in capsys.readouterr().err


def test_a_checkpoint_calibrated_per_frame_is_refused(benchmark_cameras):
    """A calibration file replaces only static calibrations: a control written for a checkpoint that reads
    a camera's calibration from every frame would leave that camera's untouched."""
    config = {
        "camera_calibration": {key: c.to_dict() for key, c in benchmark_cameras.items()},
        "frame_calibration": ["observation.images.cam_b"],
        "volume_bounds": gym_omnid.WORKSPACE_BOUNDS,
    }
    for control in ("blind", "scrambled", "perturbed"):
        with pytest.raises(ValueError, match=r"frame_calibration: expected a checkpoint with static .*cam_b"):
            control_calibrations(config, control)
