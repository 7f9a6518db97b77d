"""``bagtools grid``: an occupancy-grid map (nav2 format) from a bag's laser scans at known poses."""

from __future__ import annotations

import json

import click

from bagtools.cli.complete import complete_topics
from bagtools.cli.params import SCAN_FRAME_OFFSET_HELP, scan_frame_offset
from bagtools.cli.params import cell_size as map_cell_side


@click.command("grid")
@click.argument("bag", type=click.Path(path_type=str))
@click.option("--out", "out_dir", required=True, type=click.Path(path_type=str), help="Output directory.")
@click.option("--topic", default="/scan", shell_complete=complete_topics, show_default=True, help="LaserScan topic.")
@click.option("--poses", default="tf", show_default=True, metavar="tf|ground-truth|TRAJ.tum",
              help="Scan poses: the bag's tf, the simulator's /ground_truth, or a TUM trajectory of the robot base "
                   "in --frame (e.g. bagtools ndt-odom's trajectory.tum).")
@click.option("--frame", default=None,
              help="Fixed frame to build the map in  [default: map, or the frame a bagtools TUM file --poses names]")
@click.option("--cell-size", type=float, default=None, help="Map cell side in METRES.  [default: 0.05]")
@click.option("--cells-per-metre", type=float, default=None, help="Map cells per metre (20: 5 cm cells), instead.")
@click.option("--resolution", type=float, default=None,
              help="Old spelling: cells per metre here (MATLAB's), metres per cell in slam (nav2's); prefer --cell-size.")
@click.option("--max-range", type=float, default=None,
              help="Lower the scans' range_max to this [m]; farther returns only clear free space.")
@click.option("--base-frame", default=None,
              help="Robot frame a TUM trajectory describes (default: /odom's child frame, or base_footprint/base_link).")
@click.option("--scan-frame-offset", callback=scan_frame_offset, default=None, metavar="X,Y,YAW",
              help=SCAN_FRAME_OFFSET_HELP)
@click.option("--no-mcap", "no_mcap", is_flag=True, help="Do not write results.mcap.")
@click.option("--force", is_flag=True, help="Overwrite existing output files.")
def grid(bag: str, out_dir: str, topic: str, poses: str, frame: str | None, cell_size: float | None,
         cells_per_metre: float | None, resolution: float | None, max_range: float | None,
         base_frame: str | None, scan_frame_offset: tuple[float, float, float] | None, no_mcap: bool,
         force: bool) -> None:
    """Build an occupancy grid of BAG's laser scans ("mapping with known poses").

    Writes OUT/map.pgm + OUT/map.yaml (ROS map_server / nav2 format: load with
    nav2's map_server), OUT/map.png (the map with the scan path),
    OUT/summary.json (scans used and skipped by reason, grid size, and for
    simulated bags the map scored against the true world) and OUT/results.mcap
    (open in Foxglove, or `ros2 bag play`: /map latched as map_server publishes
    it, /trajectory, /tf, /tf_static and the scans at their stamps).

    \b
    Example:
      bagtools grid out/sim --out out/grid
      bagtools grid out/sim --out out/grid_odom --frame odom --cell-size 0.1 --force
      bagtools grid run.mcap --out grid_ndt --poses ndt/trajectory.tum
      bagtools grid real.bag --out grid --scan-frame-offset -0.064,0,0 --no-mcap
    """
    from bagtools.commands.grid import GRID_MAP_FILES, GridMapOptions, GridMapPipeline, write_grid_map
    from bagtools.outputs import check_outputs
    from bagtools.results import run_outputs

    side, note = map_cell_side(cell_size, cells_per_metre, resolution, resolution_in_metres=False)

    check_outputs(out_dir, run_outputs(GRID_MAP_FILES, not no_mcap), force, inputs=[bag, *([poses] if poses not in ('tf', 'ground-truth') else [])])  # fail before the work, not after it

    options = GridMapOptions.from_params(click.get_current_context().params)
    result = GridMapPipeline(bag, options, keep_scans=not no_mcap).run()
    for warning in result.summary.get("warnings", []):
        click.echo(f"bagtools: warning: {warning}", err=True)
    write_grid_map(result, out_dir, force, mcap=not no_mcap)
    if note:
        click.echo(f"bagtools: note: {note}", err=True)
    s, g = result.summary, result.summary["grid"]
    click.echo(f"{s['scans_used']} of {s['scans_total']} scans mapped, skipped {json.dumps(s['scans_skipped'])}; "
               f"{g['cols']}x{g['rows']} cells (width x height) of {g['cell_size_m']:g} m in {out_dir}/map.yaml")
    if "accuracy_vs_truth" in s:
        a = {k: ("n/a" if v is None else f"{v:.3f}") for k, v in s["accuracy_vs_truth"].items()
             if k in ("occupied_precision", "occupied_recall", "free_share")}
        click.echo(f"vs true world: occupied precision {a['occupied_precision']}, recall {a['occupied_recall']} "
                   f"(within 1 cell), true free space marked free {a['free_share']}")
