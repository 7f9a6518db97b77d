"""CARMEN logs read as bags (bagtools.io.carmen): every line kind, exact stamps, CARMEN's beam angles."""

from __future__ import annotations

import gzip
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bagtools.errors import BagError
from bagtools.io import decode_laserscan, decode_odometry, decode_tf_message, open_bag
from bagtools.io.carmen import FLASER_MAX_RANGE_M, carmen_beam_geometry, stamp_text_to_ns


def flaser(ranges: list[float], odom: tuple[float, float, float], stamp: str, kind: str = "FLASER") -> str:
    x, y, th = odom
    return (f"{kind} {len(ranges)} {' '.join(f'{r:.2f}' for r in ranges)} {x} {y} {th} {x} {y} {th} "
            f"{stamp} nohost {stamp}")


def robotlaser(ranges: list[float], laser: tuple, robot: tuple, stamp: str, start: float = -1.5, fov: float = 3.0,
               remissions: int = 2) -> str:
    res = fov / (len(ranges) - 1)
    rem = " ".join(["0.5"] * remissions)
    return (f"ROBOTLASER1 0 {start} {fov} {res} 20.0 0.01 0 {len(ranges)} {' '.join(f'{r:.2f}' for r in ranges)} "
            f"{remissions} {rem} {laser[0]} {laser[1]} {laser[2]} {robot[0]} {robot[1]} {robot[2]} "
            f"0.1 0.0 0.5 0.3 0.0 {stamp} nohost {stamp}")


def write(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n")
    return path


def test_stamps_are_exact_nanoseconds() -> None:
    assert stamp_text_to_ns("976052857.337530") == 976052857_337530000
    assert stamp_text_to_ns("12.5") == 12_500_000_000 and stamp_text_to_ns("7") == 7_000_000_000
    assert stamp_text_to_ns("1.0123456789") == 1_012_345_678  # beyond the nanosecond: cut, as ever


def test_stamps_written_by_printf_g_are_read_exactly() -> None:
    """A logger that wrote six significant digits (C's %g) writes a 1e9 s stamp as "1.10002e+09": read, exactly;
    what is not a number in either form is refused."""
    assert stamp_text_to_ns("1.10002e+09") == 1_100_020_000 * 10**9
    assert stamp_text_to_ns("1.1E+09") == 1_100_000_000 * 10**9
    assert stamp_text_to_ns("12.3e4") == 123_000 * 10**9 and stamp_text_to_ns("1.5e-05") == 15_000
    for text in ("1e", "e5", "nan", "inf", "1_0", "1.2.3", "1e999", "0x10", "+1"):
        with pytest.raises(ValueError):
            stamp_text_to_ns(text)


def test_flaser_beams_span_the_field_of_view() -> None:
    """180 beams from -90 to +90 degrees (180/179 apart, as the relations of the Intel log say, not CARMEN's 1
    degree), 361 half a degree apart, 401 over the 100 degrees of that SICK mode."""
    assert carmen_beam_geometry(180) == pytest.approx((-math.pi / 2, math.pi / 179))
    assert carmen_beam_geometry(361) == pytest.approx((-math.pi / 2, math.pi / 360))
    assert carmen_beam_geometry(401) == pytest.approx((-math.radians(50), math.radians(0.25)))


def test_flaser_log_is_a_bag(tmp_path: Path) -> None:
    """FLASER and ODOM lines, a mount PARAM, a comment, a line of another kind, stamps out of order."""
    ranges = [1.0 + 0.01 * i for i in range(180)]
    ranges[5] = FLASER_MAX_RANGE_M  # no return
    log = write(tmp_path / "run.clf", [
        "# a CARMEN log",
        "PARAM robot_frontlaser_offset 0.12 nohost 0",
        flaser(ranges, (0.0, 0.0, 0.0), "100.000001"),
        "ODOM 0.05 0.0 0.0 0.1 0.0 0.0 100.100000 nohost 100.1",
        flaser(ranges, (0.1, 0.0, 0.1), "100.200000"),
        flaser(ranges, (0.2, 0.0, 0.2), "100.150000"),  # stamped before the line logged before it
        "TRUEPOS 0 0 0 0 0 0 100.2 nohost 100.2",
    ])
    with open_bag(log) as bag:
        assert bag.kind == "carmen"
        assert {n: i.count for n, i in bag.topics.items()} == {"/scan": 3, "/odom": 4, "/tf": 4, "/tf_static": 1}
        assert any("TRUEPOS" in w for w in bag.warnings)
        records = list(bag.messages())
    times = [r.log_time_ns for r in records]
    assert times == sorted(times) and records[0].topic == "/tf_static"
    scans = [r.msg for r in records if r.topic == "/scan"]
    assert [s.header.seq for s in scans] == [0, 2, 1]  # the recording order, by seq
    first = decode_laserscan(scans[0])
    assert first.stamp_ns == 100_000_001_000 and first.frame_id == "laser"
    assert first.angles_rad[0] == pytest.approx(-math.pi / 2) and first.angles_rad[-1] == pytest.approx(math.pi / 2)
    assert np.isinf(first.ranges_m[5]) and first.ranges_m[6] == pytest.approx(1.06)
    odom = [decode_odometry(r.msg) for r in records if r.topic == "/odom"]
    assert [o.stamp_ns for o in odom] == [100_000_001_000, 100_100_000_000, 100_150_000_000, 100_200_000_000]
    static = decode_tf_message(records[0].msg)
    assert static.parent == ["base_link"] and static.child == ["laser"]
    assert static.translation[0] == pytest.approx([0.12, 0.0, 0.0])


def test_robotlaser_geometry_and_mount_come_from_the_line(tmp_path: Path) -> None:
    """ROBOTLASER1 says its angles and range; the mount is its laser pose against its robot pose. A log that also
    carries FLASER lines for the same scans gives one /scan per scan."""
    ranges = [2.0] * 31
    ranges[0] = 25.0  # beyond its 20 m maximum
    robot = (1.0, 2.0, math.pi / 2)
    laser = (1.0, 2.25, math.pi / 2)  # 0.25 m ahead of the base, which faces +y
    log = write(tmp_path / "run.log", [
        robotlaser(ranges, laser, robot, "5.5"),
        flaser([2.0] * 180, robot, "5.5"),
        robotlaser(ranges, laser, robot, "5.7"),
    ])
    with open_bag(log) as bag:
        assert bag.topics["/scan"].count == 2
        records = list(bag.messages())
    scan = decode_laserscan(next(r.msg for r in records if r.topic == "/scan"))
    assert scan.angles_rad[0] == pytest.approx(-1.5) and scan.angles_rad[-1] == pytest.approx(1.5)
    assert scan.range_max_m == pytest.approx(20.0) and np.isinf(scan.ranges_m[0])
    static = decode_tf_message(next(r.msg for r in records if r.topic == "/tf_static"))
    assert static.translation[0] == pytest.approx([0.25, 0.0, 0.0], abs=1e-9)


def test_rear_and_raw_lasers_and_gzip(tmp_path: Path) -> None:
    ranges = [3.0] * 180
    raw = "RAWLASER1 0 -1.5 3.0 0.1 30.0 0.01 0 31 " + " ".join(["1.0"] * 31) + " 0 7.25 nohost 7.25"
    lines = [flaser(ranges, (0.0, 0.0, 0.0), "7.0", kind="RLASER"), raw]
    path = tmp_path / "run.clf.gz"
    with gzip.open(path, "wt") as f:
        f.write("\n".join(lines) + "\n")
    with open_bag(path) as bag:
        assert set(bag.topics) == {"/scan", "/scan_rear", "/odom", "/tf", "/tf_static"}
        rear = next(r.msg for r in bag.messages(["/scan_rear"]))
        static = decode_tf_message(next(r.msg for r in bag.messages(["/tf_static"])))
    assert rear.header.frame_id == "rear_laser"
    assert static.child == ["rear_laser"]


def test_damaged_lines_are_skipped_and_said(tmp_path: Path) -> None:
    good = flaser([1.0] * 180, (0.0, 0.0, 0.0), "1.0")
    log = write(tmp_path / "run.clf", [good, "FLASER 180 1.0 2.0", "ODOM x y z 0 0 0 1.5 nohost 1.5",
                                       flaser([1.0] * 180, (0.0, 0.0, 0.0), "2.0")])
    with open_bag(log) as bag:
        assert bag.topics["/scan"].count == 2
        assert any("could not be read" in w and "1 FLASER" in w and "1 ODOM" in w for w in bag.warnings), bag.warnings


@pytest.mark.parametrize("text", ["hello, these are notes\n", "FLASER oops\n"])
def test_a_text_file_that_is_no_log_is_refused(tmp_path: Path, text: str) -> None:
    path = tmp_path / "notes.log"
    path.write_text(text)
    with pytest.raises(BagError):
        open_bag(path)


def test_info_reads_a_carmen_log(tmp_path: Path) -> None:
    log = write(tmp_path / "run.clf", [flaser([1.0] * 180, (0.1 * k, 0.0, 0.0), f"{10 + k}.0") for k in range(5)])
    result = subprocess.run([sys.executable, "-m", "bagtools", "info", str(log)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "carmen" in result.stdout and "/scan" in result.stdout and "base_link" in result.stdout
    assert "format:     CARMEN log" in result.stdout  # not "ROS distro: unknown (ROS 1)", "serialization: unknown"
    assert "ROS distro" not in result.stdout and "serialization format" not in result.stdout


@pytest.mark.parametrize("kind, topic, frame", [
    ("RAWLASER1", "/scan", "laser"), ("RAWLASER2", "/scan_rear", "rear_laser"), ("RAWLASER3", "/scan3", "laser3"),
    ("RAWLASER4", "/scan4", "laser4"), ("ROBOTLASER2", "/scan_rear", "rear_laser"), ("RLASER", "/scan_rear", "rear_laser"),
])
def test_every_laser_line_kind_has_its_topic(tmp_path: Path, kind: str, topic: str, frame: str) -> None:
    ranges = " ".join(["1.50"] * 31)
    if kind.startswith("RAWLASER"):
        line = f"{kind} 0 -1.5 3.0 0.1 30.0 0.01 0 31 {ranges} 0 3.25 nohost 3.25"
    elif kind == "ROBOTLASER2":
        line = (f"{kind} 0 -1.5 3.0 0.1 30.0 0.01 0 31 {ranges} 0 0.0 0.0 3.1416 0.0 0.0 0.0 0.0 0.0 0.5 0.3 0.0 "
                "3.25 nohost 3.25")
    else:
        line = flaser([1.5] * 180, (0.0, 0.0, 0.0), "3.25", kind=kind)
    with open_bag(write(tmp_path / "run.clf", [line])) as bag:
        assert bag.topics[topic].count == 1
        scan = decode_laserscan(next(r.msg for r in bag.messages([topic])))
    assert scan.frame_id == frame and scan.stamp_ns == 3_250_000_000 and np.allclose(scan.ranges_m, 1.5)


@pytest.mark.parametrize("saturation", [50.0, 81.91])
def test_a_laser_that_reports_no_return_as_its_largest_reading_is_found(tmp_path: Path, saturation: float) -> None:
    """FLASER lines say no maximum range; the ACES log reports no return as 50.00 over and over, Freiburg 079's
    as 81.91: that reading becomes +inf. A lone far return is a return."""
    rng = np.random.default_rng(0)
    lines = []
    for k in range(20):
        ranges = rng.uniform(1.0, 30.0, 180).round(2)
        ranges[k % 7::9] = saturation
        lines.append(flaser(list(ranges), (0.0, 0.0, 0.0), f"{10 + k}.0"))
    lone = rng.uniform(1.0, 8.0, 180).round(2)
    lone[3] = 40.0  # one far return, the largest reading of its log: no saturation
    with open_bag(write(tmp_path / "sat.clf", lines)) as bag:
        scans = [decode_laserscan(r.msg) for r in bag.messages(["/scan"])]
    assert all(s.range_max_m == pytest.approx(saturation) for s in scans)
    assert sum(int(np.isinf(s.ranges_m).sum()) for s in scans) > 300
    assert all(np.isfinite(s.ranges_m[s.ranges_m < saturation]).all() for s in scans)
    with open_bag(write(tmp_path / "lone.clf", [flaser(list(lone), (0.0, 0.0, 0.0), "5.0")])) as bag:
        scan = decode_laserscan(next(r.msg for r in bag.messages(["/scan"])))
    assert scan.ranges_m[3] == pytest.approx(40.0) and scan.range_max_m == pytest.approx(FLASER_MAX_RANGE_M)
    # the readings outrank a PARAM they contradict (Edmonton's says 10 m, and a third of its readings are farther);
    # without a no-return reading in the log, the PARAM holds
    log = write(tmp_path / "param.clf", ["PARAM robot_front_laser_max 25.0 nohost 0"] + lines)
    with open_bag(log) as bag:
        assert decode_laserscan(next(r.msg for r in bag.messages(["/scan"]))).range_max_m == pytest.approx(saturation)
    log = write(tmp_path / "param_only.clf", ["PARAM robot_front_laser_max 25.0 nohost 0",
                                              flaser(list(lone), (0.0, 0.0, 0.0), "5.0")])
    with open_bag(log) as bag:
        assert decode_laserscan(next(r.msg for r in bag.messages(["/scan"]))).range_max_m == pytest.approx(25.0)


def test_a_no_return_reading_that_wavers_is_found(tmp_path: Path) -> None:
    """Edmonton's laser reports no return as 51.14, 51.15 or 51.16, most often 51.15, and returns up to 45 m are
    real: all three readings are no return, the far returns stay (they were points 51 m away, or the PARAM's 10 m
    cut a third of the returns)."""
    rng = np.random.default_rng(1)
    lines = []
    for k in range(20):
        ranges = rng.uniform(1.0, 20.0, 180).round(2)
        ranges[::9] = rng.uniform(20.0, 45.0, 20).round(2)
        ranges[k % 5::7] = rng.choice([51.14, 51.15, 51.15, 51.15, 51.16], len(ranges[k % 5::7]))
        lines.append(flaser(list(ranges), (0.0, 0.0, 0.0), f"{10 + k}.0"))
    with open_bag(write(tmp_path / "wavers.clf", ["PARAM robot_front_laser_max 10 nohost 0"] + lines)) as bag:
        scans = [decode_laserscan(r.msg) for r in bag.messages(["/scan"])]
    assert all(s.range_max_m == pytest.approx(51.14) for s in scans)
    ranges = np.concatenate([s.ranges_m for s in scans])
    assert np.isinf(ranges).sum() == sum(len(range(k % 5, 180, 7)) for k in range(20))
    finite = ranges[np.isfinite(ranges)]
    assert (finite > 10.0).sum() > 1500 and finite.max() > 40.0


def test_a_bag_written_as_a_flaser_log_reads_back(tmp_path: Path) -> None:
    """Scans and odometry of a bag as FLASER lines: read back, the same scans at the same stamps (to the
    microsecond), readings to the centimetre (a missing one at the maximum range, read back as no return), each
    with the odometry pose nearest its stamp."""
    from bagtools.io.carmen import write_flaser_log
    from tests.conftest import make_scan, write_bag
    from tests.ndt_odom.conftest import make_odometry

    t0 = 1_700_000_000_123_456_000
    rng = np.random.default_rng(0)
    ranges = [rng.uniform(0.5, 8.0, 180) for _ in range(4)]
    ranges[1][7] = np.nan
    T = [np.eye(4) for _ in range(4)]
    for k in range(4):
        T[k][0, 3] = 0.5 * k
    msgs = [("/scan", "sensor_msgs/msg/LaserScan", t0 + k * 200_000_000, make_scan(t0 + k * 200_000_000, ranges[k]))
            for k in range(4)]
    msgs += [("/odom", "nav_msgs/msg/Odometry", t0 + k * 200_000_000 + 1000,
              make_odometry(t0 + k * 200_000_000 + 1000, "odom", "base_link", T[k])) for k in range(4)]
    bag = write_bag(tmp_path / "b", sorted(msgs, key=lambda m: m[2]))
    log = tmp_path / "b.clf"
    assert write_flaser_log(bag, log) == 4
    with open_bag(log) as read:
        scans = [decode_laserscan(r.msg) for r in read.messages(["/scan"])]
        odom = [decode_odometry(r.msg) for r in read.messages(["/odom"])]
    assert [s.stamp_ns for s in scans] == [t0 + k * 200_000_000 for k in range(4)]
    for k, s in enumerate(scans):
        expected = np.round(ranges[k], 2)
        expected[~np.isfinite(ranges[k])] = np.inf
        np.testing.assert_allclose(s.ranges_m, expected, atol=1e-6)
    assert [round(o.position_m[0], 6) for o in odom] == [0.0, 0.5, 1.0, 1.5]


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bagtools", *args], capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("damage,said", [
    (lambda w: w.__setitem__(1, "-5"), "a reading count of -5"),
    (lambda w: w.__setitem__(1, str(int(w[1]) - 1)), "FLASER line has 190 fields where its counts say 189"),
    (lambda w: w.insert(5, "1.0"), "FLASER line has 191 fields where its counts say 190"),
    (lambda w: (w.__setitem__(-3, "9300000000.5"), w.__setitem__(-1, "9300000000.5")), "outside 0 .. year 2262"),
])
def test_a_line_whose_counts_disagree_with_its_fields_is_damaged(tmp_path: Path, damage, said: str) -> None:
    """Read anyway, its stamp and poses would come from the wrong fields (a scan stamped by a range value)."""
    lines = [flaser([1.0 + 0.01 * k] * 180, (0.1 * k, 0.0, 0.0), f"{10 + k}.0") for k in range(12)]
    words = lines[5].split()
    damage(words)
    lines[5] = " ".join(words)
    log = write(tmp_path / "run.clf", lines)
    with open_bag(log) as bag:
        stamps = [decode_laserscan(r.msg).stamp_ns for r in bag.messages(["/scan"])]
        assert len(stamps) == 11 and all(10 <= s / 1e9 <= 21 for s in stamps)
        assert sum("could not be read" in w and said in w for w in bag.warnings) == 1, bag.warnings
    for command in (["info", str(log)], ["slam", str(log), "--out", str(tmp_path / "s"), "--no-mcap"]):
        done = _run(*command)
        assert done.returncode == 0 and "internal error" not in done.stderr and said in done.stderr, done.stderr


def test_readings_past_float32_are_no_returns(tmp_path: Path) -> None:
    """3.5e38 is inf as float32: a no-return reading, not an internal error (it was an IndexError)."""
    lines = [flaser([3.5e38, 1e39] + [2.0 + 0.01 * k] * 178, (0.1 * k, 0.0, 0.0), f"{10 + k}.0") for k in range(8)]
    lines = [line.replace("350000000000000004213332118054584918016.00", "3.5e38") for line in lines]
    log = write(tmp_path / "run.clf", lines)
    with open_bag(log) as bag:
        scan = decode_laserscan(next(bag.messages(["/scan"])).msg)
        assert np.isinf(scan.ranges_m[:2]).all() and not scan.valid[:2].any() and scan.valid[2:].all()
    for command in (["info", str(log)], ["ndt-odom", str(log), "--out", str(tmp_path / "n"), "--no-mcap"],
                    ["export", str(log), "/scan", "--out", str(tmp_path / "s.csv")]):
        done = _run(*command)
        assert done.returncode == 0 and "Warning" not in done.stderr, done.stderr


def test_a_truncated_gzip_log_is_read_up_to_the_cut(tmp_path: Path) -> None:
    """As a truncated MCAP: what was written before the cut, and the loss said (it was 'interrupted', exit 130)."""
    lines = [flaser([1.0 + 0.001 * k] * 180, (0.1 * k, 0.0, 0.0), f"{10 + k}.0") for k in range(400)]
    whole = gzip.compress(("\n".join(lines) + "\n").encode())
    log = tmp_path / "run.clf.gz"
    log.write_bytes(whole[: len(whole) * 2 // 3])
    with open_bag(log) as bag:
        n = bag.topics["/scan"].count
        assert 100 < n < 400 and any("truncated gzip stream" in w for w in bag.warnings), bag.warnings
    done = _run("info", str(log))
    assert done.returncode == 0 and "truncated gzip stream" in done.stderr, done.stderr


def test_a_declared_angular_resolution_lays_out_the_beams() -> None:
    """A log that says its laser's resolution (``PARAM laser_frontlaser_resolution 1``: 1 degree) is read with it,
    from -90 degrees as CARMEN does (the FHW log's 180 beams); one by which the beams would not span the field of
    view (to within two beams) is ignored: it would squeeze or overflow the scan."""
    assert carmen_beam_geometry(180, math.radians(1.0)) == pytest.approx((-math.pi / 2, math.radians(1.0)))
    assert carmen_beam_geometry(361, math.radians(0.5)) == pytest.approx((-math.pi / 2, math.radians(0.5)))
    assert carmen_beam_geometry(361, math.radians(1.0)) == pytest.approx((-math.pi / 2, math.pi / 360))
    assert carmen_beam_geometry(180, math.radians(0.5)) == pytest.approx((-math.pi / 2, math.pi / 179))


def test_a_log_declaring_its_resolution_is_read_with_it(tmp_path: Path) -> None:
    line = flaser([2.0] * 180, (0.0, 0.0, 0.0), "3.25")
    with open_bag(write(tmp_path / "declared.clf", ["PARAM laser_frontlaser_resolution 1 0.0 nohost 0", line])) as bag:
        scan = decode_laserscan(next(r.msg for r in bag.messages(["/scan"])))
    assert scan.angle_increment_rad == pytest.approx(math.radians(1.0))
    assert scan.angles_rad[0] == pytest.approx(-math.pi / 2) and scan.angles_rad[-1] == pytest.approx(math.radians(89))
    with open_bag(write(tmp_path / "plain.clf", [line])) as bag:
        scan = decode_laserscan(next(r.msg for r in bag.messages(["/scan"])))
    assert scan.angles_rad[-1] == pytest.approx(math.pi / 2)
