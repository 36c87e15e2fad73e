"""Fixtures shared by the tests; helpers in ``omnid_testing.py``, background jobs in ``omnid_jobs.py``."""

import os

# One torch (OpenMP) thread, here and in every command the tests start: their models are tiny, and on a
# shared 2-core machine a second thread mostly waits for a core (a tiny OmniD's select_action: 0.1 s with
# one thread, 0.9 s with two on a busy machine). Set OMP_NUM_THREADS to choose otherwise.
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MUJOCO_GL", "egl")

import pytest
import torch
from omnid_jobs import JobRunner

torch.set_num_threads(int(os.environ["OMP_NUM_THREADS"]))


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "jobs(*names): the test reads these background jobs (tests/omnid_jobs.py)"
    )


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Tests that read background jobs run last, in their order: their jobs run meanwhile."""
    items.sort(key=lambda item: item.get_closest_marker("jobs") is not None)  # stable


@pytest.fixture(scope="session", autouse=True)
def jobs(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):
    """The session's :class:`omnid_jobs.JobRunner`; starts the jobs of the selected tests."""
    runner = JobRunner(lambda name: tmp_path_factory.mktemp(name))
    runner.start_early(
        [name for item in request.session.items for mark in item.iter_markers("jobs") for name in mark.args]
    )
    yield runner
    runner.close()
    request.config.stash[_TIMINGS] = runner.timings()


_TIMINGS = pytest.StashKey[dict]()


def pytest_terminal_summary(terminalreporter, config: pytest.Config) -> None:
    timings = config.stash.get(_TIMINGS, {})
    if timings:
        terminalreporter.section("background jobs (wall s / of which its commands ran s)")
        for name, (wall, busy) in sorted(timings.items(), key=lambda kv: -kv[1][0]):
            terminalreporter.write_line(f"{wall:7.1f} {busy:7.1f}  {name}")


@pytest.fixture(autouse=True)
def _seed() -> None:
    torch.manual_seed(0)
