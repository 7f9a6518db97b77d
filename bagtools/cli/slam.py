"""``bagtools slam``: laser SLAM of a bag: laser odometry, loop closure, a GTSAM pose graph, the map."""

from __future__ import annotations

import click

from bagtools.cli.complete import complete_topics
from bagtools.cli.params import SCAN_FRAME_OFFSET_HELP, scan_frame_offset
from bagtools.cli.params import cell_size as map_cell_side


@click.command("slam")
@click.argument("bag", type=click.Path(path_type=str))
@click.option("--out", "out_dir", required=True, type=click.Path(path_type=str), help="Output directory.")
@click.option("--topic", default="/scan", shell_complete=complete_topics, show_default=True, help="LaserScan topic.")
@click.option("--cell-size", type=float, default=None, help="Map cell side in METRES.  [default: 0.05]")
@click.option("--cells-per-metre", type=float, default=None, help="Map cells per metre (20: 5 cm cells), instead.")
@click.option("--resolution", type=float, default=None,
              help="Old spelling: metres per cell here (nav2's), cells per metre in grid (MATLAB's); prefer --cell-size.")
@click.option("--loop-search-radius", type=float, default=5.0, show_default=True,
              help="Match keyframes this far apart [m] (plus their estimated drift) for loop closure.")
@click.option("--loop-min-score", type=float, default=0.5, show_default=True,
              help="Correlative score in [0, 1] a loop-closure match needs.")
@click.option("--no-loop-closure", is_flag=True, help="Keep the laser odometry's trajectory (no loop search).")
@click.option("--no-odometry", is_flag=True, help="Ignore the bag's wheel odometry (/odom, tf): scans only.")
@click.option("--max-range", type=float, default=None,
              help="Use returns up to this range [m] (map and loop closure); farther ones only clear free space. "
                   "[default: 20 m]")
@click.option("--relations", type=click.Path(path_type=str), default=None,
              help="Score both trajectories against this .relations file of the log (Kuemmerle et al. 2009: "
                   "'stamp_1 stamp_2 x y z roll pitch yaw' per line, as published for the Intel, Freiburg and MIT "
                   "benchmark logs).")
@click.option("--scan-frame-offset", callback=scan_frame_offset, default=None, metavar="X,Y,YAW",
              help=SCAN_FRAME_OFFSET_HELP)
@click.option("--no-mcap", is_flag=True, help="Do not write results.mcap (the map, paths, scans and loops for Foxglove).")
@click.option("--force", is_flag=True, help="Overwrite existing output files.")
def slam(bag: str, out_dir: str, topic: str, cell_size: float | None, cells_per_metre: float | None,
         resolution: float | None, loop_search_radius: float, loop_min_score: float,
         no_loop_closure: bool, no_odometry: bool, max_range: float | None, relations: str | None,
         scan_frame_offset: tuple[float, float, float] | None, no_mcap: bool, force: bool) -> None:
    """SLAM of BAG's laser scans: laser odometry, loop closures, a pose graph optimized with GTSAM, the map.

    Writes OUT/trajectory.tum (the optimized robot base pose at every scan, in
    the map frame), odometry.tum (the laser odometry alone), pose_graph.g2o
    (keyframes and constraints, VERTEX_SE2/EDGE_SE2), map.pgm + map.yaml (nav2
    map_server format), map.png (the map, the trajectory and the loop
    closures), summary.json (keyframes, loop candidates accepted and rejected by
    reason, optimization, timing, and for bags with /ground_truth, or with
    --relations, the errors of SLAM and of the laser odometry), ground_truth.tum (bags with /ground_truth)
    and results.mcap (/map, the paths, /tf, the scans and /loop_closures, to
    open in Foxglove or replay for RViz).

    \b
    Example:
      bagtools slam out/sim --out out/slam
      bagtools slam csail.mcap --out slam_scans --no-odometry --max-range 30
      bagtools slam intel --out slam_intel --relations intel.relations
      bagtools slam fr079.clf --out slam_fr079 --scan-frame-offset -0.04,0,0
      bagtools eval out/slam/trajectory.tum out/slam/ground_truth.tum --align --gap 20
    """
    from bagtools.outputs import check_outputs
    from bagtools.results import run_outputs
    from bagtools.commands.slam import SLAM_FILES, SlamOptions, SlamPipeline, write_slam
    from bagtools.pose_graph.backend import TAKEN_BY_GRAPH

    side, note = map_cell_side(cell_size, cells_per_metre, resolution, resolution_in_metres=True)

    check_outputs(out_dir, run_outputs(SLAM_FILES, not no_mcap), force, inputs=[bag, *([relations] if relations else [])])  # fail before the work, not after it

    options = SlamOptions.from_params(click.get_current_context().params)
    result = SlamPipeline(bag, options).run()
    for warning in result.summary.get("warnings", []):
        click.echo(f"bagtools: warning: {warning}", err=True)
    written = write_slam(result, out_dir, force, mcap=not no_mcap)
    if note:
        click.echo(f"bagtools: note: {note}", err=True)
    s = result.summary
    loops = s["loop_closure"]
    reasons = ", ".join(f"{n} {why}" for why, n in loops["rejected_by_reason"].items())
    uncertain = s["front_end"].get("ambiguous", 0)
    revised = s["front_end"].get("revised_by_the_next_scan", 0)  # contested steps the next scan decided otherwise
    taken = s["graph"].get(TAKEN_BY_GRAPH, 0)  # matches no second one confirmed, taken by the graph's GNC
    click.echo(f"{s['scans']} scans, {s['keyframes']} keyframes; {loops['candidates']} loop candidates: "
               f"{loops['accepted']} accepted{f' ({taken} unconfirmed, taken by the graph)' if taken else ''}, "
               f"{loops['rejected']} rejected{f' ({reasons})' if reasons else ''}; "
               f"optimized in {s['optimization']['time_s']:.2f} s; {s['timing_s']['total']:.1f} s in all"
               + (f"; {uncertain} front-end step(s) left uncertain (another place matched almost as well)"
                  if uncertain else "")
               + (f"; {revised} contested step(s) changed by the scan after them" if revised else ""))
    click.echo(f"wrote {', '.join(p.name for p in written)} in {out_dir}")
    for name, label in (("errors_slam", "SLAM"), ("errors_front_end", "laser odometry")):
        errors = s.get(name)
        if not errors:
            continue
        ape = errors["ape_aligned_m"].get("rmse")
        gap = errors["relative_gap_20"].get("trans_mean_m")
        if ape is not None:
            gap_text = f"{gap:.3f} m" if gap is not None else "n/a"
            click.echo(f"{label}: APE {ape:.3f} m after alignment (rmse), motion error over 20 scans {gap_text} (mean)")
    for name, label in (("slam", "SLAM"), ("front_end", "laser odometry")):
        scored = s.get("relations", {}).get(name)
        if not scored:
            continue
        if "trans_mean_m" not in scored:
            click.echo(f"{label}: relations: {scored.get('unavailable')}")
            continue
        click.echo(f"{label}: relations error {scored['trans_mean_m']:.3f} +- {scored['trans_std_m']:.3f} m, "
                   f"{scored['rot_mean_deg']:.2f} +- {scored['rot_std_deg']:.2f} deg over {scored['used']} of "
                   f"{scored['relations']} relations" +
                   (f" ({scored['missing']} without a pose at both stamps)" if scored.get("missing") else ""))
