"""omnid-offline-eval: the error metrics, a real replay of a dataset through a saved checkpoint, bad input."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
from gym_omnid.rotations import rot6d_from_matrix, topdown_rotation
from lerobot.policies import make_pre_post_processors
from omnid_testing import make_tiny_dataset, static_and_per_frame_twins, tiny_config

from lerobot_omnid.diagnostics.offline_eval import action_errors, evaluate_offline, main, rotation_angle_deg
from lerobot_omnid.policy.modeling_omnid import OmniDPolicy


def _action(xyz, yaw: float, gripper: float) -> np.ndarray:
    return np.concatenate([xyz, rot6d_from_matrix(topdown_rotation(yaw)), [gripper]]).astype(np.float32)


def test_action_errors_in_cm_deg_and_gripper_units() -> None:
    expert = _action([0.5, 0.1, 0.2], 0.0, 1.0)
    predicted = _action([0.53, 0.14, 0.2], math.radians(30.0), 0.25)
    errors = action_errors(predicted, expert)
    assert errors["position_cm"] == pytest.approx(5.0, abs=1e-4)  # a 3-4-5 triangle in cm
    assert errors["rotation_deg"] == pytest.approx(30.0, abs=1e-3)
    assert errors["gripper"] == pytest.approx(0.75)
    assert action_errors(expert, expert) == pytest.approx({"position_cm": 0, "rotation_deg": 0, "gripper": 0})
    # 6D rotations need not be orthonormal: a scaled copy is the same rotation.
    assert rotation_angle_deg(expert[3:9] * 3.0, expert[3:9]) == pytest.approx(0.0, abs=1e-4)


def test_replays_every_frame_of_every_episode_through_a_saved_checkpoint(tmp_path, capsys) -> None:
    root = tmp_path / "data"
    dataset = make_tiny_dataset(root, episodes=2, frames=6)
    checkpoint = tmp_path / "checkpoint"
    policy = OmniDPolicy(tiny_config())
    policy.save_pretrained(checkpoint)
    for processor in make_pre_post_processors(policy.config, dataset_stats=dataset.meta.stats):
        processor.save_pretrained(checkpoint)

    out = tmp_path / "result" / "offline_eval.json"
    assert (
        main(
            [
                "--checkpoint",
                str(checkpoint),
                "--root",
                str(root),
                "--repo-id",
                "local/tiny",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    result = json.loads(out.read_text())
    assert (result["episodes"], result["frames"]) == (2, 12)
    assert [e["frames"] for e in result["per_episode"]] == [6, 6]
    assert result["position_cm"] > 0 and result["gripper"] >= 0
    assert result["position_cm"] == pytest.approx(np.mean([e["position_cm"] for e in result["per_episode"]]))
    assert "2 episodes, 12 frames" in capsys.readouterr().out
    # The reference: holding each frame's measured pose (the state's first 10 values) and gripper.
    hold = [
        action_errors(dataset[i]["observation.state"].numpy()[:10], dataset[i]["action"].numpy())
        for i in range(len(dataset))
    ]
    for key in ("position_cm", "rotation_deg", "gripper"):
        assert result["hold"][key] == pytest.approx(np.mean([h[key] for h in hold]), rel=1e-5)

    with pytest.raises(SystemExit):  # more episodes than the dataset has: named, nothing written
        main(
            [
                "--checkpoint",
                str(checkpoint),
                "--root",
                str(root),
                "--episodes",
                "3",
                "--out",
                str(tmp_path / "x"),
            ]
        )
    assert "episodes: expected 1..2" in capsys.readouterr().err and not (tmp_path / "x").exists()


def test_a_per_frame_policy_reads_every_frames_calibration_columns(tmp_path) -> None:
    """A policy whose cameras are calibrated per frame is given the dataset's calibration columns: on a
    copy of a dataset whose columns hold its static calibration, it makes the predictions of the same
    weights calibrated statically on the original."""
    cams = ("cam_b", "cam_c")
    keys = [f"observation.images.{cam}" for cam in cams]
    dataset, columns_root, static, per_frame = static_and_per_frame_twins(
        tmp_path, cams, episodes=1, frames=5
    )
    static_root = dataset.root

    results = {}
    for name, policy, root in (("static", static, static_root), ("per_frame", per_frame, columns_root)):
        checkpoint = tmp_path / f"checkpoint_{name}"
        policy.save_pretrained(checkpoint)
        for processor in make_pre_post_processors(policy.config, dataset_stats=dataset.meta.stats):
            processor.save_pretrained(checkpoint)
        torch.manual_seed(0)  # the same diffusion noise for both
        results[name] = evaluate_offline(checkpoint, root)
    assert (
        json.loads((tmp_path / "checkpoint_per_frame" / "config.json").read_text())["frame_calibration"]
        == keys
    )
    assert results["per_frame"]["frames"] == 5
    for key in ("position_cm", "rotation_deg", "gripper"):
        assert results["per_frame"][key] == pytest.approx(results["static"][key], rel=1e-4, abs=1e-5)


def test_missing_checkpoint_or_dataset_is_named(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit):
        main(["--checkpoint", str(tmp_path / "none"), "--root", str(tmp_path)])
    assert "--checkpoint" in capsys.readouterr().err
    (tmp_path / "ckpt").mkdir()
    (tmp_path / "ckpt" / "config.json").write_text("{}")
    with pytest.raises(SystemExit):
        main(["--checkpoint", str(tmp_path / "ckpt"), "--root", str(tmp_path / "no_data")])
    assert "--root" in capsys.readouterr().err
