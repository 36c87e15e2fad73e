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


def frame_columns(calib: dict) -> tuple[torch.Tensor, torch.Tensor]:
    """(16,) extrinsics and (9,) intrinsics columns of a calibration dict."""
    return torch.tensor(calib["T_cam_world"]).flatten(), torch.tensor(calib["K"]).flatten()


def per_frame_policy() -> OmniDPolicy:
    """A policy whose cameras are calibrated per frame (no static calibration at all)."""
    keys = [f"observation.images.{c}" for c in CAMS]
    return OmniDPolicy(small_config(camera_calibration={}, frame_calibration=keys)).eval()


def with_columns(batch: dict, calibs: list[dict[str, dict]], time_dim: bool) -> dict:
    """``calibs[b][cam]``: sample b's calibration of each camera, the same for every step."""
    T = 2
    for cam in CAMS:
        ext, K = zip(*(frame_columns(c[cam]) for c in calibs), strict=True)
        ext, K = torch.stack(ext), torch.stack(K)
        if time_dim:
            ext, K = ext[:, None].expand(-1, T, -1), K[:, None].expand(-1, T, -1)
        batch[f"observation.extrinsics.{cam}"], batch[f"observation.intrinsics.{cam}"] = ext, K
    return batch


def test_each_sample_gets_the_plane_of_its_own_rig():
    policy = per_frame_policy()
    rig_a = {cam: synthetic_calibration(cam, SIZE) for cam in CAMS}
    rig_b = {cam: moved(cam) for cam in CAMS}
    batch = with_columns(random_batch(policy.config, batch_size=2), [rig_a, rig_b], time_dim=True)
    stacked = policy._stack_inputs(batch, time_dim=True)
    with torch.no_grad():
        mixed = policy._condition(stacked)
        for b, rig in enumerate((rig_a, rig_b)):
            static = OmniDPolicy(
                small_config(camera_calibration={f"observation.images.{c}": rig[c] for c in CAMS})
            )
            static.load_state_dict(policy.state_dict())
            alone = static.eval()._condition(
                {k: v[b : b + 1] for k, v in static._stack_inputs(batch, True).items()}
            )
            assert torch.allclose(mixed[b], alone[0], atol=1e-5)
    assert not torch.allclose(mixed[0], mixed[1], atol=1e-3)  # the two rigs do give different planes


def test_a_moving_camera_uses_each_steps_own_pose():
    policy = per_frame_policy()
    batch = with_columns(
        random_batch(policy.config, batch_size=1), [{c: synthetic_calibration(c, SIZE) for c in CAMS}], True
    )
    key = "observation.extrinsics.cam_c"
    batch[key] = batch[key].clone()
    batch[key][0, 1] = frame_columns(moved("cam_c"))[0]  # the camera moved between the two steps
    pix_T_cam, cam_T_world = (
        policy._stack_inputs(batch, time_dim=True)[k] for k in ("omnid.pix_T_cam", "omnid.cam_T_world")
    )
    assert pix_T_cam.shape == (1, 2, 2, 3, 3) and cam_T_world.shape == (1, 2, 2, 4, 4)
    assert torch.equal(cam_T_world[0, 0, 1].flatten(), frame_columns(synthetic_calibration("cam_c", SIZE))[0])
    assert torch.equal(cam_T_world[0, 1, 1].flatten(), frame_columns(moved("cam_c"))[0])
    # select_action queues each step's calibration with its images.
    policy.reset()
    for step in range(2):
        obs = observation(policy.config)
        for cam in CAMS:
            calib = moved(cam) if (cam == "cam_c" and step == 1) else synthetic_calibration(cam, SIZE)
            ext, K = frame_columns(calib)
            obs[f"observation.extrinsics.{cam}"], obs[f"observation.intrinsics.{cam}"] = ext[None], K[None]
        policy.select_action(obs)
    queued = torch.stack(list(policy._queues["omnid.cam_T_world"]), dim=1)
    assert torch.equal(queued[0, 1, 1].flatten(), frame_columns(moved("cam_c"))[0])


def test_missing_frame_columns_are_named():
    policy = per_frame_policy()
    obs = observation(policy.config)
    with pytest.raises(KeyError, match=r"observation\.intrinsics\.cam_b` is missing .*frame_calibration"):
        policy.select_action(obs)


def test_dataset_columns_become_frame_calibration_not_state():
    """``dataset_to_policy_features`` makes the columns STATE features; the config takes them out (so the
    normaliser never rescales them) and reads those cameras per frame; the others keep their static one."""
    from lerobot.utils.feature_utils import dataset_to_policy_features

    from lerobot_omnid.calibration.frame_columns import calibration_column_features

    features = {
        "observation.state": {"dtype": "float32", "shape": (STATE_DIM,), "names": None},
        "action": {"dtype": "float32", "shape": (10,), "names": None},
        **{
            f"observation.images.{cam}": {
                "dtype": "video",
                "shape": (SIZE, SIZE, 3),
                "names": ["height", "width", "channels"],
                "info": {} if cam == "cam_c" else {"calibration": synthetic_calibration(cam, SIZE)},
            }
            for cam in CAMS
        },
        **calibration_column_features(["cam_c"]),
    }
    config = small_config()
    config.input_features = {k: ft for k, ft in dataset_to_policy_features(features).items() if k != "action"}
    assert "observation.extrinsics.cam_c" in config.input_features  # LeRobot's doing
    config.set_dataset_feature_metadata(features)
    assert config.frame_calibration == ["observation.images.cam_c"]
    assert sorted(config.input_features) == [
        "observation.images.cam_b",
        "observation.images.cam_c",
        "observation.state",
    ]
    assert list(config.camera_calibration) == ["observation.images.cam_b"]
    OmniDPolicy(config)  # cam_c needs no static calibration
