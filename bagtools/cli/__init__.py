"""The ``bagtools`` command: a thin click shell over the library.

Each subcommand lives in its own module and is imported only when invoked, so
``bagtools --help`` stays fast. This module is the one error boundary: a
:class:`~bagtools.errors.BagtoolsError` becomes ``bagtools: <file>: <problem>``
on stderr and exit status 2; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import importlib
import sys

import click

from bagtools import __version__
from bagtools.errors import BagtoolsError

# name -> "module:attribute"; a command is registered here only once it works.
COMMANDS: dict[str, str] = {
    "info": "bagtools.cli.info:info",
    "tf": "bagtools.cli.tf:tf",
    "simulate": "bagtools.cli.simulate:simulate",
    "map-cloud": "bagtools.cli.map_cloud:map_cloud",
    "ndt-odom": "bagtools.cli.ndt_odom:ndt_odom",
    "grid": "bagtools.cli.grid:grid",
}


class LazyGroup(click.Group):
    """A click group that imports each subcommand's module on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        target = COMMANDS.get(cmd_name)
        if target is None:
            return None
        module_name, attr = target.split(":")
        return getattr(importlib.import_module(module_name), attr)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="bagtools")
def cli() -> None:
    """Tools over recorded ROS bags (MCAP, rosbag2 sqlite3, ROS 1).

    \b
    Example:
      bagtools simulate out/sim --duration 60
      bagtools info out/sim
    """


def main(argv: list[str] | None = None) -> None:
    """Console entry point: run the CLI and translate domain errors to exit status 2."""
    try:
        cli.main(args=argv, prog_name="bagtools", standalone_mode=False)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
    except click.Abort:
        click.echo("bagtools: aborted", err=True)
        sys.exit(130)
    except BagtoolsError as exc:
        click.echo(f"bagtools: {exc}", err=True)
        sys.exit(2)
    except KeyboardInterrupt:
        click.echo("bagtools: interrupted", err=True)
        sys.exit(130)
    except BrokenPipeError:
        sys.exit(0)
    sys.exit(0)
