"""The import graph of `bagtools/` has no upward or sideways arrows (docs/architecture.md, #41)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "bagtools"

#: The packages (or modules) of bagtools/commands/: each is a unit of its own, and no command imports another.
COMMANDS = ("info", "grid", "map_cloud", "ndt_odom", "slam", "localize", "export")
#: Bottom up; a package imports only from lower layers (and itself). Keep in step with docs/architecture.md.
LAYERS: list[set[str]] = [
    {"errors"},
    {"limits", "progress", "outputs", "figures", "stamps"},
    {"io", "transforms"},
    {"tf", "simtruth", "results"},
    {"dataset"},
    {"trajectory", "scan_matching", "cloud"},
    {"grid"},
    {"odometry"},
    {"pose_graph"},
    {"commands", *(f"commands.{name}" for name in COMMANDS)},
    {"batch"},
    {"cli"},
    {"__main__"},
]
LAYER_OF = {name: i for i, names in enumerate(LAYERS) for name in names}
LAYER_OF[""] = -1  # bagtools/__init__.py: its __version__, and it imports nothing


def _unit(parts: list[str] | tuple[str, ...]) -> str:
    """The unit a module (its dotted name under bagtools, as parts) belongs to: its top-level package, or
    ``commands.NAME`` for a command ('' for bagtools/__init__.py)."""
    if not parts or parts[0] == "__init__":
        return ""
    if parts[0] == "commands" and len(parts) > 1 and parts[1] != "__init__":
        return f"commands.{parts[1]}"
    return parts[0]


def _package(path: Path) -> str:
    """The unit under bagtools/ a file belongs to (see _unit)."""
    return _unit(path.relative_to(ROOT).with_suffix("").parts)


def _imports(path: Path) -> list[tuple[str, int]]:
    """(package, line) of every bagtools package ``path`` imports, at any depth (functions' own imports too)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        modules = []
        if isinstance(node, ast.Import):
            modules = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            modules = [node.module]
        for module in modules:
            parts = module.split(".")
            if parts[0] == "bagtools":
                found.append((_unit(parts[1:]), node.lineno))
    return found


def import_graph() -> list[tuple[str, str, str]]:
    """(importing package, imported package, 'file:line') of every arrow between two packages."""
    arrows = []
    for path in sorted(ROOT.rglob("*.py")):
        source = _package(path)
        for target, line in _imports(path):
            if target != source:
                arrows.append((source, target, f"{path.relative_to(ROOT.parent)}:{line}"))
    return arrows


def test_every_package_has_a_layer() -> None:
    packages = {_package(p) for p in ROOT.rglob("*.py")} - {""}
    assert packages - set(LAYER_OF) == set(), "place the new package in LAYERS and docs/architecture.md"


def test_no_arrow_points_up_or_sideways() -> None:
    wrong = [f"{where}: {source} (layer {LAYER_OF.get(source)}) imports {target} (layer {LAYER_OF.get(target)})"
             for source, target, where in import_graph()
             if LAYER_OF.get(target, 99) >= LAYER_OF.get(source, -1)]
    assert wrong == []


def test_the_check_sees_an_arrow_between_commands(tmp_path: Path) -> None:
    # the reader must find a function's own import: the way commands used to reach into each other
    probe = tmp_path / "probe.py"
    probe.write_text("def f():\n    from bagtools.commands.slam.pipeline import SlamOptions\n", encoding="utf-8")
    assert _imports(probe) == [("commands.slam", 2)]


def test_the_layers_are_the_documented_ones() -> None:
    text = (ROOT.parent / "docs" / "architecture.md").read_text(encoding="utf-8")
    for i, names in enumerate(LAYERS):
        row = next(line for line in text.splitlines() if line.startswith(f"| {i} "))
        assert names <= {w.strip("`,") for w in row.split()}, row


#: A module longer than this holds more than one idea: split it where the ideas part (issue #41).
MAX_MODULE_LINES = 500


def test_no_module_is_over_500_lines() -> None:
    long = {str(p.relative_to(ROOT.parent)): n for p in sorted(ROOT.rglob("*.py"))
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES}
    assert long == {}
