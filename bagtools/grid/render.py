"""map.png: the occupancy grid with the optimized trajectory and the accepted loop closures drawn on it."""

from __future__ import annotations

import io

import numpy as np

from bagtools.grid import OccupancyGrid
from bagtools.grid.mapio import MAX_PICTURE_PX, grey_pixels, rgba_pixels

#: Metres of map kept around the occupied cells and the trajectory in the picture.
MARGIN_M = 2.0


def _view(grid: OccupancyGrid, probability: np.ndarray, trajectory_xy: np.ndarray) -> tuple[float, float, float, float]:
    """World limits (x0, x1, y0, y1) of the picture: the occupied cells and the trajectory, plus a margin.

    Far free space seen through windows or down long corridors stays out of view.
    """
    x0, x1 = grid.x_world_limits
    y0, y1 = grid.y_world_limits
    occupied = probability > grid.occupied_threshold
    rows, cols = np.flatnonzero(occupied.any(axis=1)), np.flatnonzero(occupied.any(axis=0))
    pts = [trajectory_xy[np.isfinite(trajectory_xy).all(axis=1)]]
    if rows.size:  # the occupied cells' bounding box
        pts.append(grid.grid2world(np.array([[rows[0], cols[0]], [rows[-1], cols[-1]]])))
    xy = np.vstack(pts)
    if xy.size == 0:
        return x0, x1, y0, y1
    lo, hi = xy.min(axis=0) - MARGIN_M, xy.max(axis=0) + MARGIN_M
    return max(x0, lo[0]), min(x1, hi[0]), max(y0, lo[1]), min(y1, hi[1])


def render_slam_map_png(grid: OccupancyGrid, trajectory_xy: np.ndarray, loop_segments: np.ndarray,
                        title: str = "", width_px: int = 1600,
                        marks: list[tuple[str, np.ndarray, str, str]] = ()) -> bytes:
    """A PNG of the map (grey: white free, black occupied, mid-grey unknown), the trajectory (N,2) in red
    (NaN rows break it), each accepted loop (L,2,2: old and new keyframe positions, m) as a green segment,
    and ``marks``: (legend label, places (K,2) m, matplotlib marker, colour) drawn over the rest."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure

    traj = np.asarray(trajectory_xy, dtype=np.float64).reshape(-1, 2)
    probability = grid.occupancy_matrix("probability")
    x0, x1, y0, y1 = _view(grid, probability, traj)
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)
    dpi = 100
    width_in = width_px / dpi
    fig = Figure(figsize=(width_in, min(max(width_in * aspect, 4.0), 2.0 * width_in) + 0.8), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    # Only the cells in view, as grey RGB bytes pooled to about the picture's resolution (no colour mapping of
    # millions of cells by matplotlib).
    (r0, c0), (r1, c1) = grid.world2grid(np.array([[x0, y1], [x1, y0]]))
    r0, c0 = max(int(r0), 0), max(int(c0), 0)
    r1, c1 = min(int(r1), grid.grid_size[0] - 1), min(int(c1), grid.grid_size[1] - 1)
    grey, _ = grey_pixels(probability[r0:r1 + 1, c0:c1 + 1], MAX_PICTURE_PX)
    del probability  # the full-size matrix is not needed while the figure is drawn
    (left, top), (right, bottom) = grid.grid2world(np.array([[r0, c0], [r1, c1]]))
    half = 0.5 * grid.cell_size_m
    ax.imshow(rgba_pixels(grey), origin="upper", interpolation="nearest",
              extent=(left - half, right + half, bottom - half, top + half))
    segments = np.asarray(loop_segments, dtype=np.float64).reshape(-1, 2, 2)
    if len(segments):
        ax.add_collection(LineCollection(segments, colors="tab:green", linewidths=0.8, alpha=0.8,
                                         label=f"loop closures ({len(segments)})"))
    known = traj[np.isfinite(traj).all(axis=1)]
    if len(known):
        ax.plot(traj[:, 0], traj[:, 1], color="tab:red", linewidth=0.8, label="trajectory")
        ax.plot(known[0, 0], known[0, 1], "o", color="tab:blue", markersize=5, label="start")
        ax.plot(known[-1, 0], known[-1, 1], "s", color="tab:purple", markersize=5, label="end")
    for label, xy, marker, colour in marks:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if len(xy):
            ax.plot(xy[:, 0], xy[:, 1], marker, color=colour, markersize=9, markeredgewidth=2, linestyle="none",
                    label=f"{label} ({len(xy)})")
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title or f"SLAM map, {grid.cell_size_m:g} m/cell")
    ax.legend(loc="upper right", fontsize="small")
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.05, top=0.95)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()
