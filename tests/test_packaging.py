"""What the wheel installs: every package of the tree, the simulator under a name of ours, the license."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _pyproject() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text())


def test_every_package_of_the_tree_is_installed_and_the_simulator_as_bagtools_simulate() -> None:
    setuptools = _pyproject()["tool"]["setuptools"]
    assert setuptools["package-dir"] == {"bagtools_simulate": "simulate"}
    found = set()
    for init in REPO.glob("bagtools/**/__init__.py"):
        found.add(".".join(init.parent.relative_to(REPO).parts))
    for init in REPO.glob("simulate/**/__init__.py"):
        found.add(".".join(("bagtools_simulate", *init.parent.relative_to(REPO / "simulate").parts)))
    found.add("bagtools_simulate.data")  # the world files, a data-only package
    assert set(setuptools["packages"]) == found
    assert _pyproject()["tool"]["setuptools"]["package-data"]["bagtools_simulate.data"] == ["*.json"]
    assert not any(name == "simulate" or name.startswith("simulate.") for name in setuptools["packages"])


def test_no_code_imports_the_generic_name() -> None:
    pattern = re.compile(r"^\s*(from simulate[. ]|import simulate\b)", re.MULTILINE)
    offenders = [str(p.relative_to(REPO)) for folder in ("bagtools", "simulate", "tests", "bench", "fixtures", "docs")
                 for p in (REPO / folder).rglob("*.py") if pattern.search(p.read_text())]
    assert offenders == []


def test_the_license_ships_and_the_metadata_says_which() -> None:
    project = _pyproject()["project"]
    assert project["license"] == "Apache-2.0" and project["license-files"] == ["LICENSE"]
    assert (REPO / "LICENSE").read_text().lstrip().startswith("Apache License")
    assert project["requires-python"] == ">=3.11" and project["classifiers"]


def test_the_source_distribution_carries_the_whole_test_tree() -> None:
    """The sdist held the 4 top-level test files only: MANIFEST.in grafts the tests, the fixtures they read, the
    docs they check and the bench, so the sdist runs its tests as the repository does."""
    root = Path(__file__).resolve().parents[1]
    lines = {line.strip() for line in (root / "MANIFEST.in").read_text().splitlines()}
    assert {"graft tests", "graft fixtures", "graft docs", "graft bench"} <= lines
    assert any(p.is_dir() and (p / "__init__.py").exists() for p in (root / "tests").iterdir())  # subfolders exist
