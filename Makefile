# Set-up and the two README commands: `make demo` (the main job) and `make test` (the test suite).
PYTHON ?= python3.12
VENV ?= .venv
BIN := $(VENV)/bin
export MUJOCO_GL ?= egl

.PHONY: install system-deps test test-fast demo lint

# FFmpeg's shared libraries let LeRobot decode videos with torchcodec; without them LeRobot prints a
# long traceback and falls back to PyAV. Installed with apt-get when we are root (a failure, e.g. offline,
# only warns), otherwise explained.
system-deps:
	@if ldconfig -p 2>/dev/null | grep -q libavcodec; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "Installing FFmpeg libraries (apt-get install ffmpeg)"; \
		(apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends ffmpeg >/dev/null) \
			|| echo "apt-get install ffmpeg failed: LeRobot will fall back to PyAV for video decoding."; \
	else \
		echo "FFmpeg libraries not found and not root: run 'sudo apt-get install ffmpeg' for torchcodec (PyAV works without)."; \
	fi

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q -U pip
	$(BIN)/python -m pip install -q -e ".[dev]"
	touch $@

install: system-deps $(VENV)/.installed

# pytest-xdist workers, one per core: on 2 cores -n 2 took 362 s for `make test`, -n 3 475 s (the workers
# then compete for the cores). Their grouping and the order of the work: pyproject.toml, tests/conftest.py.
TEST_WORKERS ?= 2

# The whole suite, tests/e2e (console commands, example scripts) and the slow tests included; what CI runs.
# Measured on a fresh 2-core machine: 692 s for 941 tests at 5f64d0f (845 tests: 427 s at f2fcddd).
test: install
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS)

# Without tests/e2e: no subprocess at all (tests/conftest.py refuses one anywhere else). Measured: 112 s.
test-fast: install
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) -m "not e2e"

lint: install
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# The main job; e.g. `make demo DEMO_ARGS="--profile gpu --device cuda"` on a GPU machine.
demo: install
	$(BIN)/omnid-demo $(DEMO_ARGS)
