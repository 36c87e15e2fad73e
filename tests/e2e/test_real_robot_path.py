"""The real-robot path of ``examples/09_real_robot_path.sh`` with the sim robot (``--robot.type=omnid_sim``)
and the expert teleoperator: lerobot-record -> omnid-attach-calibration -> lerobot-train ->
lerobot-rollout, the policy's calls traced in the rollout process. (The plugins themselves:
tests/sim/test_robot_plugin.py.)"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from lerobot_omnid.calibration.rig_file import load_calibration_file
from lerobot_omnid.robot.features import ACTION_KEYS, STATE_KEYS

ROOT = Path(__file__).resolve().parents[2]
TRACE_SITECUSTOMIZE = '''
"""Test-only: in lerobot-rollout, log what the policy receives and what reaches the sim robot."""
import json, os, sys

if os.path.basename(sys.argv[0]) == "lerobot-rollout" and os.environ.get("OMNID_TRACE_FILE"):
    from lerobot.rollout.inference.sync import SyncInferenceEngine
    from lerobot_omnid.policy.modeling_omnid import OmniDPolicy
    from lerobot_omnid.robot.omnid_sim import OmniDSim

    def _log(**record):
        with open(os.environ["OMNID_TRACE_FILE"], "a") as f:
            f.write(json.dumps(record) + "\\n")

    _select_action, _get_action, _send_action = (
        OmniDPolicy.select_action, SyncInferenceEngine.get_action, OmniDSim.send_action
    )

    def select_action(self, batch, *args, **kwargs):
        images = {k: list(v.shape) for k, v in batch.items() if k.startswith("observation.images.")}
        _log(event="select_action", images=images, calibration=self.config.camera_calibration,
             matrices_from=sorted(self._calibrations))
        return _select_action(self, batch, *args, **kwargs)

    def get_action(self, obs_frame):
        action = _get_action(self, obs_frame)
        if action is not None:
            _log(event="policy_action", action=action.tolist())
        return action

    def send_action(self, action):
        applied = _send_action(self, action)
        _log(event="send_action", action={k: float(v) for k, v in action.items()}, step=self.steps,
             tcp=self._env.unwrapped.tcp_pose()[0].tolist())
        return applied

    OmniDPolicy.select_action = select_action
    SyncInferenceEngine.get_action = get_action
    OmniDSim.send_action = send_action
'''


@pytest.fixture
def real_robot_path(tmp_path) -> tuple[Path, subprocess.CompletedProcess]:
    out = tmp_path / "out"
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(textwrap.dedent(TRACE_SITECUSTOMIZE))
    trace = tmp_path / "trace.jsonl"
    env = dict(os.environ)
    env.update(
        OUT=str(out), EPISODES="2", IMAGE_SIZE="32", STEPS="4", BATCH_SIZE="2", NUM_WORKERS="0",
        SIM_EPISODE_TIME_S="2", ROLLOUT_TIME_S="3", MUJOCO_GL=env.get("MUJOCO_GL", "egl"),
        OMNID_TRACE_FILE=str(trace), PYTHONPATH=f"{site}{os.pathsep}{env.get('PYTHONPATH', '')}",
        HF_LEROBOT_HOME=str(tmp_path / "hf_lerobot"),
        PATH=f"{Path(sys.executable).parent}{os.pathsep}{env['PATH']}",
    )  # fmt: skip
    return tmp_path, subprocess.run(
        ["bash", str(ROOT / "examples" / "09_real_robot_path.sh")],
        capture_output=True,
        text=True,
        env=env,
        timeout=1200,
    )


@pytest.mark.slow
def test_real_robot_path_record_attach_train_rollout(real_robot_path):
    tmp_path, result = real_robot_path
    out, trace = tmp_path / "out", tmp_path / "trace.jsonl"
    log = result.stdout + result.stderr
    assert result.returncode == 0, f"{result.stdout[-3000:]}\n{result.stderr[-5000:]}"

    # lerobot-record wrote the robot's features under its camera names; attach added the calibration.
    cams = ["front", "left", "right", "back_left"]
    keys = [f"observation.images.{c}" for c in cams]
    info = json.loads((out / "data" / "sim_select_apple" / "meta" / "info.json").read_text())
    assert info["robot_type"] == "omnid_sim" and info["fps"] == 10 and info["total_episodes"] == 2
    assert info["features"]["observation.state"]["names"] == list(STATE_KEYS)
    assert info["features"]["action"]["names"] == list(ACTION_KEYS)
    rig = {k: c.to_dict() for k, c in load_calibration_file(out / "sim_rig.yaml").items()}
    assert list(rig) == keys
    for key in keys:
        assert info["features"][key]["shape"][:2] == [32, 32]
        assert info["features"][key]["info"]["calibration"] == rig[key]
    checkpoint = out / "train_sim" / "checkpoints" / "last" / "pretrained_model"
    assert json.loads((checkpoint / "config.json").read_text())["camera_calibration"] == rig

    # lerobot-rollout: the policy saw every camera, with its calibration, at every call ...
    records = [json.loads(line) for line in trace.read_text().splitlines()]
    calls = [r for r in records if r["event"] == "select_action"]
    assert calls, f"the policy was never called:\n{log[-3000:]}"
    for call in calls:
        assert call["images"] == {k: [1, 3, 32, 32] for k in keys}
        assert call["calibration"] == rig and call["matrices_from"] == sorted(keys)
    # ... and each of its actions reached the sim robot, in the robot's action keys.
    produced = [r["action"] for r in records if r["event"] == "policy_action"]
    sent = [r for r in records if r["event"] == "send_action"]
    assert len(produced) == len(sent) == len(calls)
    for action, received in zip(produced, sent, strict=True):
        assert list(received["action"]) == list(ACTION_KEYS)
        np.testing.assert_allclose(list(received["action"].values()), action, rtol=1e-6, atol=1e-6)
    assert [r["step"] for r in sent] == list(range(1, len(sent) + 1))
    assert f"omnid_sim disconnected after {len(sent)} actions" in log
