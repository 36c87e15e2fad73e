"""Settings shared by every test, and the guard that keeps subprocesses in ``tests/e2e``; helpers in
``omnid_testing.py`` and ``calibration_testing.py``.

The tests that start a subprocess (a console command, an example script, ``python -c``) live in
``tests/e2e``, whose conftest marks them ``e2e``; anywhere else ``subprocess.Popen`` raises, so that
``make test-fast`` (``-m "not e2e"``) starts none and a new test that starts one fails until it moves.
"""

import os
import subprocess

# One torch (OpenMP) thread, here, in every pytest-xdist worker (each imports this file) and in every
# command the tests start: their models are tiny, and on a shared 2-core machine a second thread mostly
# waits for a core (a tiny OmniD's select_action: 0.1 s with one thread, 0.9 s with two on a busy
# machine). Set OMP_NUM_THREADS to choose otherwise.
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MUJOCO_GL", "egl")

import matplotlib.font_manager  # noqa: F401  builds its font cache (with fc-list) now, not inside a test
import pytest
import torch

torch.set_num_threads(int(os.environ["OMP_NUM_THREADS"]))


class SubprocessOutsideE2E(RuntimeError):
    """A test outside ``tests/e2e`` started a subprocess."""


class _RefusedPopen(subprocess.Popen):
    """``subprocess.Popen`` (and so ``run``, ``check_output``) outside ``tests/e2e``: raises, naming the
    command. A subclass, so that ``isinstance`` checks and subclasses of ``Popen`` keep working."""

    def __init__(self, args, *unused, **unused_kwargs) -> None:
        raise SubprocessOutsideE2E(f"this test starts a subprocess: move it to tests/e2e (command: {args!r})")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The slow tests first, then the other e2e tests, then the rest (each kept in its order): with
    ``--dist loadgroup --no-loadscope-reorder`` pytest-xdist hands the work out in this order, so the long
    end-to-end runs start at once and the short in-process tests fill the workers up at the end."""
    items.sort(key=lambda item: (not item.get_closest_marker("slow"), not item.get_closest_marker("e2e")))


@pytest.hookimpl(tryfirst=True)  # before its fixtures start the group's commands
def pytest_runtest_setup(item: pytest.Item) -> None:
    """Under pytest-xdist's ``--dist=loadgroup``, fail a test of an ``xdist_group`` whose id lacks its group:
    xdist keeps a group on one worker through that suffix, which pytest 9.2 drops, so the group would
    silently spread over the workers and each would run its commands again."""
    grouped = item.get_closest_marker("xdist_group") is not None
    if grouped and getattr(item.config.option, "loadgroup", False) and "@" not in item.nodeid:
        pytest.fail(
            "pytest-xdist did not keep this test's xdist_group on one worker: this pytest and pytest-xdist "
            "do not work together with --dist=loadgroup; install the versions pyproject.toml asks for",
            pytrace=False,
        )


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    """Refuse subprocesses through a non-e2e test's whole protocol: its fixtures' setup and teardown too,
    module-scoped ones included (an autouse fixture would start after those)."""
    if item.get_closest_marker("e2e"):
        return (yield)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(subprocess, "Popen", _RefusedPopen)
        return (yield)


@pytest.fixture(autouse=True)
def _seed() -> None:
    torch.manual_seed(0)
