"""Point-cloud files with what the sensor gave: binary PCD (PCL) and PLY, with intensity, colour and the frame.

PCD v0.7 as PCL writes it: ``x y z`` float32, then ``intensity`` float32 and
``rgb`` (PCL's packed 0x00RRGGBB in a float32 field, as ``pcl::PointXYZRGB``
stores it) when the cloud has them; the frame is a header comment,
``# frame_id: map`` (PCL, Open3D and pypcd4 skip comment lines). PLY
(binary little endian): float ``x y z``, float ``intensity``, uchar ``red
green blue`` (the names Open3D, CloudCompare and MeshLab read as colour) and a
``comment frame_id: map`` line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bagtools.cloud.accumulator import MapCloud


def _packed_rgb(rgb: np.ndarray) -> np.ndarray:
    """(N,3) uint8 -> (N,) uint32 0x00RRGGBB."""
    c = rgb.astype(np.uint32)
    return (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]


def _records(columns: list[tuple[str, str, np.ndarray]]) -> np.ndarray:
    """A structured array of (name, numpy format, values) columns, in their order: the binary body of a PCD or PLY."""
    rec = np.empty(len(columns[0][2]), dtype=np.dtype({"names": [c[0] for c in columns],
                                                       "formats": [c[1] for c in columns]}))
    for name, _, values in columns:
        rec[name] = values
    return rec


def _xyz_intensity(cloud: MapCloud) -> list[tuple[str, str, np.ndarray]]:
    columns = [(axis, "<f4", cloud.points[:, k]) for k, axis in enumerate("xyz")]
    return columns + ([("intensity", "<f4", cloud.intensity)] if cloud.intensity is not None else [])


def _pcd_records(cloud: MapCloud) -> np.ndarray:
    rgb = [("rgb", "<u4", _packed_rgb(cloud.rgb))] if cloud.rgb is not None else []  # the bits of PCL's float rgb
    return _records(_xyz_intensity(cloud) + rgb)


def pcd_header(cloud: MapCloud, frame: str | None) -> str:
    """The text header of a binary PCD of ``cloud`` (``frame`` recorded as a comment)."""
    fields = cloud.fields
    n = len(cloud)
    return "\n".join([
        "# .PCD v0.7 - Point Cloud Data file format",
        *([f"# frame_id: {frame}"] if frame else []),
        "VERSION 0.7",
        f"FIELDS {' '.join(fields)}",
        f"SIZE {' '.join('4' for _ in fields)}",
        f"TYPE {' '.join('F' for _ in fields)}",
        f"COUNT {' '.join('1' for _ in fields)}",
        f"WIDTH {n}",
        "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {n}",
        "DATA binary",
    ]) + "\n"


def _ply_records(cloud: MapCloud) -> tuple[np.ndarray, list[str]]:
    columns = _xyz_intensity(cloud)
    if cloud.rgb is not None:
        columns += [(channel, "u1", cloud.rgb[:, k]) for k, channel in enumerate(("red", "green", "blue"))]
    kinds = {"<f4": "float", "u1": "uchar"}
    return _records(columns), [f"{kinds[fmt]} {name}" for name, fmt, _ in columns]


def ply_header(cloud: MapCloud, frame: str | None, props: list[str]) -> str:
    """The text header of a binary little-endian PLY of ``cloud`` (``frame`` recorded as a comment)."""
    return "\n".join([
        "ply",
        "format binary_little_endian 1.0",
        "comment written by bagtools",
        *([f"comment frame_id: {frame}"] if frame else []),
        f"element vertex {len(cloud)}",
        *(f"property {p}" for p in props),
        "end_header",
    ]) + "\n"


def write_point_cloud(path: Path, cloud: MapCloud | np.ndarray, frame: str | None = None) -> None:
    """Write ``cloud`` (or bare (N,3) points) as binary PCD or PLY, by the suffix of ``path``, in ``frame``."""
    if not isinstance(cloud, MapCloud):
        cloud = MapCloud(np.asarray(cloud, dtype=np.float32).reshape(-1, 3))
    suffix = Path(path).suffix.lower()
    if suffix == ".pcd":
        header, records = pcd_header(cloud, frame), _pcd_records(cloud)
    elif suffix == ".ply":
        records, props = _ply_records(cloud)
        header = ply_header(cloud, frame, props)
    else:
        raise ValueError(f"unknown point-cloud format {suffix!r} (expected .pcd or .ply)")
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(records.tobytes())
