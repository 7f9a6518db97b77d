"""``bagtools batch``: one command over many bags on Dask, resumable, with a fleet table."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import click

from bagtools.errors import BagtoolsError

if TYPE_CHECKING:
    from bagtools.batch import BatchPlan

#: More worker processes than this on one machine is a typo (each is a Python process of its own).
MAX_WORKERS = 1024

_COMMAND_ARGS = "bagtools.batch.command_args"
_OUT_PLACEHOLDER = "<batch --out>"
_MAX_FAILURES_SHOWN = 20


class _BatchCommand(click.Command):
    """Keeps what follows ``--`` for COMMAND: click would otherwise take it for more BAGS."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        if "--" in args:
            cut = args.index("--")
            ctx.meta[_COMMAND_ARGS] = args[cut + 1:]
            args = args[:cut]
        return super().parse_args(ctx, args)


def _command_params(command: str, args: list[str]) -> dict:
    """COMMAND OPTIONS parsed by COMMAND's own click command (same options, same checks); exit 2 when bad."""
    from bagtools.batch import get_job
    from bagtools.cli import COMMANDS, cli

    try:  # an unknown or unbatchable command is refused first, as a problem of the command line, not of a bag
        get_job(command, set(COMMANDS))
    except BagtoolsError as err:
        raise click.BadParameter(err.problem, param_hint="COMMAND") from err
    group_ctx = click.get_current_context().find_root()
    sub = cli.get_command(group_ctx, command)
    takes_out = any(p.name == "out_dir" for p in sub.params)
    argv = [_OUT_PLACEHOLDER, *(["--out", _OUT_PLACEHOLDER] if takes_out else []), *args]
    with sub.make_context(command, argv, parent=group_ctx) as sub_ctx:
        params = dict(sub_ctx.params)
    batch_ctx = click.get_current_context()
    if takes_out and params.pop("out_dir") != _OUT_PLACEHOLDER:
        raise click.UsageError("--out is batch's own option: give it before '--'", batch_ctx)
    if params.pop("force", False):
        raise click.UsageError("--force is batch's own option: give it before '--'", batch_ctx)
    params.pop("bag")
    return params


@click.command("batch", cls=_BatchCommand)
@click.argument("command")
@click.argument("bags", nargs=-1, required=True)
@click.option("--out", "out_dir", required=True, type=click.Path(path_type=str),
              help="Output directory: DIR/<bag>/ per bag, and DIR/fleet.csv, fleet.parquet, fleet.png.")
@click.option("--workers", type=click.IntRange(min=1, max=MAX_WORKERS), default=None,
              help="Worker processes of the embedded Dask cluster  [default: one per core]")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Use an existing Dask cluster (e.g. tcp://host:8786) instead of starting one; its workers must "
                   "see the bags and DIR at the same paths.")
@click.option("--force", is_flag=True, help="Redo every bag, replacing its outputs (the command's own files only).")
def batch(command: str, bags: tuple[str, ...], out_dir: str, workers: int | None, scheduler: str | None,
          force: bool) -> None:
    """Run COMMAND on every bag of BAGS in parallel on Dask, one row per bag in DIR/fleet.csv.

    COMMAND is a bagtools command that reads one bag: info (writes
    info.json), map-cloud, grid, ndt-odom, slam or localize; its options follow '--'. BAGS are
    paths or globs; a folder is searched for rosbag2 directories and .mcap,
    .db3 and .bag files. Each bag's outputs go to DIR/<bag>/, exactly as the
    command writes its --out. A failed bag is a row with its error (exit
    status 1), never the end of the batch. A rerun skips the bags already
    done and does the rest; --force redoes all.

    \b
    Example:
      bagtools batch ndt-odom /data/2026-11-22/ --out fleet/ndt
      bagtools batch grid 'runs/*/robot*' --out fleet/grid --workers 4 -- --cell-size 0.1
      bagtools batch info /nfs/bags --out /nfs/fleet/info --scheduler tcp://head:8786
      bagtools batch localize 'runs/*.mcap' --out fleet/localize -- --map building/map.yaml
    """
    from bagtools.batch import plan_batch
    from bagtools.cli import COMMANDS

    ctx = click.get_current_context()
    if scheduler is not None and workers is not None:
        raise click.UsageError("--workers sizes the embedded cluster; a --scheduler's cluster has its own workers", ctx)
    if scheduler is not None and not scheduler.strip():
        raise click.UsageError("--scheduler is empty: give the cluster's address (tcp://host:8786), or leave the "
                               "option out for a cluster on this machine", ctx)
    params = _command_params(command, list(ctx.meta.get(_COMMAND_ARGS, [])))
    plan = plan_batch(command, bags, out_dir, params, force, available=set(COMMANDS))
    try:
        _run_plan(plan, command, out_dir, workers, scheduler)
    finally:
        plan.release()


def _run_plan(plan: BatchPlan, command: str, out_dir: str, workers: int | None, scheduler: str | None) -> None:
    """Run the planned batch, write the fleet table and say how it went (exit status 1 when a bag failed)."""
    from bagtools.batch import FAILED, SKIPPED, BatchRun, ClusterSpec, write_fleet
    from bagtools.cli import Terminated

    done_before = len(plan.decided)
    if done_before:
        click.echo(f"{done_before} of {plan.total} bags need no work (done before, or refused); "
                   f"{len(plan.tasks)} to run", err=True)
    t0 = time.perf_counter()
    run = BatchRun(plan, ClusterSpec(workers=workers, scheduler=scheduler), lambda text: click.echo(text, err=True))
    try:
        rows = run.run()
    except (KeyboardInterrupt, Terminated) as exc:
        finished = run.done_count()
        how = f"terminated by signal {exc.signum}" if isinstance(exc, Terminated) else "interrupted"
        left = len(plan.tasks) - finished
        click.echo(f"bagtools: {how}: {finished} of {len(plan.tasks)} bags done, their outputs kept in {out_dir}; "
                   + (f"run the same command again to do the other {left}" if left else
                      "run the same command again to write the fleet table"), err=True)
        raise click.exceptions.Exit(128 + exc.signum if isinstance(exc, Terminated) else 130) from None
    elapsed = time.perf_counter() - t0
    counts = {s: sum(r["status"] == s for r in rows) for s in ("ok", SKIPPED, FAILED)}
    written = write_fleet(plan.out_dir, rows, plan.job,
                          title=f"bagtools batch {command}: {counts['ok']} ok, {counts[SKIPPED]} skipped, "
                                f"{counts[FAILED]} failed of {len(rows)} bags")
    failed = [row for row in rows if row["status"] == FAILED]
    for row in failed[:_MAX_FAILURES_SHOWN]:
        click.echo(f"bagtools: {row['bag']}: failed: {row['error']}", err=True)
    if len(failed) > _MAX_FAILURES_SHOWN:
        click.echo(f"bagtools: ... and {len(failed) - _MAX_FAILURES_SHOWN} more failed bags (see fleet.csv)", err=True)
    click.echo(f"{len(rows)} bags: {counts['ok']} ok, {counts[SKIPPED]} skipped (done before), {counts[FAILED]} failed "
               f"in {elapsed:.1f} s; wrote {', '.join(p.name for p in written)} in {out_dir}")
    if counts[FAILED]:
        raise click.exceptions.Exit(1)
