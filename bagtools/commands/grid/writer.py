"""Writing a grid map's files together, atomically: nav2 map.pgm + map.yaml, map.png, summary.json, results.mcap."""

from __future__ import annotations

import json
from pathlib import Path

from bagtools.grid import nav2_map_files, render_map_png
from bagtools.grid.pipeline import GridMapResult
from bagtools.outputs import OutputDir
from bagtools.results import RESULTS_MCAP, ResultsBag, run_outputs

GRID_MAP_FILES = ["map.pgm", "map.yaml", "map.png", "summary.json", RESULTS_MCAP]


def write_grid_map(result: GridMapResult, out_dir: str | Path, force: bool = False, mcap: bool = True) -> list[Path]:
    """Write map.pgm/.yaml (nav2 map_server format), map.png (with the scan path), summary.json and (with ``mcap``)
    results.mcap; all or nothing.

    results.mcap shows the scans when the pipeline kept them (``GridMapPipeline(..., keep_scans=True)``).
    Raises :class:`~bagtools.errors.OutputExistsError` if any exists and ``force`` is false.
    """
    s = result.summary
    title = f"{s.get('topic', '')} in {s.get('frame', 'map')}, {result.grid.cell_size_m:g} m/cell"
    written = ["map.pgm", "map.yaml", "map.png", "summary.json"]
    with OutputDir(out_dir, run_outputs(GRID_MAP_FILES, mcap), force) as staged:
        for name, data in nav2_map_files(result.grid, "map").items():
            (staged / name).write_bytes(data)
        (staged / "map.png").write_bytes(render_map_png(result.grid, result.scan_path_xy, title=title))
        (staged / "summary.json").write_text(json.dumps(result.summary, indent=2))
        if mcap:
            with ResultsBag(staged / RESULTS_MCAP, namespace="grid") as bag:
                write_grid_map_results(bag, result)
            written.append(RESULTS_MCAP)
    return [Path(out_dir) / name for name in written]


def write_grid_map_results(bag: ResultsBag, result: GridMapResult) -> None:
    """/map (as nav2's map_server publishes map.yaml), /trajectory (the robot base at each scan), /tf and
    /tf_static (map frame -> base -> laser) and the scans on their topic at their stamps."""
    frame = result.summary.get("frame", "map")
    bag.occupancy_grid(result.grid, frame)
    if not result.scans:
        return
    stamps = [scan.stamp_ns for scan in result.scans]
    if result.base_frame is not None:
        bag.path("/trajectory", stamps, result.T_frame_base, frame)
        bag.robot(frame, result.base_frame, stamps, result.T_frame_base, result.T_base_scan)
    else:  # no base frame known: the scan frame itself moves in the map's frame (its mount is the identity)
        bag.path("/trajectory", stamps, result.T_frame_base, frame)
        for name in result.T_base_scan:
            rows = [k for k, scan in enumerate(result.scans) if scan.frame_id == name]
            bag.tf(frame, name, [stamps[k] for k in rows], result.T_frame_base[rows])
    bag.scans(result.summary.get("topic", "/scan"), result.scans)
