"""Writing a cloud map's files together, atomically."""

from __future__ import annotations

import json
from pathlib import Path

from bagtools.cloudmap.pipeline import CloudMapResult
from bagtools.cloudmap.files import write_point_cloud
from bagtools.cloudmap.render import render_map_png
from bagtools.outputs import OutputDir

CLOUD_MAP_FILES = ["cloud_map.pcd", "cloud_map.ply", "cloud_map.png", "summary.json"]


def write_cloud_map(result: CloudMapResult, out_dir: str | Path, force: bool = False) -> list[Path]:
    """Write cloud_map.pcd/.ply/.png and summary.json into ``out_dir``; all or nothing."""
    frame = result.summary.get("frame", "map")
    with OutputDir(out_dir, CLOUD_MAP_FILES, force) as staged:
        write_point_cloud(staged / "cloud_map.pcd", result.cloud, frame)
        write_point_cloud(staged / "cloud_map.ply", result.cloud, frame)
        render_map_png(staged / "cloud_map.png", result.points, frame, result.sensor_path,
                       title=f"{result.summary.get('topic', '')} in {frame}")
        (staged / "summary.json").write_text(json.dumps(result.summary, indent=2))
    return [Path(out_dir) / name for name in CLOUD_MAP_FILES]
