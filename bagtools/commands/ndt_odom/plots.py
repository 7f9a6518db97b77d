"""Pictures of a laser-odometry run: the trajectories in one plot, and the scans superimposed."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bagtools.figures import tidy_layout
from bagtools.trajectory import Trajectory

#: Side of the pixels of the scan map, metres.
SCAN_MAP_CELL_M = 0.02
#: Larger maps get coarser pixels so the image stays at most this many pixels wide.
MAX_SCAN_MAP_PIXELS = 1600


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def render_trajectories_png(path: Path, frame: str, ndt: Trajectory, odometry: Trajectory | None = None,
                            ground_truth: Trajectory | None = None, title: str = "laser odometry") -> None:
    """x-y plot (metres, in ``frame``) of the NDT trajectory with wheel odometry and ground truth when given."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 8))
    for traj, label, style in ((ground_truth, "ground truth", dict(color="black", linewidth=2.0, alpha=0.5)),
                               (odometry, "wheel odometry", dict(color="tab:orange", linewidth=1.2)),
                               (ndt, "NDT", dict(color="tab:blue", linewidth=1.2))):
        if traj is not None and len(traj):
            xy = traj.positions[:, :2]
            ax.plot(xy[:, 0], xy[:, 1], label=label, **style)
    start = ndt.positions[0, :2]
    ax.plot(start[0], start[1], "o", color="tab:green", label="start")
    ax.set_xlabel(f"x in {frame} [m]")
    ax.set_ylabel(f"y in {frame} [m]")
    ax.set_title(title)
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    tidy_layout(fig)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def scans_in_frame(scan_points: list[np.ndarray], scan_poses: np.ndarray) -> np.ndarray:
    """(M,2) points of every scan moved into the fixed frame by its pose T_frame_scan (N,4,4)."""
    if not scan_points:
        return np.empty((0, 2))
    counts = np.array([len(p) for p in scan_points])
    xy = np.concatenate(scan_points)
    owner = np.repeat(np.arange(len(scan_points)), counts)
    R, t = scan_poses[owner, :2, :2], scan_poses[owner, :2, 3]
    return np.einsum("nij,nj->ni", R, xy) + t


def render_scan_map_png(path: Path, frame: str, scan_points: list[np.ndarray], scan_poses: np.ndarray,
                        base_xy: np.ndarray, title: str = "scans at the NDT poses") -> None:
    """All scans superimposed at their poses (a point-density image) with the robot's path on top."""
    import matplotlib.colors as mcolors

    plt = _pyplot()
    points = scans_in_frame(scan_points, scan_poses)
    fig, ax = plt.subplots(figsize=(8, 8))
    if len(points):
        extent = float(np.max(np.ptp(np.vstack((points, base_xy)), axis=0)))
        cell = max(SCAN_MAP_CELL_M, extent / MAX_SCAN_MAP_PIXELS)
        lo = np.minimum(points.min(axis=0), base_xy.min(axis=0)) - cell
        hi = np.maximum(points.max(axis=0), base_xy.max(axis=0)) + 2 * cell
        x_edges, y_edges = np.arange(lo[0], hi[0], cell), np.arange(lo[1], hi[1], cell)
        if len(x_edges) > 1 and len(y_edges) > 1:
            hist, _, _ = np.histogram2d(points[:, 0], points[:, 1], bins=(x_edges, y_edges))
            ax.imshow(np.ma.masked_equal(hist.T, 0), origin="lower", cmap="viridis", norm=mcolors.LogNorm(),
                      extent=(x_edges[0], x_edges[-1], y_edges[0], y_edges[-1]), interpolation="nearest")
    ax.plot(base_xy[:, 0], base_xy[:, 1], color="red", linewidth=1.0, label="robot path (NDT)")
    ax.set_xlabel(f"x in {frame} [m]")
    ax.set_ylabel(f"y in {frame} [m]")
    ax.set_title(f"{title} ({len(scan_points)} scans, {len(points)} points)")
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right")
    tidy_layout(fig)
    fig.savefig(path, dpi=110)
    plt.close(fig)
