"""The small hostile-input corpus over every relevant command (see tests/robustness/corpus.py).

Each test runs one command line in a forked child (tests/robustness/runner.py)
and asserts the promise: bad input gives one line ``bagtools: <file>: <problem>``
and exit status 2 (or, for plausible-but-wrong input, a ``bagtools: warning:``),
valid input exit 0; never a traceback, a kill or a timeout; and a failed run
leaves every byte of its ``--out`` directory as it was (a successful ``--force``
run replaces only the command's own outputs).

The full corpus (several hundred inputs) runs with ``python -m tests.robustness.hostile --full``.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from tests.robustness.corpus import build_corpus
from tests.robustness.runner import judge, preload, run_case

TIMEOUT_S = 60.0
MEM_LIMIT = 2 << 30  # beyond the warm parent's address space

# Built at collection: the parametrization needs the cases. The directory lives as long as the session.
_CORPUS_DIR = tempfile.TemporaryDirectory(prefix="bagtools-corpus-")
CASES = build_corpus(Path(_CORPUS_DIR.name), "small")
PARAMS = [pytest.param(case, run, id=f"{case.name}::{run.command}") for case in CASES for run in case.runs]


@pytest.fixture(scope="module", autouse=True)
def _warm_parent():
    """Import bagtools and Open3D once in this process; every run forks from it."""
    preload()


@pytest.mark.parametrize(("case", "run"), PARAMS)
def test_hostile_input(case, run) -> None:
    if case.skip:
        pytest.skip(case.skip)
    run.prepare()
    outcome = run_case(run.argv, run.watch, TIMEOUT_S, MEM_LIMIT, own=run.own, names=run.names)
    failures = judge(outcome, run.expect)
    if failures:
        lines = [f"bagtools {' '.join(run.argv)}", f"expected: {run.expect} ({case.group}; {case.note or case.name})",
                 f"got: {outcome.describe()}"]
        lines += [f"FAILED {f.kind}: {f.detail}" for f in failures]
        if outcome.traceback:
            lines.append("stderr (tail):\n" + "\n".join(outcome.stderr.strip().splitlines()[-12:]))
        pytest.fail("\n".join(lines), pytrace=False)


def test_corpus_covers_every_command() -> None:
    """The small corpus meets every command, and each expectation kind, at least once."""
    commands = {run.argv[0] if run.argv[0] != "tf" else f"tf {run.argv[1]}" for case in CASES for run in case.runs}
    assert {"info", "tf frames", "tf echo", "tf point", "map-cloud", "ndt-odom", "grid", "simulate"} <= commands
    assert {run.expect for case in CASES for run in case.runs} == {"error", "warn_or_error", "ok", "any"}
