"""Messages as table rows: flat columns per message type, stamps as int nanoseconds.

Every table starts with ``stamp_ns`` (the header stamp; for TF, each
transform's own), ``log_time_ns`` (bag time) and ``frame_id``, then the
message's fields flattened:

- LaserScan: one row per message: the scan geometry, then ``ranges`` and
  ``intensities`` (a list per row);
- PointCloud2: one row per point (points with a NaN coordinate dropped unless
  asked for): ``x y z`` and, when the cloud has them, ``intensity`` and ``r g b``;
- Odometry: ``child_frame_id``, position ``x y z``, orientation ``qx qy qz qw``
  (ROS order), twist ``vx vy vz wx wy wz`` (in the child frame), and the
  covariances as 36-element lists (row-major, as in the message);
- TF (tf2_msgs/TFMessage, ROS 1 tf/tfMessage): one row per transform:
  ``child_frame_id`` (``frame_id`` is the parent), ``x y z qx qy qz qw``;
- PointStamped: ``x y z``;
- any other type (:func:`message_rows`), flattened from its definition as the
  bag declares it: one row per message, nested fields as ``a.b.c`` columns,
  every number exactly, in its field's own type (bool, int8 ... uint64,
  float32, float64: :data:`PRIMITIVE_DTYPES`), fixed-size arrays as
  fixed-length lists, sequences as lists, except sequences of bytes
  (uint8/int8/byte/char: image data, compressed or not) as their length in
  ``NAME.bytes``, and string arrays and arrays of messages as JSON text. A
  message without a header has its bag time as ``stamp_ns`` and an empty
  ``frame_id``; a field named like one of these three columns is written as
  ``msg.NAME``.

A chunk is ``{column: array}``: 1-D arrays (one value per row), 2-D arrays
(a fixed-length list per row) or object arrays of 1-D arrays (lists whose
length varies).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from dataclasses import fields, is_dataclass
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype

from bagtools.io import (
    LASERSCAN_TYPES, ODOMETRY_TYPES, POINTCLOUD2_TYPES, TF_TYPES, Record, decode_laserscan, decode_odometry,
    decode_pointcloud2, decode_tf_message, stamp_to_ns,
)

POINTSTAMPED_TYPES = ("geometry_msgs/msg/PointStamped",)

Chunk = dict[str, np.ndarray]


def _head(n: int, stamps_ns: np.ndarray | int, log_time_ns: int, frame_ids: np.ndarray | str) -> Chunk:
    return {
        "stamp_ns": np.broadcast_to(np.asarray(stamps_ns, dtype=np.int64), (n,)),
        "log_time_ns": np.full(n, log_time_ns, dtype=np.int64),
        "frame_id": np.broadcast_to(np.asarray(frame_ids, dtype=object), (n,)),
    }


def laserscan_rows(rec: Record) -> Chunk:
    """One row per LaserScan: geometry (rad, s, m), then ``ranges`` and ``intensities`` (float32 lists)."""
    msg = rec.msg
    scan = decode_laserscan(msg)
    chunk = _head(1, scan.stamp_ns, rec.log_time_ns, scan.frame_id)
    for name in ("angle_min", "angle_max", "angle_increment", "time_increment", "scan_time", "range_min", "range_max"):
        chunk[name] = np.array([float(getattr(msg, name))])
    chunk["ranges"] = _one_list(scan.ranges_m)
    chunk["intensities"] = _one_list(scan.intensities)
    return chunk


def _one_list(values: np.ndarray) -> np.ndarray:
    """One row holding the list ``values`` (its own dtype)."""
    out = np.empty(1, dtype=object)
    out[0] = np.asarray(values)
    return out


def pointcloud2_rows(rec: Record, keep_nan: bool = False) -> Chunk:
    """One row per point: x y z (float32), intensity and r g b when the cloud has them. Points with a non-finite
    coordinate (no return of a depth camera) are dropped, as :func:`~bagtools.io.decode_pointcloud2` does,
    unless ``keep_nan`` (every point, as recorded: an organized cloud's rows and columns)."""
    cloud = decode_pointcloud2(rec.msg, keep_nan=keep_nan, attributes=True)
    n = cloud.points.shape[0]
    chunk = _head(n, cloud.stamp_ns, rec.log_time_ns, cloud.frame_id)
    for k, axis in enumerate("xyz"):
        chunk[axis] = cloud.points[:, k]
    if cloud.intensity is not None:
        chunk["intensity"] = cloud.intensity
    if cloud.rgb is not None:
        for k, channel in enumerate("rgb"):
            chunk[channel] = cloud.rgb[:, k]
    return chunk


def odometry_rows(rec: Record) -> Chunk:
    """One row per Odometry: pose (m, ROS-order quaternion), twist (m/s, rad/s, child frame), covariances."""
    odom = decode_odometry(rec.msg)
    chunk = _head(1, odom.stamp_ns, rec.log_time_ns, odom.frame_id)
    chunk["child_frame_id"] = np.array([odom.child_frame_id], dtype=object)
    values = np.concatenate([odom.position_m, odom.orientation_xyzw, odom.linear_mps, odom.angular_radps])
    for name, value in zip(("x", "y", "z", "qx", "qy", "qz", "qw", "vx", "vy", "vz", "wx", "wy", "wz"), values):
        chunk[name] = np.array([value])
    chunk["pose_covariance"] = odom.pose_covariance.reshape(1, 36)
    chunk["twist_covariance"] = odom.twist_covariance.reshape(1, 36)
    return chunk


def tf_rows(rec: Record) -> Chunk:
    """One row per transform of a TFMessage: parent as ``frame_id``, ``child_frame_id``, translation (m), rotation."""
    tf = decode_tf_message(rec.msg)
    n = len(tf)
    chunk = _head(n, tf.stamp_ns, rec.log_time_ns, tf.parent)
    chunk["child_frame_id"] = tf.child
    for k, name in enumerate(("x", "y", "z")):
        chunk[name] = tf.translation[:, k]
    for k, name in enumerate(("qx", "qy", "qz", "qw")):
        chunk[name] = tf.rotation_xyzw[:, k]
    return chunk


def pointstamped_rows(rec: Record) -> Chunk:
    """One row per PointStamped: x y z (m)."""
    msg = rec.msg
    chunk = _head(1, stamp_to_ns(msg.header.stamp), rec.log_time_ns, msg.header.frame_id)
    for name in "xyz":
        chunk[name] = np.array([float(getattr(msg.point, name))])
    return chunk


#: A ROS primitive type -> the numpy dtype its values are exported in (rosbags' own: ``byte`` is signed, as
#: rosbags deserializes it, ``char`` unsigned).
PRIMITIVE_DTYPES: dict[str, type] = {
    "bool": np.bool_, "byte": np.int8, "char": np.uint8, "int8": np.int8, "uint8": np.uint8, "int16": np.int16,
    "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64,
    "float32": np.float32, "float64": np.float64,
}
#: Sequences (variable length) of these are binary data (an image, a cloud's bytes): exported as their length.
BYTE_TYPES = ("byte", "char", "int8", "uint8")

Definitions = Callable[[str], tuple[list, list]]
"""Message type -> rosbags' (constants, fields) of its definition (:meth:`bagtools.io.BagReader.field_definitions`)."""


def message_rows(rec: Record, definitions: Definitions) -> Chunk:
    """One row per message of any type, flattened from its definition (see the module docstring): every value in
    its field's own dtype."""
    msg = rec.msg
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    chunk = _head(1, stamp_to_ns(stamp) if stamp is not None else rec.log_time_ns, rec.log_time_ns,
                  str(getattr(header, "frame_id", "")) if header is not None else "")
    for name, value in _flatten(msg, rec.msgtype, "", definitions, skip="header" if stamp is not None else None):
        while name in chunk:  # a field named like one of the export's own columns
            name = f"msg.{name}"
        chunk[name] = value
    return chunk


def _flatten(msg: Any, msgtype: str, prefix: str, definitions: Definitions,
             skip: str | None = None) -> Iterator[tuple[str, np.ndarray]]:
    """(column name, one-row column) of every leaf of ``msg`` (a rosbags message of ``msgtype``)."""
    for name, (kind, detail) in definitions(msgtype)[1]:
        if name == skip:
            continue
        column, value = f"{prefix}{name}", getattr(msg, name)
        if kind == Nodetype.NAME:
            yield from _flatten(value, detail, f"{column}.", definitions)
        elif kind == Nodetype.BASE:
            dtype = PRIMITIVE_DTYPES.get(detail[0])
            yield column, np.array([value], dtype=object if dtype is None else dtype)
        else:  # an array (fixed size) or a sequence
            (inner_kind, inner), is_sequence = detail[0], kind == Nodetype.SEQUENCE
            dtype = PRIMITIVE_DTYPES.get(inner[0]) if inner_kind == Nodetype.BASE else None
            if dtype is None:  # strings or messages
                yield column, np.array([json.dumps([_plain(v) for v in value])], dtype=object)
            elif is_sequence and inner[0] in BYTE_TYPES:  # binary data: image bytes, compressed or not
                yield f"{column}.bytes", np.array([len(value)], dtype=np.int64)
            elif is_sequence:
                yield column, _one_list(np.asarray(value, dtype=dtype))
            else:
                yield column, np.asarray(value, dtype=dtype).reshape(1, -1)


def _plain(value: Any) -> Any:
    """A message value as JSON-ready data (dataclasses as dicts, arrays as lists)."""
    if is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name)) for f in fields(value) if not f.name.startswith("__")}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


ROWS: dict[str, Callable[[Record], Chunk]] = {
    **{t: laserscan_rows for t in LASERSCAN_TYPES},
    **{t: pointcloud2_rows for t in POINTCLOUD2_TYPES},
    **{t: odometry_rows for t in ODOMETRY_TYPES},
    **{t: tf_rows for t in TF_TYPES},
    **{t: pointstamped_rows for t in POINTSTAMPED_TYPES},
}
"""Message type -> the function that turns one message into rows."""

#: What a bare decode of each type costs (the benchmark's baseline): the decoder without the flattening.
DECODERS: dict[str, Callable[[Any], Any]] = {
    **{t: decode_laserscan for t in LASERSCAN_TYPES},
    **{t: (lambda msg: decode_pointcloud2(msg, attributes=True)) for t in POINTCLOUD2_TYPES},
    **{t: decode_odometry for t in ODOMETRY_TYPES},
    **{t: decode_tf_message for t in TF_TYPES},
    **{t: (lambda msg: msg.point) for t in POINTSTAMPED_TYPES},
}
