"""OmniD conditioned on ``observation.environment_state`` (e.g. the task one-hot of ``omnid-record
--task-onehot``): appended to the state of every observation step, queued, checked, not normalised."""

from __future__ import annotations

import pytest
import torch
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.utils.constants import OBS_ENV_STATE
from omnid_testing import ACTION_DIM, STATE_DIM, random_batch, tiny_config

from lerobot_omnid.policy.configuration_omnid import OmniDConfig
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy
from lerobot_omnid.policy.processor_omnid import make_omnid_pre_post_processors

SIZE = 32
CAMS = ("cam_b", "cam_c")
ENV_DIM = 6  # one-hot over gym_omnid's six tasks


def small_config(env_state: bool = True, **overrides) -> OmniDConfig:
    config = tiny_config(
        CAMS, size=SIZE, volume_shape=(4, 4, 2), num_layers=1, down_dims=(16, 32), **overrides
    )
    if env_state:
        config.input_features[OBS_ENV_STATE] = PolicyFeature(FeatureType.ENV, (ENV_DIM,))
    return config


def onehot(task_index: int, *lead: int) -> torch.Tensor:
    """(*lead, ENV_DIM) one-hots of task ``task_index``."""
    return torch.nn.functional.one_hot(torch.full(lead, task_index), ENV_DIM).float()


def env_batch(config: OmniDConfig, task_index: int = 0, batch_size: int = 2) -> dict:
    batch = random_batch(config, batch_size=batch_size, generator=torch.Generator().manual_seed(0))
    batch[OBS_ENV_STATE] = onehot(task_index, batch_size, config.n_obs_steps)
    return batch


@pytest.mark.parametrize("fuse_last_step_only", [False, True])
def test_condition_grows_by_env_dim_per_observation_step(fuse_last_step_only):
    with_env = OmniDPolicy(small_config(fuse_last_step_only=fuse_last_step_only))
    without = OmniDPolicy(small_config(env_state=False, fuse_last_step_only=fuse_last_step_only))
    n_obs_steps = with_env.config.n_obs_steps
    assert with_env.model.global_cond_dim == without.model.global_cond_dim + ENV_DIM * n_obs_steps
    # Only the diffusion head's conditioning layers take the wider input: the encoder is unchanged.
    shapes = {k: v.shape for k, v in with_env.state_dict().items()}
    other = {k: v.shape for k, v in without.state_dict().items()}
    assert shapes.keys() == other.keys()
    assert {k for k in shapes if shapes[k] != other[k]} <= {k for k in shapes if "cond_encoder" in k}
    stacked = with_env._stack_inputs(env_batch(with_env.config), time_dim=True)
    with torch.no_grad():
        assert with_env.eval()._condition(stacked).shape == (2, with_env.model.global_cond_dim)


def test_forward_and_select_action_with_env_state():
    policy = OmniDPolicy(small_config()).train()
    loss, _ = policy.forward(env_batch(policy.config))
    loss.backward()
    assert torch.isfinite(loss)
    policy.eval().reset()
    obs = {key: torch.rand(1, *ft.shape) for key, ft in policy.config.image_features.items()}
    obs["observation.state"] = torch.randn(1, STATE_DIM)
    for step in range(3):
        obs[OBS_ENV_STATE] = onehot(step, 1)
        assert policy.select_action(obs).shape == (1, ACTION_DIM)
    # The queue holds the env state of the last n_obs_steps observations, oldest first.
    queued = torch.stack(list(policy._queues[OBS_ENV_STATE]), dim=1)  # 1, T, De
    assert torch.equal(queued, torch.stack([onehot(1, 1), onehot(2, 1)], dim=1))


@pytest.mark.parametrize("fuse_last_step_only", [False, True])
def test_condition_depends_on_the_env_state_of_every_step(fuse_last_step_only):
    policy = OmniDPolicy(small_config(fuse_last_step_only=fuse_last_step_only)).eval()
    batch = env_batch(policy.config, task_index=0)
    with torch.no_grad():
        condition = policy._condition(policy._stack_inputs(batch, time_dim=True))
        assert torch.equal(policy._condition(policy._stack_inputs(batch, time_dim=True)), condition)
        other_task = {**batch, OBS_ENV_STATE: onehot(3, 2, policy.config.n_obs_steps)}
        assert not torch.equal(policy._condition(policy._stack_inputs(other_task, time_dim=True)), condition)
        earlier_step = batch[OBS_ENV_STATE].clone()
        earlier_step[:, 0] = onehot(3, 2)
        changed = policy._condition(
            policy._stack_inputs({**batch, OBS_ENV_STATE: earlier_step}, time_dim=True)
        )
        assert not torch.equal(changed, condition)


def test_wrong_or_missing_env_state_is_a_clear_error():
    policy = OmniDPolicy(small_config())
    batch = env_batch(policy.config)
    with pytest.raises(
        ValueError, match=r"`observation.environment_state`: expected shape \(2, 2, 6\), got \(2, 2, 5\)"
    ):
        policy.forward({**batch, OBS_ENV_STATE: torch.zeros(2, 2, 5)})
    obs = {key: value[:, -1] for key, value in batch.items() if key.startswith("observation.")}
    with pytest.raises(ValueError, match=r"expected shape \(2, 6\), got \(2, 2, 6\)"):
        policy.select_action({**obs, OBS_ENV_STATE: batch[OBS_ENV_STATE]})
    del batch[OBS_ENV_STATE]
    with pytest.raises(KeyError, match=r"`observation.environment_state` is missing .*task_onehot=true"):
        policy.forward(batch)


def test_env_state_feature_under_another_key_is_refused():
    config = small_config(env_state=False)
    config.input_features["observation.task"] = PolicyFeature(FeatureType.ENV, (ENV_DIM,))
    with pytest.raises(
        ValueError, match=r"one vector feature `observation.environment_state`.*observation.task"
    ):
        OmniDPolicy(config)


def test_env_state_is_not_normalised_and_survives_save_and_load(tmp_path):
    """A single-task dataset's one-hot columns are constant: MIN_MAX would send them all to -1 (and an
    unseen task's 1 to about 2 / eps); ENV is IDENTITY."""
    config = small_config()
    assert config.normalization_mapping["ENV"].value == "IDENTITY"
    stats = {
        OBS_ENV_STATE: {"min": onehot(0), "max": onehot(0), "mean": onehot(0), "std": torch.zeros(ENV_DIM)},
        "observation.state": {"min": -torch.ones(STATE_DIM), "max": torch.ones(STATE_DIM)},
        "action": {"min": -torch.ones(ACTION_DIM), "max": torch.ones(ACTION_DIM)},
    }
    preprocessor, _ = make_omnid_pre_post_processors(config, stats)
    obs = {key: torch.rand(*ft.shape) for key, ft in config.image_features.items()}
    obs["observation.state"] = torch.zeros(STATE_DIM)
    obs[OBS_ENV_STATE] = onehot(4)
    assert torch.equal(preprocessor(obs)[OBS_ENV_STATE].cpu(), onehot(4, 1))

    policy = OmniDPolicy(config)
    policy.save_pretrained(tmp_path)
    loaded = OmniDPolicy.from_pretrained(tmp_path)
    assert loaded.config.env_state_feature == PolicyFeature(FeatureType.ENV, (ENV_DIM,))
    assert loaded.model.global_cond_dim == policy.model.global_cond_dim
