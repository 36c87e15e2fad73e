"""Background jobs: the console commands of the slow end-to-end tests, started with the session.

Such a test spends nearly all its time in subprocesses (a LeRobot console command takes 5-10 s just to
start on 2 cores) that need nothing from the tests before them. It registers its commands as a job, a
function of a :class:`Job` that runs them with ``job.run`` and returns what the test checks::

    @job("demo")
    def _demo(job: Job) -> subprocess.CompletedProcess:
        return job.run([...], timeout=900)

    @pytest.mark.jobs("demo")
    def test_demo(jobs):
        result = jobs.result("demo")
        assert result.returncode == 0  # the same assertions on the same outputs as before

When the session starts, every job of a selected test starts in its own thread, at most ``SLOTS``
subprocesses at a time beside the in-process tests, longest first (``job(name, seconds)``); the tests
that read jobs run last (conftest.py), when most of their jobs are done. ``OMNID_TEST_JOB_SLOTS=0``
starts nothing early: each job then runs when its test asks for it, in the test's thread.
"""

from __future__ import annotations

import contextlib
import heapq
import os
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

SLOTS = int(os.environ.get("OMNID_TEST_JOB_SLOTS", "2"))
_JOBS: dict[str, tuple[Callable[[Job], Any], float]] = {}


def job(name: str, seconds: float = 0.0) -> Callable:
    """Register the decorated function as job ``name``; ``seconds``: its rough length, to start long ones
    first."""

    def register(fn: Callable[[Job], Any]) -> Callable[[Job], Any]:
        if name in _JOBS and _JOBS[name][0] is not fn:
            raise ValueError(f"two jobs named {name!r}")
        _JOBS[name] = (fn, seconds)
        return fn

    return register


class Job:
    """What a job function gets: its own folder, ``run`` for its commands, ``result`` of another job."""

    def __init__(self, runner: JobRunner, name: str, tmp: Path, rank: int) -> None:
        self.name, self.tmp, self.rank, self._runner = name, tmp, rank, runner
        self.busy = 0.0  # seconds its commands ran (waiting for a slot not counted)

    def result(self, name: str) -> Any:
        return self._runner.result(name)

    def run(
        self,
        cmd: Sequence[str],
        *,
        timeout: float,
        env: dict | None = None,
        cwd: Path | None = None,
        check: bool = False,
        text: bool = True,
    ) -> subprocess.CompletedProcess:
        """``subprocess.run(cmd, capture_output=True, ...)`` in one of the runner's slots; the process and
        what it started are killed on timeout and when the session ends."""
        with self._runner.slot(self.rank):
            start = time.monotonic()
            proc = self._runner.popen(cmd, env=env, cwd=cwd, text=text)
            try:
                stdout, stderr = proc.communicate(timeout=timeout)
            except subprocess.TimeoutExpired:
                self._runner.kill(proc)
                proc.communicate()
                raise
            finally:
                self._runner.forget(proc)
                self.busy += time.monotonic() - start
        result = subprocess.CompletedProcess(list(cmd), proc.returncode, stdout, stderr)
        if check:
            result.check_returncode()
        return result


class _Running:
    def __init__(self, rank: int) -> None:
        self.rank = rank  # start order: the lower, the sooner its commands get a slot
        self.tmp: Path | None = None
        self.done = threading.Event()
        self.value: Any = None
        self.error: BaseException | None = None
        self.seconds: float | None = None  # from its start to its end
        self.busy: float | None = None  # of which its commands ran


class JobRunner:
    """Starts, runs and collects the jobs of one session (the ``jobs`` fixture)."""

    def __init__(self, make_tmp: Callable[[str], Path], slots: int = SLOTS) -> None:
        self._make_tmp, self.slots = make_tmp, slots
        self._slots = _Slots(slots) if slots else None
        self._lock = threading.Lock()
        self._jobs: dict[str, _Running] = {}
        self._procs: set[subprocess.Popen] = set()
        self._closed = False

    # --- jobs ---
    def start_early(self, names: Sequence[str]) -> None:
        """Start these jobs now in background threads (longest first), unless slots are 0."""
        if not self.slots:
            return
        for name in sorted(dict.fromkeys(names), key=lambda n: -_JOBS[n][1]):
            self._start(name, background=True)

    def result(self, name: str) -> Any:
        """The job's return value once it is done (started now if it was not); its exception, re-raised."""
        running = self._start(name, background=bool(self.slots))
        running.done.wait()
        if running.error is not None:
            raise running.error
        return running.value

    def timings(self) -> dict[str, tuple[float, float]]:
        """(wall seconds, seconds its commands ran) of each finished job."""
        return {n: (r.seconds, r.busy) for n, r in self._jobs.items() if r.seconds is not None}

    def _start(self, name: str, background: bool) -> _Running:
        if name not in _JOBS:
            raise KeyError(f"no job {name!r} (registered: {sorted(_JOBS)})")
        with self._lock:
            if name in self._jobs:
                return self._jobs[name]
            running = self._jobs[name] = _Running(rank=len(self._jobs))
            running.tmp = self._make_tmp(name)  # here, not in the job's thread
        if background:
            threading.Thread(target=self._run, args=(name, running), name=f"job-{name}", daemon=True).start()
        else:
            self._run(name, running)
        return running

    def _run(self, name: str, running: _Running) -> None:
        start = time.monotonic()
        job = Job(self, name, running.tmp, running.rank)
        try:
            running.value = _JOBS[name][0](job)
        except BaseException as error:  # handed to the test that reads the job
            running.error = error
        finally:
            running.seconds, running.busy = time.monotonic() - start, job.busy
            running.done.set()

    # --- processes ---
    def slot(self, rank: int):
        if self._closed:
            raise RuntimeError("the test session has ended")
        return self._slots.take(rank) if self._slots is not None else contextlib.nullcontext()

    def popen(self, cmd: Sequence[str], env: dict | None, cwd: Path | None, text: bool) -> subprocess.Popen:
        with self._lock:
            if self._closed:
                raise RuntimeError("the test session has ended")
            proc = subprocess.Popen(
                list(cmd),
                env=env,
                cwd=cwd,
                text=text,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
            )  # in the session's process group, as subprocess.run's: a Ctrl-C reaches it
            self._procs.add(proc)
        return proc

    def forget(self, proc: subprocess.Popen) -> None:
        with self._lock:
            self._procs.discard(proc)

    @staticmethod
    def kill(proc: subprocess.Popen) -> None:
        """Kill the process and what it started (omnid-benchmark's lerobot-eval, accelerate's workers)."""
        for pid in [*_descendants(proc.pid), proc.pid]:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)

    def close(self) -> None:
        """Kill what still runs (a test failed or the session was interrupted) and wait for the threads."""
        with self._lock:
            self._closed = True
            procs = list(self._procs)
        for proc in procs:
            self.kill(proc)
        for running in self._jobs.values():
            running.done.wait(timeout=30)


def _descendants(pid: int) -> list[int]:
    """Process ids below ``pid`` (Linux /proc; none elsewhere)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc") if os.path.isdir("/proc") else ():
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry))
    found, todo = [], [pid]
    while todo:
        below = children.get(todo.pop(), [])
        found += below
        todo += below
    return found


class _Slots:
    """``n`` slots for subprocesses; a free one goes to the waiting job that started first."""

    def __init__(self, n: int) -> None:
        self._free, self._waiting, self._cond = n, [], threading.Condition()

    @contextlib.contextmanager
    def take(self, rank: int):
        with self._cond:
            heapq.heappush(self._waiting, rank)
            self._cond.wait_for(lambda: self._free > 0 and self._waiting[0] == rank)
            heapq.heappop(self._waiting)
            self._free -= 1
            self._cond.notify_all()
        try:
            yield
        finally:
            with self._cond:
                self._free += 1
                self._cond.notify_all()
