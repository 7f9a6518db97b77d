"""Atomic outputs: nothing half-written, nothing overwritten without force, nothing else touched.

Writers produce their result in a hidden staging directory beside the target and
rename it into place. A command that writes several files uses :class:`OutputDir`,
which stages all of them and moves them in only when every one was written, so an
error leaves the destination as it was.

The rules every output follows:

- Without ``force`` an existing output is refused, checked before the work and
  again at the final rename (under a lock on the destination directory), so two
  runs writing the same place at once cannot silently replace each other.
- ``force`` replaces only what the command itself writes: a named file in an
  output directory, a single output file, or a directory that
  ``is_own_output`` recognises (e.g. a bag that ``simulate`` wrote). Anything
  else (a user's directory of files) is refused even with ``force``.
- A staging directory is owned by its process through an ``flock`` on a lock
  file inside it. Ctrl-C and SIGTERM remove it (the CLI turns SIGTERM into an
  exception); after SIGKILL or a power cut the next run that writes to the same
  place finds the lock free and removes the stale staging directory.
"""

from __future__ import annotations

import errno
import fcntl
import os
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from bagtools.errors import BagtoolsError, OutputExistsError

_LOCK_NAME = ".lock"
_STAGING_SUFFIX = ".tmp"
_OUTPUT_DIR_PREFIX = ".bagtools-"
# A staging directory with no lock file yet may be in the middle of being created.
_UNLOCKED_GRACE_S = 60.0


class OutputBusyError(BagtoolsError):
    """Another live bagtools process is writing the same output."""


def _os_problem(err: OSError) -> str:
    return err.strerror or str(err)


def check_writable(path: Path, force: bool, is_own_output: Callable[[Path], bool] | None = None) -> None:
    """Refuse ``path`` if it exists and may not be replaced.

    A directory is replaced only with ``force`` and only when ``is_own_output``
    recognises it as this command's output; a file only with ``force``.
    """
    if path.is_dir() and not path.is_symlink():
        if is_own_output is None or not is_own_output(path):
            raise OutputExistsError(
                "is an existing directory that this command did not write; --force replaces only the "
                "command's own output, so choose another path", path)
    if path.exists() and not force:
        raise OutputExistsError("already exists (use --force to overwrite)", path)


class _Staging:
    """A hidden staging directory in ``parent``, owned by this process (flock) until :meth:`close`."""

    def __init__(self, parent: Path, prefix: str) -> None:
        sweep_stale_staging(parent, prefix)
        try:
            self.path = Path(tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}.", suffix=_STAGING_SUFFIX, dir=parent))
            self._lock_fd = os.open(self.path / _LOCK_NAME, os.O_CREAT | os.O_WRONLY, 0o600)
        except OSError as err:
            raise BagtoolsError(f"cannot write here: {_os_problem(err)}", parent) from err
        fcntl.flock(self._lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)

    def close(self) -> None:
        shutil.rmtree(self.path, ignore_errors=True)
        os.close(self._lock_fd)


def _staging_is_live(staging: Path) -> bool:
    """True when a live process holds the lock of ``staging`` (or it is too new to judge)."""
    try:
        fd = os.open(staging / _LOCK_NAME, os.O_RDONLY)
    except FileNotFoundError:
        try:
            return time.time() - staging.stat().st_mtime < _UNLOCKED_GRACE_S
        except OSError:
            return False
    except OSError:
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as err:
        if err.errno in (errno.EWOULDBLOCK, errno.EAGAIN):
            return True
        raise
    finally:
        os.close(fd)
    return False


def sweep_stale_staging(parent: Path, prefix: str) -> list[Path]:
    """Remove staging directories ``parent/<prefix>*.tmp`` whose owner process is gone; return the live ones."""
    live: list[Path] = []
    try:
        candidates = [p for p in parent.iterdir() if p.name.startswith(prefix) and p.name.endswith(_STAGING_SUFFIX)]
    except OSError:
        return live
    for staging in candidates:
        if not staging.is_dir() or staging.is_symlink():
            continue
        if _staging_is_live(staging):
            live.append(staging)
        else:
            shutil.rmtree(staging, ignore_errors=True)
    return live


@contextmanager
def _directory_lock(directory: Path) -> Iterator[None]:
    """Hold an exclusive flock on ``directory`` itself (serializes the final renames of concurrent runs)."""
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def _make_parent(path: Path) -> None:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise BagtoolsError(f"cannot create the output directory: {_os_problem(err)}", path) from err
    if not path.is_dir():
        raise BagtoolsError("is not a directory", path)


def _replace_onto(staged: Path, path: Path, force: bool, is_own_output: Callable[[Path], bool] | None) -> None:
    """Move ``staged`` onto ``path`` under the directory lock, re-checking what is there now."""
    with _directory_lock(path.parent):
        check_writable(path, force, is_own_output)
        if path.is_dir() and not path.is_symlink():
            # Own output directory, with force: move the old one aside, the new one in, then drop the old.
            trash = Path(tempfile.mkdtemp(prefix=f".{path.name}.old.", suffix=_STAGING_SUFFIX, dir=path.parent))
            os.replace(path, trash / path.name)
            os.replace(staged, path)
            shutil.rmtree(trash, ignore_errors=True)
        elif force:
            os.replace(staged, path)
        else:
            os.rename(staged, path)


@contextmanager
def atomic_path(path: str | Path, force: bool = False,
                is_own_output: Callable[[Path], bool] | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; move it onto ``path`` when the block succeeds.

    The caller writes a file (or creates a directory) at the yielded path. The
    staging directory is removed if the block raises (including Ctrl-C and,
    through the CLI, SIGTERM). An existing directory at ``path`` is replaced
    only with ``force`` and when ``is_own_output(path)`` is true.
    """
    path = Path(path)
    check_writable(path, force, is_own_output)
    _make_parent(path.parent)
    staging = _Staging(path.parent, f".{path.name}.")
    staged = staging.path / path.name
    try:
        yield staged
        if not staged.exists():
            raise BagtoolsError("writer produced no output", path)
        _replace_onto(staged, path, force, is_own_output)
    except OSError as err:
        raise BagtoolsError(f"cannot write: {_os_problem(err)}", path) from err
    finally:
        staging.close()


def write_bytes_atomic(path: str | Path, data: bytes, force: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically and return ``path``."""
    with atomic_path(path, force) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text_atomic(path: str | Path, text: str, force: bool = False) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically and return ``path``."""
    return write_bytes_atomic(path, text.encode("utf-8"), force)


def check_outputs(out_dir: str | Path, names: list[str], force: bool) -> None:
    """Raise before any work is done if ``out_dir`` cannot take ``names``.

    Refuses an ``out_dir`` that is a file, a named output that is a directory,
    an existing named file without ``force``, and a directory another live
    bagtools run is writing into.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise BagtoolsError("is not a directory", out_dir)
    for name in names:
        target = out_dir / name
        if target.is_dir() and not target.is_symlink():
            raise OutputExistsError("is a directory, where this command writes a file; move it or choose another --out",
                                    target)
        check_writable(target, force)
    if out_dir.is_dir():
        _refuse_live_writers(out_dir)


def _refuse_live_writers(out_dir: Path) -> None:
    others = [p for p in sweep_stale_staging(out_dir, _OUTPUT_DIR_PREFIX)
              if not p.name.startswith(f"{_OUTPUT_DIR_PREFIX}{os.getpid()}.")]
    if others:
        raise OutputBusyError("another bagtools run is writing into this directory; wait for it to finish "
                              "or choose another --out", out_dir)


class OutputDir:
    """Stage a command's output files and publish them together.

    Usage::

        with OutputDir(out_dir, ["map.pgm", "map.yaml"], force) as staged:
            (staged / "map.pgm").write_bytes(...)

    On entry, refuses (``OutputExistsError``) if any named file already exists in
    ``out_dir`` and ``force`` is false, and (``OutputBusyError``) if another
    live run is writing there. On success every staged file is renamed into
    ``out_dir`` (the existence check repeated under a lock on ``out_dir``) and
    named outputs this run did not produce are removed, so no stale result from
    an earlier run remains; on error nothing in ``out_dir`` changes. Files not
    named in ``names`` are never touched.
    """

    def __init__(self, out_dir: str | Path, names: list[str], force: bool = False) -> None:
        self.out_dir = Path(out_dir)
        self.names = list(names)
        self.force = force
        self._staging: _Staging | None = None
        self._files: Path | None = None

    def __enter__(self) -> Path:
        check_outputs(self.out_dir, self.names, self.force)
        _make_parent(self.out_dir)
        self._staging = _Staging(self.out_dir, _OUTPUT_DIR_PREFIX)
        _refuse_live_writers(self.out_dir)
        self._files = self._staging.path / "files"
        self._files.mkdir()
        return self._files

    def __exit__(self, exc_type, exc, tb) -> None:
        if self._staging is None or self._files is None:
            return
        try:
            if exc_type is None:
                self._publish(self._files)
        except OSError as err:
            raise BagtoolsError(f"cannot write: {_os_problem(err)}", self.out_dir) from err
        finally:
            self._staging.close()

    def _publish(self, files: Path) -> None:
        produced = sorted(p.name for p in files.iterdir())
        unnamed = [name for name in produced if name not in self.names]
        if unnamed:
            raise BagtoolsError(f"internal error: staged outputs not declared: {', '.join(unnamed)}", self.out_dir)
        with _directory_lock(self.out_dir):
            for name in self.names:  # what another run wrote meanwhile is refused too
                target = self.out_dir / name
                if target.is_dir() and not target.is_symlink():
                    raise OutputExistsError("is a directory, where this command writes a file", target)
                check_writable(target, self.force)
            for name in produced:
                os.replace(files / name, self.out_dir / name)
            # With force, a named output this run did not produce must not
            # survive from an earlier run and pass for a result of this one.
            for name in self.names:
                stale = self.out_dir / name
                if name not in produced and (stale.is_file() or stale.is_symlink()):
                    stale.unlink()
