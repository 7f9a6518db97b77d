"""Sensor messages decoded straight from their CDR bytes, without building a rosbags message first.

A LaserScan or PointCloud2 is a short header and one or two long arrays. Read
through rosbags, every message becomes a tree of objects and a copy of its
arrays before :mod:`bagtools.io.decode` turns it into numpy arrays; here the
arrays are numpy views of the message's bytes, and the header is unpacked with
one ``struct`` call per part. Each function returns exactly what
:func:`~bagtools.io.decode_laserscan` or :func:`~bagtools.io.decode_pointcloud2`
returns for the deserialized message, or None for anything but a sound message
in plain little-endian CDR (a big-endian encapsulation, a malformed length, a
header the decoder would refuse): the caller deserializes those the usual way
and gets the usual result or error.

Layout (ROS 2, XCDR1, offsets after the 4-byte encapsulation header, every
field aligned to its size): ``std_msgs/Header`` is ``int32 sec, uint32 nanosec,
string frame_id`` (a uint32 length counting the closing NUL, then the bytes).
"""

from __future__ import annotations

import struct
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from bagtools.io.decode import (
    CloudArrays,
    DecodeError,
    LaserScanArrays,
    OdometrySample,
    TfRows,
    _scan_geometry,
    decode_pointcloud2,
)

_U32 = struct.Struct("<I")
_STAMP_AND_LENGTH = struct.Struct("<iII")  # sec, nanosec, frame_id length
# A LaserScan's header is followed by angle_min, angle_max, angle_increment, time_increment, scan_time,
# range_min, range_max (float32) and the ranges' count: see _scan_head.
_CLOUD_SIZE = struct.Struct("<III")  # height, width, fields' count
_FIELD_TAIL = struct.Struct("<IBxxxI")  # offset, datatype (padded), count
_CLOUD_STEPS = struct.Struct("<?xxxIII")  # is_bigendian (padded), point_step, row_step, data's byte count


def _header(raw: bytes | memoryview) -> tuple[int, int, str, int] | None:
    """(sec, nanosec, frame_id, offset after the header, aligned to 4) of a little-endian CDR message, or None."""
    if len(raw) < 4 + _STAMP_AND_LENGTH.size or raw[0] != 0 or raw[1] != 1:
        return None
    sec, nanosec, length = _STAMP_AND_LENGTH.unpack_from(raw, 4)
    end = 4 + _STAMP_AND_LENGTH.size + length
    if length == 0 or end > len(raw) or raw[end - 1] != 0 or not 0 <= nanosec < 1_000_000_000 or sec < 0:
        return None
    frame_id = _frame_id(bytes(raw[end - length:end - 1]))
    if frame_id is None:
        return None
    return sec, nanosec, frame_id, 4 + ((end - 4 + 3) & ~3)


@lru_cache(maxsize=256)
def _frame_id(text: bytes) -> str | None:
    """A frame id's UTF-8 bytes as text (None if they are not UTF-8); a topic repeats one or a few."""
    try:
        return text.decode("utf-8")
    except UnicodeDecodeError:
        return None


@lru_cache(maxsize=64)
def _scan_head(frame_id_length: int) -> struct.Struct:
    """The fixed part of a LaserScan whose frame id has this many bytes (its NUL included), from the stamp to
    the ranges' count: sec, nanosec, length, frame id, the seven float32 limits and the count."""
    pad = -(4 + 4 + 4 + frame_id_length) % 4
    return struct.Struct(f"<iII{frame_id_length}s{pad}x7fI")


_NO_INTENSITIES = np.empty(0, dtype="<f4")
_NO_INTENSITIES.flags.writeable = False


def laserscan_from_cdr(raw: bytes | memoryview) -> LaserScanArrays | None:
    """sensor_msgs/msg/LaserScan CDR bytes -> :class:`~bagtools.io.LaserScanArrays` (ranges are views of
    ``raw``), or None where :func:`~bagtools.io.decode_laserscan` of the deserialized message must decide."""
    size = len(raw)
    if size < 4 + _STAMP_AND_LENGTH.size or raw[0] != 0 or raw[1] != 1:
        return None
    (length,) = _U32.unpack_from(raw, 12)
    head = _scan_head(length) if 0 < length < size else None
    if head is None or 4 + head.size > size:
        return None
    sec, nanosec, _, text, angle_min, angle_max, increment, time_increment, scan_time, range_min, range_max, n = \
        head.unpack_from(raw, 4)
    pos = 4 + head.size
    if pos + 4 * n + 4 > size or text[-1] != 0 or not 0 <= nanosec < 1_000_000_000 or sec < 0:
        return None
    frame_id = _frame_id(text[:-1])
    ranges = np.frombuffer(raw, dtype="<f4", count=n, offset=pos)
    pos += 4 * n
    (m,) = _U32.unpack_from(raw, pos)
    if pos + 4 + 4 * m > size or frame_id is None:
        return None
    intensities = np.frombuffer(raw, dtype="<f4", count=m, offset=pos + 4) if m else _NO_INTENSITIES
    try:
        angles, low, high, notes = _scan_geometry(angle_min, increment, angle_max, n, range_min, range_max)
    except DecodeError:
        return None
    return LaserScanArrays(sec * 1_000_000_000 + nanosec, frame_id, ranges, angles, low, high, intensities, notes,
                           increment, time_increment, scan_time)


class _Time(NamedTuple):
    sec: int
    nanosec: int


class _Header(NamedTuple):
    stamp: _Time
    frame_id: str


class _PointField(NamedTuple):
    name: str
    offset: int
    datatype: int
    count: int


class _PointCloud2(NamedTuple):
    """The fields of a PointCloud2 that :func:`~bagtools.io.decode_pointcloud2` reads; ``data`` a uint8 view."""

    header: _Header
    height: int
    width: int
    fields: tuple[_PointField, ...]
    is_bigendian: bool
    point_step: int
    row_step: int
    data: np.ndarray


def _cloud_fields(raw: bytes | memoryview) -> _PointCloud2 | None:
    """The PointCloud2 in little-endian CDR ``raw`` with its data as a view, or None when malformed."""
    head = _header(raw)
    if head is None:
        return None
    sec, nanosec, frame_id, pos = head
    if pos + _CLOUD_SIZE.size > len(raw):
        return None
    height, width, n_fields = _CLOUD_SIZE.unpack_from(raw, pos)
    pos += _CLOUD_SIZE.size
    fields = []
    for _ in range(n_fields):
        if pos + 4 > len(raw):
            return None
        (length,) = _U32.unpack_from(raw, pos)
        end = pos + 4 + length
        tail = 4 + ((end - 4 + 3) & ~3)
        if length == 0 or tail + _FIELD_TAIL.size > len(raw):
            return None
        try:
            name = bytes(raw[pos + 4:end - 1]).decode("utf-8")
        except UnicodeDecodeError:
            return None
        offset, datatype, count = _FIELD_TAIL.unpack_from(raw, tail)
        fields.append(_PointField(name, offset, datatype, count))
        pos = tail + _FIELD_TAIL.size
    if pos + _CLOUD_STEPS.size > len(raw):
        return None
    is_bigendian, point_step, row_step, n_bytes = _CLOUD_STEPS.unpack_from(raw, pos)
    pos += _CLOUD_STEPS.size
    if pos + n_bytes > len(raw):
        return None
    data = np.frombuffer(raw, dtype=np.uint8, count=n_bytes, offset=pos)
    return _PointCloud2(_Header(_Time(sec, nanosec), frame_id), height, width, tuple(fields), bool(is_bigendian),
                        point_step, row_step, data)


def pointcloud2_from_cdr(raw: bytes | memoryview, keep_nan: bool = False, attributes: bool = False) -> CloudArrays | None:
    """sensor_msgs/msg/PointCloud2 CDR bytes -> :class:`~bagtools.io.CloudArrays`, as
    :func:`~bagtools.io.decode_pointcloud2` gives it, or None where that function must decide
    (the message read the usual way)."""
    msg = _cloud_fields(raw)
    if msg is None:
        return None
    try:
        return decode_pointcloud2(msg, keep_nan=keep_nan, attributes=attributes)
    except DecodeError:
        return None



_TRANSFORM = struct.Struct("<7d")  # translation x, y, z; rotation x, y, z, w


def tf_from_cdr(raw: bytes | memoryview) -> TfRows | None:
    """tf2_msgs/msg/TFMessage CDR bytes -> :class:`~bagtools.io.decode.TfRows` (as
    :func:`~bagtools.io.decode.tf_rows` gives for the deserialized message), or None when malformed."""
    size = len(raw)
    if size < 8 or raw[0] != 0 or raw[1] != 1:
        return None
    (n,) = _U32.unpack_from(raw, 4)
    pos = 8
    rows = []
    for _ in range(n):
        pos = 4 + ((pos - 4 + 3) & ~3)
        if pos + _STAMP_AND_LENGTH.size > size:
            return None
        sec, nanosec, length = _STAMP_AND_LENGTH.unpack_from(raw, pos)
        pos += _STAMP_AND_LENGTH.size
        parent = _cdr_text(raw, pos, length)
        pos = 4 + ((pos + length - 4 + 3) & ~3)
        if parent is None or pos + 4 > size or not 0 <= nanosec < 1_000_000_000:
            return None
        (length,) = _U32.unpack_from(raw, pos)
        child = _cdr_text(raw, pos + 4, length)
        pos = 4 + ((pos + 4 + length - 4 + 7) & ~7)
        if child is None or pos + _TRANSFORM.size > size:
            return None
        rows.append((parent, child, sec * 1_000_000_000 + nanosec, *_TRANSFORM.unpack_from(raw, pos)))
        pos += _TRANSFORM.size
    return TfRows(rows)


#: An Odometry's float64 fields after its frame ids: pose (position 3, orientation 4, covariance 36), twist (linear 3,
#: angular 3, covariance 36).
_ODOMETRY_DOUBLES = 85


def odometry_from_cdr(raw: bytes | memoryview) -> OdometrySample | None:
    """nav_msgs/msg/Odometry CDR bytes -> :class:`~bagtools.io.decode.OdometrySample` (as
    :func:`~bagtools.io.decode.decode_odometry` gives for the deserialized message), or None when malformed."""
    head = _header(raw)
    if head is None:
        return None
    sec, nanosec, frame_id, pos = head
    if pos + 4 > len(raw):
        return None
    (length,) = _U32.unpack_from(raw, pos)
    child = _cdr_text(raw, pos + 4, length)
    pos = 4 + ((pos + 4 + length - 4 + 7) & ~7)  # the doubles align to 8 (CDR counts from after the 4-byte header)
    if child is None or pos + 8 * _ODOMETRY_DOUBLES > len(raw):
        return None
    v = np.frombuffer(raw, dtype="<f8", count=_ODOMETRY_DOUBLES, offset=pos).astype(np.float64)
    return OdometrySample(sec * 1_000_000_000 + nanosec, frame_id, child, v[0:3], v[3:7], v[43:46], v[46:49],
                          v[7:43].reshape(6, 6), v[49:85].reshape(6, 6))


def _cdr_text(raw: bytes | memoryview, pos: int, length: int) -> str | None:
    """The CDR string of ``length`` bytes (its NUL included) at ``pos``, or None when malformed."""
    if length == 0 or pos + length > len(raw) or raw[pos + length - 1] != 0:
        return None
    return _frame_id(bytes(raw[pos:pos + length - 1]))
