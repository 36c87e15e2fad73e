"""The package's wings: no import runs upward (no cycle between wings), the layout in the README matches the
code, and the modules of the console commands are named after them."""

import ast
import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).parents[1]
PACKAGE = ROOT / "lerobot_omnid"
WINGS = ("policy", "calibration", "measure", "benchmark", "diagnostics", "viz")


def unit_of(module: str) -> str:
    """``lerobot_omnid.policy.backbone`` -> ``policy``; a top-level module is its own unit."""
    return module.split(".")[1]


def imports_between_units() -> dict[str, set[str]]:
    """Every unit (wing or top-level module) -> the units its modules import, at any depth in the file."""
    graph: dict[str, set[str]] = {}
    for path in PACKAGE.rglob("*.py"):
        module = ".".join(path.relative_to(ROOT).with_suffix("").parts)
        if module == "lerobot_omnid.__init__":
            continue  # the package's registration imports, by design
        unit = unit_of(module)
        targets = graph.setdefault(unit, set())
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            for name in names:
                parts = name.split(".")
                internal = parts[0] == "lerobot_omnid" and len(parts) > 1 and parts[1] != unit
                if internal and ((PACKAGE / parts[1]).is_dir() or (PACKAGE / f"{parts[1]}.py").exists()):
                    targets.add(parts[1])
    return graph


def test_no_import_cycle_between_wings():
    graph = imports_between_units()
    assert set(WINGS) <= set(graph)

    def reaches(start: str, goal: str, seen: set[str]) -> bool:
        for nxt in graph.get(start, ()):
            if nxt == goal or (nxt not in seen and reaches(nxt, goal, seen | {nxt})):
                return True
        return False

    cycles = sorted(unit for unit in graph if reaches(unit, unit, {unit}))
    assert not cycles, f"import cycles through {cycles}: { ({u: sorted(graph[u]) for u in cycles}) }"


def test_shared_modules_import_no_wing_that_imports_them():
    graph = imports_between_units()
    # The policy's geometry and the names everything uses sit below every wing.
    for shared in ("geometry", "cli", "keys"):
        assert not graph[shared] - {"cli", "keys"}, f"{shared} imports {graph[shared]}"
    assert "policy" not in graph["calibration"]


def test_console_commands_live_in_modules_named_after_them():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    for command, target in scripts.items():
        module = target.split(":")[0]
        assert module.rsplit(".", 1)[-1] == command.removeprefix("omnid-").replace("-", "_"), command


def test_readme_layout_lists_every_module():
    readme = (ROOT / "README.md").read_text()
    layout = readme.split("## Layout", 1)[1]
    listed = set(re.findall(r"\b(\w+\.py)\b", layout))
    modules = {p.name for p in PACKAGE.rglob("*.py") if p.name != "__init__.py"}
    assert modules <= listed, f"missing from the README's layout: {sorted(modules - listed)}"
    for wing in WINGS:
        assert f"{wing}/" in layout
