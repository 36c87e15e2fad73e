"""``omnid-record``'s default form of the calibration: every camera's in every frame, as dataset columns.

Datasets of two rigs recorded with the default flags merge with LeRobot's own ``lerobot-edit-dataset``
and keep each episode's own rig's calibration (tests/e2e/test_default_calibration_merge.py);
``--static-calibration`` opts out (not with the wrist camera); the env gives the columns by default, so an
OmniD checkpoint trained on them evaluates without a flag, and a checkpoint with a static calibration acts
exactly as without them; LeRobot's stock policies train and act on such a dataset; the benchmark, whose
controls replace a static calibration, keeps recording the static form.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch
from gym_omnid.constants import ACTION_DIM, STATE_DIM
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata
from lerobot.datasets.factory import resolve_delta_timestamps
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.envs.factory import make_env, make_env_pre_post_processors
from lerobot.envs.utils import preprocess_observation
from lerobot.policies.act.configuration_act import ACTConfig
from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
from lerobot.policies.factory import make_policy, make_pre_post_processors
from lerobot.policies.vqbet.configuration_vqbet import VQBeTConfig
from lerobot.scripts.lerobot_eval import rollout
from omnid_testing import record_rigs_with_default_flags, tiny_config

from lerobot_omnid.benchmark import demo, rigs_and_wrist
from lerobot_omnid.benchmark.commands import record_command
from lerobot_omnid.benchmark.plan import PROFILES, TASK0, build_plan
from lerobot_omnid.calibration.frame_columns import extrinsics_key, is_calibration_key
from lerobot_omnid.env_config import OmniDEnvConfig
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy
from lerobot_omnid.record import build_parser, main, record_dataset

SIZE = 32
CAMERA = "cam_b"
IMAGE_KEY = f"observation.images.{CAMERA}"
RIGS = ("default", "closer")


@pytest.fixture(scope="module")
def rig_roots(tmp_path_factory) -> dict[str, Path]:
    """One expert episode per rig, recorded by ``omnid-record`` with no calibration flag."""
    return record_rigs_with_default_flags(tmp_path_factory.mktemp("default_calibration"), RIGS, CAMERA, SIZE)


def test_per_frame_is_the_default_and_static_calibration_opts_out(tmp_path, capsys):
    parser = build_parser()
    assert parser.parse_args([]).per_frame_calibration is True
    assert parser.parse_args(["--per-frame-calibration"]).per_frame_calibration is True  # still accepted
    assert parser.parse_args(["--static-calibration"]).per_frame_calibration is False
    root = tmp_path / "ds"
    for argv, named in (
        (["--per-frame-calibration", "--static-calibration"], "--per-frame-calibration"),
        (["--cameras", "cam_b,cam_wrist", "--static-calibration"], "cam_wrist moves with the arm"),
    ):
        with pytest.raises(SystemExit) as exit_info:
            main([*argv, "--episodes", "1", "--root", str(root)])
        assert exit_info.value.code == 2
        err = capsys.readouterr().err
        assert "--static-calibration" in err and named in err
    with pytest.raises(ValueError, match=r"cam_wrist moves with the arm.*--static-calibration"):
        record_dataset(root, episodes=1, cameras=["cam_wrist"], per_frame_calibration=False)
    assert not root.exists()


def test_the_env_gives_the_columns_by_default_and_a_static_checkpoint_ignores_them(tmp_path):
    """``lerobot-eval``'s own rollout of an OmniD checkpoint whose calibration is in its config.json: the
    same actions with the default observation (columns included) as without the columns. The env's rig is
    not the checkpoint's, so a policy that read the columns would act differently."""
    cfg = OmniDEnvConfig(cameras=[CAMERA, "cam_c"], image_size=SIZE, episode_length=4, rig="closer")
    assert cfg.per_frame_calibration and cfg.features_map[f"extrinsics.{CAMERA}"] == extrinsics_key(CAMERA)
    calibration = dataclasses.replace(cfg, rig="default").camera_calibrations()
    image = PolicyFeature(FeatureType.VISUAL, (3, SIZE, SIZE))
    config = tiny_config(
        input_features={
            "observation.state": PolicyFeature(FeatureType.STATE, (STATE_DIM,)),
            **{f"observation.images.{cam}": image for cam in cfg.cameras},
        },
        output_features={"action": PolicyFeature(FeatureType.ACTION, (ACTION_DIM,))},
        camera_calibration=calibration,
        zero_init_compression=False,  # the images reach the actions before any training
    )
    OmniDPolicy(config).save_pretrained(tmp_path / "static")
    policy = OmniDPolicy.from_pretrained(tmp_path / "static").eval()
    assert not policy.config.frame_calibration
    preprocessor, postprocessor = make_pre_post_processors(policy.config)
    actions, observed = {}, {}
    for per_frame in (True, False):
        env_cfg = dataclasses.replace(cfg, per_frame_calibration=per_frame)
        vec = make_env(env_cfg, n_envs=1)["omnid"][0]
        env_pre, env_post = make_env_pre_post_processors(env_cfg, policy.config)
        torch.manual_seed(0)
        try:
            result = rollout(vec, policy, env_pre, env_post, preprocessor, postprocessor, seeds=[0],
                             return_observations=True)  # fmt: skip
        finally:
            vec.close()
        actions[per_frame], observed[per_frame] = result["action"], set(result["observation"])
    assert extrinsics_key(CAMERA) in observed[True] and extrinsics_key(CAMERA) not in observed[False]
    assert torch.isfinite(actions[True]).all()
    torch.testing.assert_close(actions[True], actions[False], rtol=0, atol=0)


def test_a_per_frame_checkpoint_evaluates_with_the_default_env(tmp_path):
    """An OmniD checkpoint trained on the default recording reads every camera's calibration from the
    columns; ``lerobot-eval --env.type=omnid`` gives them without a flag (without them: the missing column
    named)."""
    cfg = OmniDEnvConfig(cameras=[CAMERA], image_size=SIZE, episode_length=3)
    image = PolicyFeature(FeatureType.VISUAL, (3, SIZE, SIZE))
    config = tiny_config(
        input_features={
            "observation.state": PolicyFeature(FeatureType.STATE, (STATE_DIM,)),
            IMAGE_KEY: image,
        },
        output_features={"action": PolicyFeature(FeatureType.ACTION, (ACTION_DIM,))},
        camera_calibration={},
        frame_calibration=[IMAGE_KEY],
    )
    OmniDPolicy(config).save_pretrained(tmp_path / "per_frame")
    policy = OmniDPolicy.from_pretrained(tmp_path / "per_frame").eval()
    preprocessor, postprocessor = make_pre_post_processors(policy.config)
    for per_frame in (None, False):  # None: the default
        env_cfg = cfg if per_frame is None else dataclasses.replace(cfg, per_frame_calibration=per_frame)
        vec = make_env(env_cfg, n_envs=1)["omnid"][0]
        env_pre, env_post = make_env_pre_post_processors(env_cfg, policy.config)
        try:
            if per_frame is None:
                result = rollout(vec, policy, env_pre, env_post, preprocessor, postprocessor, seeds=[0])
                assert torch.isfinite(result["action"]).all()
            else:
                with pytest.raises(KeyError, match=r"observation\.intrinsics\.cam_b` is missing"):
                    rollout(vec, policy, env_pre, env_post, preprocessor, postprocessor, seeds=[0])
        finally:
            vec.close()


def _stock_config(policy_type: str) -> DiffusionConfig | ACTConfig | VQBeTConfig:
    """A CPU-tiny LeRobot policy. VQ-BeT counts its input features as observation tokens, so it is given
    the images and the state only (``--policy.input_features``, as ``omnid-benchmark`` does): left to
    LeRobot, the calibration columns would be tokens too (docs/calibration.md)."""
    no_download = {"device": "cpu", "pretrained_backbone_weights": None}
    if policy_type == "diffusion":
        sizes = {"down_dims": (16, 32), "horizon": 8, "n_action_steps": 4, "num_inference_steps": 2}
        return DiffusionConfig(**no_download, **sizes, crop_shape=None, use_group_norm=True)
    if policy_type == "act":
        sizes = {"dim_model": 32, "n_heads": 2, "dim_feedforward": 64, "chunk_size": 4, "n_action_steps": 4}
        return ACTConfig(**no_download, **sizes, n_encoder_layers=1, n_decoder_layers=1, use_vae=False)
    inputs = {
        IMAGE_KEY: PolicyFeature(FeatureType.VISUAL, (3, SIZE, SIZE)),
        "observation.state": PolicyFeature(FeatureType.STATE, (STATE_DIM,)),
    }
    sizes = {"gpt_n_layer": 1, "gpt_n_head": 2, "gpt_hidden_dim": 32, "vqvae_embedding_dim": 32}
    sizes |= {"vqvae_enc_hidden_dim": 32, "spatial_softmax_num_keypoints": 8}
    return VQBeTConfig(
        **no_download,
        **sizes,
        crop_shape=None,
        use_group_norm=True,
        n_obs_steps=2,
        action_chunk_size=8,
        input_features=inputs,
    )


@pytest.mark.parametrize("policy_type", ["diffusion", "act", "vqbet"])
def test_stock_policies_train_and_act_on_a_per_frame_dataset(rig_roots, policy_type):
    """LeRobot's DP, ACT and VQ-BeT on one rig's default recording, whose columns are constant (min ==
    max): normalisation, loss and actions stay finite, with the env's columns and without them."""
    meta = LeRobotDatasetMetadata("local/default", root=rig_roots["default"])
    stats = meta.stats[extrinsics_key(CAMERA)]
    np.testing.assert_array_equal(stats["min"], stats["max"])
    policy = make_policy(_stock_config(policy_type), ds_meta=meta)
    columns = [key for key in policy.config.input_features if is_calibration_key(key)]
    assert len(columns) == (0 if policy_type == "vqbet" else 2)  # LeRobot made them STATE inputs
    preprocessor, postprocessor = make_pre_post_processors(policy.config, dataset_stats=meta.stats)
    delta_timestamps = resolve_delta_timestamps(policy.config, meta)
    dataset = LeRobotDataset("local/default", root=rig_roots["default"], delta_timestamps=delta_timestamps,
                             video_backend="pyav")  # fmt: skip
    batch = preprocessor(next(iter(torch.utils.data.DataLoader(dataset, batch_size=2))))
    for key in columns:
        assert torch.isfinite(batch[key]).all()
    policy.train()
    loss, _ = policy.forward(batch)
    assert torch.isfinite(loss)

    policy.eval()
    for per_frame in (True, False):
        env_cfg = OmniDEnvConfig(cameras=[CAMERA], image_size=SIZE, per_frame_calibration=per_frame)
        vec = make_env(env_cfg, n_envs=1)["omnid"][0]
        env_pre, _ = make_env_pre_post_processors(env_cfg, policy.config)
        try:
            obs, _ = vec.reset(seed=[0])
            observation = {**preprocess_observation(obs), "task": [vec.call("task_description")[0]]}
        finally:
            vec.close()
        assert (extrinsics_key(CAMERA) in observation) == per_frame
        policy.reset()
        action = postprocessor(policy.select_action(preprocessor(env_pre(observation))))
        assert action.shape == (1, ACTION_DIM) and torch.isfinite(action).all()


def test_benchmark_and_demo_record_the_static_form_and_rigs_and_wrist_per_frame(tmp_path, monkeypatch):
    """The benchmark's controls and omnid-robustness replace a static calibration: its recordings (and the
    main job's) say ``--static-calibration``; the rigs measurement keeps its per-frame command line."""
    parser = build_parser()
    assert "--static-calibration" in record_command(TASK0, 1, [CAMERA], SIZE, tmp_path / "d")
    records = [run.cmd for run in build_plan(PROFILES["mini"], tmp_path, (TASK0,)) if run.kind == "record"]
    assert records
    for cmd in records:
        assert parser.parse_args(list(cmd[1:])).per_frame_calibration is False, cmd

    class Planned(Exception):
        """Stops the main job once it has planned its runs, before any runs."""

    def stop(runs: list, *args, **kwargs) -> None:
        raise Planned(runs)

    monkeypatch.setattr(demo, "execute", stop)
    monkeypatch.setattr(demo, "code_commit", lambda: "abc123")  # git runs in a subprocess
    with pytest.raises(Planned) as planned:
        demo.main(["--out", str(tmp_path / "demo")])
    (record,) = [run for run in planned.value.args[0] if run.kind == "record"]
    assert parser.parse_args(list(record.cmd[1:])).per_frame_calibration is False

    for dataset, (rig, *_) in rigs_and_wrist.DATASETS.items():
        cmd = rigs_and_wrist.record(tmp_path, dataset)
        assert cmd[-3:] == ["--rig", rig, "--per-frame-calibration"] and "--static-calibration" not in cmd
        assert parser.parse_args(cmd[1:]).per_frame_calibration is True
