"""``bagtools localize``: where the robot was in a map it already has, at every scan, with no initial pose."""

from __future__ import annotations

import click

from bagtools.cli.complete import complete_topics
from bagtools.cli.params import SCAN_FRAME_OFFSET_HELP, initial_pose, scan_frame_offset


@click.command("localize")
@click.argument("bag", type=click.Path(path_type=str))
@click.option("--map", "map_yaml", required=True, type=click.Path(path_type=str),
              help="The nav2 map to localize in (map.yaml, as map_server reads it).")
@click.option("--out", "out_dir", required=True, type=click.Path(path_type=str), help="Output directory.")
@click.option("--topic", default="/scan", shell_complete=complete_topics, show_default=True, help="LaserScan topic.")
@click.option("--initial-pose", callback=initial_pose, default=None, metavar="X,Y,YAW",
              help="The robot base's pose in the map at the first scan [m, m, rad]; without it the whole map is "
                   "searched.")
@click.option("--no-odometry", is_flag=True, help="Ignore the bag's wheel odometry (/odom, tf): scans only.")
@click.option("--scan-frame-offset", callback=scan_frame_offset, default=None, metavar="X,Y,YAW",
              help=SCAN_FRAME_OFFSET_HELP)
@click.option("--no-smoothing", is_flag=True,
              help="Each scan's own match on the map, as an online localizer has it (default: the path smoothed "
                   "with the laser odometry, offline).")
@click.option("--no-mcap", is_flag=True, help="Do not write results.mcap (the map, the paths and the scans, for Foxglove).")
@click.option("--force", is_flag=True, help="Overwrite existing output files.")
def localize(bag: str, map_yaml: str, out_dir: str, topic: str, initial_pose: tuple[float, float, float] | None,
             no_odometry: bool, scan_frame_offset: tuple[float, float, float] | None, no_smoothing: bool,
             no_mcap: bool, force: bool) -> None:
    """Localize BAG's laser scans in a map it already has (nav2 map.yaml), from no initial pose.

    The first scans are searched for over the whole map at every heading; the
    places that match are followed until the scans tell them apart (a map that
    repeats itself is said to); then each scan is matched against the map with
    the odometry's step as its prior. While the laser odometry goes on matching
    scan to scan, the robot is held near where it says: a scan the map does not
    explain there (a part it saw only from afar) is carried by the motion, not
    moved to a look-alike. A robot that is lost (kidnapped: the scans break
    off) is searched for again, counted and shown. Last,
    the path is smoothed: the map matches and the laser odometry in one pose
    graph (GTSAM), cut where the robot was lost.

    Writes OUT/trajectory.tum (the robot base in the map frame at every
    localized scan), map_to_odom.tum (the correction a localizer publishes),
    localization.png (the map, the path, the first fix, lost and recovered
    places), summary.json (per-scan score and state, time to the first fix,
    lost and recovered counts), results.mcap (for Foxglove), and where the bag
    has its own localization (AMCL's map -> odom on /tf, or its /amcl_pose)
    bag_localizer.tum and localizer_comparison.png: where the two part, and by
    how much;
    ground_truth.tum and both localizers' errors for simulated bags.

    \b
    Example:
      bagtools grid out/sim --out out/grid --poses ground-truth
      bagtools localize out/sim2 --map out/grid/map.yaml --out out/localize
      bagtools localize robot.mcap --map building/map.yaml --out loc --no-odometry
      bagtools localize robot.mcap --map building/map.yaml --out loc --initial-pose 2.0,-1.5,1.57
    """
    from bagtools.commands.localize import LOCALIZE_FILES, LocalizeOptions, LocalizePipeline, write_localize
    from bagtools.outputs import check_outputs
    from bagtools.results import run_outputs

    check_outputs(out_dir, run_outputs(LOCALIZE_FILES, not no_mcap), force, inputs=[bag, map_yaml])  # fail before the work, not after it
    options = LocalizeOptions.from_params(click.get_current_context().params)
    result = LocalizePipeline(bag, map_yaml, options, keep_scans=not no_mcap).run()
    s = result.summary
    for warning in s.get("warnings", []):
        click.echo(f"bagtools: warning: {warning}", err=True)
    written = write_localize(result, out_dir, force, mcap=not no_mcap)
    fix = s["first_fix"]
    fix_text = "no fix" if fix is None else f"first fix {fix['seconds_after_first_scan']:.1f} s after the first scan"
    click.echo(f"{s['scans_localized']} of {s['scans']} scans localized; {fix_text}; lost {s['lost']}, "
               f"recovered {s['recovered']}; corrected {s['corrected']}; {s['speed_x_real_time']:.0f}x real time")
    own = s.get("bag_localizer")
    if own and own.get("scans_compared"):
        click.echo(f"the bag's own localizer: {own['translation_m']['mean']:.3f} m and {own['heading_deg']['mean']:.2f} "
                   f"deg from ours on average (max {own['translation_m']['max']:.3f} m), parting in "
                   f"{len(own['parts'])} stretch(es)")
    for name, label in (("ours", "ours"), ("bag_localizer", "the bag's localizer")):
        errors = s.get("ground_truth", {}).get(name, {})
        ape, aligned = errors.get("ape_m", {}).get("rmse"), errors.get("ape_aligned_m", {}).get("rmse")
        if ape is not None and aligned is not None:
            click.echo(f"APE against /ground_truth, {label}: {ape:.4f} m (rmse), {aligned:.4f} m after SE(2) alignment "
                       "(the aligned figure counts when the map has a frame of its own, as a SLAM map does)")
    click.echo(f"wrote {', '.join(p.name for p in written)} in {out_dir}")
