"""A checkpoint copied with other cameras as its image inputs (how the few-shot runs start DP, ACT and VQ-BeT
on camera A): the copied config, the folded camera columns, and a DP copy that acts as the camera in every
slot."""

from __future__ import annotations

import json

import pytest
import torch
from omnid_testing import tiny_diffusion_config

from lerobot_omnid.benchmark import checkpoint_cameras


def test_checkpoint_copy_with_other_cameras(tmp_path, capsys):
    src = tmp_path / "pretrained_model"
    src.mkdir()
    image = {"type": "VISUAL", "shape": [3, 64, 64]}
    features = {"observation.state": {"type": "STATE", "shape": [16]}}
    features |= {f"observation.images.cam_{c}": image for c in "bcde"}
    (src / "config.json").write_text(
        json.dumps({"type": "act", "input_features": features, "chunk_size": 16})
    )
    (src / "model.safetensors").write_bytes(b"weights")
    dst = tmp_path / "copy"
    assert checkpoint_cameras.main(["--src", str(src), "--dst", str(dst), "--cameras", "cam_a"]) == 0
    config = json.loads((dst / "config.json").read_text())
    assert config["input_features"] == {
        "observation.state": features["observation.state"],
        "observation.images.cam_a": image,
    }
    assert config["chunk_size"] == 16 and (dst / "model.safetensors").read_bytes() == b"weights"
    assert json.loads((src / "config.json").read_text())["input_features"] == features  # source untouched
    with pytest.raises(SystemExit):
        checkpoint_cameras.main(["--src", str(tmp_path / "nowhere"), "--dst", str(dst), "--cameras", "cam_a"])
    assert "--src" in capsys.readouterr().err


def test_fold_camera_columns_sums_each_steps_camera_blocks():
    # E=1, 2 obs steps of [state 1, 2 cameras x F=2, env 1]: columns e | s0 a0 a1 b0 b1 v0 | s1 ...
    weight = torch.arange(13.0).reshape(1, 13)
    folded = checkpoint_cameras.fold_camera_columns(weight, 1, 2, before=1, after=1, n_cameras=2)
    assert folded.tolist() == [[0.0, 1.0, 2 + 4, 3 + 5, 6.0, 7.0, 8 + 10, 9 + 11, 12.0]]
    with pytest.raises(ValueError, match="columns, got 13"):
        checkpoint_cameras.fold_camera_columns(weight, 1, 2, before=1, after=1, n_cameras=3)


def test_diffusion_copy_with_one_camera_acts_as_the_camera_in_every_slot(tmp_path):
    """LeRobot's DP with a shared encoder, copied from two cameras to camera A: the copy's noise prediction
    on camera A's images equals the original's given those images from both cameras."""
    from lerobot.policies.diffusion.modeling_diffusion import DiffusionPolicy
    from lerobot.utils.constants import OBS_IMAGES, OBS_STATE

    torch.manual_seed(0)
    DiffusionPolicy(tiny_diffusion_config()).save_pretrained(tmp_path / "two")
    checkpoint_cameras.retarget_cameras(tmp_path / "two", tmp_path / "one", ["cam_a"])
    two = DiffusionPolicy.from_pretrained(tmp_path / "two").eval()
    one = DiffusionPolicy.from_pretrained(tmp_path / "one").eval()
    assert list(one.config.image_features) == ["observation.images.cam_a"]
    state, images = torch.randn(3, 2, 5), torch.rand(3, 2, 1, 3, 32, 32)
    noisy, t = torch.randn(3, 8, 4), torch.tensor([3, 50, 99])
    with torch.no_grad():
        cond_two = two.diffusion._prepare_global_conditioning(
            {OBS_STATE: state, OBS_IMAGES: images.expand(-1, -1, 2, -1, -1, -1)}
        )
        cond_one = one.diffusion._prepare_global_conditioning({OBS_STATE: state, OBS_IMAGES: images})
        expected = two.diffusion.unet(noisy, t, global_cond=cond_two)
        actual = one.diffusion.unet(noisy, t, global_cond=cond_one)
    assert cond_one.shape[1] < cond_two.shape[1]
    torch.testing.assert_close(actual, expected, rtol=1e-4, atol=1e-5)
    with pytest.raises(ValueError, match="with one, got 3"):
        checkpoint_cameras.retarget_cameras(tmp_path / "two", tmp_path / "x", ["cam_a", "cam_d", "cam_e"])
