"""``bagtools export``: one topic of a bag as a CSV, Parquet or NPZ table."""

from __future__ import annotations

import click


@click.command("export")
@click.argument("bag", type=click.Path(path_type=str))
@click.argument("topic")
@click.option("--out", "out", required=True, type=click.Path(path_type=str),
              help="Output file: .csv, .parquet or .npz (the suffix picks the format).")
@click.option("--force", is_flag=True, help="Overwrite an existing output file.")
def export(bag: str, topic: str, out: str, force: bool) -> None:
    """Write TOPIC of BAG as a table: one row per message (per point of a
    PointCloud2, per transform of a TFMessage), flat columns, stamps in integer
    nanoseconds.

    Columns: stamp_ns (header stamp), log_time_ns (bag time), frame_id, then the
    message's fields: LaserScan geometry and ranges/intensities lists;
    PointCloud2 x y z [intensity] [r g b]; Odometry child_frame_id, x y z,
    qx qy qz qw, vx vy vz wx wy wz and the covariances; TF child_frame_id,
    x y z qx qy qz qw; PointStamped x y z. Lists are list columns in Parquet,
    2-D arrays in NPZ and numbered columns (ranges.0, ranges.1, ...) in CSV.

    \b
    Example:
      bagtools export out/sim /odom --out odom.csv
      bagtools export out/sim /scan --out scans.parquet
      bagtools export out/sim /camera/depth/points --out points.npz --force
      python -c "import pandas as pd; print(pd.read_parquet('scans.parquet'))"
    """
    from bagtools.export import export_topic

    summary = export_topic(bag, topic, out, force)
    for warning in summary.warnings:
        click.echo(f"bagtools: warning: {warning}", err=True)
    click.echo(f"{summary.messages} {summary.msgtype} messages on {topic}: {summary.rows} rows, columns "
               f"{' '.join(summary.columns)} in {out}")
