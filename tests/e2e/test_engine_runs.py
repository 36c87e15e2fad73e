"""The experiment engine: fingerprints, stamps, resume, failures; with tiny Python commands as the tools."""

import json
import shutil
import sys

import pytest
from omnid_testing import evaluation

from lerobot_omnid.measure.engine import Run, execute, is_done, plan, state


def test_runs_once_then_reuses_and_reruns_what_changed(tmp_path):
    out = tmp_path / "campaign"
    runs = plan([evaluation(out, "a"), evaluation(out, "b", needs=["a"])], out)
    status, _ = execute(runs, out, commit="abc")
    assert status == {"a": "ran", "b": "ran"} and all(is_done(r) for r in runs)
    stamp = json.loads((out / "stamps" / "b.json").read_text())
    assert stamp["commit"] == "abc" and stamp["fingerprint"] == runs[1].fingerprint
    assert execute(runs, out)[0] == {"a": "reused", "b": "reused"}
    # Another command for a: a reruns, and b below it, though b's own command is the same.
    changed = plan([evaluation(out, "a", rate="100"), evaluation(out, "b", needs=["a"])], out)
    assert changed[1].cmd == runs[1].cmd and state(changed[1]) == "stale"
    assert execute(changed, out)[0] == {"a": "ran", "b": "ran"}


def test_a_file_read_from_outside_the_plan_is_part_of_the_fingerprint(tmp_path):
    out, weights = tmp_path / "campaign", tmp_path / "model.safetensors"
    weights.write_bytes(b"first")
    runs = plan([evaluation(out, "a", inputs=[weights])], out)
    execute(runs, out)
    assert is_done(plan([evaluation(out, "a", inputs=[weights])], out)[0])
    weights.write_bytes(b"retrained")
    assert state(plan([evaluation(out, "a", inputs=[weights])], out)[0]) == "stale"


def test_a_copied_campaign_folder_resumes(tmp_path):
    out = tmp_path / "campaign"
    execute(plan([evaluation(out, "a")], out), out)
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    assert is_done(plan([evaluation(copy, "a")], copy)[0])


def test_stale_and_unfinished_outputs_are_removed_before_the_rerun(tmp_path):
    out = tmp_path / "campaign"
    (out / "a").mkdir(parents=True)
    (out / "a" / "left_over.txt").write_text("by an interrupted run")
    runs = plan([evaluation(out, "a")], out)
    assert state(runs[0]) == "to run"
    execute(runs, out)
    assert not (out / "a" / "left_over.txt").exists() and is_done(runs[0])


def test_a_failure_blocks_what_needs_it_or_stops_naming_its_log(tmp_path, capsys):
    out = tmp_path / "campaign"
    failing = Run("a", "eval", (sys.executable, "-c", "raise SystemExit(3)"), out / "a")
    runs = plan([failing, evaluation(out, "b", needs=["a"]), evaluation(out, "c")], out)
    assert execute(runs, out)[0] == {"a": "failed", "b": "blocked", "c": "ran"}
    assert "b: skipped, it needs a" in capsys.readouterr().out
    with pytest.raises(SystemExit, match=r"a: FAILED \(exit code 3, output incomplete\); log: .*a\.log"):
        execute(runs, out, stop_on_failure=True)
