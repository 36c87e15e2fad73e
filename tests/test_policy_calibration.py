"""One calibration path: parsed once into buffers, a calibration file merged into the config for good, and a
checkpoint saved before the package moved into wings still loads."""

import json
import shutil
from pathlib import Path

import pytest
import torch
from omnid_testing import STATE_DIM, random_batch, synthetic_calibration, tiny_config
from safetensors.torch import save_file

from lerobot_omnid.calibration.schema import CameraCalibration
from lerobot_omnid.policy.configuration_omnid import OmniDConfig
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy

FIXTURE = Path(__file__).parent / "fixtures" / "checkpoint_v0_1"
SIZE = 32
CAMS = ("cam_b", "cam_c")


def small_config(**overrides) -> OmniDConfig:
    return tiny_config(CAMS, size=SIZE, volume_shape=(4, 4, 2), num_layers=1, down_dims=(16, 32), **overrides)


def observation(config: OmniDConfig) -> dict:
    obs = {key: torch.rand(1, *ft.shape) for key, ft in config.image_features.items()}
    obs["observation.state"] = torch.randn(1, STATE_DIM)
    return obs


def moved(cam: str) -> dict:
    """``cam``'s synthetic calibration with the camera 10 cm further along its own x axis."""
    calib = synthetic_calibration(cam, SIZE)
    calib["T_cam_world"][0][3] -= 0.1
    return calib


def test_matrices_are_buffers_built_once_and_follow_the_calibration():
    policy = OmniDPolicy(small_config())
    assert "pix_T_cam" not in policy.state_dict()  # config.json holds the calibration, not the weights
    pix_T_cam, cam_T_world = policy.camera_matrices(3, (SIZE, SIZE))
    assert pix_T_cam.shape == (3, 2, 3, 3) and cam_T_world.shape == (3, 2, 4, 4)
    again, _ = policy.camera_matrices(3, (SIZE, SIZE))
    assert again.data_ptr() == pix_T_cam.data_ptr()  # not rebuilt for the next call
    expected = torch.tensor(synthetic_calibration("cam_c", SIZE)["K"], dtype=torch.float32)
    assert torch.equal(pix_T_cam[1, 1], expected)

    # Another input size (no resize_shape): intrinsics for that size.
    big, _ = policy.camera_matrices(1, (2 * SIZE, 2 * SIZE))
    big_K = CameraCalibration.from_dict(synthetic_calibration("cam_c", SIZE)).resized((2 * SIZE, 2 * SIZE)).K
    assert torch.allclose(big[0, 1], torch.tensor(big_K))

    # set_calibration changes the matrices and the config that is saved.
    policy.set_calibration({"observation.images.cam_c": CameraCalibration.from_dict(moved("cam_c"))})
    _, cam_T_world = policy.camera_matrices(1, (SIZE, SIZE))
    assert cam_T_world[0, 1, 0, 3].item() == pytest.approx(moved("cam_c")["T_cam_world"][0][3])
    assert policy.config.camera_calibration["observation.images.cam_c"] == moved("cam_c")


def test_resize_shape_gives_the_backbone_inputs_intrinsics():
    policy = OmniDPolicy(small_config(resize_shape=(16, 16)))
    pix_T_cam, _ = policy.camera_matrices(1, (SIZE, SIZE))
    K16 = CameraCalibration.from_dict(synthetic_calibration("cam_b", SIZE)).resized((16, 16)).K
    assert torch.allclose(pix_T_cam[0, 0], torch.tensor(K16))


def test_matrices_move_with_the_policy():
    policy = OmniDPolicy(small_config())
    policy.camera_matrices(1, (SIZE, SIZE))
    policy.to(torch.float64)  # stands in for a device move: buffers are converted with the parameters
    pix_T_cam, _ = policy.camera_matrices(1, (SIZE, SIZE))
    assert pix_T_cam.dtype == torch.float64


def test_forward_does_not_parse_the_calibration(monkeypatch):
    policy = OmniDPolicy(small_config())
    batch = random_batch(policy.config)
    policy.forward(batch)

    def fail(*args, **kwargs):
        raise AssertionError("the calibration was parsed again in forward")

    monkeypatch.setattr(CameraCalibration, "from_dict", fail)
    monkeypatch.setattr(OmniDConfig, "calibration", fail)
    loss, _ = policy.forward(batch)
    assert torch.isfinite(loss)


def test_calibration_file_is_merged_once_and_the_checkpoint_never_needs_it(tmp_path):
    rig = tmp_path / "rig.json"
    rig.write_text(json.dumps({"cam_c": moved("cam_c")}))
    config = small_config(calibration_path=str(rig))
    assert config.calibration_path is None
    assert config.camera_calibration["observation.images.cam_c"] == moved("cam_c")
    policy = OmniDPolicy(config)
    policy.save_pretrained(tmp_path / "ckpt")
    saved = json.loads((tmp_path / "ckpt" / "config.json").read_text())
    assert saved["calibration_path"] is None
    assert saved["camera_calibration"]["observation.images.cam_c"] == moved("cam_c")

    # Later edits of the file do not reach the checkpoint; neither does its deletion.
    rig.write_text(json.dumps({"cam_c": synthetic_calibration("cam_c", SIZE)}))
    loaded = OmniDPolicy.from_pretrained(tmp_path / "ckpt")
    assert loaded.config.camera_calibration["observation.images.cam_c"] == moved("cam_c")
    rig.unlink()
    loaded = OmniDPolicy.from_pretrained(tmp_path / "ckpt")
    _, cam_T_world = loaded.camera_matrices(1, (SIZE, SIZE))
    assert cam_T_world[0, 1, 0, 3].item() == pytest.approx(moved("cam_c")["T_cam_world"][0][3])


def test_calibration_file_wins_over_the_dataset(tmp_path):
    rig = tmp_path / "rig.json"
    rig.write_text(json.dumps({"cam_c": moved("cam_c")}))
    config = small_config(calibration_path=str(rig))
    features = {
        f"observation.images.{cam}": {
            "dtype": "video",
            "shape": (SIZE, SIZE, 3),
            "names": ["height", "width", "channels"],
            "info": {"calibration": synthetic_calibration(cam, SIZE)},
        }
        for cam in CAMS
    }
    config.set_dataset_feature_metadata(features)
    assert config.camera_calibration["observation.images.cam_c"] == moved("cam_c")
    assert config.camera_calibration["observation.images.cam_b"] == synthetic_calibration("cam_b", SIZE)


def test_checkpoint_saved_before_the_wings_still_loads(tmp_path):
    """``tests/fixtures/checkpoint_v0_1``: the config.json the flat-layout code (commit fb0f37a) saved, and
    its state dict's names and shapes; random weights of those shapes must load strictly."""
    ckpt = tmp_path / "ckpt"
    shutil.copytree(FIXTURE, ckpt)
    shapes = json.loads((ckpt / "state_dict_shapes.json").read_text())
    save_file(
        {k: torch.randn(s) if s else torch.randn(()) for k, s in shapes.items()}, ckpt / "model.safetensors"
    )
    policy = OmniDPolicy.from_pretrained(ckpt, strict=True).eval()
    assert {k: list(v.shape) for k, v in policy.state_dict().items()} == shapes
    assert policy.select_action(observation(policy.config)).shape == (1, 10)
