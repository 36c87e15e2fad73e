"""One calibration path: parsed once into buffers, a calibration file merged into the config for good, and a
checkpoint saved before the package moved into wings still loads."""

import json
import shutil
from pathlib import Path

import pytest
import torch
from omnid_testing import STATE_DIM, random_batch, synthetic_calibration, tiny_config
from safetensors.torch import save_file

from lerobot_omnid.calibration.schema import CalibrationError, CameraCalibration
from lerobot_omnid.policy import modeling_omnid, omni_feature_generator
from lerobot_omnid.policy.configuration_omnid import OmniDConfig
from lerobot_omnid.policy.modeling_omnid import FRAME_MATRICES, OmniDPolicy
from lerobot_omnid.policy.omni_feature_generator import camera_geometry

FIXTURE = Path(__file__).parents[1] / "fixtures" / "checkpoint_v0_1"
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


def planes(policy: OmniDPolicy, batch: dict) -> torch.Tensor:
    """The OFG's plane (B, T, Q, D) of a batch with a time dimension, through the policy's own calibration
    path: the matrices its inputs stack for every sample and step, into the model's encoder."""
    stacked = policy._stack_inputs(batch, time_dim=True)
    images = stacked["observation.images"]
    _, out = policy.model.encode_images(images, *(stacked[k] for k in FRAME_MATRICES))
    return out.plane.unflatten(0, images.shape[:2])


def static_policy(policy: OmniDPolicy, rig: dict[str, dict]) -> OmniDPolicy:
    """The same weights with ``rig`` as static calibration: the reference the per-frame path must match."""
    static = OmniDPolicy(small_config(camera_calibration={f"observation.images.{c}": rig[c] for c in CAMS}))
    static.load_state_dict(policy.state_dict())
    return static.eval()


def static_plane(policy: OmniDPolicy, rig: dict[str, dict], images: torch.Tensor) -> torch.Tensor:
    """images (1, 1, S, 3, H, W) of one step -> the plane (Q, D) a policy calibrated statically with ``rig``
    computes from them."""
    static = static_policy(policy, rig)
    _, out = static.model.encode_images(images, *static.camera_matrices(1, (SIZE, SIZE)))
    return out.plane[0]


def check_each_sample_gets_the_plane_of_its_own_rig(policy: OmniDPolicy) -> None:
    rig_a = {cam: synthetic_calibration(cam, SIZE) for cam in CAMS}
    rig_b = {cam: moved(cam) for cam in CAMS}
    batch = with_columns(random_batch(policy.config, batch_size=2), [rig_a, rig_b], time_dim=True)
    with torch.no_grad():
        mixed = planes(policy, batch)
        images = policy._stack_inputs(batch, time_dim=True)["observation.images"]
        for b, rig in enumerate((rig_a, rig_b)):
            for t in range(2):
                alone = static_plane(policy, rig, images[b : b + 1, t : t + 1])
                assert torch.allclose(mixed[b, t], alone, atol=1e-5), f"sample {b}, step {t}"
        same_images = planes(
            policy,
            with_columns(
                {k: v[:1].expand(2, *v.shape[1:]) for k, v in batch.items()}, [rig_a, rig_b], time_dim=True
            ),
        )
    assert not torch.allclose(same_images[0], same_images[1], atol=1e-3)  # the rigs do give other planes


def broadcast_sample_0(method):
    """A faulty variant of a (pix_T_cam, cam_T_world) producer: every sample gets sample 0's matrices."""

    def faulty(*args, **kwargs):
        return tuple(m[:1].expand_as(m) for m in method(*args, **kwargs))

    return faulty


def test_each_sample_gets_the_plane_of_its_own_rig():
    check_each_sample_gets_the_plane_of_its_own_rig(per_frame_policy())


@pytest.mark.parametrize(
    "fault", ["sample 0's columns broadcast", "identity extrinsics", "OFG uses sample 0"]
)
def test_the_per_sample_check_catches_a_faulty_calibration_path(monkeypatch, fault):
    """The check above can fail: each injected fault (the policy giving every sample sample 0's
    per-frame matrices; the per-frame extrinsics ignored; the OFG projecting with batch element 0's
    calibration, as the authors' code did) makes it fail."""
    if fault == "sample 0's columns broadcast":
        monkeypatch.setattr(OmniDPolicy, "frame_matrices", broadcast_sample_0(OmniDPolicy.frame_matrices))
    elif fault == "identity extrinsics":
        monkeypatch.setattr(
            modeling_omnid, "extrinsics_from_column", lambda v: torch.eye(4).expand(*v.shape[:-1], 4, 4)
        )
    else:

        def first_sample_geometry(anchors_world, pix_T_cam, cam_T_world, image_hw):
            pix_T_cam, cam_T_world = (m[:1].expand_as(m) for m in (pix_T_cam, cam_T_world))
            return camera_geometry(anchors_world, pix_T_cam, cam_T_world, image_hw)

        monkeypatch.setattr(omni_feature_generator, "camera_geometry", first_sample_geometry)
    with pytest.raises(AssertionError):
        check_each_sample_gets_the_plane_of_its_own_rig(per_frame_policy())


def check_a_moving_camera_uses_each_steps_own_pose(policy: OmniDPolicy) -> None:
    """Two samples whose cameras move differently: sample 0's cam_c moves between its two steps, sample
    1's cam_b; every (sample, step) plane must be the plane of that step's rig."""
    still = {cam: synthetic_calibration(cam, SIZE) for cam in CAMS}
    rigs = [[still, {**still, "cam_c": moved("cam_c")}], [{**still, "cam_b": moved("cam_b")}, still]]
    batch = random_batch(policy.config, batch_size=2)
    for cam in CAMS:
        ext, K = (
            torch.stack(
                [torch.stack([frame_columns(rigs[b][t][cam])[i] for t in range(2)]) for b in range(2)]
            )
            for i in (0, 1)
        )
        batch[f"observation.extrinsics.{cam}"], batch[f"observation.intrinsics.{cam}"] = ext, K
    with torch.no_grad():
        mixed = planes(policy, batch)
        images = policy._stack_inputs(batch, time_dim=True)["observation.images"]
        for b in range(2):
            for t in range(2):
                alone = static_plane(policy, rigs[b][t], images[b : b + 1, t : t + 1])
                assert torch.allclose(mixed[b, t], alone, atol=1e-5), f"sample {b}, step {t}"


def test_a_moving_camera_uses_each_steps_own_pose():
    policy = per_frame_policy()
    check_a_moving_camera_uses_each_steps_own_pose(policy)
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
    assert torch.equal(queued[0, 0, 1].flatten(), frame_columns(synthetic_calibration("cam_c", SIZE))[0])
    assert torch.equal(queued[0, 1, 1].flatten(), frame_columns(moved("cam_c"))[0])


def last_step_for_every_step(method):
    """A faulty variant: every observation step gets the last step's matrices."""

    def faulty(*args, **kwargs):
        return tuple(m[:, -1:].expand_as(m) if m.ndim == 5 else m for m in method(*args, **kwargs))

    return faulty


@pytest.mark.parametrize("fault", ["last step for every step", "sample 0's columns broadcast"])
def test_the_moving_camera_check_catches_a_faulty_calibration_path(monkeypatch, fault):
    method = OmniDPolicy.frame_matrices
    wrap = last_step_for_every_step if fault == "last step for every step" else broadcast_sample_0
    monkeypatch.setattr(OmniDPolicy, "frame_matrices", wrap(method))
    with pytest.raises(AssertionError):
        check_a_moving_camera_uses_each_steps_own_pose(per_frame_policy())


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


@pytest.mark.parametrize(
    ("column", "value", "reason"),
    [
        ("intrinsics", torch.zeros(9), "K is not"),
        ("extrinsics", torch.zeros(16), "last row is not"),
        (
            "extrinsics",
            torch.diag(torch.tensor([2.0, 2.0, 2.0, 1.0])).flatten(),
            "rotation part is not a rot",
        ),
        ("extrinsics", torch.diag(torch.tensor([1.0, 1.0, -1.0, 1.0])).flatten(), "not a rotation"),
        ("intrinsics", torch.full((9,), float("nan")), "non-finite"),
    ],
    ids=["zero K", "zero T", "scaled T", "reflection", "NaN K"],
)
def test_a_bad_frame_calibration_names_the_camera_episode_and_frame(column, value, reason):
    """Per-frame columns are checked like a static calibration (a proper K, a rigid T_cam_world), frame by
    frame; the error names the camera, the sample, its step and, in a training batch, its episode and
    frame."""
    policy = per_frame_policy()
    rig = {cam: synthetic_calibration(cam, SIZE) for cam in CAMS}
    batch = with_columns(random_batch(policy.config, batch_size=2), [rig, rig], time_dim=True)
    batch["episode_index"], batch["frame_index"] = torch.tensor([3, 7]), torch.tensor([40, 12])
    key = f"observation.{column}.cam_c"
    batch[key] = batch[key].clone()
    batch[key][1, 0] = value  # sample 1's first step: frame 11 of episode 7
    pattern = (
        rf"observation\.images\.cam_c: the per-frame calibration of batch sample 1, observation step 0 of 2, "
        rf"episode 7, frame 11 is not a camera's: .*{reason}"
    )
    with pytest.raises(CalibrationError, match=pattern):
        policy.forward(batch)
    # At inference (no time dimension, no episode): the sample.
    obs = observation(policy.config)
    for cam in CAMS:
        ext, K = frame_columns(rig[cam])
        obs[f"observation.extrinsics.{cam}"], obs[f"observation.intrinsics.{cam}"] = ext[None], K[None]
    obs[key] = value[None]
    with pytest.raises(CalibrationError, match=r"cam_c: the per-frame calibration of batch sample 0 is not"):
        policy.select_action(obs)


def test_frame_columns_of_another_shape_say_so():
    policy = per_frame_policy()
    rig = {cam: synthetic_calibration(cam, SIZE) for cam in CAMS}
    batch = with_columns(random_batch(policy.config, batch_size=2), [rig, rig], time_dim=True)
    batch["observation.intrinsics.cam_b"] = batch["observation.intrinsics.cam_b"][..., :8]
    with pytest.raises(
        ValueError, match=r"observation\.intrinsics\.cam_b`: expected shape \(2, 2, 9\), got "
    ):
        policy.forward(batch)


def test_set_calibration_refuses_a_camera_calibrated_per_frame():
    policy = per_frame_policy()
    calib = CameraCalibration.from_dict(moved("cam_c"))
    with pytest.raises(CalibrationError, match=r"observation\.images\.cam_c'\] are calibrated per frame"):
        policy.set_calibration({"observation.images.cam_c": calib})
    assert "observation.images.cam_c" not in policy.config.camera_calibration


def test_without_the_ofg_a_per_frame_policy_acts_and_trains():
    """The "w/o OFG" ablation on a per-frame dataset: the columns are simply not used."""
    keys = [f"observation.images.{c}" for c in CAMS]
    policy = OmniDPolicy(small_config(camera_calibration={}, frame_calibration=keys, use_ofg=False))
    rig = {cam: synthetic_calibration(cam, SIZE) for cam in CAMS}
    loss, _ = policy.forward(with_columns(random_batch(policy.config), [rig, rig], time_dim=True))
    assert torch.isfinite(loss)
    policy.eval().reset()
    for _ in range(3):
        obs = observation(policy.config)
        for cam in CAMS:
            ext, K = frame_columns(rig[cam])
            obs[f"observation.extrinsics.{cam}"], obs[f"observation.intrinsics.{cam}"] = ext[None], K[None]
        assert policy.select_action(obs).shape == (1, 10)
