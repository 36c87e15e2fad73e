"""Every test in this folder starts subprocesses (console commands, the example scripts, ``python -c``): each
is marked ``e2e``, which ``make test-fast`` deselects and which lets it start them (tests/conftest.py).

Tests that share a command's output read it from a module-scoped fixture, and their module is grouped onto
one pytest-xdist worker (``xdist_group``, with ``--dist loadgroup``) so that the command runs once."""

from pathlib import Path

import pytest

E2E = Path(__file__).parent


@pytest.hookimpl(tryfirst=True)  # before ``-m`` deselects by marker
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if item.path.is_relative_to(E2E):
            item.add_marker(pytest.mark.e2e)
