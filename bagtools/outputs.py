"""Atomic output writing: nothing half-written, nothing overwritten without force.

Writers produce a temporary file beside the target and rename it into place.
A command that writes several files uses :class:`OutputDir`, which stages all of
them in a hidden temporary directory and moves them in only when every one was
written, so an error leaves the destination as it was.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from bagtools.errors import BagtoolsError, OutputExistsError


def check_writable(path: Path, force: bool) -> None:
    """Raise :class:`OutputExistsError` if ``path`` exists and ``force`` is false."""
    if path.exists() and not force:
        raise OutputExistsError("already exists (use --force to overwrite)", path)


@contextmanager
def atomic_path(path: str | Path, force: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    The temporary file or directory is removed if the block raises (including
    KeyboardInterrupt). A directory target is replaced as a whole.
    """
    path = Path(path)
    check_writable(path, force)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    staged = tmp / path.name
    try:
        yield staged
        if not staged.exists():
            raise BagtoolsError("writer produced no output", path)
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        os.replace(staged, path)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def write_bytes_atomic(path: str | Path, data: bytes, force: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically and return ``path``."""
    with atomic_path(path, force) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text_atomic(path: str | Path, text: str, force: bool = False) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically and return ``path``."""
    return write_bytes_atomic(path, text.encode("utf-8"), force)


def check_outputs(out_dir: str | Path, names: list[str], force: bool) -> None:
    """Raise before any work is done if ``out_dir`` cannot take ``names`` (not a directory, or files exist without force)."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise BagtoolsError("is not a directory", out_dir)
    for name in names:
        check_writable(out_dir / name, force)


class OutputDir:
    """Stage a command's output files and publish them together.

    Usage::

        with OutputDir(out_dir, ["map.pgm", "map.yaml"], force) as staged:
            (staged / "map.pgm").write_bytes(...)

    On entry, refuses (``OutputExistsError``) if any named file already exists in
    ``out_dir`` and ``force`` is false. On success every staged file is renamed
    into ``out_dir`` and named outputs this run did not produce are removed (so
    no stale result from an earlier run remains); on error nothing in
    ``out_dir`` changes.
    """

    def __init__(self, out_dir: str | Path, names: list[str], force: bool = False) -> None:
        self.out_dir = Path(out_dir)
        self.names = list(names)
        self.force = force
        self._tmp: Path | None = None

    def __enter__(self) -> Path:
        check_outputs(self.out_dir, self.names, self.force)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self._tmp = Path(tempfile.mkdtemp(prefix=".bagtools-", suffix=".tmp", dir=self.out_dir))
        return self._tmp

    def __exit__(self, exc_type, exc, tb) -> None:
        assert self._tmp is not None
        try:
            if exc_type is None:
                produced = {p.name for p in self._tmp.iterdir()}
                for name in sorted(produced):
                    os.replace(self._tmp / name, self.out_dir / name)
                # With force, a named output this run did not produce must not
                # survive from an earlier run and pass for a result of this one.
                for name in self.names:
                    stale = self.out_dir / name
                    if name not in produced and stale.is_file():
                        stale.unlink()
        finally:
            shutil.rmtree(self._tmp, ignore_errors=True)
