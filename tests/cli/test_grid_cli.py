"""``bagtools grid``: outputs in nav2 format, --force, help, and every bad input as one line with exit status 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bagtools.cli import main
from bagtools.grid import read_nav2_map
from bagtools.commands.grid import GRID_MAP_FILES
from tests.conftest import FIXTURES, make_scan, make_tf, write_bag

S = 1_000_000_000
T0 = 1_700_000_000 * S
SIM_BAG = FIXTURES / "sim_random_nocloud_20s"


def run(argv: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    out = capsys.readouterr()
    return exit_info.value.code, out.out, out.err


def assert_one_line_error(code: int, err: str, *fragments: str) -> None:
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bagtools: "), err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])


def test_help_has_an_example(capsys) -> None:
    code, out, _ = run(["grid", "--help"], capsys)
    assert code == 0
    assert "Example:" in out and "bagtools grid out/sim --out out/grid" in out
    assert "--poses" in out and "--max-range" in out and "--resolution" in out


def test_writes_a_nav2_map_png_and_summary(tmp_path: Path, capsys) -> None:
    out_dir = tmp_path / "grid"
    code, out, err = run(["grid", str(SIM_BAG), "--out", str(out_dir), "--poses", "ground-truth"], capsys)
    assert code == 0, err
    assert "101 of 101 scans mapped" in out and "vs true world: occupied precision 1.000" in out
    assert sorted(p.name for p in out_dir.iterdir()) == sorted(GRID_MAP_FILES)
    summary = json.loads((out_dir / "summary.json").read_text())
    yaml_text = (out_dir / "map.yaml").read_text()
    for line in ("image: map.pgm", "mode: trinary", "resolution: 0.05", "negate: 0", "occupied_thresh: 0.65",
                 "free_thresh: 0.196"):
        assert line in yaml_text.splitlines()
    nav2 = read_nav2_map(out_dir / "map.yaml")
    grid = summary["grid"]
    assert nav2.pixels.shape == (grid["rows"], grid["cols"])
    assert f"{grid['cols']}x{grid['rows']} cells (width x height)" in out  # as nav2 and image tools say it
    assert set(np.unique(nav2.pixels)) == {0, 205, 254}
    assert nav2.origin == (*grid["origin_xy_m"], 0.0) and nav2.resolution_m == 0.05
    assert int((nav2.ternary() == 1).sum()) == grid["occupied_cells"]
    assert int((nav2.ternary() == 0).sum()) == grid["free_cells"]
    assert (out_dir / "map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert summary["accuracy_vs_truth"]["occupied_recall"] >= 0.9


def test_refuses_to_overwrite_without_force(tmp_path: Path, capsys) -> None:
    out_dir = tmp_path / "grid"
    assert run(["grid", str(SIM_BAG), "--out", str(out_dir)], capsys)[0] == 0
    before = {p.name: p.read_bytes() for p in out_dir.iterdir()}
    code, _, err = run(["grid", str(SIM_BAG), "--out", str(out_dir), "--resolution", "10"], capsys)
    assert_one_line_error(code, err, "already exists (use --force to overwrite)")
    assert {p.name: p.read_bytes() for p in out_dir.iterdir()} == before
    code, out, _ = run(["grid", str(SIM_BAG), "--out", str(out_dir), "--resolution", "10", "--force"], capsys)
    assert code == 0 and "of 0.1 m" in out
    assert read_nav2_map(out_dir / "map.yaml").resolution_m == 0.1


def _odom_only_bag(path: Path, ranges: np.ndarray | None = None, scans: bool = True) -> Path:
    """odom -> base_link and base_link -> base_scan, 2 s; scans with ``ranges`` (default: a 1 m circle)."""
    msgs = [("/tf_static", "tf2_msgs/msg/TFMessage", T0, make_tf(T0, "base_link", "base_scan", (0, 0, 0.1), (0, 0, 0, 1)))]
    for i in range(11):
        t = T0 + i * S // 5
        msgs.append(("/tf", "tf2_msgs/msg/TFMessage", t, make_tf(t, "odom", "base_link", (0.01 * i, 0, 0), (0, 0, 0, 1))))
        if scans and 0 < i < 10:
            r = np.full(360, 1.0, dtype=np.float32) if ranges is None else ranges
            msgs.append(("/scan", "sensor_msgs/msg/LaserScan", t, make_scan(t, r)))
    return write_bag(path, msgs)


@pytest.mark.parametrize(
    ("make", "args", "fragments"),
    [
        (lambda p: _odom_only_bag(p, scans=False), [], ["no topic '/scan' in the bag (topics: /tf, /tf_static)"]),
        (lambda p: _odom_only_bag(p), [], ["frame 'map' is not in the tf tree (frames: base_link, base_scan, odom)"]),
        (lambda p: _odom_only_bag(p), ["--frame", "world"], ["frame 'world' is not in the tf tree"]),
        (lambda p: _odom_only_bag(p, np.full(360, np.nan, dtype=np.float32)), ["--frame", "odom"],
         ["none of the 9 scans on /scan could be used in frame 'odom' (9 no valid ranges)"]),
        (lambda p: _odom_only_bag(p, np.full(360, np.inf, dtype=np.float32)), ["--frame", "odom"],
         ["no scan on /scan has a return within its range limits"]),
        (lambda p: _odom_only_bag(p), ["--poses", "ground-truth"], ["--poses ground-truth needs a /ground_truth topic"]),
        (lambda p: _odom_only_bag(p), ["--frame", "odom", "--topic", "/tf"],
         ["topic '/tf' has type tf2_msgs/msg/TFMessage, expected sensor_msgs/msg/LaserScan"]),
        (lambda p: p / "missing_bag", [], ["missing_bag"]),
    ],
    ids=["no-scan-topic", "no-map-frame", "unknown-frame", "all-nan", "all-inf", "no-ground-truth", "not-a-scan-topic",
         "missing-bag"],
)
def test_bad_bags(tmp_path: Path, capsys, make, args: list[str], fragments: list[str]) -> None:
    bag = make(tmp_path / "bag")
    out_dir = tmp_path / "out"
    code, _, err = run(["grid", str(bag), "--out", str(out_dir), *args], capsys)
    assert_one_line_error(code, err, *fragments)
    assert not out_dir.exists()


def test_scans_outside_the_tf_data_say_why(tmp_path: Path, capsys) -> None:
    msgs = [("/tf", "tf2_msgs/msg/TFMessage", T0, make_tf(T0, "odom", "base_scan", (0, 0, 0), (0, 0, 0, 1))),
            ("/tf", "tf2_msgs/msg/TFMessage", T0 + S, make_tf(T0 + S, "odom", "base_scan", (0, 0, 0), (0, 0, 0, 1)))]
    for i in range(3):
        t = T0 + (5 + i) * S
        msgs.append(("/scan", "sensor_msgs/msg/LaserScan", t, make_scan(t, np.full(360, 1.0, dtype=np.float32))))
    bag = write_bag(tmp_path / "late", msgs)
    code, _, err = run(["grid", str(bag), "--out", str(tmp_path / "o"), "--frame", "odom"], capsys)
    assert_one_line_error(code, err, "none of the 3 scans on /scan could be used in frame 'odom' (3 after pose data)",
                          "scan frame base_scan, tf frames: base_scan, odom")


@pytest.mark.parametrize(
    ("args", "fragments"),
    [
        (["--resolution", "0"], ["--resolution must be between 0.1 and 1000 cells per metre (cells of 10 m to 1 mm), got 0.0"]),
        (["--max-range", "-1"], ["--max-range must be a positive number of metres, got -1.0"]),
        (["--poses", "ground-truth", "--frame", "odom"], ["--poses ground-truth gives poses in the map frame"]),
        (["--poses", "nowhere.tum"], ["nowhere.tum: no such trajectory file"]),
    ],
    ids=["resolution", "max-range", "ground-truth-frame", "missing-tum"],
)
def test_bad_options(tmp_path: Path, capsys, args: list[str], fragments: list[str]) -> None:
    code, _, err = run(["grid", str(SIM_BAG), "--out", str(tmp_path / "o"), *args], capsys)
    assert_one_line_error(code, err, *fragments)


def test_bad_tum_file(tmp_path: Path, capsys) -> None:
    tum = tmp_path / "bad.tum"
    tum.write_text("1700000000.0 1 2 3\n")
    code, _, err = run(["grid", str(SIM_BAG), "--out", str(tmp_path / "o"), "--poses", str(tum)], capsys)
    assert_one_line_error(code, err, "bad.tum: line 1: expected 8 values")


def test_real_turtlebot3_bag_warns_about_the_scan_frame(real_dir: Path, tmp_path: Path, capsys) -> None:
    bag = real_dir / "turtlebot3_real_lidar_odom.bag"
    code, out, err = run(["grid", str(bag), "--out", str(tmp_path / "o"), "--frame", "odom"], capsys)
    assert code == 0, err
    assert ("bagtools: warning: no transform from base_link to base_scan in the bag; "
            "assuming the scan frame is the base frame") in err.splitlines()
    assert "scans mapped" in out
    assert read_nav2_map(tmp_path / "o" / "map.yaml").ternary().max() == 1


def test_a_scan_with_a_negative_stamp_is_skipped_before_the_work_not_a_failure_after_it(tmp_path: Path,
                                                                                          capsys) -> None:
    """The results.mcap writer cannot hold a time before 1970: the scan is skipped and counted when read, so the
    run ends well (it used to fail after all the work, in the writer)."""
    t0 = 1_700_000_000_000_000_000
    msgs = [("/tf", "tf2_msgs/msg/TFMessage", t0 + i * 100_000_000,
             make_tf(t0 + i * 100_000_000, "map", "base_scan", (0.01 * i, 0, 0), (0, 0, 0, 1))) for i in range(20)]
    ranges = np.full(360, 2.0, dtype=np.float32)
    msgs += [("/scan", "sensor_msgs/msg/LaserScan", t0 + i * 200_000_000 + 1, make_scan(t0 + i * 200_000_000, ranges))
             for i in range(1, 9)]
    msgs.append(("/scan", "sensor_msgs/msg/LaserScan", t0 + 5, make_scan(-2_000_000_000, ranges)))
    bag = write_bag(tmp_path / "negative", sorted(msgs, key=lambda m: m[2]))
    code, out, err = run(["grid", str(bag), "--out", str(tmp_path / "out")], capsys)
    assert code == 0, err
    assert "unusable header: LaserScan header stamp -2.000000000 s is negative" in err
    assert (tmp_path / "out" / "results.mcap").is_file()


@pytest.mark.parametrize("damage, said", [
    ("backwards", "skipped: header stamp not after the previous scan's (time going backwards)"),
    ("one stamp", "cannot time its scans (every stamp is 1700000000.200000048 s), so --poses tf cannot place them"),
    ("nanosec", "unusable header: LaserScan header stamp has nanosec 1500000000, outside 0 .. 999999999"),
])
def test_grid_refuses_the_scan_timing_ndt_odom_and_slam_refuse(damage: str, said: str, tmp_path: Path,
                                                                capsys) -> None:
    """Scans stamped backwards or with a nanosec field past a second are placed by a wrong time: grid skips and
    counts them as ndt-odom and slam do (precision fell to 0.36-0.60 silently). Scans all at one stamp cannot be
    placed in tf at all: refused, with the way out (a trajectory made in logging order)."""
    t0 = 1_700_000_000_000_000_000
    msgs = [("/tf", "tf2_msgs/msg/TFMessage", t0 + i * 100_000_000,
             make_tf(t0 + i * 100_000_000, "map", "base_scan", (0.01 * i, 0, 0), (0, 0, 0, 1))) for i in range(40)]
    ranges = np.full(360, 2.0, dtype=np.float32)
    scans = [make_scan(t0 + i * 200_000_000, ranges) for i in range(1, 19)]
    if damage == "backwards":
        scans[5].header.stamp.sec, scans[6].header.stamp.sec = scans[6].header.stamp.sec, scans[5].header.stamp.sec
        scans[5].header.stamp.nanosec, scans[6].header.stamp.nanosec = (scans[6].header.stamp.nanosec,
                                                                        scans[5].header.stamp.nanosec)
    elif damage == "one stamp":
        for scan in scans[1:]:
            scan.header.stamp.sec, scan.header.stamp.nanosec = scans[0].header.stamp.sec, scans[0].header.stamp.nanosec
    else:
        scans[5].header.stamp.nanosec = 1_500_000_000
    msgs += [("/scan", "sensor_msgs/msg/LaserScan", t0 + (i + 1) * 200_000_000 + 1, scan) for i, scan in enumerate(scans)]
    bag = write_bag(tmp_path / damage.replace(" ", "_"), sorted(msgs, key=lambda m: m[2]))
    code, out, err = run(["grid", str(bag), "--out", str(tmp_path / "out"), "--no-mcap"], capsys)
    assert code == (2 if damage == "one stamp" else 0), err  # stamps that say nothing cannot place a scan in tf
    assert said in err, err
