"""The six-task profile's one-model-for-every-task path with the real tools at tiny sizes, on two tasks:
`omnid-record --task-onehot`, `lerobot-edit-dataset` merge, `lerobot-train` of OmniD and DP on the merged
set, `lerobot-eval --env.task_onehot=true` on each task with the blind controls, and the report's section.
(Its plan: tests/benchmark/test_benchmark_plan.py.)"""

from __future__ import annotations

import json
import os

import pytest

import lerobot_omnid.benchmark.benchmark as bench
from lerobot_omnid.benchmark import plan as plan_module

TASKS = ("select_apple", "add_condiment")
TINY = "--episodes 1 --steps 2 --batch-size 2 --num-workers 0 --eval-episodes 1 --eval-seeds 1 "
TINY += "--episode-length 10 --settings id --methods omnid,diffusion"


@pytest.mark.slow
def test_one_model_for_every_task_trains_on_the_merged_set_and_is_told_the_task(tmp_path, monkeypatch):
    """``omnid-benchmark`` in this process (so that the benchmark can be made of two tasks), running the real
    tools as subprocesses."""
    monkeypatch.setattr(plan_module, "available_tasks", lambda: TASKS)
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    out = tmp_path / "bench"
    sizing = tmp_path / "sizing.json"
    sizing.write_text(json.dumps({task: 2 for task in TASKS}))
    argv = ["--profile", "six-tasks", "--out", str(out), "--task-steps", str(sizing), *TINY.split()]
    assert bench.main([*argv, "--tasks", ",".join(TASKS)]) == 0
    info = json.loads((out / "data" / "all_tasks_bcde_onehot" / "meta" / "info.json").read_text())
    assert info["total_episodes"] == 2 and info["features"]["observation.environment_state"]["shape"] == [6]
    for method in ("omnid", "diffusion"):
        model = out / "train_multitask" / method / "all_tasks" / "checkpoints" / "last" / "pretrained_model"
        config = json.loads((model / "config.json").read_text())
        assert config["input_features"]["observation.environment_state"] == {"type": "ENV", "shape": [6]}
    summary = json.loads((out / "summary.json").read_text())
    cells = {(e["model"], e["task"], e["control"]) for e in summary["evaluations"]}
    for method in ("omnid", "diffusion"):
        for task in TASKS:
            assert {(f"{method}_multitask", task, ""), (f"{method}_multitask", task, "blind")} <= cells
    assert "## One model for every task against one model per task" in (out / "report.md").read_text()
