"""The experiment engine's checks of a plan, and when a run counts as done: made by the planned command,
below the planned inputs. (Running plans with tiny Python commands as the tools:
tests/e2e/test_engine_runs.py.)"""

import dataclasses

import pytest
from omnid_testing import by_name, evaluation

from lerobot_omnid.benchmark.plan import PROFILES, TASK0, build_plan
from lerobot_omnid.measure import engine
from lerobot_omnid.measure.engine import CHECKPOINT, Run, is_done, plan


def test_a_plan_is_checked(tmp_path):
    with pytest.raises(ValueError, match="two runs are named 'a'"):
        plan([evaluation(tmp_path, "a"), evaluation(tmp_path, "a")], tmp_path)
    with pytest.raises(ValueError, match=r"b needs \['a'\], which are not planned before it"):
        plan([evaluation(tmp_path, "b", needs=["a"])], tmp_path)
    with pytest.raises(ValueError, match="kind 'bake' is not one of"):
        plan([Run("a", "bake", ("true",), tmp_path)], tmp_path)
    with pytest.raises(RuntimeError, match="not planned"):
        engine.write_stamp(evaluation(tmp_path, "a"), None, 0.0)


def test_a_run_is_done_only_when_made_by_the_planned_command(tmp_path):
    runs = build_plan(PROFILES["mini"], tmp_path, (TASK0,))
    named = by_name(runs)
    train, offline = named[f"train/omnid/{TASK0}"], named[f"offline/omnid/{TASK0}/id"]
    assert not any(is_done(r) for r in runs)
    (offline.output).mkdir(parents=True)
    (offline.output / "offline_eval.json").write_text("{}")
    assert engine.state(offline) == "stale"  # products, but no stamp: made by whom?
    engine.write_stamp(offline, "abc", 1.0)
    assert is_done(offline)
    (train.output / CHECKPOINT).mkdir(parents=True)
    engine.write_stamp(train, "abc", 1.0)
    assert engine.state(train) == "to run"  # a checkpoint folder without weights is unfinished
    (train.output / CHECKPOINT / "model.safetensors").write_bytes(b"")
    assert is_done(train)
    # The same run planned with another command, or below another dataset, is not the one stamped.
    other = by_name(build_plan(dataclasses.replace(PROFILES["mini"], steps=3), tmp_path, (TASK0,)))
    assert engine.state(other[train.name]) == "stale" and engine.state(other[offline.name]) == "stale"
    other = by_name(build_plan(dataclasses.replace(PROFILES["mini"], episodes=2), tmp_path, (TASK0,)))
    assert other[train.name].cmd == train.cmd and engine.state(other[train.name]) == "stale"
