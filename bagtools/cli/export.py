"""``bagtools export``: one topic of a bag as a CSV, Parquet or NPZ table."""

from __future__ import annotations

import click

from bagtools.cli.complete import complete_topics


@click.command("export")
@click.argument("bag", type=click.Path(path_type=str))
@click.argument("topic", shell_complete=complete_topics)
@click.option("--out", "out", required=True, type=click.Path(path_type=str),
              help="Output file: .csv, .parquet or .npz (the suffix picks the format).")
@click.option("--force", is_flag=True, help="Overwrite an existing output file.")
@click.option("--keep-nan", is_flag=True,
              help="Keep a PointCloud2's points with a NaN coordinate (dropped by default, as decoders do).")
def export(bag: str, topic: str, out: str, force: bool, keep_nan: bool) -> None:
    """Write TOPIC of BAG as a table: one row per message (per point of a
    PointCloud2, per transform of a TFMessage), flat columns, stamps in integer
    nanoseconds.

    Columns: stamp_ns (header stamp), log_time_ns (bag time), frame_id, then the
    message's fields: LaserScan geometry and ranges/intensities lists;
    PointCloud2 x y z [intensity] [r g b] (points with a NaN coordinate dropped
    unless --keep-nan); Odometry child_frame_id, x y z,
    qx qy qz qw, vx vy vz wx wy wz and the covariances; TF child_frame_id,
    x y z qx qy qz qw; PointStamped x y z. Any other type (Imu, JointState,
    CompressedImage, custom messages) is flattened from its definition: nested
    fields as a.b.c columns, numeric arrays as lists, byte sequences as their
    length (NAME.bytes), string arrays and arrays of messages as JSON text; a
    message without a header has its bag time as stamp_ns (a field named like
    one of the first three columns is written as msg.NAME). Every value is
    exact, in its field's own type (int8 ... uint64, float32, float64, bool).
    Lists are list columns in Parquet, 2-D arrays in NPZ (varying lengths
    padded, with NAME.length) and numbered columns (ranges.0, ranges.1, ...) in
    CSV. NPZ is compressed, and a text column that repeats (frame_id) is
    stored once: NAME holds each row's index into NAME.values; a few long
    texts: NAME.utf8 and NAME.offsets.

    \b
    Example:
      bagtools export out/sim /odom --out odom.csv
      bagtools export out/sim /scan --out scans.parquet
      bagtools export out/sim /imu --out imu.parquet
      bagtools export out/sim /camera/depth/points --out points.npz --force
      python -c "import pandas as pd; print(pd.read_parquet('scans.parquet'))"
    """
    from bagtools.commands.export import export_topic

    summary = export_topic(bag, topic, out, force, keep_nan=keep_nan)
    for warning in summary.warnings:
        click.echo(f"bagtools: warning: {warning}", err=True)
    lists = ""
    if summary.list_columns:
        spread = " (each over NAME.0, NAME.1, ...)" if summary.format == "csv" else ""
        lists = f"; lists: {' '.join(summary.list_columns)}{spread}"
    click.echo(f"{summary.messages} {summary.msgtype} messages on {topic}: {summary.rows} rows, columns "
               f"{' '.join(summary.columns)}{lists} in {out}")
