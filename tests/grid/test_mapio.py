"""nav2 PGM + YAML writer/reader round trip, pixel values, nav2 loading rules, bad files, PNG."""

from __future__ import annotations

import io
import os

import numpy as np
import pytest

from bagtools.errors import BagtoolsError, OutputExistsError
from bagtools.grid import OccupancyGrid, nav2_map_files, read_nav2_map, render_map_png, write_map_png, write_nav2_map
from bagtools.grid.mapio import pgm_bytes, read_pgm


def toy_grid() -> OccupancyGrid:
    """3 x 4 cells at 5 cm, bottom-left at (-1.25, 2.5); top-left occupied, bottom row free."""
    p = np.array([
        [0.95, 0.5, 0.5, 0.3],
        [0.5, 0.7, 0.19, 0.5],
        [0.1, 0.1, 0.1, 0.66],
    ])
    return OccupancyGrid.from_probabilities(p, 20.0, (-1.25, 2.5))


def test_pgm_pixels_and_layout(tmp_path):
    yaml_path = write_nav2_map(toy_grid(), tmp_path)
    assert yaml_path == tmp_path / "map.yaml"
    data = (tmp_path / "map.pgm").read_bytes()
    header = b"P5\n4 3\n255\n"
    assert data.startswith(header) and len(data) == len(header) + 12
    pixels = np.frombuffer(data[len(header):], dtype=np.uint8).reshape(3, 4)
    # row 0 of the image is the top of the map
    assert pixels.tolist() == [
        [0, 205, 205, 205],
        [205, 0, 254, 205],
        [254, 254, 254, 0],
    ]


def test_yaml_fields(tmp_path):
    write_nav2_map(toy_grid(), tmp_path, name="floor")
    text = (tmp_path / "floor.yaml").read_text()
    assert text.splitlines() == [
        "image: floor.pgm",
        "mode: trinary",
        "resolution: 0.05",
        "origin: [-1.25, 2.5, 0.0]",
        "negate: 0",
        "occupied_thresh: 0.65",
        "free_thresh: 0.196",
    ]


def test_round_trip_keeps_classes_and_geometry(tmp_path):
    rng = np.random.default_rng(5)
    grid = OccupancyGrid(3.0, 2.0, 20.0, (-7.3, 1.15))
    for _ in range(5):
        pose = np.r_[rng.uniform([-6.5, 1.5], [-5.0, 2.8]), rng.uniform(-3, 3)]
        grid.insert_ray(pose, rng.uniform(0.2, 2.5, 90), np.linspace(-np.pi, np.pi, 90, endpoint=False), 2.0)
    write_nav2_map(grid, tmp_path / "out")
    loaded = read_nav2_map(tmp_path / "out" / "map.yaml")
    np.testing.assert_array_equal(loaded.ternary(), grid.occupancy_matrix("ternary"))
    assert set(np.unique(loaded.occupancy)) <= {-1, 0, 100}
    assert loaded.resolution_m == pytest.approx(grid.cell_size_m)
    np.testing.assert_allclose(loaded.origin[:2], grid.grid_location_in_world, atol=1e-9)
    assert loaded.origin[2] == 0.0 and loaded.mode == "trinary" and not loaded.negate


def test_nav2_rules_for_unknown_pixels(tmp_path):
    """205 reads as p = 0.196: unknown with our free_thresh, free with map_saver's 0.25 default."""
    (tmp_path / "m.pgm").write_bytes(pgm_bytes(np.array([[0, 205, 254, 100]], dtype=np.uint8)))
    (tmp_path / "ours.yaml").write_text(
        "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    (tmp_path / "loose.yaml").write_text(
        "image: m.pgm  # comment\nmode: trinary\nresolution: 0.1\norigin: [0.0, 0.0, 0.0]\n"
        "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n")
    (tmp_path / "neg.yaml").write_text(
        "image: 'm.pgm'\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 1\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    assert read_nav2_map(tmp_path / "ours.yaml").occupancy.tolist() == [[100, -1, 0, -1]]
    assert read_nav2_map(tmp_path / "loose.yaml").occupancy.tolist() == [[100, 0, 0, -1]]
    # negate: bright is occupied. 100/255 = 0.39 is in between
    assert read_nav2_map(tmp_path / "neg.yaml").occupancy.tolist() == [[0, 100, 100, -1]]


def test_ascii_pgm_with_comments_and_maxval(tmp_path):
    (tmp_path / "a.pgm").write_bytes(b"P2\n# made by hand\n3 1\n15\n0 15 8\n")
    assert read_pgm(tmp_path / "a.pgm").tolist() == [[0, 255, 136]]


def test_refuses_to_overwrite_without_force(tmp_path):
    write_nav2_map(toy_grid(), tmp_path)
    before = (tmp_path / "map.pgm").read_bytes()
    other = OccupancyGrid(1.0, 1.0, 10.0)
    with pytest.raises(OutputExistsError):
        write_nav2_map(other, tmp_path)
    assert (tmp_path / "map.pgm").read_bytes() == before
    write_nav2_map(other, tmp_path, force=True)
    assert (tmp_path / "map.pgm").read_bytes().startswith(b"P5\n10 10\n255\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.pgm", "map.yaml"]


def test_nav2_map_files_for_staged_outputs():
    files = nav2_map_files(toy_grid(), name="level1")
    assert sorted(files) == ["level1.pgm", "level1.yaml"]
    assert b"image: level1.pgm" in files["level1.yaml"]


GOOD_YAML = "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"


@pytest.mark.parametrize(
    "yaml_text, image, match",
    [
        (None, b"P5\n1 1\n255\n\x00", "not found"),
        (GOOD_YAML, None, "not found"),
        (GOOD_YAML.replace("origin: [0, 0, 0]", "origin: [0, 0]"), b"P5\n1 1\n255\n\x00", "origin"),
        (GOOD_YAML.replace("resolution: 0.05\n", ""), b"P5\n1 1\n255\n\x00", "resolution"),
        (GOOD_YAML.replace("resolution: 0.05", "resolution: fine"), b"P5\n1 1\n255\n\x00", "not a number"),
        (GOOD_YAML.replace("resolution: 0.05", "resolution: -1"), b"P5\n1 1\n255\n\x00", "positive"),
        (GOOD_YAML.replace("image: m.pgm\n", ""), b"P5\n1 1\n255\n\x00", "image"),
        (GOOD_YAML + "- a list item\n", b"P5\n1 1\n255\n\x00", "not YAML"),
        ("- image: m.pgm\n", b"P5\n1 1\n255\n\x00", "not a mapping"),
        (GOOD_YAML.replace("origin: [0, 0, 0]", "origin: [1e308, 0, 0]"), b"P5\n1 1\n255\n\x00", "not a map of a place"),
        (GOOD_YAML.replace("free_thresh: 0.196", "free_thresh: 0.65") + "mode: scale\n",
         b"P5\n1 1\n255\n\x00", "mode scale needs occupied_thresh above free_thresh"),
        (GOOD_YAML.replace("negate: 0", "negate: maybe"), b"P5\n1 1\n255\n\x00", "negate"),
        (GOOD_YAML + "mode: fancy\n", b"P5\n1 1\n255\n\x00", "mode"),
        (GOOD_YAML, b"\x89PNG\r\n\x1a\n", "not a PGM"),
        (GOOD_YAML, b"P5\n4 4\n255\n\x00\x00", "truncated"),
        (GOOD_YAML, b"P5\n4 4\n65535\n", "8-bit"),
        (GOOD_YAML, b"P5\nfour 4\n255\n", "malformed"),
    ],
)
def test_bad_map_files_raise_one_line_errors(tmp_path, yaml_text, image, match):
    if yaml_text is not None:
        (tmp_path / "map.yaml").write_text(yaml_text)
    if image is not None:
        (tmp_path / "m.pgm").write_bytes(image)
    with pytest.raises(BagtoolsError, match=match) as info:
        read_nav2_map(tmp_path / "map.yaml")
    assert info.value.path is not None and info.value.path.endswith((".yaml", ".pgm"))
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("yaml_text", [
    "{image: m.pgm, resolution: 0.05, origin: [0, 0, 0], negate: 0, occupied_thresh: 0.65, free_thresh: 0.196}\n",
    "image: m.pgm\nresolution: 0.05\norigin:\n  - 0\n  - 0\n  - 0\nnegate: 0\noccupied_thresh: 0.65\n"
    "free_thresh: 0.196\n",
    "\ufeff" + GOOD_YAML,
])
def test_map_yaml_in_any_yaml_style_reads(tmp_path, yaml_text):
    """A flow mapping, a block list and a byte-order mark are YAML as map_server reads it (they were refused)."""
    (tmp_path / "map.yaml").write_text(yaml_text, encoding="utf-8")
    (tmp_path / "m.pgm").write_bytes(b"P5\n2 1\n255\n\x00\xfe")
    assert read_nav2_map(tmp_path / "map.yaml").occupancy.tolist() == [[100, 0]]


def test_a_map_image_that_is_a_pipe_or_a_device_is_refused(tmp_path):
    """Reading a FIFO hung; /dev/zero grew to 3.8 GB before 'out of memory' named the bag."""
    fifo = tmp_path / "m.pgm"
    os.mkfifo(fifo)
    for image in (str(fifo), "/dev/zero"):
        (tmp_path / "map.yaml").write_text(GOOD_YAML.replace("m.pgm", image))
        with pytest.raises(BagtoolsError, match="map image is not a regular file") as info:
            read_nav2_map(tmp_path / "map.yaml")
        assert info.value.path == image


def test_png_render_has_metric_extent_and_trajectory(tmp_path):
    import matplotlib.image as mpimg

    grid = OccupancyGrid(4.0, 2.0, 20.0, (-2.0, -1.0))
    angles = np.linspace(-np.pi, np.pi, 180, endpoint=False)
    grid.insert_ray([0.0, 0.0, 0.0], np.full(180, 0.9), angles, 3.0)
    plain = mpimg.imread(io.BytesIO(render_map_png(grid)), format="png")
    path = write_map_png(grid, tmp_path / "map.png", trajectory_xy=np.array([[-1.5, -0.5], [0.0, 0.0], [1.5, 0.5]]))
    drawn = mpimg.imread(path, format="png")
    assert drawn.shape == plain.shape and drawn.shape[1] > drawn.shape[0]  # wider than tall, like the map

    def reddish(img):
        return (img[..., 0] > 0.6) & (img[..., 1] < 0.4) & (img[..., 2] < 0.4)

    assert reddish(drawn).sum() > 50 and reddish(plain).sum() == 0
    with pytest.raises(OutputExistsError):
        write_map_png(grid, path)
    with pytest.raises(ValueError, match="trajectory"):
        render_map_png(grid, trajectory_xy=np.zeros(5))


def test_grey_pixels_pool_cells_beyond_the_picture_keeping_thin_walls() -> None:
    from bagtools.grid.mapio import grey_pixels

    p = np.full((10, 7), 0.1)  # free
    p[4, :] = 0.9  # a wall one cell thick
    p[:, 6] = 0.5  # unknown
    same, k = grey_pixels(p.copy(), 10)
    assert k == 1 and same.dtype == np.uint8 and same.shape == (10, 7)
    assert np.array_equal(same, np.rint(255.0 * (1.0 - p)).astype(np.uint8))
    pooled, k = grey_pixels(p.copy(), 4)  # 10 cells a side -> blocks of 3 x 3
    assert k == 3 and pooled.shape == (4, 3)
    wall = np.rint(255.0 * (1.0 - 0.9))
    assert (pooled[1, :2] == wall).all() and pooled[1, 2] == 128  # rows 3..5 hold the wall: the darkest wins
    assert (pooled[0, :2] == 230).all() and pooled[0, 2] == 128  # free; the last block column is unknown


def test_map_pictures_of_a_large_map_stay_small_in_memory() -> None:
    """A 250 m x 200 m map at 5 cm (20 million cells) used to take 1.5 GB beyond the grid to draw (matplotlib
    colour-mapped every float cell); now its pixels are pooled to the picture's size first. Measured in a child
    process, whose peak is its own."""
    import subprocess
    import sys

    script = """
import resource, numpy as np
from bagtools.grid import OccupancyGrid, render_map_png
from bagtools.grid.render import render_slam_map_png
grid = OccupancyGrid(250.0, 200.0, 20.0)
grid.insert_ray(np.array([5.0, 5.0, 0.0]), np.array([240.0]), np.array([0.7]), max_range=300.0)
path = np.array([[10.0, 10.0], [200.0, 150.0]])
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
pngs = render_slam_map_png(grid, path, np.zeros((0, 2, 2))), render_map_png(grid, path)
assert all(p.startswith(b"\\x89PNG") for p in pngs)
print((resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024.0)
"""
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert float(out.stdout.strip()) < 500.0, out.stdout


def test_wall_faces_are_the_borders_of_occupied_and_free_cells(tmp_path):
    """A 4 x 3 image (row 0 at the top; F free, U unknown, O occupied), origin [1, 2, 90 degrees], 0.5 m cells:

        F U O O
        F O U O
        F F F F

    Each occupied cell gives the midpoint of each side it shares with a free cell (not with an unknown one, nor
    the image's edge), and one with no free neighbour its centre."""
    pixels = np.full((3, 4), 254, dtype=np.uint8)
    pixels[0, 1] = pixels[1, 2] = 205
    pixels[0, 2] = pixels[0, 3] = pixels[1, 1] = pixels[1, 3] = 0
    (tmp_path / "m.pgm").write_bytes(b"P5\n4 3\n255\n" + pixels.tobytes())
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.5\norigin: [1.0, 2.0, 1.5707963267948966]\n"
                                     "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    faces = read_nav2_map(tmp_path / "m.yaml").wall_faces()

    def place(u: float, v: float) -> list[float]:  # u columns from the image's left edge, v rows from its top
        x, y = u * 0.5, (3 - v) * 0.5
        return [1.0 - y, 2.0 + x]  # turned by 90 degrees about the origin

    expected = [place(1.0, 1.5), place(1.5, 2.0),  # row 1, column 1: its left and lower sides
                place(3.5, 2.0),  # row 1, column 3: its lower side
                place(2.5, 0.5), place(3.5, 0.5)]  # row 0, columns 2 and 3: no free neighbour
    assert sorted(map(tuple, np.round(faces, 9))) == sorted(map(tuple, np.round(expected, 9)))
