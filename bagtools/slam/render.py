"""map.png: the occupancy grid with the optimized trajectory and the accepted loop closures drawn on it."""

from __future__ import annotations

import io

import numpy as np

from bagtools.grid import OccupancyGrid

#: Metres of map kept around the occupied cells and the trajectory in the picture.
MARGIN_M = 2.0


def _view(grid: OccupancyGrid, trajectory_xy: np.ndarray) -> tuple[float, float, float, float]:
    """World limits (x0, x1, y0, y1) of the picture: the occupied cells and the trajectory, plus a margin.

    Far free space seen through windows or down long corridors stays out of view.
    """
    x0, x1 = grid.x_world_limits
    y0, y1 = grid.y_world_limits
    occupied = np.argwhere(grid.occupancy_matrix("ternary") == 1)
    pts = [trajectory_xy[np.isfinite(trajectory_xy).all(axis=1)]]
    if occupied.size:
        pts.append(grid.grid2world(occupied))
    xy = np.vstack(pts)
    if xy.size == 0:
        return x0, x1, y0, y1
    lo, hi = xy.min(axis=0) - MARGIN_M, xy.max(axis=0) + MARGIN_M
    return max(x0, lo[0]), min(x1, hi[0]), max(y0, lo[1]), min(y1, hi[1])


def render_slam_map_png(grid: OccupancyGrid, trajectory_xy: np.ndarray, loop_segments: np.ndarray,
                        title: str = "", width_px: int = 1600) -> bytes:
    """A PNG of the map (grey: white free, black occupied, mid-grey unknown), the trajectory (N,2) in red
    and each accepted loop (L,2,2: old and new keyframe positions, m) as a green segment."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure

    traj = np.asarray(trajectory_xy, dtype=np.float64).reshape(-1, 2)
    x0, x1, y0, y1 = _view(grid, traj)
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)
    dpi = 100
    width_in = width_px / dpi
    fig = Figure(figsize=(width_in, min(max(width_in * aspect, 4.0), 2.0 * width_in) + 0.8), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    gx0, gx1 = grid.x_world_limits
    gy0, gy1 = grid.y_world_limits
    ax.imshow(grid.occupancy_matrix("probability"), cmap="gray_r", vmin=0.0, vmax=1.0, origin="upper",
              extent=(gx0, gx1, gy0, gy1), interpolation="nearest")
    segments = np.asarray(loop_segments, dtype=np.float64).reshape(-1, 2, 2)
    if len(segments):
        ax.add_collection(LineCollection(segments, colors="tab:green", linewidths=0.8, alpha=0.8,
                                         label=f"loop closures ({len(segments)})"))
    if len(traj):
        ax.plot(traj[:, 0], traj[:, 1], color="tab:red", linewidth=0.8, label="trajectory")
        ax.plot(traj[0, 0], traj[0, 1], "o", color="tab:blue", markersize=5, label="start")
        ax.plot(traj[-1, 0], traj[-1, 1], "s", color="tab:purple", markersize=5, label="end")
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title or f"SLAM map, {grid.cell_size_m:g} m/cell")
    ax.legend(loc="upper right", fontsize="small")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()
