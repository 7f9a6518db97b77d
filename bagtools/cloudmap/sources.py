"""Sensor data of a bag as 3D points in the sensor frame: the dataset iterator of the mappers.

A PointCloud2 topic gives its finite points; a LaserScan topic gives its valid
returns at z = 0 of the scan frame. Either way the consumer sees one
:class:`SensorPoints` per message, in bag order.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from bagtools.io import LASERSCAN_TYPES, POINTCLOUD2_TYPES, BagReader, decode_laserscan, decode_pointcloud2


@dataclass(frozen=True)
class SensorPoints:
    """One message's points: ``points`` (N,3) float32 in ``frame_id`` at header ``stamp_ns``; ``log_time_ns`` is its bag time."""

    stamp_ns: int
    log_time_ns: int
    frame_id: str
    points: np.ndarray


def iter_sensor_points(bag: BagReader, topic: str) -> Iterator[SensorPoints]:
    """Yield the points of every PointCloud2 or LaserScan message on ``topic``.

    Raises :class:`~bagtools.errors.TopicError` if the topic is missing or of another type.
    """
    info = bag.require_topic(topic, POINTCLOUD2_TYPES + LASERSCAN_TYPES)
    is_scan = info.msgtype in LASERSCAN_TYPES
    for rec in bag.messages([topic]):
        if is_scan:
            scan = decode_laserscan(rec.msg)
            xy = scan.points_xy()
            points = np.zeros((xy.shape[0], 3), dtype=np.float32)
            points[:, :2] = xy
            yield SensorPoints(scan.stamp_ns, rec.log_time_ns, scan.frame_id, points)
        else:
            cloud = decode_pointcloud2(rec.msg)
            yield SensorPoints(cloud.stamp_ns, rec.log_time_ns, cloud.frame_id, cloud.points)
