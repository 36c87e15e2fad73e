"""Every protocol plans the same command lines on the experiment engine as before it.

``fixtures/planned_commands_2dae655.json`` holds the commands each protocol planned at commit 2dae655,
before the engine: the benchmark's ``mini``, ``mini-fewshot`` and ``gpu8`` profiles, a tiny one and two
training seeds, the robustness sweep (default and tiny), the main job (its profile and a tiny one), the
readout selection (validation and test) and rigs-and-wrist (with and without a given checkpoint). Paths
are written as ``<out>``, ``<bin>``, ``<python>`` and ``<tmp>``. The one intended change since: the
recordings of protocols that perturb or replace a static calibration say ``--static-calibration``, now
that the recorder's default is per-frame calibration.
"""

import contextlib
import io
import json
import shlex
import sys
from pathlib import Path

import pytest
from omnid_testing import checkpoint_dir

import lerobot_omnid.benchmark.benchmark as bench
from lerobot_omnid.benchmark import demo, readout_selection, rigs_and_wrist, robustness
from lerobot_omnid.env_config import OmniDEnvConfig

BEFORE = json.loads((Path(__file__).parents[1] / "fixtures" / "planned_commands_2dae655.json").read_text())
TINY = "--episodes 1 --steps 2 --batch-size 2 --image-size 64 --num-workers 0 --eval-episodes 1"
TINY += " --episode-length 10"
BENCHMARK = {
    "benchmark_mini": [],
    "benchmark_mini_fewshot": ["--profile", "mini-fewshot"],
    "benchmark_gpu8": ["--profile", "gpu8"],
    "benchmark_tiny": [*TINY.split(), "--settings", "id", "--heldout-episodes", "1"],
    "benchmark_two_seeds": ["--train-seeds", "1000,1001", "--eval-episodes", "30", "--heldout-episodes", "0"],
}
DEMO = {"demo_cpu": [], "demo_tiny": ["--episodes", "2", "--steps", "2", "--eval-episodes", "1"]}
DEMO["demo_tiny"] += ["--episode-length", "10"]


def planned(main, argv: list[str], tmp: Path, out: Path) -> list[list[str]]:
    """The commands ``main(argv + --dry-run)`` prints, with the fixture's path placeholders."""
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        main([*argv, "--dry-run"])
    lines = text.getvalue().splitlines()
    commands = [shlex.split(lines[i + 1]) for i, line in enumerate(lines[:-1]) if line.startswith("[")]
    bin_dir = str(Path(sys.executable).parent)

    def placeholders(arg: str) -> str:
        arg = arg.replace(sys.executable, "<python>").replace(str(out), "<out>").replace(bin_dir, "<bin>")
        return arg.replace(str(tmp), "<tmp>")

    return [[placeholders(a) for a in cmd] for cmd in commands]


def with_static_recordings(commands: list[list[str]]) -> list[list[str]]:
    """The fixture's commands with the one intended change: static-calibration protocols say so."""
    return [
        [*cmd, "--static-calibration"]
        if cmd[0].endswith("omnid-record") and "--per-frame-calibration" not in cmd
        else cmd
        for cmd in commands
    ]


@pytest.mark.parametrize("variant", sorted(BENCHMARK))
def test_benchmark_plans_the_same_commands(variant, tmp_path, monkeypatch):
    monkeypatch.setattr(bench, "code_commit", lambda: "abc123")  # git runs in a subprocess
    out = tmp_path / "out"
    assert planned(bench.main, ["--out", str(out), *BENCHMARK[variant]], tmp_path, out) == (
        with_static_recordings(BEFORE[variant])
    )


@pytest.mark.parametrize("variant", sorted(DEMO))
def test_main_job_plans_the_same_commands(variant, tmp_path):
    out = tmp_path / "out"
    assert planned(demo.main, ["--out", str(out), *DEMO[variant]], tmp_path, out) == (
        with_static_recordings(BEFORE[variant])
    )


def test_robustness_plans_the_same_commands(tmp_path):
    calibrations = OmniDEnvConfig(image_size=64).camera_calibrations()
    omnid = checkpoint_dir(tmp_path / "ckpts" / "omnid", "omnid", calibrations)
    dp = checkpoint_dir(tmp_path / "ckpts" / "dp", "diffusion", calibrations)
    out = tmp_path / "out"
    default = ["--out", str(out), "--checkpoint", f"omnid={omnid}", "--checkpoint", f"dp={dp}"]
    assert planned(robustness.main, default, tmp_path, out) == BEFORE["robustness_default"]
    tiny = ["--out", str(out), "--checkpoint", f"omnid={omnid}", "--levels", "0,1", "--draws", "1"]
    tiny += ["--eval-episodes", "2", "--dead-cameras", "cam_b"]
    assert planned(robustness.main, tiny, tmp_path, out) == BEFORE["robustness_tiny"]


def test_readout_selection_plans_the_same_commands(tmp_path):
    out = tmp_path / "out"
    validation = planned(readout_selection.main, ["--out", str(out)], tmp_path, out)
    assert validation == with_static_recordings(BEFORE["readout_validation"])
    out.mkdir()
    (out / readout_selection.SELECTION_FILE).write_text(json.dumps({"selected": "keypoints"}))
    both = planned(readout_selection.main, ["--out", str(out), "--test"], tmp_path, out)
    assert [cmd for cmd in both if cmd not in validation] == BEFORE["readout_test"]


def test_rigs_and_wrist_plans_the_same_commands(tmp_path):
    out = tmp_path / "out"
    assert planned(rigs_and_wrist.main, ["--out", str(out)], tmp_path, out) == BEFORE["rigs_and_wrist"]
    calibrations = OmniDEnvConfig(image_size=64).camera_calibrations()
    given = checkpoint_dir(tmp_path / "ckpts" / "omnid", "omnid", calibrations)
    argv = ["--out", str(out), "--one-rig-checkpoint", str(given)]
    assert planned(rigs_and_wrist.main, argv, tmp_path, out) == BEFORE["rigs_and_wrist_given"]
