"""Every command starts at once (#44): the CLI and what `bagtools info` needs import no heavy library; each is
imported where it is first needed (scipy, matplotlib, gtsam, dask, pyarrow, Open3D)."""

from __future__ import annotations

import os
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
    assert _imported_after("import bagtools.commands.info") == []


def _cli_env(user_setting: str | None) -> str:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if user_setting is not None:
        env["OPENBLAS_NUM_THREADS"] = user_setting
    probe = ("import sys, os, bagtools.cli\n"
             "assert 'numpy' not in sys.modules, 'numpy loaded before the CLI set its threads'\n"
             "print(os.environ.get('OPENBLAS_NUM_THREADS'))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, env=env)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_the_cli_runs_blas_on_one_thread_unless_the_user_says_otherwise() -> None:
    # OpenBLAS spreading small products over the cores cost slam 60 % more CPU for the same wall time (#44)
    assert _cli_env(None) == "1"
    assert _cli_env("2") == "2"
