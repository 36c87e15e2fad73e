"""OmniD policy: per-sample calibration, camera subsets, gradients, save/load, bad input."""

import json

import pytest
import torch
from lerobot.configs.types import FeatureType, PolicyFeature
from omnid_testing import ACTION_DIM, STATE_DIM, random_batch, synthetic_calibration, tiny_config

from lerobot_omnid.calibration.schema import CalibrationError, CameraCalibration
from lerobot_omnid.geometry import look_at
from lerobot_omnid.policy.configuration_omnid import OmniDConfig
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy
from lerobot_omnid.policy.plane_readout import plane_keypoints

SIZE = 64


def observation(config: OmniDConfig, batch_size: int = 1) -> dict:
    obs = {key: torch.rand(batch_size, *ft.shape) for key, ft in config.image_features.items()}
    obs["observation.state"] = torch.randn(batch_size, STATE_DIM)
    return obs


def fixed_noise(config: OmniDConfig, batch_size: int = 1) -> torch.Tensor:
    return torch.randn(batch_size, config.horizon, ACTION_DIM, generator=torch.Generator().manual_seed(1))


def use_cameras(policy: OmniDPolicy, cams: tuple[str, ...]) -> None:
    """Point an existing policy at other cameras: features and calibration only, weights untouched."""
    keys = [f"observation.images.{c}" for c in cams]
    others = {k: ft for k, ft in policy.config.input_features.items() if ft.type is not FeatureType.VISUAL}
    policy.config.input_features = {
        **others,
        **{k: PolicyFeature(FeatureType.VISUAL, (3, SIZE, SIZE)) for k in keys},
    }
    policy.set_calibration(
        {
            k: CameraCalibration.from_dict(synthetic_calibration(c, SIZE))
            for k, c in zip(keys, cams, strict=True)
        }
    )


def ofg_inputs(policy: OmniDPolicy, batch_size: int):
    pix_T_cam, cam_T_world = policy.camera_matrices(batch_size, (SIZE, SIZE))
    return pix_T_cam.clone(), cam_T_world.clone()


def test_config_validation_messages():
    with pytest.raises(ValueError, match="`vision_backbone`: expected one of"):
        tiny_config(vision_backbone="vgg16")
    with pytest.raises(ValueError, match="divisible by `num_heads`"):
        tiny_config(d_model=30, num_heads=4)
    with pytest.raises(ValueError, match="multiple of 2\\*\\*len\\(down_dims\\)"):
        tiny_config(horizon=10)
    with pytest.raises(ValueError, match="`pillar_axis`: expected one of"):
        tiny_config(pillar_axis="w")
    with pytest.raises(ValueError, match="`plane_readout`: expected one of"):
        tiny_config(plane_readout="mean")
    with pytest.raises(ValueError, match="volume_bounds"):
        tiny_config(volume_bounds=((1.0, 0.0), (0.0, 1.0), (0.0, 1.0)))


def test_each_sample_uses_its_own_calibration():
    policy = OmniDPolicy(tiny_config()).eval()
    images = torch.rand(1, 1, 4, 3, SIZE, SIZE).expand(2, -1, -1, -1, -1, -1)
    pix_T_cam, cam_T_world = ofg_inputs(policy, 2)
    # Sample 1: every camera moved (looking at another point of the table).
    for s, cam in enumerate(("cam_b", "cam_c", "cam_d", "cam_e")):
        moved = synthetic_calibration(cam, SIZE, target=(0.6, 0.15, 0.05))
        cam_T_world[1, s] = torch.tensor(moved["T_cam_world"])
    both = policy.model.encode_images(images, pix_T_cam, cam_T_world)[1].plane
    alone = [
        policy.model.encode_images(images[i : i + 1], pix_T_cam[i : i + 1], cam_T_world[i : i + 1])[1].plane
        for i in range(2)
    ]
    assert torch.allclose(both[0], alone[0][0], atol=1e-5)
    assert torch.allclose(both[1], alone[1][0], atol=1e-5)
    assert not torch.allclose(both[0], both[1], atol=1e-3)


def test_camera_that_sees_nothing_gets_no_weight():
    policy = OmniDPolicy(tiny_config()).eval()
    images = torch.rand(1, 1, 4, 3, SIZE, SIZE)
    pix_T_cam, cam_T_world = ofg_inputs(policy, 1)
    away = cam_T_world.clone()
    away[0, 0] = look_at(torch.tensor([1.3, 0.0, 0.6]), torch.tensor([3.0, 0.0, 0.6]))  # cam_b looks away
    _, out = policy.model.encode_images(images, pix_T_cam, away)
    assert out.geometry.anchor_visible[0, 0].sum() == 0
    assert out.attention_weights[0, 0].abs().sum() == 0
    # Weights of every query seen by some camera sum to one over cameras x anchors x points.
    totals = out.attention_weights.sum(dim=(1, 4, 5))  # B, Q, heads
    seen = out.geometry.anchor_visible.any(dim=(1, 3))  # B, Q
    assert torch.allclose(totals[seen], torch.ones_like(totals[seen]), atol=1e-5)
    # Dropping the blind camera changes nothing.
    without = policy.model.encode_images(images[:, :, 1:], pix_T_cam[:, 1:], away[:, 1:])[1].plane
    assert torch.allclose(out.plane, without, atol=1e-5)


@pytest.mark.parametrize("cams", [("cam_a",), ("cam_b", "cam_c"), ("cam_a", "cam_c", "cam_e")])
def test_model_built_for_bcde_runs_on_other_cameras(cams):
    policy = OmniDPolicy(tiny_config()).eval()
    state_before = {k: v.clone() for k, v in policy.state_dict().items()}
    use_cameras(policy, cams)
    action = policy.select_action(observation(policy.config), noise=fixed_noise(policy.config))
    assert action.shape == (1, ACTION_DIM) and torch.isfinite(action).all()
    assert all(torch.equal(state_before[k], v) for k, v in policy.state_dict().items())


def test_gradients_reach_queries_offsets_weights_backbone():
    policy = OmniDPolicy(tiny_config()).train()
    optimizer = torch.optim.SGD(policy.parameters(), lr=1e-2)
    # The compression starts at zero (upstream gradient from the second step on), and so do offsets and
    # attention logits (samples on the projections, uniform weights): the camera embedding, behind the
    # logits, gets gradient from the third step on.
    for _ in range(3):
        optimizer.zero_grad()
        loss, _ = policy.forward(random_batch(policy.config))
        loss.backward()
        optimizer.step()
    layer = policy.model.ofg.layers[0].cross_attn
    for name, param in {
        "query_embed": policy.model.ofg.query_embed,
        "sampling_offsets": layer.sampling_offsets.weight,
        "attention_logits": layer.attention_logits.weight,
        "camera_embed": layer.camera_embed[0].weight,
        "backbone": policy.model.backbone.stem[0].weight,
        "unet": next(policy.model.unet.parameters()),
    }.items():
        assert param.grad is not None and param.grad.abs().sum() > 0, name


def test_plane_enters_the_condition_from_zero():
    policy = OmniDPolicy(tiny_config()).train()
    images = torch.rand(2, 1, 4, 3, SIZE, SIZE)
    condition, out = policy.model.encode_images(images, *ofg_inputs(policy, 2))
    assert out.plane.abs().sum() > 0 and condition.abs().sum() == 0
    loss, _ = policy.forward(random_batch(policy.config))
    loss.backward()
    assert policy.model.ofg.compress.weight.grad.abs().sum() > 0  # so the plane enters after one step
    plain = OmniDPolicy(tiny_config(zero_init_compression=False))
    assert plain.model.encode_images(images, *ofg_inputs(plain, 2))[0].abs().sum() > 0


def test_plane_keypoints_are_expected_plane_positions():
    plane_xy = torch.tensor([[-1.0, -1.0], [-1.0, 1.0], [1.0, -1.0], [1.0, 1.0]])
    compressed = torch.zeros(1, 4, 2)
    compressed[0, 2, 0] = 50.0  # channel 0 peaks at the third query, channel 1 is flat
    keypoints = plane_keypoints(compressed, plane_xy)
    assert keypoints.shape == (1, 2, 2)
    torch.testing.assert_close(keypoints[0, 0], plane_xy[2])
    torch.testing.assert_close(keypoints[0, 1], torch.zeros(2))


def test_keypoint_readout_trains_and_acts(tmp_path):
    policy = OmniDPolicy(tiny_config(plane_readout="keypoints", compressed_channels=3)).train()
    volume = policy.config.feature_volume
    images = torch.rand(2, 1, 4, 3, SIZE, SIZE)
    condition, out = policy.model.encode_images(images, *ofg_inputs(policy, 2))
    assert condition.shape == (2, 1, 6) and policy.model.ofg.out_dim == 6
    assert out.compressed.shape == (2, volume.num_queries, 3)
    assert condition.abs().max() <= 1.0 and condition.std(dim=0).sum() > 0  # depends on the images
    loss, _ = policy.forward(random_batch(policy.config))
    loss.backward()
    assert policy.model.ofg.compress.weight.grad.abs().sum() > 0
    assert policy.model.backbone.stem[0].weight.grad.abs().sum() > 0
    policy.eval()
    obs = observation(policy.config)
    expected = policy.select_action(obs, noise=fixed_noise(policy.config))
    policy.save_pretrained(tmp_path)
    loaded = OmniDPolicy.from_pretrained(tmp_path).eval()
    assert loaded.config.plane_readout == "keypoints"
    assert torch.equal(loaded.select_action(obs, noise=fixed_noise(policy.config)), expected)


def test_training_reduces_loss_on_a_fixed_batch():
    policy = OmniDPolicy(tiny_config()).train()
    batch = random_batch(policy.config, batch_size=4, generator=torch.Generator().manual_seed(0))
    optimizer = torch.optim.AdamW(policy.parameters(), lr=1e-3)
    losses = []
    for _ in range(15):
        torch.manual_seed(0)  # same noise and timesteps each step: a pure fitting problem
        loss, _ = policy.forward(batch)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    assert losses[-1] < 0.5 * losses[0]


def test_save_and_load_give_identical_actions(tmp_path):
    policy = OmniDPolicy(tiny_config()).eval()
    obs = observation(policy.config)
    expected = policy.select_action(obs, noise=fixed_noise(policy.config))
    policy.save_pretrained(tmp_path)
    loaded = OmniDPolicy.from_pretrained(tmp_path).eval()
    assert loaded.config.camera_calibration == policy.config.camera_calibration
    assert torch.equal(loaded.select_action(obs, noise=fixed_noise(policy.config)), expected)


def test_without_ofg_ablation_trains_and_acts():
    policy = OmniDPolicy(tiny_config(use_ofg=False))
    assert not hasattr(policy.model, "ofg")
    loss, _ = policy.forward(random_batch(policy.config))
    loss.backward()
    policy.eval()
    assert policy.select_action(observation(policy.config)).shape == (1, ACTION_DIM)


def test_resize_shape_resizes_images_and_intrinsics_together():
    """With ``resize_shape`` the backbone sees resized images and the anchors project with the matching K:
    they land where the full-size policy puts them in the image. Fails if either half ignores the option."""
    resized = OmniDPolicy(tiny_config(resize_shape=(32, 32))).eval()
    full = OmniDPolicy(tiny_config()).eval()
    images = torch.rand(1, 1, 4, 3, SIZE, SIZE)
    seen = {}
    resized.model.backbone.register_forward_hook(lambda m, i, o: seen.update(resized=tuple(i[0].shape[-2:])))
    full.model.backbone.register_forward_hook(lambda m, i, o: seen.update(full=tuple(i[0].shape[-2:])))
    pix_T_cam, cam_T_world = resized.camera_matrices(1, (SIZE, SIZE))
    _, out_resized = resized.model.encode_images(images, pix_T_cam, cam_T_world)
    _, out_full = full.model.encode_images(images, *full.camera_matrices(1, (SIZE, SIZE)))
    assert seen == {"resized": (32, 32), "full": (SIZE, SIZE)}
    full_K = full.camera_matrices(1, (SIZE, SIZE))[0]
    assert pix_T_cam[0, 0, 0, 0].item() == pytest.approx(full_K[0, 0, 0, 0].item() / 2)
    assert torch.allclose(out_resized.geometry.anchor_grid, out_full.geometry.anchor_grid, atol=1e-5)


def test_missing_calibration_is_a_clear_error():
    with pytest.raises(CalibrationError, match=r"observation\.images\.cam_b: no camera calibration"):
        OmniDPolicy(tiny_config(camera_calibration={}))


def test_image_key_without_calibration_is_a_clear_error():
    policy = OmniDPolicy(tiny_config()).eval()
    use_cameras(policy, ("cam_b",))
    policy.config.input_features["observation.images.extra"] = PolicyFeature(
        FeatureType.VISUAL, (3, SIZE, SIZE)
    )
    obs = observation(policy.config)
    with pytest.raises(CalibrationError, match=r"observation\.images\.extra: no camera calibration"):
        policy.select_action(obs)


@pytest.mark.parametrize("key", ["observation.images.cam_c", "observation.state"])
def test_nan_inputs_are_rejected(key):
    policy = OmniDPolicy(tiny_config()).eval()
    obs = observation(policy.config)
    obs[key] = obs[key].clone()
    obs[key].view(-1)[3] = float("nan")
    with pytest.raises(ValueError, match=f"`{key}` contains NaN"):
        policy.select_action(obs)
    batch = random_batch(policy.config)
    batch[key].view(-1)[0] = float("nan")
    with pytest.raises(ValueError, match=f"`{key}` contains NaN"):
        policy.forward(batch)


def test_wrong_image_rank_is_rejected():
    policy = OmniDPolicy(tiny_config()).eval()
    obs = observation(policy.config)
    obs["observation.images.cam_d"] = obs["observation.images.cam_d"][0]  # (3, H, W)
    with pytest.raises(
        ValueError, match=r"`observation\.images\.cam_d`: expected images of shape \(B, 3, H, W\)"
    ):
        policy.select_action(obs)
    obs = observation(policy.config)
    with pytest.raises(KeyError, match=r"observation\.images\.cam_b"):
        policy.select_action({k: v for k, v in obs.items() if k != "observation.images.cam_b"})


def test_dataset_calibration_flows_into_config():
    config = tiny_config(cams=("cam_b",), camera_calibration={}, cameras=["cam_c", "cam_d"])
    features = {
        "observation.state": {"dtype": "float32", "shape": (STATE_DIM,), "names": None},
        "action": {"dtype": "float32", "shape": (ACTION_DIM,), "names": None},
    }
    for cam in ("cam_b", "cam_c", "cam_d"):
        features[f"observation.images.{cam}"] = {
            "dtype": "video",
            "shape": (SIZE, SIZE, 3),
            "names": ["height", "width", "channels"],
            "info": {"video.fps": 10, "calibration": synthetic_calibration(cam, SIZE)},
        }
    config.set_dataset_feature_metadata(features)
    assert list(config.image_features) == ["observation.images.cam_c", "observation.images.cam_d"]
    assert set(config.camera_calibration) == {"observation.images.cam_c", "observation.images.cam_d"}
    del features["observation.images.cam_d"]["info"]["calibration"]
    with pytest.raises(CalibrationError, match=r"observation\.images\.cam_d: no camera calibration"):
        config.set_dataset_feature_metadata(features)
    config.cameras = ["cam_z"]
    with pytest.raises(ValueError, match="`cameras`"):
        config.set_dataset_feature_metadata(features)


def test_calibration_file_and_cameras_select_an_unseen_view(tmp_path):
    """Evaluation on a view the checkpoint never saw: `cameras` + `calibration_path` on the loaded config."""
    trained = OmniDPolicy(tiny_config())
    trained.save_pretrained(tmp_path / "ckpt")
    calib_file = tmp_path / "rig.json"
    calib_file.write_text(json.dumps({"cam_a": synthetic_calibration("cam_a", SIZE)}))
    config = OmniDConfig.from_pretrained(tmp_path / "ckpt")
    config.cameras = ["cam_a"]
    config.calibration_path = str(calib_file)
    config.__post_init__()
    policy = OmniDPolicy.from_pretrained(tmp_path / "ckpt", config=config).eval()
    assert policy.camera_keys == ["observation.images.cam_a"]
    assert policy.config.camera_calibration["observation.images.cam_a"] == synthetic_calibration(
        "cam_a", SIZE
    )
    assert policy.select_action(observation(policy.config)).shape == (1, ACTION_DIM)


def test_bad_calibration_file_names_file_and_camera(tmp_path):
    bad = synthetic_calibration("cam_a", SIZE)
    bad["K"] = [[1.0, 0.0], [0.0, 1.0]]
    path = tmp_path / "rig.json"
    path.write_text(json.dumps({"cam_a": bad}))
    with pytest.raises(CalibrationError, match=r"rig\.json: cam_a\.K: expected a 3x3"):
        tiny_config(calibration_path=str(path))


def test_backbone_loads_a_local_weights_file(tmp_path):
    import torchvision

    reference = torchvision.models.resnet18(weights=None)
    path = tmp_path / "resnet18.pt"
    torch.save(reference.state_dict(), path)
    policy = OmniDPolicy(tiny_config(pretrained_backbone_weights=str(path), use_group_norm=False))
    assert torch.equal(policy.model.backbone.stem[0].weight, reference.conv1.weight)
    assert torch.equal(policy.model.backbone.stages[2][0].conv1.weight, reference.layer3[0].conv1.weight)
    with pytest.raises(ValueError, match="`use_group_norm=True` cannot load"):
        OmniDPolicy(tiny_config(pretrained_backbone_weights=str(path)))
    with pytest.raises(FileNotFoundError, match="`pretrained_backbone_weights`: no file"):
        OmniDPolicy(
            tiny_config(pretrained_backbone_weights=str(tmp_path / "missing.pt"), use_group_norm=False)
        )


def test_resnet101_backbone_for_the_ablation():
    policy = OmniDPolicy(tiny_config(vision_backbone="resnet101"))
    assert policy.model.backbone.out_channels == 1024  # layer3 of a Bottleneck ResNet
    loss, _ = policy.forward(random_batch(policy.config, batch_size=1))
    assert torch.isfinite(loss)


def test_fuse_last_step_only_encodes_one_step_and_keeps_both_states():
    policy = OmniDPolicy(tiny_config(fuse_last_step_only=True))
    full = OmniDPolicy(tiny_config())
    image_dim = policy.model.ofg.out_dim
    assert policy.model.global_cond_dim == image_dim + STATE_DIM * 2
    assert full.model.global_cond_dim == (image_dim + STATE_DIM) * 2
    seen = []
    policy.model.backbone.register_forward_hook(lambda m, i, o: seen.append(i[0].shape[0]))
    batch = random_batch(policy.config, batch_size=2)
    loss, _ = policy.forward(batch)
    loss.backward()
    assert seen == [2 * 4]  # B * S images, one observation step
    # The earlier step's images do not matter, its state does.
    policy.eval()
    stacked = policy._stack_inputs(batch, time_dim=True)
    with torch.no_grad():
        cond = policy._condition(stacked)
        other = {k: v.clone() for k, v in stacked.items()}
        other["observation.images"][:, 0] = torch.rand_like(other["observation.images"][:, 0])
        assert torch.equal(policy._condition(other), cond)
        other["observation.state"][:, 0] += 1.0
        assert not torch.equal(policy._condition(other), cond)
    obs = observation(policy.config)
    assert policy.select_action(obs).shape == (1, ACTION_DIM)
