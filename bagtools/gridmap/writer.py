"""Writing a grid map's files together, atomically: nav2 map.pgm + map.yaml, map.png, summary.json."""

from __future__ import annotations

import json
from pathlib import Path

from bagtools.grid import nav2_map_files, render_map_png
from bagtools.gridmap.pipeline import GridMapResult
from bagtools.outputs import OutputDir

GRID_MAP_FILES = ["map.pgm", "map.yaml", "map.png", "summary.json"]


def write_grid_map(result: GridMapResult, out_dir: str | Path, force: bool = False) -> list[Path]:
    """Write map.pgm/.yaml (nav2 map_server format), map.png (with the scan path) and summary.json; all or nothing.

    Raises :class:`~bagtools.errors.OutputExistsError` if any exists and ``force`` is false.
    """
    s = result.summary
    title = f"{s.get('topic', '')} in {s.get('frame', 'map')}, {result.grid.cell_size_m:g} m/cell"
    with OutputDir(out_dir, GRID_MAP_FILES, force) as staged:
        for name, data in nav2_map_files(result.grid, "map").items():
            (staged / name).write_bytes(data)
        (staged / "map.png").write_bytes(render_map_png(result.grid, result.scan_path_xy, title=title))
        (staged / "summary.json").write_text(json.dumps(result.summary, indent=2))
    return [Path(out_dir) / name for name in GRID_MAP_FILES]
