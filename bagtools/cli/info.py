"""``bagtools info``: topics, time span and tf tree of a bag."""

from __future__ import annotations

import json

import click


@click.command()
@click.argument("bag", type=click.Path(path_type=str))
@click.option("--json", "as_json", is_flag=True, help="Print the description as JSON.")
def info(bag: str, as_json: bool) -> None:
    """Describe BAG: topics (type, count, frequency, QoS), duration, storage and the tf tree.

    Like `ros2 bag info`, also the storage id (mcap, sqlite3, ros1), the bag
    size on disk, the ROS distro and serialization format the bag records, and
    each topic's offered QoS profiles (latching for ROS 1).

    BAG is a rosbag2 directory, a .mcap or .db3 file, or a ROS 1 .bag.

    \b
    Example:
      bagtools info out/turtlebot3_sim
      bagtools info recording.mcap --json > info.json
    """
    from bagtools.commands.info import describe_bag, format_description

    desc = describe_bag(bag)
    for warning in desc.warnings:
        click.echo(f"bagtools: warning: {warning}", err=True)
    click.echo(json.dumps(desc.to_json(), indent=2) if as_json else format_description(desc))
