"""Which bags a batch covers, and the name of each one's output directory.

``find_bags`` expands the BAGS arguments of ``bagtools batch``: a path names
one bag (a rosbag2 directory, a .mcap, .db3 or .bag file); a glob
(``/data/*/run*``) and a directory that is not itself a bag are searched for
bags. A directory is a rosbag2 bag when it holds ``metadata.yaml``; in any
other directory each .mcap, .db3 and .bag file is a bag of its own (a folder
of recordings), and sub-directories are searched in turn. Hidden entries and
batch output directories are never searched.

``output_names`` gives every bag a unique, deterministic directory name: the
bag's own name, with its parent folder's name in front when two bags share a
name, and a short hash of the path when even that is not enough.
"""

from __future__ import annotations

import glob
import hashlib
import os
from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path

from bagtools.errors import BagError, BagtoolsError

#: Suffixes of single-file bags (MCAP, rosbag2 sqlite3, ROS 1).
BAG_SUFFIXES = (".mcap", ".db3", ".bag")
#: A directory holding this file is a batch's output directory (see :mod:`bagtools.batch.fleet`).
BATCH_MANIFEST = ".bagtools-batch.json"
BATCH_LOCK = ".bagtools-batch.lock"
#: Names the batch itself writes in its output directory, which no bag may take.
RESERVED_NAMES = frozenset({"fleet.csv", "fleet.parquet", "fleet.png", BATCH_MANIFEST})


def is_rosbag2_dir(path: Path) -> bool:
    """True for a directory holding a rosbag2 ``metadata.yaml``."""
    return path.is_dir() and (path / "metadata.yaml").is_file()


def _walk(directory: Path, skip: set[Path]) -> Iterable[Path]:
    """Bags inside ``directory`` (not itself a bag)."""
    for root, dirs, files in os.walk(directory):
        root_path = Path(root)
        dirs.sort()
        keep = []
        for name in dirs:
            sub = root_path / name
            if name.startswith(".") or sub.resolve() in skip or (sub / BATCH_MANIFEST).exists():
                continue
            if is_rosbag2_dir(sub):
                yield sub
            else:
                keep.append(name)
        dirs[:] = keep
        for name in sorted(files):
            if not name.startswith(".") and name.endswith(BAG_SUFFIXES):
                yield root_path / name


def _expand(path: Path, explicit: bool, skip: set[Path]) -> list[Path]:
    """The bags ``path`` stands for; ``explicit`` paths name a bag even when they do not look like one."""
    if path.is_dir() and not is_rosbag2_dir(path):
        return sorted(_walk(path, skip))
    if path.name == "metadata.yaml":
        return [path.parent]
    if path.is_dir() or explicit or path.name.endswith(BAG_SUFFIXES):
        return [path]
    return []


def find_bags(args: Sequence[str], skip: Iterable[str | Path] = ()) -> list[Path]:
    """The bags named by paths, globs and folders in ``args``, absolute, each once, in argument order.

    ``skip`` lists directories never searched (the batch's own output). A path
    that does not exist, a glob matching nothing and an argument that holds no
    bag raise :class:`~bagtools.errors.BagtoolsError` (bad arguments, before
    any work). A file named explicitly is taken as a bag whatever it holds; if
    it is not one, its row in the batch says so.
    """
    skip_set = {Path(p).resolve() for p in skip}
    found: dict[Path, None] = {}
    for arg in args:
        if glob.has_magic(arg) and not Path(arg).exists():
            matches = sorted(glob.glob(os.path.expanduser(arg), recursive=True))
            if not matches:
                raise BagtoolsError("matches no file or directory", arg)
            bags = [bag for m in matches for bag in _expand(Path(m), False, skip_set)]
        else:
            path = Path(arg).expanduser()
            if not path.exists():
                raise BagError("no such file or directory", arg)
            bags = _expand(path, True, skip_set)
        if not bags:
            raise BagtoolsError("holds no bag (no rosbag2 directory, .mcap, .db3 or .bag file)", arg)
        for bag in bags:
            found.setdefault(bag.absolute(), None)
    return list(found)


def _base_name(bag: Path) -> str:
    return bag.stem if bag.suffix in BAG_SUFFIXES and not bag.is_dir() else bag.name


def _path_hash(bag: Path) -> str:
    return hashlib.sha1(str(bag).encode("utf-8")).hexdigest()[:8]


def output_names(bags: Sequence[Path]) -> list[str]:
    """One directory name per bag, unique among ``bags`` and never one of :data:`RESERVED_NAMES`.

    ``/a/run1`` -> ``run1``; with ``/b/run1`` also in the batch -> ``a__run1``
    and ``b__run1``; names still equal after that (or reserved, or hidden)
    get ``-<8 hex digits of the path's hash>``. The result depends only on
    the set of bags, so a rerun over the same bags finds the same directories.
    """
    bases = [_base_name(b) or "bag" for b in bags]
    by_base: dict[str, list[int]] = defaultdict(list)
    for i, base in enumerate(bases):
        by_base[base].append(i)
    names = list(bases)
    for base, members in by_base.items():
        if len(members) > 1:
            for i in members:
                names[i] = f"{bags[i].parent.name}__{base}"
    counts: dict[str, int] = defaultdict(int)
    for name in names:
        counts[name] += 1
    for i, name in enumerate(names):
        if counts[name] > 1 or name in RESERVED_NAMES or name.startswith("."):
            names[i] = f"{bases[i].lstrip('.') or 'bag'}-{_path_hash(bags[i])}"
    return names
