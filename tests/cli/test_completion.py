"""Shell completion: topics and tf frames come from the bag given earlier on the line."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import click

from bagtools.cli.complete import complete_frames, complete_topics


def _complete(words: list[str]) -> list[str]:
    """What bash completion offers for the last word of ``bagtools WORDS`` (click's bash_complete protocol)."""
    env = dict(os.environ, _BAGTOOLS_COMPLETE="bash_complete", COMP_WORDS=" ".join(["bagtools", *words]),
               COMP_CWORD=str(len(words)))
    out = subprocess.run([sys.executable, "-c", "from bagtools.cli import main; main()"], env=env,
                         capture_output=True, text=True, timeout=120).stdout
    return [line.split(",", 1)[1] for line in out.splitlines() if "," in line]


def test_topics_and_frames_of_the_bag(synthetic_bag: Path) -> None:
    ctx = click.Context(click.Command("export"))
    ctx.params = {"bag": str(synthetic_bag)}
    assert [c.value for c in complete_topics(ctx, None, "/s")] == ["/scan"]
    assert {c.value for c in complete_frames(ctx, None, "base")} == {"base_link", "base_scan"}
    ctx.params = {"bag": str(synthetic_bag.parent / "missing")}
    assert complete_topics(ctx, None, "") == [] and complete_frames(ctx, None, "") == []  # never an error


def test_the_shell_gets_them(synthetic_bag: Path) -> None:
    assert _complete(["export", str(synthetic_bag), "/c"]) == ["/cloud"]
    assert _complete(["tf", "echo", str(synthetic_bag), "od"]) == ["odom"]
    assert _complete(["slam", str(synthetic_bag), "--topic", "/sc"]) == ["/scan"]
