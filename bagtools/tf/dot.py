"""The tf tree as Graphviz dot text (what tf2's view_frames draws)."""

from __future__ import annotations

from bagtools.tf.frames import FrameInfo


def _quote(name: str) -> str:
    return '"' + name.replace('"', '\\"') + '"'


def render_dot(infos: list[FrameInfo], origin_ns: int | None = None) -> str:
    """A ``digraph`` with one edge parent -> child per frame, labelled static or rate and time range.

    Times are relative to ``origin_ns`` (e.g. the bag start) when given, else absolute seconds.
    """
    lines = ["digraph tf {", "  rankdir=TB;", "  node [shape=box];"]
    for info in infos:
        if info.is_static:
            label = "static"
        else:
            offset = origin_ns or 0
            label = (f"{info.rate_hz:.1f} Hz, {info.count} samples\\n"
                     f"{(info.first_ns - offset) / 1e9:.2f}..{(info.last_ns - offset) / 1e9:.2f} s")
        for parent in info.parents:
            style = "" if parent == info.parent else ", style=dashed"
            lines.append(f"  {_quote(parent)} -> {_quote(info.child)} [label={_quote(label)}{style}];")
    lines.append("}")
    return "\n".join(lines) + "\n"
