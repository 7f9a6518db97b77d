"""``bagtools ndt-odom``: the robot's trajectory from its laser scans by 2D NDT scan matching."""

from __future__ import annotations

import click

from bagtools.cli.complete import complete_topics
from bagtools.cli.params import SCAN_FRAME_OFFSET_HELP, scan_frame_offset


@click.command("ndt-odom")
@click.argument("bag", type=click.Path(path_type=str))
@click.option("--out", "out_dir", required=True, type=click.Path(path_type=str), help="Output directory.")
@click.option("--topic", default="/scan", shell_complete=complete_topics, show_default=True, help="LaserScan topic.")
@click.option("--init", type=click.Choice(["auto", "odom", "constant-velocity", "zero"]), default="auto",
              show_default=True,
              help="Guess NDT starts from first (auto: the odometry when the bag has it, else constant velocity); "
                   "the others are tried too when they disagree.")
@click.option("--no-search", "no_search", is_flag=True,
              help="Never run the grid search, even when no guess can be trusted (faster, less robust).")
@click.option("--no-odometry", "no_odometry", is_flag=True, help="Ignore the bag's wheel odometry.")
@click.option("--holonomic", is_flag=True,
              help="The laser is handheld or flies: its steps need not follow a wheeled robot's arcs.")
@click.option("--reference", type=click.Choice(["previous", "keyframe"]), default="keyframe", show_default=True,
              help="Match against the previous scan, or a keyframe submap replaced after 0.5 m, 20 deg or a falling "
                   "score.")
@click.option("--cell-size", type=float, default=None,
              help="NDT cell side [m]  [default: a sixth of the scans' 90th-percentile range, within 0.5..1 m]")
@click.option("--cell-model", type=click.Choice(["widened", "paper"]), default="widened", show_default=True,
              help="NDT cell covariances: widened along walls (less drift) or as in Biber and Strasser's paper.")
@click.option("--min-score", type=float, default=0.1, show_default=True,
              help="Normalized NDT score in [0, 1] below which a match falls back to its guess.")
@click.option("--max-speed", type=float, default=1.5, show_default=True,
              help="Fastest the robot moves [m/s]: bounds constant velocity and the search.")
@click.option("--max-turn-rate", type=float, default=2.0, show_default=True, help="Fastest the robot turns [rad/s].")
@click.option("--scan-frame-offset", callback=scan_frame_offset, default=None, metavar="X,Y,YAW",
              help=SCAN_FRAME_OFFSET_HELP)
@click.option("--no-mcap", "no_mcap", is_flag=True, help="Do not write results.mcap.")
@click.option("--force", is_flag=True, help="Overwrite existing output files.")
def ndt_odom(bag: str, out_dir: str, topic: str, init: str, no_search: bool, no_odometry: bool, holonomic: bool,
             reference: str,
             cell_size: float | None, cell_model: str, min_score: float, max_speed: float, max_turn_rate: float,
             scan_frame_offset: tuple[float, float, float] | None, no_mcap: bool, force: bool) -> None:
    """Laser odometry of BAG: match its scans in order by 2D NDT and chain the motions.

    Each scan starts from the best guess (wheel odometry, constant velocity,
    no motion); when no guess can be trusted (a poor score, guesses that
    disagree, scans far apart, no odometry) a grid search over what the robot
    can have done seeds NDT. Odometry the scans contradict is not followed, and
    every such event is counted and warned about.

    Writes OUT/trajectory.tum (the robot base in the odometry frame, TUM format
    for evo), odometry.tum (wheel odometry at the scan stamps), ground_truth.tum
    (bags with /ground_truth), trajectory.png, scan_map.png, summary.json
    (matches, searches, fallbacks, rejected odometry, time per pair, and APE /
    RPE per metre of NDT and odometry against the ground truth, equal to
    evo_ape / evo_rpe on the same files) and results.mcap (open in Foxglove, or
    `ros2 bag play`: the trajectories as nav_msgs/Path, /tf, /tf_static, the
    scans at their stamps and /cloud_map, the scans at their NDT poses).

    \b
    Example:
      bagtools ndt-odom out/sim --out out/ndt
      evo_ape tum out/ndt/ground_truth.tum out/ndt/trajectory.tum
      bagtools ndt-odom real.bag --out ndt --scan-frame-offset -0.064,0,0 --no-odometry --no-mcap
    """
    from bagtools.errors import BagtoolsError
    from bagtools.commands.ndt_odom import NDT_ODOM_FILES, NdtOdomOptions, NdtOdomPipeline, write_ndt_odom
    from bagtools.outputs import check_outputs
    from bagtools.results import run_outputs

    check_outputs(out_dir, run_outputs(NDT_ODOM_FILES, not no_mcap), force, inputs=[bag])  # fail before the work, not after it

    options = NdtOdomOptions.from_params(click.get_current_context().params)
    result = NdtOdomPipeline(bag, options, keep_scans=not no_mcap).run()
    for warning in result.summary.get("warnings", []):
        click.echo(f"bagtools: warning: {warning}", err=True)
    if result.problem is not None:  # a failed run changes nothing in --out
        raise BagtoolsError(result.problem, bag)
    written = write_ndt_odom(result, out_dir, force, mcap=not no_mcap)
    s = result.summary
    click.echo(f"{s['scans_used']} scans: {s['pairs_matched']} pairs matched ({s['searched']} needed a search), "
               f"{s['fallbacks']} fell back to their guess, {s['odometry_rejected']} odometry steps rejected; "
               f"wrote {', '.join(p.name for p in written)} in {out_dir}")
    for name, label in (("errors_ndt", "NDT"), ("errors_odometry", "odometry")):
        ape = s.get(name, {}).get("ape_translation_m", {})
        rpe = s.get(name, {}).get("rpe_translation_m_per_1m", {})
        if "rmse" in ape:
            rpe_text = f"{rpe['rmse']:.4f} m per m" if "rmse" in rpe else "n/a"
            click.echo(f"{label}: APE rmse {ape['rmse']:.4f} m, RPE rmse {rpe_text}")
