"""Run the lab guide (docs/lab.md): extract its code blocks, run them in order, collect what they print.

Used by ``docs/make_figures.py`` (which pastes the printed output back into the
guide and copies the figures into ``docs/img``) and by ``tests/docs/test_lab.py``
(which runs the guide on a short bag so it cannot go stale).

The guide's conventions:

- a fenced ```` ```sh ```` block holds ``bagtools`` commands, one per line
  (``\\`` continues a line, ``#`` starts a comment); they run in-process
  through :func:`bagtools.cli.main`;
- a fenced ```` ```python ```` block is run in one Python session shared by the
  whole guide (like a notebook), in the guide's working directory;
- a fenced ```` ```text ```` block right after a runnable block is what that
  block prints; ``make docs`` rewrites it from a real run;
- ``<!-- exact -->`` on the line before a runnable block: its output does not
  depend on the bag, so the test compares it with the guide's text block;
- ``--duration N`` of a command is what the test shortens.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shlex
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

DOCS = Path(__file__).resolve().parent
LAB_MD = DOCS / "lab.md"
IMG_DIR = DOCS / "img"
RUNNABLE = ("sh", "python")
EXACT_MARK = "<!-- exact -->"
_FENCE = re.compile(r"^```(\w*)\s*$")
_DURATION = re.compile(r"--duration\s+\S+")

# Figures of the guide (docs/img/NAME) -> the file the guide's own blocks write (relative to its directory).
FIGURES: dict[str, str] = {
    "tf_frames.png": "lab/fig_tf_frames.png",
    "clicked_point.png": "lab/clicked/point.png",
    "cloud_maps.png": "lab/fig_cloud_maps.png",
    "ndt_pair.png": "lab/fig_ndt_pair.png",
    "ndt_trajectory.png": "lab/ndt/trajectory.png",
    "grid_insert_ray.png": "lab/fig_grid_insert_ray.png",
    "grids.png": "lab/fig_grids.png",
}
# Written by make_figures.py itself (the speed experiment), not by a block of the guide.
GENERATED_FIGURES = ("speed.png",)


@dataclass(frozen=True)
class Block:
    """A fenced code block of the guide: its language, code and line span (fence lines, 0-based)."""

    lang: str
    code: str
    first_line: int
    last_line: int
    exact: bool = False


@dataclass(frozen=True)
class Step:
    """A runnable block and the ```text block after it (its printed output in the guide), if any."""

    block: Block
    output: Block | None


def parse_blocks(text: str) -> list[Block]:
    """Every fenced block of a markdown text, in order."""
    lines = text.split("\n")
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        match = _FENCE.match(lines[i])
        if not match:
            i += 1
            continue
        end = i + 1
        while end < len(lines) and lines[end].rstrip() != "```":
            end += 1
        if end == len(lines):
            raise ValueError(f"lab.md line {i + 1}: code block never closed")
        before = next((lines[k].strip() for k in range(i - 1, -1, -1) if lines[k].strip()), "")
        blocks.append(Block(match.group(1), "\n".join(lines[i + 1:end]), i, end, before == EXACT_MARK))
        i = end + 1
    return blocks


def steps(text: str) -> list[Step]:
    """The runnable blocks of the guide, each with its output block (a ```text block right after it)."""
    lines = text.split("\n")
    blocks = parse_blocks(text)
    out: list[Step] = []
    for k, block in enumerate(blocks):
        if block.lang not in RUNNABLE:
            continue
        nxt = blocks[k + 1] if k + 1 < len(blocks) else None
        adjacent = nxt is not None and nxt.lang == "text" and not any(
            line.strip() for line in lines[block.last_line + 1:nxt.first_line])
        out.append(Step(block, nxt if adjacent else None))
    return out


def shell_commands(code: str) -> Iterator[list[str]]:
    """The argument vectors of a ```sh block (continuations joined, comments dropped)."""
    logical = re.sub(r"\\\n", " ", code)
    for line in logical.split("\n"):
        argv = shlex.split(line, comments=True)
        if not argv:
            continue
        if argv[0] != "bagtools":
            raise ValueError(f"a ```sh block of lab.md may only run bagtools, got: {line.strip()}")
        yield argv[1:]


def shorten(code: str, duration_s: float | None) -> str:
    """The block with every ``--duration`` set to ``duration_s`` (unchanged when None)."""
    if duration_s is None:
        return code
    return _DURATION.sub(f"--duration {duration_s:g}", code)


class CommandFailed(RuntimeError):
    """A command or Python block of the guide failed."""


class LabSession:
    """Runs the guide's blocks in order in ``workdir``: bagtools in-process, Python in one shared namespace."""

    def __init__(self, workdir: Path, duration_s: float | None = None) -> None:
        self.workdir = Path(workdir)
        self.duration_s = duration_s
        self.namespace: dict = {"__name__": "__lab__"}

    def run(self, block: Block) -> str:
        """Run one runnable block; returns what it printed on stdout."""
        code = shorten(block.code, self.duration_s)
        with _chdir(self.workdir):
            if block.lang == "sh":
                return "".join(self._bagtools(argv) for argv in shell_commands(code))
            return self._python(code, block)

    def _bagtools(self, argv: list[str]) -> str:
        from bagtools.cli import main

        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                main(argv)
                code = 0
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else 1
        if code != 0:
            raise CommandFailed(f"bagtools {shlex.join(argv)} exited with {code}: {err.getvalue().strip()}")
        return out.getvalue()

    def _python(self, code: str, block: Block) -> str:
        out = io.StringIO()
        compiled = compile(code, f"lab.md:{block.first_line + 2}", "exec")
        with contextlib.redirect_stdout(out):
            exec(compiled, self.namespace)  # noqa: S102 - the guide's own code
        return out.getvalue()


@contextlib.contextmanager
def _chdir(path: Path) -> Iterator[None]:
    previous = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(previous)


def paste_outputs(text: str, outputs: dict[int, str]) -> str:
    """The guide with the ```text block after each runnable block replaced by its new output.

    ``outputs`` maps a runnable block's first line to what it printed.
    """
    lines = text.split("\n")
    replacements = []
    for step in steps(text):
        if step.output is not None and step.block.first_line in outputs:
            body = [line.rstrip() for line in outputs[step.block.first_line].rstrip("\n").split("\n")]
            if any(line.startswith("```") for line in body):
                raise ValueError(f"output of lab.md line {step.block.first_line + 1} contains a code fence")
            replacements.append((step.output.first_line + 1, step.output.last_line, body))
    for start, end, body in sorted(replacements, reverse=True):
        lines[start:end] = body
    return "\n".join(lines)


def replace_between(text: str, name: str, body: str) -> str:
    """Replace what lies between ``<!-- NAME:begin -->`` and ``<!-- NAME:end -->``."""
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    if text.count(begin) != 1 or text.count(end) != 1:
        raise ValueError(f"lab.md must hold {begin} and {end} once each")
    head, rest = text.split(begin)
    _, tail = rest.split(end)
    return f"{head}{begin}\n{body.strip()}\n{end}{tail}"


def between(text: str, name: str) -> str:
    """What lies between ``<!-- NAME:begin -->`` and ``<!-- NAME:end -->`` (stripped)."""
    return text.split(f"<!-- {name}:begin -->")[1].split(f"<!-- {name}:end -->")[0].strip()
