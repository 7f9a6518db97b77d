"""Occupancy grids as files: the ROS map_server / nav2 PGM + YAML pair, and a PNG for people.

The nav2 format (nav2_map_server's map_io): a greyscale image, row 0 the top of
the map (largest y), and a YAML file with ``image``, ``mode``, ``resolution``
(metres per cell), ``origin`` ([x, y, yaw] of the lower-left corner of the
lower-left pixel, metres and rad), ``negate``, ``occupied_thresh`` and
``free_thresh``. map_server turns pixel value v into p = (255 - v) / 255 (v /
255 when negate is 1); in trinary mode p > occupied_thresh is occupied (100),
p < free_thresh is free (0), anything else unknown (-1).

We write pixels 0 (occupied), 254 (free) and 205 (unknown), as map_saver does.
205 reads as p = 50/255 = 0.196, so the YAML's free_thresh must not exceed that
for unknown cells to load as unknown: we write occupied_thresh 0.65 and
free_thresh 0.196 (ROS map_saver's values). These thresholds only say how the
pixels are read; the grid's own thresholds decided which pixels are which.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools.limits import MAX_MAP_ORIGIN_M
from bagtools.figures import tidy_layout
from bagtools.grid.occupancy import OccupancyGrid
from bagtools.outputs import OutputDir, atomic_path

PIXEL_OCCUPIED = 0
PIXEL_FREE = 254
PIXEL_UNKNOWN = 205
YAML_OCCUPIED_THRESH = 0.65
YAML_FREE_THRESH = 0.196


#: A map picture's raster holds at most this many pixels a side: larger maps pool cells (see grey_pixels).
MAX_PICTURE_PX = 2000


def _fmt(x: float) -> str:
    """A float for YAML: rounded to 1e-9, shortest repr, never '-0.0'."""
    value = round(float(x), 9) + 0.0
    return repr(value)


def ternary_to_pixels(ternary: np.ndarray) -> np.ndarray:
    """Grid classes (1 occupied, 0 free, -1 unknown) -> uint8 pixels 0 / 254 / 205, same layout."""
    ternary = np.asarray(ternary)
    pixels = np.full(ternary.shape, PIXEL_UNKNOWN, dtype=np.uint8)
    pixels[ternary == 1] = PIXEL_OCCUPIED
    pixels[ternary == 0] = PIXEL_FREE
    return pixels


def pgm_bytes(pixels: np.ndarray) -> bytes:
    """A binary (P5) 8-bit PGM of a (rows, cols) uint8 image, row 0 at the top."""
    pixels = np.ascontiguousarray(pixels, dtype=np.uint8)
    if pixels.ndim != 2:
        raise ValueError(f"pixels must be 2-D, got shape {pixels.shape}")
    rows, cols = pixels.shape
    return f"P5\n{cols} {rows}\n255\n".encode("ascii") + pixels.tobytes()


def nav2_yaml_text(image_name: str, resolution_m: float, origin_xy: tuple[float, float] | np.ndarray) -> str:
    """The map YAML for a trinary PGM: resolution in metres per cell, origin of the lower-left pixel."""
    x, y = (float(v) for v in origin_xy)
    return (
        f"image: {image_name}\n"
        "mode: trinary\n"
        f"resolution: {_fmt(resolution_m)}\n"
        f"origin: [{_fmt(x)}, {_fmt(y)}, 0.0]\n"
        "negate: 0\n"
        f"occupied_thresh: {YAML_OCCUPIED_THRESH}\n"
        f"free_thresh: {YAML_FREE_THRESH}\n"
    )


def nav2_map_files(grid: OccupancyGrid, name: str = "map") -> dict[str, bytes]:
    """The nav2 map of ``grid`` as {file name: contents}: ``<name>.pgm`` and ``<name>.yaml``.

    For callers that stage several outputs in one :class:`bagtools.outputs.OutputDir`.
    """
    pixels = ternary_to_pixels(grid.occupancy_matrix("ternary"))
    image = f"{name}.pgm"
    return {
        image: pgm_bytes(pixels),
        f"{name}.yaml": nav2_yaml_text(image, grid.cell_size_m, grid.grid_location_in_world).encode("utf-8"),
    }


def write_nav2_map(grid: OccupancyGrid, out_dir: str | Path, name: str = "map", force: bool = False) -> Path:
    """Write ``out_dir/<name>.pgm`` and ``out_dir/<name>.yaml`` together, atomically; returns the YAML path.

    Raises :class:`bagtools.errors.OutputExistsError` if either exists and ``force`` is false.
    """
    files = nav2_map_files(grid, name)
    with OutputDir(out_dir, list(files), force) as staged:
        for fname, data in files.items():
            (staged / fname).write_bytes(data)
    return Path(out_dir) / f"{name}.yaml"


# ---- reading ----------------------------------------------------------------------


@dataclass(frozen=True)
class Nav2Map:
    """A map as nav2's map_server loads it.

    ``occupancy`` holds the nav_msgs/OccupancyGrid values (100 occupied, 0 free,
    -1 unknown, 1..99 in scale mode) laid out like the image: row 0 at the top.
    """

    yaml_path: Path
    image_path: Path
    mode: str
    resolution_m: float
    origin: tuple[float, float, float]
    negate: bool
    occupied_thresh: float
    free_thresh: float
    pixels: np.ndarray
    occupancy: np.ndarray

    def ternary(self) -> np.ndarray:
        """(rows, cols) int8: 1 occupied, 0 free, -1 unknown or in between, row 0 at the top."""
        out = np.full(self.occupancy.shape, -1, dtype=np.int8)
        out[self.occupancy == 100] = 1
        out[self.occupancy == 0] = 0
        return out

    def known(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: whether the map knows what is at map-frame places ``xy`` (N, 2) (m): a free or occupied
        cell, not an unknown one, nor a place off the image."""
        x, y, yaw = self.origin
        c, s = math.cos(yaw), math.sin(yaw)
        local = (np.asarray(xy, dtype=np.float64).reshape(-1, 2) - np.array([x, y])) @ np.array([[c, -s], [s, c]])
        cols = np.floor(local[:, 0] / self.resolution_m).astype(np.intp)
        rows = self.occupancy.shape[0] - 1 - np.floor(local[:, 1] / self.resolution_m).astype(np.intp)
        inside = (cols >= 0) & (cols < self.occupancy.shape[1]) & (rows >= 0) & (rows < self.occupancy.shape[0])
        out = np.zeros(len(local), dtype=bool)
        out[inside] = self.occupancy[rows[inside], cols[inside]] >= 0
        return out

    def occupied_points(self) -> np.ndarray:
        """(N, 2) map-frame x, y (m) of the centres of the occupied cells (occupancy 100), the origin's yaw
        applied as map_server places the image: its lower-left pixel's corner at the origin pose."""
        rows, cols = np.nonzero(self.occupancy == 100)
        return self._image_to_map(cols + 0.5, rows + 0.5)

    def wall_faces(self) -> np.ndarray:
        """(N, 2) map-frame x, y (m) of where the walls face the free space: the midpoint of every side an occupied
        cell shares with a free one (4-neighbours), and the centre of each occupied cell with no free neighbour.

        A laser sees a wall's surface, and in a map raytraced from scans that surface is the border between the
        free and the occupied cells: beams that end a little further on, or pass the wall at a grazing angle, clear
        the near part of the cells it crosses. Matching scans to the occupied cells' centres instead places the
        robot about half a cell towards the walls it sees (1.8-2.7 cm forward on the benchmark logs' slam maps,
        whose laser looks ahead)."""
        occupied, free = self.occupancy == 100, self.occupancy == 0
        padded = np.pad(free, 1)
        rows, cols = np.nonzero(occupied)
        u, v, facing = [], [], np.zeros(len(rows), dtype=bool)
        for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            side = padded[rows + 1 + dr, cols + 1 + dc]
            facing |= side
            u.append(cols[side] + 0.5 + 0.5 * dc)
            v.append(rows[side] + 0.5 + 0.5 * dr)
        u.append(cols[~facing] + 0.5)
        v.append(rows[~facing] + 0.5)
        return self._image_to_map(np.concatenate(u), np.concatenate(v))

    def _image_to_map(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(N, 2) map-frame x, y (m) of image places ``u`` (columns, from the left edge) and ``v`` (rows, from the
        top edge), in cells: map_server puts the image's lower-left corner at the origin pose."""
        local = np.c_[np.asarray(u, dtype=np.float64) * self.resolution_m,
                      (self.occupancy.shape[0] - np.asarray(v, dtype=np.float64)) * self.resolution_m]
        x, y, yaw = self.origin
        c, s = math.cos(yaw), math.sin(yaw)
        return local @ np.array([[c, s], [-s, c]]) + np.array([x, y])


def _regular_file(path: Path, what: str) -> None:
    """Refuse a ``what`` (map YAML, map image) that is missing, a directory, a pipe or a device (reading /dev/zero
    or a FIFO never ends)."""
    if not path.exists():
        raise BagtoolsError(f"{what} not found", path)
    if not path.is_file():
        raise BagtoolsError(f"{what} is not a regular file (a directory, a pipe or a device)", path)


def _parse_map_yaml(path: Path) -> dict[str, object]:
    """The mapping of a map YAML, parsed as YAML (flow or block style, a byte-order mark allowed)."""
    from ruamel.yaml import YAML, YAMLError

    _regular_file(path, "map YAML")
    try:
        text = path.read_text(encoding="utf-8-sig")
        fields = YAML(typ="safe", pure=True).load(text)
    except (OSError, UnicodeDecodeError) as exc:
        raise BagtoolsError(f"cannot read map YAML ({exc.__class__.__name__})", path) from None
    except YAMLError as exc:
        raise BagtoolsError(f"not YAML: {' '.join(str(exc).split())[:200]}", path) from None
    if not isinstance(fields, dict):
        raise BagtoolsError("map YAML is not a mapping of keys to values (image, resolution, origin, ...)", path)
    return fields


def _number(fields: dict[str, object], key: str, path: Path) -> float:
    if key not in fields:
        raise BagtoolsError(f"map YAML has no '{key}'", path)
    try:
        value = float(fields[key])  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise BagtoolsError(f"'{key}' is not a number: {fields[key]!r}", path) from None
    if not math.isfinite(value):
        raise BagtoolsError(f"'{key}' is not finite: {fields[key]!r}", path)
    return value


def _origin(fields: dict[str, object], path: Path) -> tuple[float, float, float]:
    """``origin`` as [x, y, yaw] (a YAML list in flow or block style)."""
    value = fields.get("origin")
    if value is None:
        raise BagtoolsError("map YAML has no 'origin'", path)
    try:
        origin = tuple(float(v) for v in value) if isinstance(value, (list, tuple)) else ()  # type: ignore[union-attr]
    except (TypeError, ValueError):
        origin = ()
    if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
        raise BagtoolsError(f"'origin' must be [x, y, yaw], got {value!r}", path)
    if max(abs(origin[0]), abs(origin[1])) > MAX_MAP_ORIGIN_M:
        raise BagtoolsError(f"'origin' {list(origin)} lies beyond {MAX_MAP_ORIGIN_M:g} m: not a map of a place", path)
    return origin  # type: ignore[return-value]


def _pgm_tokens(data: bytes, count: int, path: Path) -> tuple[list[int], int]:
    """The first ``count`` header integers after the magic, and the offset just past them."""
    tokens: list[int] = []
    pos = 2
    while len(tokens) < count:
        while pos < len(data) and data[pos:pos + 1].isspace():
            pos += 1
        if pos < len(data) and data[pos:pos + 1] == b"#":
            while pos < len(data) and data[pos:pos + 1] not in (b"\n", b"\r"):
                pos += 1
            continue
        start = pos
        while pos < len(data) and data[pos:pos + 1].isdigit():
            pos += 1
        if start == pos:
            raise BagtoolsError("PGM header is malformed", path)
        tokens.append(int(data[start:pos]))
    return tokens, pos


def read_pgm(path: str | Path) -> np.ndarray:
    """A PGM image (binary P5 or ASCII P2, max value up to 255) as (rows, cols) uint8, row 0 at the top."""
    path = Path(path)
    _regular_file(path, "map image")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise BagtoolsError(f"cannot read map image ({exc.__class__.__name__})", path) from None
    magic = data[:2]
    if magic not in (b"P5", b"P2"):
        raise BagtoolsError("not a PGM image (expected P5 or P2); only PGM map images are supported", path)
    (cols, rows, maxval), pos = _pgm_tokens(data, 3, path)
    if cols <= 0 or rows <= 0 or not 0 < maxval <= 255:
        raise BagtoolsError(f"unsupported PGM size {cols}x{rows} or max value {maxval} (8-bit only)", path)
    if magic == b"P5":
        body = data[pos + 1:pos + 1 + rows * cols]
        if len(body) < rows * cols:
            raise BagtoolsError(f"PGM is truncated: {len(body)} of {rows * cols} pixels", path)
        values = np.frombuffer(body, dtype=np.uint8).reshape(rows, cols)
    else:
        words = data[pos:].split()
        if len(words) < rows * cols:
            raise BagtoolsError(f"PGM is truncated: {len(words)} of {rows * cols} pixels", path)
        try:
            values = np.array([int(w) for w in words[:rows * cols]], dtype=np.int64).reshape(rows, cols)
        except ValueError:
            raise BagtoolsError("PGM pixel data is not numeric", path) from None
        if values.min() < 0 or values.max() > maxval:
            raise BagtoolsError("PGM pixel values exceed the max value", path)
    if maxval != 255:
        values = np.rint(values.astype(np.float64) * 255.0 / maxval)
    return values.astype(np.uint8)


def read_nav2_map(yaml_path: str | Path) -> Nav2Map:
    """Load a map_server / nav2 map (YAML + PGM) with nav2's pixel-to-occupancy rules.

    Raises :class:`bagtools.errors.BagtoolsError` naming the file for a missing or
    malformed YAML or image.
    """
    yaml_path = Path(yaml_path)
    fields = _parse_map_yaml(yaml_path)
    image = fields.get("image", "")
    if not image or not isinstance(image, str):
        raise BagtoolsError("map YAML has no 'image' file name", yaml_path)
    image_path = Path(image) if Path(image).is_absolute() else yaml_path.parent / image
    resolution = _number(fields, "resolution", yaml_path)
    if resolution <= 0:
        raise BagtoolsError(f"'resolution' must be positive, got {resolution}", yaml_path)
    occ_th = _number(fields, "occupied_thresh", yaml_path)
    free_th = _number(fields, "free_thresh", yaml_path)
    origin = _origin(fields, yaml_path)
    negate_text = str(fields.get("negate", "0")).strip().lower()
    if negate_text not in ("0", "1", "true", "false"):
        raise BagtoolsError(f"'negate' must be 0 or 1, got {negate_text!r}", yaml_path)
    negate = negate_text in ("1", "true")
    mode = str(fields.get("mode", "trinary")).strip().lower()
    if mode not in ("trinary", "scale", "raw"):
        raise BagtoolsError(f"'mode' must be trinary, scale or raw, got {mode!r}", yaml_path)
    if mode == "scale" and not occ_th > free_th:  # scale maps the shades between them: none between equal ones
        raise BagtoolsError(f"mode scale needs occupied_thresh above free_thresh, got {occ_th} and {free_th}",
                            yaml_path)
    pixels = read_pgm(image_path)
    # The occupancy of each of the 256 grey values, then looked up per pixel (a 12000 x 12000 image needs no
    # float copies of itself).
    values = np.arange(256, dtype=np.uint8)
    shade = values.astype(np.float64) / 255.0
    occ = shade if negate else 1.0 - shade
    if mode == "raw":
        table = np.where(values <= 100, values, -1).astype(np.int8)
    else:
        table = np.full(256, -1, dtype=np.int8)
        if mode == "scale":  # a PGM has no alpha channel: every pixel is opaque
            between = np.rint((occ - free_th) / (occ_th - free_th) * 100.0)
            table = np.clip(between, -128, 127).astype(np.int8)
        table[occ > occ_th] = 100
        table[(occ < free_th) & ~(occ > occ_th)] = 0
    occupancy = table[pixels]
    return Nav2Map(yaml_path, image_path, mode, resolution, origin, negate, occ_th, free_th, pixels, occupancy)  # type: ignore[arg-type]


# ---- the picture for people -------------------------------------------------------


def render_map_png(
    grid: OccupancyGrid,
    trajectory_xy: np.ndarray | None = None,
    title: str | None = None,
    dpi: int = 100,
) -> bytes:
    """A PNG of the map: occupancy probability in grey (white free, black occupied,
    mid-grey unknown) on metric axes, with an optional (N, 2) world trajectory drawn on it."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    x0, x1 = grid.x_world_limits
    y0, y1 = grid.y_world_limits
    rows, cols = grid.grid_size
    aspect = rows / cols
    width_in = 8.0
    fig = Figure(figsize=(width_in, min(max(width_in * aspect, 3.0), 16.0) + 0.8), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    # grey bytes, pooled to about the picture's resolution: no colour mapping of millions of float cells
    grey, _ = grey_pixels(grid.occupancy_matrix("probability"), MAX_PICTURE_PX)
    ax.imshow(rgba_pixels(grey), origin="upper", extent=(x0, x1, y0, y1),
              interpolation="nearest")
    if trajectory_xy is not None:
        traj = _trajectory(trajectory_xy)
        if traj.shape[0]:
            ax.plot(traj[:, 0], traj[:, 1], color="tab:red", linewidth=1.2, label="trajectory")
            ax.plot(traj[0, 0], traj[0, 1], "o", color="tab:green", markersize=5, label="start")
            ax.plot(traj[-1, 0], traj[-1, 1], "s", color="tab:blue", markersize=5, label="end")
            ax.legend(loc="upper right", fontsize="small")
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title if title is not None else f"occupancy grid, {grid.cell_size_m:g} m/cell")
    tidy_layout(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def grey_pixels(probability: np.ndarray, max_px: int) -> tuple[np.ndarray, int]:
    """(grey (R, C) uint8: 255 free, 0 occupied; the cells per pixel k) of a probability matrix, for a picture
    at most ``max_px`` pixels a side: k x k blocks of cells become one pixel, the darkest of them (a wall one
    cell thick stays visible). ``probability`` is overwritten (it is the caller's scratch copy)."""
    k = max(1, -(-max(probability.shape) // max_px))
    np.subtract(1.0, probability, out=probability)
    probability *= 255.0
    np.rint(probability, out=probability)
    rows, cols = probability.shape
    if k == 1:
        return probability.astype(np.uint8), 1
    grey = np.full((-(-rows // k), -(-cols // k)), 255, dtype=np.uint8)
    for r in range(k):  # the minimum over each block, one block offset at a time (no k^2 x temporary)
        for c in range(k):
            part = probability[r::k, c::k].astype(np.uint8)
            view = grey[:part.shape[0], :part.shape[1]]
            np.minimum(view, part, out=view)
    return grey, k


def rgba_pixels(grey: np.ndarray) -> np.ndarray:
    """Opaque RGBA bytes (R, C, 4) of grey pixels (R, C) uint8: what matplotlib's imshow draws without converting
    (an RGB or a colour-mapped array is first converted at full size)."""
    rgba = np.empty(grey.shape + (4,), dtype=np.uint8)
    rgba[..., :3] = grey[..., None]
    rgba[..., 3] = 255
    return rgba


def _trajectory(trajectory_xy: np.ndarray) -> np.ndarray:
    traj = np.asarray(trajectory_xy, dtype=np.float64)
    if traj.ndim != 2 or traj.shape[1] < 2:
        raise ValueError(f"trajectory must be (N, 2) [x y], got shape {traj.shape}")
    traj = traj[:, :2]
    return traj[np.all(np.isfinite(traj), axis=1)]


def write_map_png(
    grid: OccupancyGrid, path: str | Path, trajectory_xy: np.ndarray | None = None,
    title: str | None = None, force: bool = False,
) -> Path:
    """Write :func:`render_map_png` to ``path`` atomically (refusing to overwrite unless ``force``)."""
    data = render_map_png(grid, trajectory_xy, title)
    with atomic_path(path, force) as tmp:
        tmp.write_bytes(data)
    return Path(path)
