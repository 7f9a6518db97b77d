"""``bagtools tf``: the tf tree, transforms over time, and points followed through frames."""

from __future__ import annotations

import click

from bagtools.cli.complete import complete_frames, complete_topics


def _warn(warnings: list[str]) -> None:
    for warning in warnings:
        click.echo(f"bagtools: warning: {warning}", err=True)


@click.group()
def tf() -> None:
    """tf of a bag: the frame tree, one transform over time, a point seen from several frames.

    \b
    Example:
      bagtools tf frames run.mcap --dot tf.dot
      bagtools tf echo run.mcap map base_link --rate 2
      bagtools tf point run.mcap --out out/pt --point 1 0 0 --frame map
    """


@tf.command()
@click.argument("bag", type=click.Path(path_type=str))
@click.option("--dot", "dot_file", type=click.Path(path_type=str), help="Also write the tree as Graphviz dot.")
@click.option("--force", is_flag=True, help="Overwrite the --dot file if it exists.")
def frames(bag: str, dot_file: str | None, force: bool) -> None:
    """Print the tf tree of BAG: parent, static or dynamic, rate and time range per frame.

    Times are seconds relative to the earliest dynamic transform.

    \b
    Example:
      bagtools tf frames run.mcap
      bagtools tf frames run.mcap --dot tf.dot && dot -Tpdf tf.dot -o tf.pdf
    """
    from pathlib import Path

    from bagtools.outputs import check_writable, write_text_atomic
    from bagtools.tf.dot import render_dot
    from bagtools.tf.tree import read_frame_tree

    if dot_file:
        check_writable(Path(dot_file), force, inputs=[bag])  # before the work, not after it
    tree = read_frame_tree(bag)
    _warn(tree.warnings)
    if dot_file:
        write_text_atomic(dot_file, render_dot(tree.infos, tree.origin_ns), force, inputs=[bag])
    click.echo(tree.text())


@tf.command()
@click.argument("bag", type=click.Path(path_type=str))
@click.argument("target", shell_complete=complete_frames)
@click.argument("source", shell_complete=complete_frames)
@click.option("--rate", "rate_hz", type=float, default=1.0, show_default=True, help="Samples per second of bag time.")
@click.option("--csv", "csv_file", type=click.Path(path_type=str), help="Write the samples as CSV instead of text.")
@click.option("--force", is_flag=True, help="Overwrite the --csv file if it exists.")
def echo(bag: str, target: str, source: str, rate_hz: float, csv_file: str | None, force: bool) -> None:
    """Print the pose of SOURCE in TARGET over BAG, like tf2_echo TARGET SOURCE.

    Translation, quaternion (x y z w) and roll-pitch-yaw at --rate Hz over the
    span where the transform exists (interpolated as tf2 does).

    \b
    Example:
      bagtools tf echo run.mcap odom base_link --rate 5
      bagtools tf echo run.mcap map base_link --rate 10 --csv map_base.csv
    """
    from pathlib import Path

    from bagtools.outputs import check_writable, write_text_atomic
    from bagtools.tf.echo import echo_bag, echo_csv, format_echo

    if csv_file:
        check_writable(Path(csv_file), force, inputs=[bag])  # before the work, not after it
    table, warnings = echo_bag(bag, target, source, rate_hz)
    _warn(warnings)
    if csv_file:
        write_text_atomic(csv_file, echo_csv(table), force, inputs=[bag])
        click.echo(f"wrote {table.stamp_ns.size} samples of {target} -> {source} to {csv_file}")
    else:
        click.echo(format_echo(table))


@tf.command()
@click.argument("bag", type=click.Path(path_type=str))
@click.option("--out", "out_dir", required=True, type=click.Path(path_type=str),
              help="Directory for point.csv, point.png and summary.json.")
@click.option("--point", type=float, nargs=3, default=None, metavar="X Y Z", help="A point in metres, fixed in --frame.")
@click.option("--frame", shell_complete=complete_frames, help="The frame the --point is fixed in.")
@click.option("--topic", shell_complete=complete_topics, help="Follow every geometry_msgs/PointStamped on this topic (e.g. /clicked_point).")
@click.option("--targets", help="Comma-separated frames to express the point in [default: those of "
                                "map,odom,base_footprint in the bag].")
@click.option("--rate", "rate_hz", type=float, default=10.0, show_default=True, help="Time steps per second.")
@click.option("--force", is_flag=True, help="Overwrite existing outputs in --out.")
def point(bag: str, out_dir: str, point: tuple[float, float, float] | None, frame: str | None, topic: str | None,
          targets: str | None, rate_hz: float, force: bool) -> None:
    """Follow a point fixed in one frame through BAG, expressed in each target frame.

    A point fixed in map stays put in map, drifts in odom and moves in the
    robot's base frame as it drives. Writes point.csv, point.png, summary.json.

    \b
    Example:
      bagtools tf point run.mcap --out out/pt --point 2 1 0 --frame map --targets map,odom,base_link
      bagtools tf point run.mcap --out out/clicks --topic /clicked_point
    """
    from bagtools.tf.point import follow_point_bag

    target_list = [t.strip() for t in targets.split(",") if t.strip()] if targets else None
    track, warnings = follow_point_bag(bag, out_dir, point, frame, topic, target_list, rate_hz, force)
    _warn(warnings)
    click.echo(f"followed {len(track.points)} point(s) over {track.stamp_ns.size} steps in "
               f"{', '.join(track.targets)}; wrote {out_dir}/point.csv, point.png, summary.json")
