"""Every command starts at once (#44): the CLI and what `bagtools info` needs import no heavy library; each is
imported where it is first needed (scipy, matplotlib, gtsam, dask, pyarrow, Open3D)."""

from __future__ import annotations

import subprocess
import sys

HEAVY = ("scipy", "matplotlib", "gtsam", "dask", "distributed", "pyarrow", "open3d")


def _imported_after(code: str) -> list[str]:
    probe = f"import sys\n{code}\nprint(' '.join(h for h in {HEAVY!r} if h in sys.modules))"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.split()


def test_the_cli_and_every_command_module_import_nothing_heavy() -> None:
    code = ("import importlib, pkgutil, bagtools.cli as cli\n"
            "for m in pkgutil.iter_modules(cli.__path__): importlib.import_module('bagtools.cli.' + m.name)")
    assert _imported_after(code) == []


def test_info_imports_nothing_heavy() -> None:
    assert _imported_after("import bagtools.baginfo") == []
