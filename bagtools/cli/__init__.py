"""The ``bagtools`` command: a thin click shell over the library.

Each subcommand lives in its own module and is imported only when invoked, so
``bagtools --help`` stays fast. This module is the one error boundary: every error
becomes one line, ``bagtools: <file>: <problem>``, on stderr and exit status 2
(see :func:`main`).
"""

from __future__ import annotations

import importlib
import os
import signal
import sys
import traceback

import click

# One thread per BLAS call, set before numpy loads (a user's own setting wins). The work is many small products (a
# scan's points by a rotation), which OpenBLAS splits across the cores and then spins on: slam of the FHW log took
# 37 CPU s with it and 23 without, in the same wall time and with identical results. Dask's workers do the same.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from bagtools import __version__  # noqa: E402
from bagtools.errors import BagtoolsError  # noqa: E402

# name -> "module:attribute"; a command is registered here only once it works.
COMMANDS: dict[str, str] = {
    "info": "bagtools.cli.info:info",
    "tf": "bagtools.cli.tf:tf",
    "simulate": "bagtools.cli.simulate:simulate",
    "map-cloud": "bagtools.cli.map_cloud:map_cloud",
    "ndt-odom": "bagtools.cli.ndt_odom:ndt_odom",
    "grid": "bagtools.cli.grid:grid",
    "slam": "bagtools.cli.slam:slam",
    "localize": "bagtools.cli.localize:localize",
    "export": "bagtools.cli.export:export",
    "eval": "bagtools.cli.evaluate:evaluate",
    "batch": "bagtools.cli.batch:batch",
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


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]}, invoke_without_command=True)
@click.version_option(__version__, prog_name="bagtools")
@click.pass_context
def cli(ctx: click.Context) -> None:
    """Tools over recorded ROS bags (MCAP, rosbag2 sqlite3, ROS 1) and CARMEN logs.

    \b
    Example:
      bagtools simulate out/sim --duration 60
      bagtools info out/sim
    """
    if ctx.invoked_subcommand is None:  # `bagtools` alone: the help, as git and ros2 print theirs
        click.echo(ctx.get_help())


def _input_name(argv: list[str]) -> str | None:
    """The file a command line is about: the first argument after the command names that is not an option."""
    names = set(COMMANDS) | {"frames", "echo", "point"}
    for arg in argv:
        if arg.startswith("-") or arg in names:
            continue
        return arg
    return None


def _usage_line(exc: click.UsageError, argv: list[str]) -> str:
    """A click usage error as one line that names the file (when there is one) and points to --help."""
    ctx = exc.ctx
    command = ctx.command_path if ctx is not None else "bagtools"
    problem = " ".join(exc.format_message().split()).rstrip(".")
    if problem:
        problem = problem[0].lower() + problem[1:]
    # A bad value of a parameter is said with the file it was given for; a command line that is wrong as a whole
    # (an unexpected extra argument, a missing option, an unknown command) blames no file.
    about_a_value = isinstance(exc, click.BadParameter) and not isinstance(exc, click.MissingParameter)
    subject = _input_name(argv) if about_a_value and exc.param_hint != "COMMAND" else None
    prefix = f"{subject}: " if subject else ""
    return f"bagtools: {prefix}{problem} (see '{command} --help')"


class Terminated(BaseException):
    """SIGTERM or SIGHUP arrived: unwind like Ctrl-C, so staged outputs are removed."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated(signum)


def _deliver_again(unraisable: object) -> None:
    """``sys.unraisablehook`` while a command runs: a :class:`Terminated` raised where Python can only ignore it
    (the signal arrived during a weakref or import-lock callback) is not lost: the signal is sent again a moment
    later, from a helper thread, and raised once the main thread is out of the callback. Anything else goes to
    Python's own hook."""
    exc = getattr(unraisable, "exc_value", None)
    if isinstance(exc, Terminated):
        import threading

        threading.Timer(0.01, os.kill, (os.getpid(), exc.signum)).start()
        return
    sys.__unraisablehook__(unraisable)


def main(argv: list[str] | None = None) -> None:
    """Console entry point: run the CLI and translate errors to one line and exit status 2.

    Domain errors (:class:`BagtoolsError`), click's usage errors and the
    operating system's refusals (:class:`OSError`) become ``bagtools: <file>:
    <problem>``. Anything else is a bug: it is reported on one line as an
    internal error naming the input, with the traceback when BAGTOOLS_DEBUG is
    set, and exit status 2 so scripts treat it as a failed input.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    previous = {sig: signal.signal(sig, _raise_terminated) for sig in (signal.SIGTERM, signal.SIGHUP)}
    previous_hook, sys.unraisablehook = sys.unraisablehook, _deliver_again
    try:
        code = _run(args)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        sys.unraisablehook = previous_hook
    sys.exit(code)


def _run(args: list[str]) -> int:
    try:
        # Without standalone mode click returns (not raises) the status of ctx.exit(n), e.g. batch's 1.
        status = cli.main(args=args, prog_name="bagtools", standalone_mode=False)
    except click.exceptions.Exit as exc:
        return exc.exit_code
    except click.UsageError as exc:
        if type(exc).__name__ == "NoArgsIsHelpError" and exc.ctx is not None:  # bare `bagtools` or `bagtools tf`
            click.echo(exc.ctx.get_help(), err=True)
        else:
            click.echo(_usage_line(exc, args), err=True)
        return 2
    except click.ClickException as exc:
        click.echo(f"bagtools: {' '.join(exc.format_message().split())}", err=True)
        return exc.exit_code
    except (click.Abort, KeyboardInterrupt):
        click.echo("bagtools: interrupted; nothing was written", err=True)
        return 130
    except Terminated as exc:
        click.echo(f"bagtools: terminated by signal {exc.signum}; nothing was written", err=True)
        return 128 + exc.signum
    except BrokenPipeError:
        return 0
    except BagtoolsError as exc:
        if exc.path is None:  # an option's value: name the input it was given for
            exc.path = _input_name(args)
        click.echo(f"bagtools: {exc}", err=True)
        return 2
    except OSError as exc:
        where = exc.filename if exc.filename is not None else _input_name(args)
        click.echo(f"bagtools: {where}: {exc.strerror or exc}", err=True)
        return 2
    except MemoryError:
        click.echo(f"bagtools: {_input_name(args)}: out of memory (is the input damaged, or an option too large?)",
                   err=True)
        return 2
    except Exception as exc:  # a bug: one line for the user, the traceback on request
        if os.environ.get("BAGTOOLS_DEBUG"):
            traceback.print_exc()
        detail = " ".join(str(exc).split())[:300]
        click.echo(f"bagtools: {_input_name(args)}: internal error ({type(exc).__name__}: {detail}); "
                   "please report it with BAGTOOLS_DEBUG=1 set for the traceback", err=True)
        return 2
    return status if isinstance(status, int) else 0
