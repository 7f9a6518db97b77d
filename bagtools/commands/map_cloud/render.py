"""Pictures of a point-cloud map: PNG top and side views (the files are in :mod:`bagtools.commands.map_cloud.files`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bagtools.figures import tidy_layout


#: The views' rasters have at most this many cells a side (a figure is some 900 pixels wide): a large map gets
#: coarser cells, never a raster sized by its extent (7 GiB for 600 m at 2 cm, terabytes for a damaged cloud).
MAX_CELLS_PER_SIDE = 1000


def _grid_edges(u: np.ndarray, v: np.ndarray, cell_m: float) -> tuple[np.ndarray, np.ndarray]:
    extent = max(float(np.ptp(u)), float(np.ptp(v)))
    cell_m = max(cell_m, extent / MAX_CELLS_PER_SIDE)
    u_edges = np.linspace(u.min() - cell_m, u.min() - cell_m + cell_m * (np.ceil(np.ptp(u) / cell_m) + 3),
                          int(np.ceil(np.ptp(u) / cell_m)) + 4)
    v_edges = np.linspace(v.min() - cell_m, v.min() - cell_m + cell_m * (np.ceil(np.ptp(v) / cell_m) + 3),
                          int(np.ceil(np.ptp(v) / cell_m)) + 4)
    return u_edges, v_edges


def _finish_axes(ax, label_u: str, label_v: str, title: str) -> None:
    ax.set_xlabel(label_u)
    ax.set_ylabel(label_v)
    ax.set_title(title)
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)


def _height_image(fig, ax, points: np.ndarray, cell_m: float, frame: str, title: str) -> None:
    """Top view: the highest point of each cell, coloured by height, so walls stand out from the floor."""
    if points.shape[0] == 0:
        ax.text(0.5, 0.5, "no points", ha="center", va="center", transform=ax.transAxes)
    else:
        u_edges, v_edges = _grid_edges(points[:, 0], points[:, 1], cell_m)
        iu = np.clip(np.searchsorted(u_edges, points[:, 0], side="right") - 1, 0, u_edges.size - 2)
        iv = np.clip(np.searchsorted(v_edges, points[:, 1], side="right") - 1, 0, v_edges.size - 2)
        top = np.full((v_edges.size - 1, u_edges.size - 1), -np.inf)
        np.maximum.at(top, (iv, iu), points[:, 2].astype(np.float64))
        image = ax.imshow(np.ma.masked_invalid(np.where(np.isinf(top), np.nan, top)), origin="lower", cmap="viridis",
                          extent=(u_edges[0], u_edges[-1], v_edges[0], v_edges[-1]), interpolation="nearest")
        fig.colorbar(image, ax=ax, label=f"highest z in {frame} [m]", shrink=0.8)
    _finish_axes(ax, f"x in {frame} [m]", f"y in {frame} [m]", title)


def _density(ax, u: np.ndarray, v: np.ndarray, cell_m: float, label_u: str, label_v: str, title: str) -> None:
    """Side view: point density (log scale)."""
    import matplotlib.colors as mcolors

    if u.size == 0:
        ax.text(0.5, 0.5, "no points", ha="center", va="center", transform=ax.transAxes)
    else:
        u_edges, v_edges = _grid_edges(u, v, cell_m)
        hist, _, _ = np.histogram2d(u, v, bins=(u_edges, v_edges))
        ax.imshow(np.ma.masked_equal(hist.T, 0), origin="lower", cmap="magma_r", norm=mcolors.LogNorm(),
                  extent=(u_edges[0], u_edges[-1], v_edges[0], v_edges[-1]), interpolation="nearest")
    _finish_axes(ax, label_u, label_v, title)


def render_map_png(path: Path, points: np.ndarray, frame: str, trajectory_xyz: np.ndarray | None = None,
                   title: str = "point-cloud map") -> None:
    """Top view (x-y) and side view (x-z) of ``points`` as point-density images, with the sensor path on top."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, side) = plt.subplots(2, 1, figsize=(8, 10), gridspec_kw={"height_ratios": [3, 1]})
    cell = 0.02
    _height_image(fig, top, points, cell, frame, f"{title}: top view ({len(points)} points)")
    _density(side, points[:, 0], points[:, 2], cell, f"x in {frame} [m]", f"z in {frame} [m]", "side view (point density)")
    if trajectory_xyz is not None and len(trajectory_xyz):
        top.plot(trajectory_xyz[:, 0], trajectory_xyz[:, 1], color="red", linewidth=1.0, label="sensor path")
        top.legend(loc="upper right")
    tidy_layout(fig)
    fig.savefig(path, dpi=110)
    plt.close(fig)
