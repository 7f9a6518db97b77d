"""``bagtools tf frames|echo|point`` on synthetic and real bags, including the exit-2 error cases."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from bagtools.cli import main
from tests.conftest import make_tf, write_bag

S = 1_000_000_000
T0 = 1_700_000_000 * S


def run(argv: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    out = capsys.readouterr()
    return exit_info.value.code, out.out, out.err


@pytest.fixture
def drive_bag(tmp_path: Path) -> Path:
    """10 s: map->odom (static offset 1 m in y), odom->base_footprint driving +x at 0.5 m/s (10 Hz), /clicked_point."""
    from tests.conftest import TYPESTORE

    T = TYPESTORE.types
    msgs = [("/tf_static", "tf2_msgs/msg/TFMessage", T0,
             make_tf(T0, "base_footprint", "base_link", (0.0, 0.0, 0.1), (0, 0, 0, 1)))]
    for i in range(101):
        t = T0 + i * S // 10
        msgs.append(("/tf", "tf2_msgs/msg/TFMessage", t, make_tf(t, "odom", "base_footprint", (0.05 * i, 0, 0), (0, 0, 0, 1))))
        if i % 10 == 0:
            msgs.append(("/tf", "tf2_msgs/msg/TFMessage", t, make_tf(t, "map", "odom", (0, 1.0, 0), (0, 0, 0, 1))))
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=T0 // S + 2, nanosec=0), frame_id="map")
    clicked = T["geometry_msgs/msg/PointStamped"](header=header, point=T["geometry_msgs/msg/Point"](x=3.0, y=1.0, z=0.0))
    msgs.append(("/clicked_point", "geometry_msgs/msg/PointStamped", T0 + 2 * S, clicked))
    msgs.sort(key=lambda m: m[2])
    return write_bag(tmp_path / "drive", msgs)


def test_frames_prints_tree_and_writes_dot(drive_bag: Path, tmp_path: Path, capsys) -> None:
    dot = tmp_path / "tf.dot"
    code, out, _ = run(["tf", "frames", str(drive_bag), "--dot", str(dot)], capsys)
    assert code == 0
    assert out.splitlines()[0] == "map"
    assert "base_footprint  (dynamic, 10.0 Hz, 101 samples, +0.00..+10.00 s)" in out
    assert "base_link  (static)" in out
    text = dot.read_text()
    assert text.startswith("digraph tf {") and '"odom" -> "base_footprint"' in text and '"map" -> "odom"' in text
    code, _, err = run(["tf", "frames", str(drive_bag), "--dot", str(dot)], capsys)
    assert code == 2 and "already exists" in err


def test_echo_text_and_csv(drive_bag: Path, tmp_path: Path, capsys) -> None:
    code, out, _ = run(["tf", "echo", str(drive_bag), "odom", "base_link", "--rate", "2"], capsys)
    assert code == 0
    assert out.count("At time") == 21
    assert "- Translation: [0.250, 0.000, 0.100]" in out   # 0.5 s in, interpolated between samples
    csv_path = tmp_path / "echo.csv"
    code, _, _ = run(["tf", "echo", str(drive_bag), "map", "base_link", "--rate", "4", "--csv", str(csv_path)], capsys)
    assert code == 0
    rows = list(csv.DictReader(csv_path.open()))
    assert len(rows) == 41                                   # 0..10 s at 4 Hz
    assert int(rows[0]["stamp_ns"]) == T0 and float(rows[4]["x_m"]) == pytest.approx(0.5)
    assert float(rows[4]["y_m"]) == pytest.approx(1.0) and float(rows[4]["qw"]) == pytest.approx(1.0)


def test_point_follows_fixed_point(drive_bag: Path, tmp_path: Path, capsys) -> None:
    out_dir = tmp_path / "pt"
    code, out, _ = run(["tf", "point", str(drive_bag), "--out", str(out_dir), "--point", "3", "1", "0",
                        "--frame", "map", "--targets", "map,odom,base_footprint", "--rate", "1"], capsys)
    assert code == 0 and "followed 1 point(s) over 11 steps" in out
    rows = list(csv.DictReader((out_dir / "point.csv").open()))
    assert len(rows) == 11
    x_base = np.array([float(r["base_footprint_x_m"]) for r in rows])
    np.testing.assert_allclose(x_base, 3.0 - 0.5 * np.arange(11))      # the robot drives towards it
    assert {float(r["odom_y_m"]) for r in rows} == {0.0}
    summary = json.loads((out_dir / "summary.json").read_text())
    assert summary["points"][0]["in_targets"]["map"]["max_offset_from_first_m"] == 0.0
    assert summary["points"][0]["in_targets"]["base_footprint"]["path_length_m"] == pytest.approx(5.0)
    assert (out_dir / "point.png").stat().st_size > 1000
    code, _, err = run(["tf", "point", str(drive_bag), "--out", str(out_dir), "--point", "3", "1", "0", "--frame", "map"],
                       capsys)
    assert code == 2 and "already exists" in err


def test_point_from_clicked_topic_with_default_targets(drive_bag: Path, tmp_path: Path, capsys) -> None:
    code, _, _ = run(["tf", "point", str(drive_bag), "--out", str(tmp_path / "c"), "--topic", "/clicked_point"], capsys)
    assert code == 0
    summary = json.loads((tmp_path / "c" / "summary.json").read_text())
    assert summary["targets"] == ["map", "odom", "base_footprint"]
    assert summary["points"][0]["clicked_ns"] == T0 + 2 * S and summary["points"][0]["xyz"] == [3.0, 1.0, 0.0]


@pytest.mark.parametrize("argv, message", [
    (["tf", "echo", "{bag}", "odom", "nothere"], "frame 'nothere' is not in the bag's tf (nearest by name: "),
    (["tf", "echo", "{bag}", "odom", "/odom"], "cannot start with a '/'"),
    (["tf", "echo", "{bag}", "odom", "base_link", "--rate", "0"], "rate must be a positive"),
    (["tf", "point", "{bag}", "--out", "{tmp}/p", "--point", "1", "2", "3", "--frame", "map", "--targets", "map,moon"],
     '"moon" passed to'),
    (["tf", "point", "{bag}", "--out", "{tmp}/p", "--topic", "/nope"], "no topic '/nope'"),
    (["tf", "point", "{bag}", "--out", "{tmp}/p", "--point", "1", "2", "3"], "give either --point"),
    (["tf", "frames", "{tmp}/missing.mcap"], "missing.mcap"),
])
def test_bad_input_is_one_line_and_exit_2(drive_bag: Path, tmp_path: Path, capsys, argv, message) -> None:
    argv = [a.format(bag=drive_bag, tmp=tmp_path) for a in argv]
    code, _, err = run(argv, capsys)
    assert code == 2
    assert err.startswith("bagtools: ") and err.count("\n") == 1 and message in err
    assert "frame(s) in all, see `bagtools tf frames`" in err or "nothere" not in message


def test_unconnected_frames_exit_2(tmp_path: Path, capsys) -> None:
    msgs = [("/tf", "tf2_msgs/msg/TFMessage", T0 + i * S, make_tf(T0 + i * S, p, c, (0, 0, 0), (0, 0, 0, 1)))
            for i in range(3) for p, c in [("odom", "base"), ("world", "thing")]]
    bag = write_bag(tmp_path / "two_trees", msgs)
    code, _, err = run(["tf", "echo", str(bag), "odom", "thing"], capsys)
    assert code == 2 and "not part of the same tree" in err


def test_echo_on_real_ros1_bag_matches_sqlite_copy(real_dir: Path, capsys) -> None:
    results = []
    for name in ("tf_example.bag", "tf_example"):
        code, out, _ = run(["tf", "echo", str(real_dir / name), "odom", "base_link", "--rate", "0.5"], capsys)
        assert code == 0
        results.append(out)
    assert results[0] == results[1] and results[0].count("At time") == 26


def test_frames_on_real_nav2_bag(real_dir: Path, capsys) -> None:
    code, out, _ = run(["tf", "frames", str(real_dir / "nav2_turtlebot.mcap")], capsys)
    assert code == 0
    lines = out.splitlines()
    assert lines[0] == "map" and "odom  (dynamic" in lines[1] and "base_link  (dynamic" in lines[2]
    assert sum("(static)" in line for line in lines) == 29


def test_point_with_empty_targets_is_one_line_exit_2(drive_bag: Path, tmp_path: Path, capsys) -> None:
    code, _, err = run(["tf", "point", str(drive_bag), "--out", str(tmp_path / "p"), "--point", "1", "2", "3",
                        "--frame", "map", "--targets", ","], capsys)
    assert code == 2 and err.count("\n") == 1 and "no target frames" in err
    assert not (tmp_path / "p").exists()


def test_point_default_targets_use_base_link_without_base_footprint(tmp_path: Path, capsys) -> None:
    msgs = [("/tf", "tf2_msgs/msg/TFMessage", T0 + i * S // 10,
             make_tf(T0 + i * S // 10, "odom", "base_link", (0.1 * i, 0, 0), (0, 0, 0, 1))) for i in range(11)]
    bag = write_bag(tmp_path / "odom_base_link", msgs)
    code, out, _ = run(["tf", "point", str(bag), "--out", str(tmp_path / "p"), "--point", "2", "0", "0",
                        "--frame", "odom", "--rate", "1"], capsys)
    assert code == 0 and "over 2 steps in odom, base_link" in out
    summary = json.loads((tmp_path / "p" / "summary.json").read_text())
    assert summary["targets"] == ["odom", "base_link"]
    assert summary["points"][0]["in_targets"]["base_link"]["last_xyz_m"] == pytest.approx([1.0, 0.0, 0.0])


def test_tf_commands_report_a_truncated_mcap(drive_bag: Path, tmp_path: Path, capsys) -> None:
    data = next(drive_bag.glob("*.mcap")).read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    for argv in (["tf", "frames", str(cut)], ["tf", "echo", str(cut), "odom", "base_link"],
                 ["tf", "point", str(cut), "--out", str(tmp_path / "p"), "--point", "1", "0", "0", "--frame", "odom"],
                 ["tf", "point", str(cut), "--out", str(tmp_path / "c"), "--topic", "/clicked_point"]):
        code, _, err = run(argv, capsys)
        assert code == 0, argv
        assert "warning: " in err and "truncated MCAP" in err and "recovered" in err, argv


def test_a_rate_too_low_for_a_second_sample_gives_the_first_one_and_no_warning(drive_bag: Path, capsys) -> None:
    """--rate 1e-300: one step is longer than any span (1e309 ns overflows to inf), so one sample, and no numpy
    RuntimeWarning (0 * inf) on stderr."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code, out, err = run(["tf", "echo", str(drive_bag), "odom", "base_footprint", "--rate", "1e-300"], capsys)
    assert code == 0 and err == "", err
    assert out.count("At time") == 1, out
