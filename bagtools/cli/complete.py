"""Shell completion of names from the bag given earlier on the line: topics and tf frames.

Click completes commands and options by itself (see the README for the one line each shell needs); these add
what only the bag knows. A bag that cannot be read completes nothing: completion never prints an error into
the shell.
"""

from __future__ import annotations

import click
from click.shell_completion import CompletionItem

from bagtools.errors import BagtoolsError


def _bag(ctx: click.Context) -> str | None:
    """The BAG argument: parsed, or (while an option still waits for its value, click leaves the line unparsed)
    the first word of the command's arguments that is not an option."""
    return ctx.params.get("bag") or next((a for a in ctx.args if not a.startswith("-")), None)


def complete_topics(ctx: click.Context, param: click.Parameter, incomplete: str) -> list[CompletionItem]:
    """The bag's topics starting with ``incomplete``, each with its message type."""
    from bagtools.io import open_bag

    bag = _bag(ctx)
    if not bag:
        return []
    try:
        with open_bag(bag) as reader:
            topics = list(reader.topics.values())
    except (BagtoolsError, OSError):
        return []
    return [CompletionItem(t.name, help=t.msgtype) for t in topics if t.name.startswith(incomplete)]


def complete_frames(ctx: click.Context, param: click.Parameter, incomplete: str) -> list[CompletionItem]:
    """The bag's tf frames starting with ``incomplete``."""
    from bagtools.tf import TfBuffer

    bag = _bag(ctx)
    if not bag:
        return []
    try:
        frames = TfBuffer.from_bag(bag).frames
    except (BagtoolsError, OSError):
        return []
    return [CompletionItem(f) for f in frames if f.startswith(incomplete)]
