"""``tf frames``: the tf tree of a bag with parent, kind, rate and time range per frame."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from bagtools.tf.frames import FrameInfo, frame_infos, render_tree
from bagtools.tf.repair import tf_conflicts


@dataclass(frozen=True)
class FrameTree:
    """The frames of a bag (sorted by child).

    ``origin_ns`` is the earliest header stamp of a dynamic transform (the bag
    start if there is none): times are shown relative to it, since header
    stamps (e.g. simulation time) need not match the bag's recording clock.
    ``warnings`` are the reader's (e.g. a truncated MCAP read up to the cut) and
    what is wrong with the tf data (see :func:`bagtools.tf.repair.tf_conflicts`).
    """

    path: str
    origin_ns: int
    infos: list[FrameInfo]
    warnings: list[str] = field(default_factory=list)

    def text(self) -> str:
        """The indented tree, times relative to ``origin_ns``."""
        return render_tree(self.infos, self.origin_ns) if self.infos else "(no /tf or /tf_static transforms)"


def read_frame_tree(bag: str | Path) -> FrameTree:
    """Read /tf and /tf_static of ``bag`` and summarize each child frame; raises BagError/TopicError."""
    from bagtools.io import open_bag, read_tf_arrays

    with open_bag(bag) as reader:
        dynamic, static = read_tf_arrays(reader)
        infos = frame_infos(dynamic, static)
        firsts = [f.first_ns for f in infos if not f.is_static]
        warnings = list(reader.warnings) + tf_conflicts(dynamic, static)
        return FrameTree(str(reader.path), min(firsts) if firsts else int(reader.start_ns), infos, warnings)
