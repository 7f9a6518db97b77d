"""``bagtools map-cloud``: a point-cloud map from a bag's clouds (or scans) and its tf."""

from __future__ import annotations

import json

import click

from bagtools.cli.complete import complete_topics


@click.command("map-cloud")
@click.argument("bag", type=click.Path(path_type=str))
@click.option("--out", "out_dir", required=True, type=click.Path(path_type=str), help="Output directory.")
@click.option("--topic", default="/camera/depth/points", shell_complete=complete_topics, show_default=True, help="PointCloud2 or LaserScan topic.")
@click.option("--frame", default="map", show_default=True, help="Fixed frame to build the map in.")
@click.option("--stamp", type=click.Choice(["message", "latest"]), default="message", show_default=True,
              help="Pose at each message's header stamp, or the newest tf available when it arrived.")
@click.option("--sample", type=float, default=None,
              help="Random fraction of each cloud to keep.  [default: 0.01 of a PointCloud2, all of a LaserScan]")
@click.option("--voxel", type=float, default=None, help="Voxel-downsample the map to this edge length [m].")
@click.option("--max-range", type=float, default=None, help="Drop points farther than this from the sensor [m].")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the random sampling.")
@click.option("--refine", is_flag=True,
              help="Register each cloud to the map built so far (Open3D ICP: point-to-plane, coloured when the "
                   "cloud has rgb), starting at its tf pose: a sharp map from drifting odometry. Writes the refined "
                   "poses as trajectory.tum; --sample defaults to 0.1.")
@click.option("--no-mcap", "no_mcap", is_flag=True, help="Do not write results.mcap.")
@click.option("--force", is_flag=True, help="Overwrite existing output files.")
def map_cloud(bag: str, out_dir: str, topic: str, frame: str, stamp: str, sample: float | None, voxel: float | None,
              max_range: float | None, seed: int, refine: bool, no_mcap: bool, force: bool) -> None:
    """Build a point-cloud map of BAG in a fixed frame ("mapping with known poses").

    Writes OUT/cloud_map.pcd and .ply (PCL, Open3D, CloudCompare: x y z, and
    intensity and rgb when the sensor gave them, averaged per voxel; the frame in
    a header comment), cloud_map.png (top and side views), summary.json (clouds
    used and skipped by reason, points, and for simulated bags the distance of
    the map to the true surfaces) and results.mcap (open in Foxglove, or
    `ros2 bag play`: /cloud_map, /trajectory, /tf, /tf_static and each cloud
    that went into the map, on its topic at its stamp). With --refine, each
    cloud is first registered to the map so far by Open3D's ICP, and the
    refined poses are written as trajectory.tum (TUM, for evo).

    \b
    Example:
      bagtools map-cloud out/turtlebot3_sim --out out/cloud_map --voxel 0.02
      bagtools map-cloud run.mcap --out odom_map --frame odom --stamp latest --no-mcap
      bagtools map-cloud run.mcap --out sharp_map --frame odom --refine
    """
    from bagtools.commands.map_cloud import CloudMapOptions, CloudMapPipeline, write_cloud_map
    from bagtools.commands.map_cloud.writer import cloud_map_outputs
    from bagtools.outputs import check_outputs

    check_outputs(out_dir, cloud_map_outputs(not no_mcap, refine), force, inputs=[bag])  # fail before the work

    options = CloudMapOptions.from_params(click.get_current_context().params)
    result = CloudMapPipeline(bag, options, keep_inputs=not no_mcap).run()
    for warning in result.summary.get("warnings", []):
        click.echo(f"bagtools: warning: {warning}", err=True)
    write_cloud_map(result, out_dir, force, mcap=not no_mcap)
    s = result.summary
    click.echo(f"{s['clouds_used']} clouds mapped, skipped {json.dumps(s['clouds_skipped'])}; "
               f"{s['points_out']} points in {out_dir}/cloud_map.pcd")
    if "refined" in s:
        r = s["refined"]
        click.echo(f"refined: {r['clouds_registered']} clouds registered to the map by ICP, "
                   f"{r['clouds_kept_at_tf_pose']} kept at their tf pose (corrected); poses in {out_dir}/trajectory.tum")
    if "accuracy_vs_truth_m" in s:
        acc = s["accuracy_vs_truth_m"]
        click.echo(f"distance to true surfaces: mean {acc['mean']:.4f} m, median {acc['median']:.4f} m, p95 {acc['p95']:.4f} m")
