"""Run one ``bagtools`` command line in a forked child and classify what happened.

The parent imports bagtools and its heavy dependencies once (:func:`preload`);
each run forks, so it costs the command's own work only. In the child the
address space is limited (``RLIMIT_AS``, 2 GiB beyond the warm parent's: a
decoder that believes a lying size field gets a MemoryError, reported as a
traceback, instead of the machine's OOM killer), stdout and stderr go to
temporary files, and ``bagtools.cli.main(argv)`` runs: its ``SystemExit`` code
becomes the exit status; any other exception prints its traceback and exits 99.

The parent waits with a timeout (and kills the child's process group after it),
then classifies the outcome: exit status, signal, timeout, traceback, the
one-line error format ``bagtools: <file>: <problem>``, ``bagtools: warning:``
lines, and whether the output directory changed (a snapshot of names, sizes,
SHA-256 and mtimes before and after).

If forking misbehaves, set ``BAGTOOLS_ROBUSTNESS_MODE=subprocess`` (or pass
``mode="subprocess"``): each run is then a fresh ``python -m
tests.robustness.runner --child`` process with the same limits (slower: every
run imports Open3D again).
"""

from __future__ import annotations

import hashlib
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

DEFAULT_TIMEOUT_S = 60.0
DEFAULT_MEM_LIMIT = 2 << 30  # address space a run may add to what the warm parent has mapped (see _address_limit)
TRACEBACK_EXIT = 99
REPO = Path(__file__).resolve().parents[2]

_preloaded = False


def preload() -> None:
    """Import bagtools' commands and everything they import lazily, so forked runs start warm."""
    global _preloaded
    if _preloaded:
        return
    import matplotlib

    matplotlib.use("Agg")
    import importlib

    import matplotlib.pyplot  # noqa: F401

    for name in ("open3d", "scipy.spatial", "bagtools.cli", "bagtools.cli.info", "bagtools.cli.tf",
                 "bagtools.cli.map_cloud", "bagtools.cli.ndt_odom", "bagtools.cli.grid", "bagtools.cli.simulate",
                 "bagtools.commands.info", "bagtools.commands.map_cloud", "bagtools.commands.ndt_odom", "bagtools.commands.grid", "bagtools.tf.point",
                 "bagtools.tf.echo", "bagtools.tf.tree", "bagtools.tf.dot", "bagtools_simulate.pipeline"):
        try:
            importlib.import_module(name)
        except ImportError:  # a module renamed by the library: the child imports what it needs anyway
            pass
    _preloaded = True


# ---------------------------------------------------------------------------- snapshots


Snapshot = dict[str, tuple]  # relative path -> ("f", size, sha256, mtime_ns) | ("d",) | ("l", target)


def snapshot(root: Path | None) -> Snapshot | None:
    """Every file and directory under ``root`` (None if ``root`` does not exist)."""
    if root is None or not os.path.lexists(root):
        return None
    root = Path(root)
    if root.is_symlink() or not root.is_dir():
        return {".": _entry(root)}
    out: Snapshot = {".": ("d",)}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            out[str(p.relative_to(root))] = _entry(p)
    return out


def _entry(p: Path) -> tuple:
    if p.is_symlink():
        return ("l", os.readlink(p))
    if p.is_dir():
        return ("d",)
    st = p.stat()
    try:
        digest = hashlib.sha256(p.read_bytes()).hexdigest()[:16]
    except OSError as err:
        digest = f"unreadable: {err}"
    return ("f", st.st_size, digest, st.st_mtime_ns)


def diff_snapshots(before: Snapshot | None, after: Snapshot | None, own: tuple[str, ...] = ()) -> list[str]:
    """Changes from ``before`` to ``after``, ignoring top-level names in ``own`` ('*': ignore everything)."""
    if "*" in own:
        return []
    if before is None and after is None:
        return []
    if before is None:
        return [f"created (did not exist before): {sorted(after)[:6]}"]
    if after is None:
        return ["removed entirely"]
    changes = []
    for key in sorted(set(before) | set(after)):
        top = key.split(os.sep, 1)[0]
        if top in own:
            continue
        a, b = before.get(key), after.get(key)
        if a == b:
            continue
        if a is None:
            changes.append(f"new {key}")
        elif b is None:
            changes.append(f"deleted {key}")
        elif a[0] != b[0]:
            changes.append(f"{key}: {a[0]} became {b[0]}")
        elif a[0] == "f":
            what = [n for n, i in (("size", 1), ("content", 2), ("mtime", 3)) if a[i] != b[i]]
            changes.append(f"{key}: {', '.join(what)} changed")
        else:
            changes.append(f"{key}: changed")
    return changes


# ---------------------------------------------------------------------------- outcome


@dataclass
class Outcome:
    """What one run did; see :func:`run_case`."""

    argv: list[str]
    exit_code: int | None          # None when killed by a signal or timed out
    signal: int | None
    timed_out: bool
    seconds: float
    stdout: str
    stderr: str
    out_diff: list[str] = field(default_factory=list)  # changes under out_dir beyond what was allowed
    names: tuple[str, ...] = ()

    @property
    def lines(self) -> list[str]:
        return [line for line in self.stderr.splitlines() if line.strip()]

    @property
    def warning_lines(self) -> list[str]:
        return [line for line in self.lines if line.startswith("bagtools: warning:")]

    @property
    def error_lines(self) -> list[str]:
        return [line for line in self.lines if line.startswith("bagtools: ") and not line.startswith("bagtools: warning:")]

    @property
    def other_lines(self) -> list[str]:
        return [line for line in self.lines if not line.startswith("bagtools: ")]

    @property
    def traceback(self) -> bool:
        return "Traceback (most recent call last)" in self.stderr or self.exit_code == TRACEBACK_EXIT

    @property
    def exception(self) -> str | None:
        """The exception line of a traceback (e.g. 'ValueError: ...'), if any."""
        if not self.traceback:
            return None
        # After the last traceback header come indented frames, then the exception line (its message may
        # continue over more lines, e.g. a garbage text quoted in it).
        tail = self.stderr.split("Traceback (most recent call last):")[-1].splitlines()
        for line in tail[1:]:
            if line.strip() and not line.startswith(" "):
                return line
        return "exit 99 without a traceback line" if self.exit_code == TRACEBACK_EXIT else "?"

    @property
    def memory_error(self) -> bool:
        return bool(self.exception and self.exception.startswith(("MemoryError", "numpy.core._exceptions._ArrayMemoryError",
                                                                   "numpy._core._exceptions._ArrayMemoryError"))) \
            or "std::bad_alloc" in self.stderr

    @property
    def killed(self) -> bool:
        return self.signal is not None and not self.timed_out

    @property
    def one_line_error(self) -> bool:
        """Exactly one non-warning 'bagtools: ' line and nothing else but warnings on stderr."""
        return len(self.error_lines) == 1 and not self.other_lines

    @property
    def names_path(self) -> bool:
        """The error line names one of the files (or options) at fault (any of ``names``; true if none given)."""
        if not self.error_lines:
            return False
        if not self.names:
            return True
        line = self.error_lines[0]
        return any(n and n in line for n in self.names)

    @property
    def out_changed(self) -> bool:
        return bool(self.out_diff)

    @property
    def stderr_first(self) -> str:
        return self.lines[0] if self.lines else ""

    @property
    def stderr_last(self) -> str:
        return self.lines[-1] if self.lines else ""

    def describe(self) -> str:
        status = ("timeout" if self.timed_out else f"signal {self.signal}" if self.signal is not None
                  else f"exit {self.exit_code}")
        return f"{status} in {self.seconds:.1f}s; stderr: {self.stderr_first!r}" + (
            f" ... {self.stderr_last!r}" if len(self.lines) > 1 else "")


# ---------------------------------------------------------------------------- running


def _address_limit(mem_limit_bytes: int) -> int:
    """The child's RLIMIT_AS: what this process has mapped now plus ``mem_limit_bytes``.

    Relative, not absolute, so that the budget does not depend on what the parent
    imported (Open3D alone maps over 1 GiB of address space; pytest and hypothesis
    add more): with the default, a run that tries to allocate 2 GiB more than a
    warm bagtools process fails with MemoryError, whatever ran before it.
    """
    try:
        with open("/proc/self/status") as f:
            vm = next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmSize:"))
    except (OSError, StopIteration):
        vm = 0
    return vm + mem_limit_bytes


def _child(argv: list[str], out_path: str, err_path: str, limit: int) -> None:
    """In the forked child: never returns."""
    code = 98
    try:
        os.setpgid(0, 0)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        for fd, path in ((1, out_path), (2, err_path)):
            target = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            os.dup2(target, fd)
            os.close(target)
        sys.stdin = open(0, closefd=False)
        sys.stdout = open(1, "w", closefd=False, encoding="utf-8", errors="backslashreplace")
        sys.stderr = open(2, "w", closefd=False, encoding="utf-8", errors="backslashreplace", buffering=1)
        sys.argv = ["bagtools", *argv]
        code = _call_main(argv)
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)


def _call_main(argv: list[str]) -> int:
    import traceback

    try:
        from bagtools.cli import main

        main(argv)
        return 0
    except SystemExit as exc:
        if exc.code is None:
            return 0
        if isinstance(exc.code, int):
            return exc.code
        print(exc.code, file=sys.stderr)
        return 1
    except BaseException:  # noqa: BLE001 - anything else is a bug: keep the traceback, as Python would
        traceback.print_exc()
        return TRACEBACK_EXIT


@dataclass
class Pending:
    """A started run; :meth:`poll` or :meth:`wait` for its :class:`Outcome`."""

    argv: list[str]
    out_dir: Path | None
    own: tuple[str, ...]
    names: tuple[str, ...]
    timeout_s: float
    before: Snapshot | None
    tmp: Path
    start: float
    pid: int | None = None
    proc: subprocess.Popen | None = None
    timed_out: bool = False

    def _status(self, block: bool) -> int | None:
        if self.proc is not None:
            try:
                self.proc.wait(timeout=None if block else 0)
            except subprocess.TimeoutExpired:
                return None
            return self.proc.returncode
        pid, status = os.waitpid(self.pid, 0 if block else os.WNOHANG)
        if pid == 0:
            return None
        return os.waitstatus_to_exitcode(status)

    def _kill(self) -> None:
        pid = self.proc.pid if self.proc is not None else self.pid
        try:
            os.killpg(pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass

    def poll(self) -> Outcome | None:
        code = self._status(block=False)
        if code is None:
            if time.monotonic() - self.start > self.timeout_s:
                self.timed_out = True
                self._kill()
                code = self._status(block=True)
            else:
                return None
        return self._finish(code)

    def wait(self) -> Outcome:
        while True:
            outcome = self.poll()
            if outcome is not None:
                return outcome
            time.sleep(0.01)

    def _finish(self, code: int) -> Outcome:
        seconds = time.monotonic() - self.start
        stdout = (self.tmp / "stdout").read_text(errors="backslashreplace")
        stderr = (self.tmp / "stderr").read_text(errors="backslashreplace")
        for name in ("stdout", "stderr"):
            (self.tmp / name).unlink(missing_ok=True)
        self.tmp.rmdir()
        exit_code, sig = (code, None) if code >= 0 else (None, -code)
        if self.timed_out:
            exit_code = None
        outcome = Outcome(self.argv, exit_code, sig, self.timed_out, seconds, stdout, stderr, names=self.names)
        if self.out_dir is not None:
            after = snapshot(self.out_dir)
            own = self.own if exit_code == 0 else ()
            outcome.out_diff = diff_snapshots(self.before, after, own)
        return outcome


def start_case(argv: list[str], out_dir: Path | None = None, timeout_s: float = DEFAULT_TIMEOUT_S,
               mem_limit_bytes: int = DEFAULT_MEM_LIMIT, *, own: tuple[str, ...] = (), names: tuple[str, ...] = (),
               mode: str | None = None) -> Pending:
    """Start ``bagtools argv`` in a child (fork, or ``mode='subprocess'``); see :func:`run_case`."""
    mode = mode or os.environ.get("BAGTOOLS_ROBUSTNESS_MODE", "fork")
    argv = [str(a) for a in argv]
    before = snapshot(out_dir)
    tmp = Path(tempfile.mkdtemp(prefix="bagtools-run-"))
    out_path, err_path = str(tmp / "stdout"), str(tmp / "stderr")
    limit = _address_limit(mem_limit_bytes)
    pending = Pending(argv, None if out_dir is None else Path(out_dir), tuple(own), tuple(names), timeout_s, before,
                      tmp, time.monotonic())
    if mode == "subprocess":
        with open(out_path, "wb") as out, open(err_path, "wb") as err:
            env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
            pending.proc = subprocess.Popen(
                [sys.executable, "-m", "tests.robustness.runner", "--child", str(mem_limit_bytes), "--", *argv],
                stdin=subprocess.DEVNULL, stdout=out, stderr=err, cwd=REPO, env=env, start_new_session=True)
        pending.start = time.monotonic()
        return pending
    preload()
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:
        _child(argv, out_path, err_path, limit)
    pending.pid = pid
    pending.start = time.monotonic()
    return pending


def run_case(argv: list[str], out_dir: Path | None = None, timeout_s: float = DEFAULT_TIMEOUT_S,
             mem_limit_bytes: int = DEFAULT_MEM_LIMIT, *, own: tuple[str, ...] = (), names: tuple[str, ...] = (),
             mode: str | None = None) -> Outcome:
    """Run ``bagtools.cli.main(argv)`` in a forked child and classify the outcome.

    Args:
        argv: the command line without the program name.
        out_dir: a directory (or file) whose contents are compared before and after;
            a failed run must not change it, a successful one may change only ``own``.
        timeout_s: wall-clock limit; the child's process group is killed after it.
        mem_limit_bytes: address space the child may map beyond what the parent has
            mapped at the fork (its RLIMIT_AS is the sum; see :func:`_address_limit`).
        own: top-level names under ``out_dir`` that a successful run may create or
            replace (the command's own outputs); '*' allows anything.
        names: strings of which the error line should contain one (the file at fault).
    """
    return start_case(argv, out_dir, timeout_s, mem_limit_bytes, own=own, names=names, mode=mode).wait()


def run_many(jobs: list[dict], workers: int = 1, on_done=None) -> list[Outcome]:
    """Run several :func:`start_case` keyword dicts with up to ``workers`` children at once, in order of results."""
    results: list[Outcome | None] = [None] * len(jobs)
    running: dict[int, Pending] = {}
    next_job = 0
    while next_job < len(jobs) or running:
        while next_job < len(jobs) and len(running) < max(1, workers):
            job = jobs[next_job]
            prepare = job.get("prepare")
            if prepare is not None:
                prepare()
            kwargs = {k: v for k, v in job.items() if k != "prepare"}
            running[next_job] = start_case(**kwargs)
            next_job += 1
        done = []
        for index, pending in running.items():
            outcome = pending.poll()
            if outcome is not None:
                results[index] = outcome
                done.append(index)
                if on_done is not None:
                    on_done(index, outcome)
        for index in done:
            del running[index]
        if not done:
            time.sleep(0.01)
    return [r for r in results if r is not None]


def _child_main(args: list[str]) -> None:
    """``python -m tests.robustness.runner --child MEM -- ARGV...``: the subprocess mode's child."""
    mem = int(args[1])
    argv = args[args.index("--") + 1:]
    preload()  # the same baseline as a forked child's, then the same budget beyond it
    limit = _address_limit(mem)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    sys.stdout.flush()
    code = _call_main(argv)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        _child_main(sys.argv[1:])
    print("usage: python -m tests.robustness.runner --child MEM_BYTES -- ARGV...", file=sys.stderr)
    sys.exit(2)


# ---------------------------------------------------------------------------- judging

EXPECTATIONS = ("error", "warn_or_error", "ok", "any")

#: Failure kinds, in the order reports list them.
KINDS = ("traceback", "killed", "timeout", "data-changed", "accepted-bad-input", "silent-on-bad-input",
         "refused-valid-input", "error-not-one-line", "error-names-no-file", "unexpected-exit-code")


@dataclass(frozen=True)
class Failure:
    kind: str
    detail: str


def judge(outcome: Outcome, expect: str) -> list[Failure]:
    """What is wrong with ``outcome`` for an input expected to give ``expect``.

    - ``error``: exit 2 with exactly one ``bagtools: <file>: <problem>`` line (warnings allowed before it);
    - ``warn_or_error``: exit 0 with at least one ``bagtools: warning:`` line, or an error as above;
    - ``ok``: exit 0 (warnings allowed);
    - ``any``: exit 0, or an error as above (damage that no reader can detect, or a value either way is right).

    Always: no traceback, no kill, no timeout, and ``out_diff`` empty (the runner already
    allowed the command's own outputs to change on exit 0).
    """
    if expect not in EXPECTATIONS:
        raise ValueError(f"unknown expectation {expect!r}")
    found: list[Failure] = []
    if outcome.timed_out:
        found.append(Failure("timeout", f"no exit after {outcome.seconds:.0f} s"))
    elif outcome.killed:
        found.append(Failure("killed", f"killed by signal {outcome.signal} ({signal.Signals(outcome.signal).name})"))
    elif outcome.traceback:
        found.append(Failure("traceback", outcome.exception or "?"))
    else:
        code = outcome.exit_code
        if code == 0:
            if expect == "error":
                found.append(Failure("accepted-bad-input", "exit 0, expected an error"))
            elif expect == "warn_or_error" and not outcome.warning_lines:
                found.append(Failure("silent-on-bad-input", "exit 0 without a 'bagtools: warning:' line"))
        elif code == 2:
            if expect == "ok":
                found.append(Failure("refused-valid-input", "exit 2 on a valid input"))
            elif not outcome.one_line_error:
                found.append(Failure("error-not-one-line",
                                     f"{len(outcome.error_lines)} error line(s) and {len(outcome.other_lines)} other line(s)"))
            elif not outcome.names_path:
                found.append(Failure("error-names-no-file", f"none of {list(outcome.names)} in the error line"))
        else:
            found.append(Failure("unexpected-exit-code", f"exit {code}"))
    if outcome.out_diff:
        found.append(Failure("data-changed", "; ".join(outcome.out_diff[:5])
                             + (f" (+{len(outcome.out_diff) - 5} more)" if len(outcome.out_diff) > 5 else "")))
    return found
