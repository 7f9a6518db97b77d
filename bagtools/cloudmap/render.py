"""Pictures and files of a point-cloud map: PNG top and side views, PCD and PLY through Open3D."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def write_point_cloud(path: Path, points: np.ndarray) -> None:
    """Write (N,3) points as PCD or PLY (by suffix) with Open3D, binary."""
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))
    if not o3d.io.write_point_cloud(str(path), cloud, write_ascii=False):
        raise OSError(f"Open3D could not write {path}")


def _density(ax, u: np.ndarray, v: np.ndarray, cell_m: float, label_u: str, label_v: str, title: str) -> None:
    import matplotlib.colors as mcolors

    if u.size == 0:
        ax.text(0.5, 0.5, "no points", ha="center", va="center", transform=ax.transAxes)
    else:
        u_edges = np.arange(u.min() - cell_m, u.max() + 2 * cell_m, cell_m)
        v_edges = np.arange(v.min() - cell_m, v.max() + 2 * cell_m, cell_m)
        hist, _, _ = np.histogram2d(u, v, bins=(u_edges, v_edges))
        ax.imshow(np.ma.masked_equal(hist.T, 0), origin="lower", cmap="viridis", norm=mcolors.LogNorm(),
                  extent=(u_edges[0], u_edges[-1], v_edges[0], v_edges[-1]), interpolation="nearest")
    ax.set_xlabel(label_u)
    ax.set_ylabel(label_v)
    ax.set_title(title)
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)


def render_map_png(path: Path, points: np.ndarray, frame: str, trajectory_xyz: np.ndarray | None = None,
                   title: str = "point-cloud map") -> None:
    """Top view (x-y) and side view (x-z) of ``points`` as point-density images, with the sensor path on top."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, side) = plt.subplots(2, 1, figsize=(8, 10), gridspec_kw={"height_ratios": [3, 1]})
    cell = 0.02
    _density(top, points[:, 0], points[:, 1], cell, f"x in {frame} [m]", f"y in {frame} [m]", f"{title}: top view ({len(points)} points)")
    _density(side, points[:, 0], points[:, 2], cell, f"x in {frame} [m]", f"z in {frame} [m]", "side view")
    if trajectory_xyz is not None and len(trajectory_xyz):
        top.plot(trajectory_xyz[:, 0], trajectory_xyz[:, 1], color="red", linewidth=1.0, label="sensor path")
        top.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
