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
- ``force`` replaces a directory only when it carries bagtools' own mark
  (:func:`mark_own_output`, a ``.bagtools-output.json`` listing the files the
  command wrote) and holds nothing else; never by the shape of its content.
- No output may be an input, lie inside one (a rosbag2 directory), or hold one
  (:func:`refuse_input_overlap`): a result written into a bag changes the
  recording for every later read.
- A staging directory carries bagtools' mark: a lock file with a fixed first
  line, owned by its process through an ``flock``. Ctrl-C and SIGTERM remove it
  (the CLI turns SIGTERM into an exception; the signals are held while staging
  is set up and while results are renamed into place); after SIGKILL or a
  power cut the next run that writes to the same place finds the lock free and
  removes the stale staging directory. A directory without the mark is never
  removed, whatever its name.
- A failed or interrupted run leaves the file system as it found it: the
  output directories it created are removed again when they are still empty.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from bagtools.errors import BagtoolsError, OutputExistsError

_LOCK_NAME = ".bagtools-staging.lock"
_LOCK_MARK = b"bagtools staging directory: removed when its owner process is gone\n"
_STAGING_SUFFIX = ".tmp"
_OUTPUT_DIR_PREFIX = ".bagtools-"
#: The mark a command leaves in a directory it writes whole (e.g. simulate's bag).
OWN_OUTPUT_MARK = ".bagtools-output.json"
_HELD_SIGNALS = tuple(s for s in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None)) if s is not None)


class OutputBusyError(BagtoolsError):
    """Another live bagtools process is writing the same output."""


def _os_problem(err: OSError) -> str:
    return err.strerror or str(err)


@contextmanager
def _signals_held() -> Iterator[None]:
    """Hold Ctrl-C, SIGTERM and SIGHUP for the block and deliver them after it.

    Wraps the few steps that must not be cut in half (creating and marking a
    staging directory, moving results into place), so an interrupt lands
    before or after them, where the clean-up of the caller runs. Only the main
    thread handles signals; elsewhere the block runs as it is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []

    def hold(signum: int, frame: object) -> None:
        pending.append(signum)

    previous = {sig: signal.signal(sig, hold) for sig in _HELD_SIGNALS}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        for sig in dict.fromkeys(pending):
            signal.raise_signal(sig)


def _real(path: str | Path) -> Path:
    return Path(os.path.realpath(os.path.expanduser(path)))


def _input_extent(path: str | Path) -> Path:
    """The real path a read of input ``path`` covers: a file inside a rosbag2 directory stands for the directory."""
    real = _real(path)
    if not real.is_dir() and (real.parent / "metadata.yaml").is_file():
        return real.parent
    return real


def refuse_input_overlap(output: str | Path, inputs: Iterable[str | Path], may_hold: bool = False) -> None:
    """Raise :class:`BagtoolsError` if ``output`` is one of ``inputs``, lies inside one, or holds one.

    Paths are compared after resolving symlinks (and hard links, for files that
    exist). ``may_hold``: a directory the command writes only named files into
    may hold an input (``grid run.mcap --out .``); anything else may not.
    """
    out = _real(output)
    for given in inputs:
        extent = _input_extent(given)
        same_file = out.exists() and extent.exists() and os.path.samefile(out, extent)
        if out == extent or same_file:
            raise BagtoolsError(f"is the input {given}; choose another output path", output)
        if extent in out.parents:
            raise BagtoolsError(f"lies inside the input {extent}; writing there would change the recording, so "
                                "choose an output path outside it", output)
        if not may_hold and out in extent.parents:
            raise BagtoolsError(f"holds the input {given}; choose an output path that does not contain it", output)


def check_writable(path: Path, force: bool, is_own_output: Callable[[Path], bool] | None = None,
                   inputs: Iterable[str | Path] = ()) -> None:
    """Refuse ``path`` if it exists and may not be replaced, or if it overlaps one of ``inputs``.

    A directory is replaced only with ``force`` and only when ``is_own_output``
    recognises it as this command's output; a file (or a symlink, even a
    dangling one) only with ``force``.
    """
    refuse_input_overlap(path, inputs)
    if path.is_dir() and not path.is_symlink():
        if is_own_output is None or not is_own_output(path):
            raise OutputExistsError(
                "is an existing directory that this command did not write; --force replaces only the "
                "command's own output, so choose another path", path)
    if os.path.lexists(path) and not force:
        raise OutputExistsError("already exists (use --force to overwrite)", path)


def mark_own_output(directory: Path, command: str) -> None:
    """Mark ``directory`` (about to be published) as written whole by ``command``, listing its files."""
    files = sorted(p.name for p in directory.iterdir())
    (directory / OWN_OUTPUT_MARK).write_text(json.dumps({"written_by": f"bagtools {command}", "files": files},
                                                        indent=1) + "\n")


def is_own_output(directory: Path, command: str) -> bool:
    """True when ``directory`` may be replaced whole by ``command`` with ``--force``.

    It must be empty, or carry the mark :func:`mark_own_output` left and hold
    exactly the files listed there (nothing of the user's was added).
    """
    try:
        entries = {p.name: p for p in directory.iterdir()}
        if not entries:
            return True
        mark = json.loads((directory / OWN_OUTPUT_MARK).read_text())
    except (OSError, ValueError):
        return False
    if not isinstance(mark, dict) or mark.get("written_by") != f"bagtools {command}":
        return False
    files = mark.get("files")
    if not isinstance(files, list) or set(entries) != {*map(str, files), OWN_OUTPUT_MARK}:
        return False
    return all(p.is_file() and not p.is_symlink() for p in entries.values())


class _Staging:
    """A hidden staging directory in ``parent``, marked as bagtools' and owned by this process (flock) until
    :meth:`close`. Creation is all or nothing, also under Ctrl-C and SIGTERM."""

    def __init__(self, parent: Path, prefix: str) -> None:
        sweep_stale_staging(parent, prefix)
        self.path: Path | None = None
        self._lock_fd: int | None = None
        try:
            with _signals_held():
                self.path = Path(tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}.", suffix=_STAGING_SUFFIX,
                                                  dir=parent))
                self._lock_fd = os.open(self.path / _LOCK_NAME, os.O_CREAT | os.O_WRONLY, 0o600)
                fcntl.flock(self._lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                os.write(self._lock_fd, _LOCK_MARK)
        except OSError as err:
            self.close()
            raise BagtoolsError(f"cannot write here: {_os_problem(err)}", parent) from err
        except BaseException:
            self.close()
            raise

    def __enter__(self) -> _Staging:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        with _signals_held():
            if self.path is not None:
                shutil.rmtree(self.path, ignore_errors=True)
                self.path = None
            if self._lock_fd is not None:
                os.close(self._lock_fd)
                self._lock_fd = None


def _staging_state(staging: Path, prefix: str) -> str:
    """'live' (its owner holds the lock), 'stale' (bagtools' mark, owner gone; or an interrupted creation, see
    :func:`_interrupted_creation`) or 'foreign' (no mark: not ours)."""
    try:
        fd = os.open(staging / _LOCK_NAME, os.O_RDONLY | os.O_NOFOLLOW)
    except OSError:
        return "stale" if _interrupted_creation(staging, prefix) else "foreign"
    try:
        if os.read(fd, len(_LOCK_MARK)) != _LOCK_MARK:
            return "stale" if _interrupted_creation(staging, prefix) else "foreign"
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as err:
        if err.errno in (errno.EWOULDBLOCK, errno.EAGAIN):
            return "live"
        return "foreign"
    finally:
        os.close(fd)
    return "stale"


def _interrupted_creation(staging: Path, prefix: str) -> bool:
    """Is ``staging`` (named ``<prefix><pid>.<random>.tmp``, without bagtools' mark) one whose creation was cut
    short (SIGKILL between making the directory and writing its mark)? Then it holds nothing but, perhaps, a part
    of the mark, and the process its name gives is gone."""
    try:
        entries = list(staging.iterdir())
        if entries and ([e.name for e in entries] != [_LOCK_NAME] or entries[0].is_symlink()
                        or not _LOCK_MARK.startswith(entries[0].read_bytes())):
            return False
    except OSError:
        return False
    pid = staging.name[len(prefix):].split(".", 1)[0]
    if not pid.isdigit():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except OSError:  # alive, another user's
        return False
    return False


def sweep_stale_staging(parent: Path, prefix: str) -> list[Path]:
    """Remove bagtools' staging directories ``parent/<prefix>*.tmp`` whose owner process is gone; return the
    live ones. A directory of that name without bagtools' mark is left alone, unless it is one whose creation
    was cut short (:func:`_interrupted_creation`: empty but for part of the mark, its owner gone)."""
    live: list[Path] = []
    try:
        candidates = [p for p in parent.iterdir() if p.name.startswith(prefix) and p.name.endswith(_STAGING_SUFFIX)]
    except OSError:
        return live
    for staging in candidates:
        if not staging.is_dir() or staging.is_symlink():
            continue
        state = _staging_state(staging, prefix)
        if state == "live":
            live.append(staging)
        elif state == "stale":
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


def _make_parent(path: Path) -> list[Path]:
    """Create directory ``path`` and its missing parents; return those created, outermost first."""
    missing = [p for p in (path, *path.parents) if not os.path.lexists(p)][::-1]
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        _remove_created(missing)
        raise BagtoolsError(f"cannot create the output directory: {_os_problem(err)}", path) from err
    if not path.is_dir():
        raise BagtoolsError("is not a directory", path)
    return missing


def _remove_created(created: list[Path]) -> None:
    """Remove the directories a failed run created (``_make_parent``'s list), innermost first, if still empty."""
    for directory in reversed(created):
        try:
            directory.rmdir()
        except OSError:
            return


def _replace_onto(staged: Path, path: Path, force: bool, is_own_output: Callable[[Path], bool] | None) -> None:
    """Move ``staged`` onto ``path`` under the directory lock, re-checking what is there now."""
    with _directory_lock(path.parent), _signals_held():
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
def atomic_path(path: str | Path, force: bool = False, is_own_output: Callable[[Path], bool] | None = None,
                inputs: Iterable[str | Path] = ()) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; move it onto ``path`` when the block succeeds.

    The caller writes a file (or creates a directory) at the yielded path. The
    staging directory, and any parent directory this call created, are removed
    if the block raises (including Ctrl-C and, through the CLI, SIGTERM). An
    existing directory at ``path`` is replaced only with ``force`` and when
    ``is_own_output(path)`` is true. ``path`` may not overlap ``inputs``.
    """
    path = Path(path)
    check_writable(path, force, is_own_output, inputs)
    created = _make_parent(path.parent)
    done = False
    try:
        with _Staging(path.parent, f".{path.name}.") as staging:
            staged = staging.path / path.name
            yield staged
            if not staged.exists():
                raise BagtoolsError("writer produced no output", path)
            _replace_onto(staged, path, force, is_own_output)
            done = True
    except OSError as err:
        raise BagtoolsError(f"cannot write: {_os_problem(err)}", path) from err
    finally:
        if not done:
            _remove_created(created)


def write_bytes_atomic(path: str | Path, data: bytes, force: bool = False, inputs: Iterable[str | Path] = ()) -> Path:
    """Write ``data`` to ``path`` atomically and return ``path``; ``path`` may not overlap ``inputs``."""
    with atomic_path(path, force, inputs=inputs) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text_atomic(path: str | Path, text: str, force: bool = False, inputs: Iterable[str | Path] = ()) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically and return ``path``; ``path`` may not overlap ``inputs``."""
    return write_bytes_atomic(path, text.encode("utf-8"), force, inputs)


def check_outputs(out_dir: str | Path, names: list[str], force: bool, inputs: Iterable[str | Path] = ()) -> None:
    """Raise before any work is done if ``out_dir`` cannot take ``names``.

    Refuses an ``out_dir`` that is a file or lies inside one of ``inputs`` (a
    rosbag2 directory), a named output that is an input or a directory, an
    existing named file (or symlink) without ``force``, and a directory another
    live bagtools run is writing into.
    """
    out_dir = Path(out_dir)
    inputs = list(inputs)
    refuse_input_overlap(out_dir, inputs, may_hold=True)
    if os.path.lexists(out_dir) and not out_dir.is_dir():
        raise BagtoolsError("is not a directory", out_dir)
    for name in names:
        target = out_dir / name
        if target.is_dir() and not target.is_symlink():
            raise OutputExistsError("is a directory, where this command writes a file; move it or choose another --out",
                                    target)
        check_writable(target, force, inputs=inputs)
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
        self._created: list[Path] = []

    def __enter__(self) -> Path:
        check_outputs(self.out_dir, self.names, self.force)
        self._created = _make_parent(self.out_dir)
        try:
            self._staging = _Staging(self.out_dir, _OUTPUT_DIR_PREFIX)
            _refuse_live_writers(self.out_dir)
            self._files = self._staging.path / "files"
            self._files.mkdir()
        except BaseException:
            self._close(published=False)
            raise
        return self._files

    def __exit__(self, exc_type, exc, tb) -> None:
        if self._staging is None or self._files is None:
            return
        published = False
        try:
            if exc_type is None:
                self._publish(self._files)
                published = True
        except OSError as err:
            raise BagtoolsError(f"cannot write: {_os_problem(err)}", self.out_dir) from err
        finally:
            self._close(published)
        if isinstance(exc, OSError):  # writing a staged file failed (a full disk): name the output, not the input
            raise BagtoolsError(f"cannot write: {_os_problem(exc)}", self.out_dir) from exc

    def _close(self, published: bool) -> None:
        """Remove the staging directory and, unless results were published, the directories this run created."""
        if self._staging is not None:
            self._staging.close()
        if not published:
            _remove_created(self._created)

    def _publish(self, files: Path) -> None:
        produced = sorted(p.name for p in files.iterdir())
        unnamed = [name for name in produced if name not in self.names]
        if unnamed:
            raise BagtoolsError(f"internal error: staged outputs not declared: {', '.join(unnamed)}", self.out_dir)
        with _directory_lock(self.out_dir), _signals_held():
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
