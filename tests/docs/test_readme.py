"""The README is the front door (issue #41): short, with the two commands, and a page per command.

README.md stays at most 150 lines; its "Two commands" section holds `make demo` and
`make test` (CI runs the README's test command, see .ci/run); every command `bagtools`
registers has its page docs/commands/<name>.md, linked from the README, naming every
option the command has; every relative link of the README and of the pages resolves.
"""

from __future__ import annotations

import re
from pathlib import Path

import click

from bagtools.cli import cli

REPO = Path(__file__).resolve().parents[2]
README = REPO / "README.md"
PAGES = REPO / "docs" / "commands"
MAX_README_LINES = 150

LINK = re.compile(r"\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
FENCE = re.compile(r"^(```|~~~).*?^\1", re.MULTILINE | re.DOTALL)
INLINE_CODE = re.compile(r"`[^`\n]*`")


def _registered_commands() -> dict[str, click.Command]:
    """Every command `bagtools --help` lists, by name.

    The group is lazy (each command's module is imported on first use), so its
    ``.commands`` mapping is empty until then: ask it as click's help does.
    """
    ctx = click.Context(cli)
    commands = {name: cli.get_command(ctx, name) for name in cli.list_commands(ctx)}
    assert commands, "bagtools registers no command"
    assert all(command is not None for command in commands.values())
    return commands


def _options(command: click.Command) -> set[str]:
    """The long option names of a command (and of its subcommands, for a group like `tf`), without --help."""
    names = {opt for param in command.params if isinstance(param, click.Option) for opt in param.opts
             if opt.startswith("--")}
    if isinstance(command, click.Group):
        for sub in command.commands.values():
            names |= _options(sub)
    return names - {"--help"}


def _section(text: str, title: str) -> str:
    """The body of the `## title` section of a markdown text (up to the next heading of level 1 or 2)."""
    match = re.search(rf"^## {re.escape(title)}\s*$(.*?)(?=^#{{1,2}} |\Z)", text, re.MULTILINE | re.DOTALL)
    assert match, f"no '## {title}' section"
    return match.group(1)


def _relative_links(path: Path) -> list[str]:
    """The link targets of a markdown file outside code, except web links and in-page anchors."""
    text = INLINE_CODE.sub("", FENCE.sub("", path.read_text()))
    targets = []
    for target in LINK.findall(text):
        if re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target) or target.startswith("#"):  # http(s), mailto, anchors
            continue
        targets.append(target.split("#", 1)[0])
    return targets


def test_the_readme_is_at_most_150_lines() -> None:
    lines = README.read_text().splitlines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines; move reference text to docs/commands/"


def test_the_two_commands_section_holds_make_demo_and_make_test() -> None:
    two = _section(README.read_text(), "Two commands")
    assert "make demo" in two
    assert "make test" in two
    assert "make test" in (REPO / ".ci" / "run").read_text(), "CI must run the README's test command"


def test_every_registered_command_has_a_page_linked_from_the_readme() -> None:
    readme = README.read_text()
    linked = {Path(target).as_posix() for target in _relative_links(README)}
    for name in _registered_commands():
        page = PAGES / f"{name}.md"
        assert page.is_file(), f"no page for `bagtools {name}`: {page.relative_to(REPO)}"
        assert f"docs/commands/{name}.md" in linked, f"README.md does not link docs/commands/{name}.md"
        assert f"bagtools {name}" in readme, f"README.md has no synopsis of `bagtools {name}`"


def test_every_page_names_its_commands_options() -> None:
    for name, command in _registered_commands().items():
        page = (PAGES / f"{name}.md").read_text()
        assert f"bagtools {name} --help" in page, f"docs/commands/{name}.md does not point to `bagtools {name} --help`"
        missing = sorted(opt for opt in _options(command) if not re.search(rf"{re.escape(opt)}(?![\w-])", page))
        assert not missing, f"docs/commands/{name}.md does not name {missing}"


def test_every_relative_link_of_the_readme_and_the_pages_resolves() -> None:
    files = [README, *sorted(PAGES.glob("*.md"))]
    assert len(files) > 1, "docs/commands/ has no pages"
    broken = []
    for path in files:
        for target in _relative_links(path):
            if not target:
                continue
            resolved = (path.parent / target).resolve()
            if not resolved.is_file():
                broken.append(f"{path.relative_to(REPO)}: ({target})")
    assert not broken, "links to files that do not exist:\n" + "\n".join(broken)
