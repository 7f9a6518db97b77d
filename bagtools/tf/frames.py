"""The tf tree of a bag, frame by frame: parent, static or dynamic, rate, time range."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from bagtools.io.decode import TfArrays


@dataclass(frozen=True)
class FrameInfo:
    """One child frame of the tf tree.

    ``parents`` lists every parent the frame had, in order of first appearance
    (a frame may change parent over time); ``parent`` is the last one.
    ``rate_hz`` is the mean sample rate of a dynamic frame (0 for static or a
    single sample); ``first_ns``/``last_ns`` are header stamps, int ns.
    """

    child: str
    parent: str
    parents: tuple[str, ...]
    is_static: bool
    count: int
    rate_hz: float
    first_ns: int
    last_ns: int

    def to_dict(self) -> dict:
        return asdict(self) | {"parents": list(self.parents)}


def _strip(ids: np.ndarray) -> np.ndarray:
    return np.array([s.lstrip("/") for s in ids], dtype=object) if ids.size else ids


def frame_infos(dynamic: TfArrays, static: TfArrays) -> list[FrameInfo]:
    """Summarize every child frame of ``dynamic`` and ``static`` (leading '/' stripped, as tf2 does)."""
    infos: dict[str, FrameInfo] = {}
    for arrays, is_static in ((dynamic, False), (static, True)):
        if not len(arrays):
            continue
        children, parents = _strip(arrays.child), _strip(arrays.parent)
        names, first_index, inverse = np.unique(children.astype(str), return_index=True, return_inverse=True)
        counts = np.bincount(inverse, minlength=names.size)
        first_ns = np.full(names.size, np.iinfo(np.int64).max)
        last_ns = np.full(names.size, np.iinfo(np.int64).min)
        np.minimum.at(first_ns, inverse, arrays.stamp_ns)
        np.maximum.at(last_ns, inverse, arrays.stamp_ns)
        for k, child in enumerate(names):
            rows = np.flatnonzero(inverse == k)
            ordered_parents = tuple(dict.fromkeys(parents[rows]))
            span_s = (last_ns[k] - first_ns[k]) / 1e9
            rate = (counts[k] - 1) / span_s if (not is_static and counts[k] > 1 and span_s > 0) else 0.0
            info = FrameInfo(str(child), str(parents[rows[-1]]), ordered_parents, is_static, int(counts[k]), float(rate),
                             int(first_ns[k]), int(last_ns[k]))
            previous = infos.get(info.child)
            if previous is not None and not previous.is_static:
                # Published on both /tf and /tf_static: keep the dynamic description.
                info = FrameInfo(previous.child, previous.parent, tuple(dict.fromkeys(previous.parents + ordered_parents)),
                                 False, previous.count + info.count, previous.rate_hz, previous.first_ns, previous.last_ns)
            infos[info.child] = info
    return sorted(infos.values(), key=lambda f: f.child)


def _describe(info: FrameInfo, origin_ns: int | None) -> str:
    if info.is_static:
        return "static"
    if origin_ns is None:
        span = f"{info.first_ns / 1e9:.3f}..{info.last_ns / 1e9:.3f} s"
    else:
        span = f"{(info.first_ns - origin_ns) / 1e9:+.2f}..{(info.last_ns - origin_ns) / 1e9:+.2f} s"
    extra = f", parents {' -> '.join(info.parents)}" if len(info.parents) > 1 else ""
    return f"dynamic, {info.rate_hz:.1f} Hz, {info.count} samples, {span}{extra}"


#: Deeper levels of the drawn tree are not indented further (a 3000-frame chain must not draw 12 kB lines).
MAX_INDENT_LEVELS = 32


def render_tree(infos: list[FrameInfo], origin_ns: int | None = None) -> str:
    """Draw the frames as an indented tree, roots first, children sorted by name.

    Times are shown relative to ``origin_ns`` (e.g. the bag's start) when given,
    otherwise as absolute seconds.
    """
    by_parent: dict[str, list[FrameInfo]] = {}
    for info in infos:
        by_parent.setdefault(info.parent, []).append(info)
    children = {f.child for f in infos}
    roots = sorted({f.parent for f in infos} - children)
    lines: list[str] = []
    seen: set[str] = set()
    for root in roots:  # depth first with an explicit stack: a chain thousands of frames deep is fine
        lines.append(root)
        stack = [(info, "", i == 0) for i, info in enumerate(sorted(by_parent.get(root, []), key=lambda f: f.child,
                                                                   reverse=True))]
        while stack:
            info, prefix, last = stack.pop()
            shown = prefix if len(prefix) <= 4 * MAX_INDENT_LEVELS else prefix[:4 * MAX_INDENT_LEVELS] + "… "
            lines.append(f"{shown}{'└── ' if last else '├── '}{info.child}  ({_describe(info, origin_ns)})")
            if info.child in seen:
                continue
            seen.add(info.child)
            kids = sorted(by_parent.get(info.child, []), key=lambda f: f.child, reverse=True)
            child_prefix = prefix + ("    " if last else "│   ")
            stack.extend((kid, child_prefix, i == 0) for i, kid in enumerate(kids))
    orphans = children - seen
    if orphans:  # frames in a loop of parents, which tf2 would reject at lookup
        lines.append("frames in a parent loop: " + ", ".join(sorted(orphans)))
    return "\n".join(lines)
