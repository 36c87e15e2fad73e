"""OmniD and the per-frame column ``observation.camera_visible`` (``omnid-record --hidden-cameras``): each
sample fuses only the cameras it shows, matched by name, in training (AND-ed with camera dropout) and at
inference; the column is never a state input nor normalised; its camera names come from the dataset."""

from __future__ import annotations

import pytest
import torch
from lerobot.configs.types import FeatureType
from lerobot.utils.feature_utils import dataset_to_policy_features
from omnid_testing import ACTION_DIM, STATE_DIM, random_batch, synthetic_calibration, tiny_config

from lerobot_omnid.camera_visibility import CAMERA_VISIBLE_KEY, camera_visible_feature, visible_cameras
from lerobot_omnid.policy import modeling_omnid
from lerobot_omnid.policy.configuration_omnid import OmniDConfig
from lerobot_omnid.policy.modeling_omnid import VISIBLE_CAMERAS, OmniDPolicy, camera_dropout_mask
from lerobot_omnid.policy.processor_omnid import make_omnid_pre_post_processors

SIZE = 32
CAMS = ("cam_b", "cam_c", "cam_d")  # the policy's cameras
RECORDED = ["cam_a", "cam_d", "cam_c", "cam_b"]  # the column's cameras: one more, in another order


def small_config(camera_visible_names: list[str] | None = RECORDED, **overrides) -> OmniDConfig:
    """A tiny OmniD whose plane reaches the condition from the start (no zero-initialised compression)."""
    return tiny_config(
        CAMS,
        size=SIZE,
        volume_shape=(4, 4, 2),
        num_layers=1,
        down_dims=(16, 32),
        zero_init_compression=False,
        camera_visible_names=camera_visible_names,
        **overrides,
    )


def column(*shown: tuple[str, ...], steps: int = 2) -> torch.Tensor:
    """(B, steps, R) column of a batch whose sample b shows the cameras ``shown[b]``."""
    rows = [[1.0 if cam in cams else 0.0 for cam in RECORDED] for cams in shown]
    return torch.tensor(rows)[:, None].expand(-1, steps, -1).clone()


def condition(policy: OmniDPolicy, batch: dict) -> torch.Tensor:
    with torch.no_grad():
        return policy._condition(policy._stack_inputs(batch, time_dim=True))


def check_a_hidden_camera_does_not_reach_the_condition(policy: OmniDPolicy) -> None:
    """cam_c hidden in sample 0 and shown in sample 1: new cam_c images change sample 1's condition only."""
    batch = random_batch(policy.config, generator=torch.Generator().manual_seed(0))
    batch[CAMERA_VISIBLE_KEY] = column(("cam_b", "cam_d"), ("cam_b", "cam_c", "cam_d"))
    before = condition(policy, batch)
    batch["observation.images.cam_c"] = torch.rand_like(batch["observation.images.cam_c"])
    after = condition(policy, batch)
    assert torch.allclose(before[0], after[0], atol=1e-6)
    assert not torch.allclose(before[1], after[1], atol=1e-4)


def test_a_hidden_camera_does_not_reach_the_condition():
    check_a_hidden_camera_does_not_reach_the_condition(OmniDPolicy(small_config()).eval())


@pytest.mark.parametrize("fault", ["column read by position", "column ignored", "sample 0's row for all"])
def test_the_hidden_camera_check_catches_a_faulty_mapping(monkeypatch, fault):
    """The check above can fail: the column's values taken in the policy's camera order instead of by
    name, the column not used, or sample 0's row used for the whole batch."""

    def faulty(values, names, cameras):
        if fault == "column read by position":
            return values[..., : len(cameras)] > 0.5
        mask = visible_cameras(values, names, cameras)
        if fault == "column ignored":
            return torch.ones_like(mask)
        return mask[:1].expand_as(mask)

    monkeypatch.setattr(modeling_omnid, "visible_cameras", faulty)
    with pytest.raises(AssertionError):
        check_a_hidden_camera_does_not_reach_the_condition(OmniDPolicy(small_config()).eval())


def test_the_column_is_not_a_state_input():
    """The condition and every weight have the shapes of a policy made without the column."""
    with_column, without = OmniDPolicy(small_config()), OmniDPolicy(small_config(None))
    assert with_column.model.global_cond_dim == without.model.global_cond_dim
    assert {k: v.shape for k, v in with_column.state_dict().items()} == {
        k: v.shape for k, v in without.state_dict().items()
    }
    batch = random_batch(with_column.config)
    batch[CAMERA_VISIBLE_KEY] = column(("cam_b",), ("cam_c", "cam_d"))
    assert condition(with_column.eval(), batch).shape == (2, without.model.global_cond_dim)


def test_dropout_keeps_only_visible_cameras_and_at_least_one():
    cpu = torch.device("cpu")
    torch.manual_seed(0)
    available = torch.rand(2000, 4) < 0.5
    available[torch.arange(2000), torch.randint(4, (2000,))] = True  # at least one per sample
    mask = camera_dropout_mask(2000, 4, 0.5, cpu, available=available)
    assert not (mask & ~available).any() and mask.any(dim=1).all()
    assert (mask != available).any()  # dropout still drops some of the visible cameras
    single = camera_dropout_mask(2000, 4, 0.0, cpu, single_rate=1.0, available=available)
    assert (single.sum(dim=1) == 1).all() and not (single & ~available).any()
    # The one camera kept is drawn uniformly among the visible ones: samples showing B and C keep each half.
    two = torch.tensor([True, True, False, False]).expand(4000, 4)
    share = camera_dropout_mask(4000, 4, 0.0, cpu, single_rate=1.0, available=two).float().mean(dim=0)
    assert abs(share[0] - 0.5) < 0.03 and share[2:].sum() == 0
    assert torch.equal(camera_dropout_mask(10, 4, 0.0, cpu, available=available[:10]), available[:10])


def test_training_combines_the_column_with_dropout(monkeypatch):
    """In training the mask reaching the model is the dropout mask AND the column, one camera at least;
    without dropout it is the column itself."""
    masks = []

    def spy(policy):
        original = policy.model.global_condition

        def recorded(*args, **kwargs):
            masks.append(args[4])
            return original(*args, **kwargs)

        monkeypatch.setattr(policy.model, "global_condition", recorded)
        return policy

    shown = [("cam_b", "cam_c"), ("cam_d",), ("cam_b", "cam_c", "cam_d"), ("cam_c",)] * 8
    expected = torch.tensor([[cam in cams for cam in CAMS] for cams in shown])
    for config, check in (
        (small_config(camera_dropout=0.5), lambda m: not (m & ~expected).any() and m.any(dim=1).all()),
        (small_config(), lambda m: torch.equal(m, expected)),
    ):
        policy = spy(OmniDPolicy(config).train())
        batch = random_batch(policy.config, batch_size=len(shown))
        batch[CAMERA_VISIBLE_KEY] = column(*shown)
        loss, _ = policy.forward(batch)
        assert torch.isfinite(loss)
        assert check(masks[-1])
    assert (masks[0] != expected).any()  # dropout dropped some visible cameras


def test_select_action_leaves_hidden_cameras_out_and_runs_without_the_column():
    """At inference the column, when the observations have it, hides cameras as in training; an env
    never sends it, and the policy then fuses every camera."""
    policy = OmniDPolicy(small_config()).eval()
    noise = torch.randn(1, policy.config.horizon, ACTION_DIM, generator=torch.Generator().manual_seed(1))
    obs = {key: torch.rand(1, 3, SIZE, SIZE) for key in policy.config.image_features}
    obs["observation.state"] = torch.randn(1, STATE_DIM)

    def action(cam_c: torch.Tensor, shown: tuple[str, ...] | None) -> torch.Tensor:
        policy.reset()
        step = {**obs, "observation.images.cam_c": cam_c}
        if shown is not None:
            step[CAMERA_VISIBLE_KEY] = column(shown, steps=1)[:, 0]
        return policy.select_action(step, noise=noise)

    one, other = torch.rand(1, 3, SIZE, SIZE), torch.rand(1, 3, SIZE, SIZE)
    assert torch.allclose(action(one, ("cam_b", "cam_d")), action(other, ("cam_b", "cam_d")), atol=1e-6)
    assert not torch.allclose(action(one, CAMS), action(other, CAMS), atol=1e-4)
    assert not torch.allclose(action(one, None), action(other, None), atol=1e-4)
    assert len(policy._queues[VISIBLE_CAMERAS]) == 0  # nothing queued without the column


def test_a_sample_showing_none_of_the_policys_cameras_is_a_clear_error():
    policy = OmniDPolicy(small_config()).eval()
    batch = random_batch(policy.config)
    batch["episode_index"] = torch.tensor([3, 7])
    batch["frame_index"] = torch.tensor([12, 40])
    batch[CAMERA_VISIBLE_KEY] = column(("cam_b",), ("cam_a",))  # sample 1 shows only a camera not used
    with pytest.raises(
        ValueError,
        match=r"`observation.camera_visible`: batch sample 1, observation step 0 of 2, episode 7, frame 39 "
        r"shows none of the policy's cameras",
    ):
        policy.forward(batch)
    # Each step shows a camera, but no camera is shown at every step: one set per sample is refused too.
    batch[CAMERA_VISIBLE_KEY] = column(("cam_b",), ("cam_c",))
    batch[CAMERA_VISIBLE_KEY][1, 0] = column(("cam_d",), steps=1)[0, 0]
    with pytest.raises(ValueError, match=r"batch samples \[1\] show none of the policy's cameras at every"):
        policy.forward(batch)


@pytest.mark.parametrize(
    ("names", "value", "message"),
    [
        (None, None, "`camera_visible_names` is None"),
        (RECORDED, torch.full((2, 2, 4), -1.0), r"expected 0.0 \(hidden\) or 1.0 \(visible\).*unnormalised"),
        (RECORDED, torch.ones(2, 2, 3), r"expected shape \(2, 2, 4\)"),
        (["cam_a", "cam_b", "cam_c", "cam_e"], None, r"the policy's cameras \['cam_d'\] are not among"),
    ],
)
def test_a_column_the_policy_cannot_read_is_a_clear_error(names, value, message):
    policy = OmniDPolicy(small_config(names))
    batch = random_batch(policy.config)
    batch[CAMERA_VISIBLE_KEY] = column(CAMS, CAMS) if value is None else value
    with pytest.raises(ValueError, match=message):
        policy.forward(batch)


def dataset_features(cams: tuple[str, ...] = ("cam_a", *CAMS)) -> dict:
    """Features as ``omnid-record --hidden-cameras`` writes them (static calibration, for brevity)."""
    return {
        "observation.state": {"dtype": "float32", "shape": (STATE_DIM,), "names": None},
        "action": {"dtype": "float32", "shape": (ACTION_DIM,), "names": None},
        **{
            f"observation.images.{cam}": {
                "dtype": "video",
                "shape": (SIZE, SIZE, 3),
                "names": ["height", "width", "channels"],
                "info": {"calibration": synthetic_calibration(cam, SIZE)},
            }
            for cam in cams
        },
        CAMERA_VISIBLE_KEY: camera_visible_feature(list(cams)),
    }


def config_from_dataset(features: dict, **overrides) -> OmniDConfig:
    """What LeRobot's ``make_policy`` does with a dataset: its policy features, then the config's hook."""
    config = small_config(None, camera_calibration={}, **overrides)
    config.input_features = {k: ft for k, ft in dataset_to_policy_features(features).items() if k != "action"}
    config.set_dataset_feature_metadata(features)
    return config


def test_a_config_made_from_the_datasets_features_reads_the_column(tmp_path):
    features = dataset_features()
    assert dataset_to_policy_features(features)[CAMERA_VISIBLE_KEY].type is FeatureType.STATE  # LeRobot's
    config = config_from_dataset(features, cameras=["cam_d", "cam_b"])
    assert config.camera_visible_names == ["cam_a", *CAMS]
    assert sorted(config.input_features) == [
        "observation.images.cam_b",
        "observation.images.cam_d",
        "observation.state",
    ]
    policy = OmniDPolicy(config).eval()
    batch = random_batch(config)
    rows = torch.tensor([[0.0, 1.0, 0.0, 0.0], [1.0, 0.0, 1.0, 1.0]])  # over cam_a, cam_b, cam_c, cam_d
    batch[CAMERA_VISIBLE_KEY] = rows[:, None].repeat(1, 2, 1)
    stacked = policy._stack_inputs(batch, time_dim=True)
    assert torch.equal(stacked[VISIBLE_CAMERAS][:, 0], torch.tensor([[False, True], [True, False]]))
    assert torch.isfinite(policy._condition(stacked)).all()
    # Kept out of the normaliser: a column constant in the dataset reaches the policy as it is.
    ones = torch.ones(4)
    stats = {
        CAMERA_VISIBLE_KEY: {"min": ones, "max": ones, "mean": ones, "std": torch.zeros(4)},
        "observation.state": {"min": -torch.ones(STATE_DIM), "max": torch.ones(STATE_DIM)},
        "action": {"min": -torch.ones(ACTION_DIM), "max": torch.ones(ACTION_DIM)},
    }
    preprocessor, _ = make_omnid_pre_post_processors(config, stats)
    obs = {key: torch.rand(3, SIZE, SIZE) for key in config.image_features}
    obs["observation.state"] = torch.zeros(STATE_DIM)
    obs[CAMERA_VISIBLE_KEY] = torch.tensor([0.0, 1.0, 1.0, 1.0])
    assert torch.equal(preprocessor(obs)[CAMERA_VISIBLE_KEY].cpu(), obs[CAMERA_VISIBLE_KEY])
    # config.json carries the names, so a checkpoint reads the column without the dataset.
    policy.save_pretrained(tmp_path)
    assert OmniDPolicy.from_pretrained(tmp_path).config.camera_visible_names == ["cam_a", *CAMS]
    # A dataset without the column leaves none.
    without = dataset_features()
    del without[CAMERA_VISIBLE_KEY]
    assert config_from_dataset(without).camera_visible_names is None


def test_a_column_the_config_cannot_use_is_refused():
    features = dataset_features()
    features[CAMERA_VISIBLE_KEY] = camera_visible_feature(["cam_a", "cam_b", "cam_c"])
    with pytest.raises(ValueError, match=r"policy's cameras \['cam_d'\] are not among the column's cameras"):
        config_from_dataset(features)
    features[CAMERA_VISIBLE_KEY]["names"] = None
    with pytest.raises(ValueError, match=r"names are the R distinct recorded cameras"):
        config_from_dataset(features)
    config = config_from_dataset(dataset_features(), use_ofg=False)
    with pytest.raises(ValueError, match=r"`camera_visible_names`: expected None with use_ofg=false"):
        OmniDPolicy(config)
