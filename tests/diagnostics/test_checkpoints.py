"""The expert frames the probes read: the frames asked for, each with its episode's grasp place."""

import numpy as np
import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_omnid.diagnostics.checkpoints import GRIPPER, POSITION, expert_frames

FRAMES_PER_EPISODE = 10


def write_episodes(root, grasps: list[tuple[int, tuple[float, float]]]) -> None:
    """One episode per ``(first closed frame, grasp x-y)``: the gripper opens, then closes at that frame with
    the TCP at that x-y; before it, the TCP wanders elsewhere."""
    features = {
        "observation.state": {"dtype": "float32", "shape": (2,), "names": ["s0", "s1"]},
        "action": {"dtype": "float32", "shape": (GRIPPER + 1,), "names": None},
        "observation.images.cam_b": {
            "dtype": "video",
            "shape": (64, 64, 3),
            "names": ["height", "width", "channels"],
        },
    }
    dataset = LeRobotDataset.create("local/expert", fps=10, features=features, root=root, use_videos=True)
    rng = np.random.default_rng(0)
    for close, xy in grasps:
        for f in range(FRAMES_PER_EPISODE):
            action = rng.uniform(-1, 1, GRIPPER + 1).astype(np.float32)
            action[GRIPPER] = 1.0 if f >= close else 0.0
            if f == close:
                action[POSITION] = (*xy, 0.1)
            image = np.full((64, 64, 3), f * 20, np.uint8)
            state = np.array([f, close], np.float32)
            dataset.add_frame(
                {"observation.images.cam_b": image, "observation.state": state, "action": action, "task": "t"}
            )
        dataset.save_episode()
    dataset.finalize()


def test_expert_frames_pairs_each_frame_with_its_episodes_grasp(tmp_path):
    write_episodes(tmp_path / "expert", [(6, (0.5, -0.2)), (8, (0.3, 0.1))])
    items, grasp = expert_frames(tmp_path / "expert", range(0, 5, 2))
    assert [int(item["observation.state"][0]) for item in items] == [0, 2, 4] * 2
    assert [int(item["episode_index"]) for item in items] == [0, 0, 0, 1, 1, 1]
    expected = torch.tensor([[0.5, -0.2]] * 3 + [[0.3, 0.1]] * 3)
    assert grasp.shape == (6, 2) and torch.allclose(grasp, expected)


def test_expert_frames_refuses_an_episode_that_grasps_within_the_frames(tmp_path):
    """A frame at or after the grasp may show the object moved: the probe's target would be wrong."""
    write_episodes(tmp_path / "expert", [(6, (0.5, -0.2)), (3, (0.3, 0.1))])
    with pytest.raises(ValueError, match="episode 1: expected the gripper to close after frame 4"):
        expert_frames(tmp_path / "expert", range(0, 5, 2))
