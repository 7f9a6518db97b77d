"""Regenerate everything the lab guide (docs/lab.md) shows from real runs.

    python docs/make_figures.py [--workdir build/lab] [--seeds 0 1 2 3 4] [--skip-speed]

1. Runs every command and Python block of the guide, in order, in a fresh work
   directory with the guide's own durations, and pastes what each printed into
   the ```text block after it.
2. Copies the figures those blocks wrote into docs/img (downscaled to an 8-bit
   palette, each well under 150 kB).
3. Runs the speed experiment of section 7 (every speed limit, seed and odometry
   noise level), writes docs/lab_speed.json, docs/img/speed.png and the table
   in the guide, and sets the example run's --duration to the one it measured.
4. Checks that what the guide's prose says about these numbers still holds, and
   fails naming the sentence that no longer does.

Everything is seeded, so two runs on one machine write the same files. ``make
docs`` runs this script.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")
DOCS = Path(__file__).resolve().parent
REPO = DOCS.parent
sys.path[:0] = [str(DOCS), str(REPO)]

import numpy as np  # noqa: E402

import labdoc  # noqa: E402

SPEED_JSON = DOCS / "lab_speed.json"
SPEED_PNG = "speed.png"
# (max linear m/s, max angular rad/s): from crawling to the TurtleBot3 Waffle's limits.
SPEED_SETTINGS = ((0.05, 0.35), (0.10, 0.70), (0.18, 1.20), (0.26, 1.82))
SPEED_SEEDS = (0, 1, 2, 3, 4)
SPEED_NOISES = ("realistic", "high")
SPEED_ROUTE = "random"
# The simulated AMCL stamps map -> odom this far ahead of the scan it was computed for (nav2's transform_tolerance).
AMCL_TRANSFORM_TOLERANCE_NS = 1_000_000_000
# The example run the guide shows (section 7): its --duration is set from the experiment.
EXAMPLE_LINE = re.compile(r"^(bagtools simulate lab/speed/fast --route random --seed (\d+) --odom-noise \w+ "
                          r"--max-linear ([\d.]+) --max-angular ([\d.]+) --duration )(\S+)( --no-cloud)$", re.M)
MAX_WIDTH_PX = 1000
PALETTE_COLOURS = 256


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


# ---------------------------------------------------------------------- 1, 2: the guide's own blocks

def run_guide(text: str, workdir: Path) -> str:
    """Run every block of the guide in ``workdir``; the guide with the fresh outputs pasted in."""
    session = labdoc.LabSession(workdir)
    outputs = {}
    for step in labdoc.steps(text):
        started = time.monotonic()
        outputs[step.block.first_line] = session.run(step.block)
        log(f"  lab.md:{step.block.first_line + 2} ({step.block.lang}) {time.monotonic() - started:.1f} s")
    return labdoc.paste_outputs(text, outputs)


def save_small_png(source: Path, target: Path) -> None:
    """``source`` as an 8-bit palette PNG at most MAX_WIDTH_PX wide."""
    from PIL import Image

    target.parent.mkdir(exist_ok=True)
    with Image.open(source) as image:
        image = image.convert("RGB")
        if image.width > MAX_WIDTH_PX:
            image = image.resize((MAX_WIDTH_PX, round(image.height * MAX_WIDTH_PX / image.width)), Image.LANCZOS)
        small = image.quantize(colors=PALETTE_COLOURS, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
        small.save(target, optimize=True)


def copy_figures(workdir: Path) -> None:
    for name, source in labdoc.FIGURES.items():
        save_small_png(workdir / source, labdoc.IMG_DIR / name)


# ---------------------------------------------------------------------- 3: the speed experiment

@dataclass(frozen=True)
class SpeedRun:
    seed: int
    max_linear_mps: float
    max_angular_radps: float
    odom_noise: str


def loop_duration_s(seed: int, max_linear_mps: float, max_angular_radps: float) -> float:
    """Seconds the simulated robot needs to drive the random tour of ``seed`` once at these limits.

    Asks the simulator's planner (the same controller ``bagtools simulate`` runs)
    how long one loop takes, so every run of the experiment maps the same walls.
    """
    from bagtools_simulate.pipeline import ODOM_RATE_HZ, SimConfig, plan_trajectory
    from bagtools_simulate.robot.routes import make_route
    from bagtools_simulate.world import load_world

    world = load_world("turtlebot3_world")
    loop = make_route(SPEED_ROUTE, world, seed).loop_xy
    loop_m = float(np.sum(np.linalg.norm(np.diff(np.vstack([loop, loop[:1]]), axis=0), axis=1)))
    duration_s = 2.0 * loop_m / max_linear_mps + 30.0
    for _ in range(5):  # the planned path's length depends on the duration: plan again with the one found
        config = SimConfig(duration_s=duration_s, seed=seed, route=SPEED_ROUTE, max_linear_mps=max_linear_mps,
                           max_angular_radps=max_angular_radps, cloud=False)
        motion = plan_trajectory(config, world).motion
        driven_m = np.cumsum(np.abs(motion.v_mps)) * motion.dt_s
        if driven_m[-1] < loop_m:
            duration_s += 10.0
            continue
        found = round(int(np.searchsorted(driven_m, loop_m) + 1) / ODOM_RATE_HZ + 0.5, 1)
        if found == duration_s:
            return found
        duration_s = found
    raise RuntimeError(f"no stable duration for one loop of seed {seed} at {max_linear_mps} m/s")


def bagtools(*argv: str) -> None:
    """Run one bagtools command in-process; raise if it fails."""
    session = labdoc.LabSession(Path.cwd())
    session._bagtools([str(a) for a in argv])


def tf_pose_error(bag: Path, lag_free_tum: Path) -> dict:
    """RMS error of tf's map -> robot base against /ground_truth at the scan stamps, as published and without AMCL's lag.

    "Without the lag": map -> odom looked up 1 s (the transform tolerance) after
    the stamp, which is the correction AMCL computed for that very scan. Those
    poses (at every /ground_truth stamp) are also written to ``lag_free_tum``
    for ``bagtools grid --poses``, as section 7 of the guide does for one run.
    """
    from bagtools.io import decode_laserscan, open_bag
    from bagtools.simtruth import read_ground_truth
    from bagtools.tf import TfBuffer
    from bagtools.trajectory import Trajectory, write_tum
    from bagtools.transforms import tform2pose, wrap_to_pi

    buffer = TfBuffer.from_bag(bag)
    with open_bag(bag) as reader:
        truth_ns, T_map_base_true, base = read_ground_truth(reader)
        scan_ns = np.array([decode_laserscan(rec.msg).stamp_ns for rec in reader.messages(["/scan"])])
    result = {"scans": int(scan_ns.size),
              "distance_m": float(np.sum(np.hypot(*np.diff(T_map_base_true[:, :2, 3], axis=0).T)))}
    for key, lag_ns in (("", 0), ("_no_lag", AMCL_TRANSFORM_TOLERANCE_NS)):
        T_map_odom, valid = buffer.lookup("map", "odom", scan_ns + lag_ns, return_mask=True)
        estimate = tform2pose(T_map_odom[valid] @ buffer.lookup("odom", base, scan_ns[valid]))
        truth = tform2pose(T_map_base_true[np.searchsorted(truth_ns, scan_ns[valid])])
        position_m = np.hypot(*(estimate[:, :2] - truth[:, :2]).T)
        yaw_deg = np.rad2deg(wrap_to_pi(estimate[:, 2] - truth[:, 2]))
        result[f"position_rms_m{key}"] = float(np.sqrt(np.mean(position_m**2)))
        result[f"yaw_rms_deg{key}"] = float(np.sqrt(np.mean(yaw_deg**2)))
    T_map_odom, valid = buffer.lookup("map", "odom", truth_ns + AMCL_TRANSFORM_TOLERANCE_NS, return_mask=True)
    T_map_base = T_map_odom[valid] @ buffer.lookup("odom", base, truth_ns[valid])
    write_tum(lag_free_tum, Trajectory(truth_ns[valid], T_map_base), force=True, frame="map", body=base)
    return result


def grid_score(bag: Path, out: Path, *options: str) -> dict:
    bagtools("grid", bag, "--out", out, "--force", *options)
    score = json.loads((out / "summary.json").read_text())["accuracy_vs_truth"]
    return {"precision": score["occupied_precision"], "recall": score["occupied_recall"]}


def speed_experiment(workdir: Path, seeds: tuple[int, ...]) -> dict:
    """Every (setting, seed, noise) run: its duration, tf pose error and the grids' scores."""
    runs = []
    root = workdir / "speed_experiment"
    root.mkdir(parents=True, exist_ok=True)
    for seed in seeds:
        for linear, angular in SPEED_SETTINGS:
            duration = loop_duration_s(seed, linear, angular)
            for noise in SPEED_NOISES:
                started = time.monotonic()
                bag = root / f"seed{seed}_v{linear:.2f}_{noise}"
                bagtools("simulate", bag, "--route", SPEED_ROUTE, "--seed", seed, "--odom-noise", noise,
                         "--max-linear", linear, "--max-angular", angular, "--duration", duration, "--no-cloud",
                         "--force")
                lag_free = bag.with_name(bag.name + "_no_lag.tum")
                run = {"seed": seed, "max_linear_mps": linear, "max_angular_radps": angular, "odom_noise": noise,
                       "duration_s": duration, **tf_pose_error(bag, lag_free),
                       "tf": grid_score(bag, bag.with_name(bag.name + "_grid_tf")),
                       "tf_no_lag": grid_score(bag, bag.with_name(bag.name + "_grid_no_lag"), "--poses", lag_free)}
                # Ground-truth poses and the scans do not depend on the odometry noise: one grid per seed and setting.
                if noise == SPEED_NOISES[0]:
                    run["ground_truth"] = grid_score(bag, bag.with_name(bag.name + "_grid_truth"),
                                                     "--poses", "ground-truth")
                runs.append(run)
                log(f"  seed {seed} {linear} m/s {angular} rad/s {noise}: {duration} s, "
                    f"tf {run['tf']['precision']:.3f}/{run['tf']['recall']:.3f} "
                    f"({time.monotonic() - started:.1f} s)")
    return {"route": SPEED_ROUTE, "seeds": list(seeds), "settings": [list(s) for s in SPEED_SETTINGS],
            "noises": list(SPEED_NOISES), "runs": runs, "summary": summarize(runs)}


def _mean_sd(values: list[float]) -> list[float]:
    return [statistics.fmean(values), statistics.stdev(values) if len(values) > 1 else 0.0]


def summarize(runs: list[dict]) -> list[dict]:
    """Per setting: mean and standard deviation over the seeds of every measure."""
    rows = []
    for linear, angular in SPEED_SETTINGS:
        same = [r for r in runs if r["max_linear_mps"] == linear and r["max_angular_radps"] == angular]
        first = [r for r in same if "ground_truth" in r]
        row = {"max_linear_mps": linear, "max_angular_radps": angular,
               "duration_s": _mean_sd([r["duration_s"] for r in first]),
               "scans_per_m": _mean_sd([r["scans"] / r["distance_m"] for r in first]),
               "ground_truth": {k: _mean_sd([r["ground_truth"][k] for r in first]) for k in ("precision", "recall")}}
        for noise in SPEED_NOISES:
            these = [r for r in same if r["odom_noise"] == noise]
            row[noise] = {
                "position_rms_cm": _mean_sd([100 * r["position_rms_m"] for r in these]),
                "yaw_rms_deg": _mean_sd([r["yaw_rms_deg"] for r in these]),
                "precision": _mean_sd([r["tf"]["precision"] for r in these]),
                "recall": _mean_sd([r["tf"]["recall"] for r in these]),
                "yaw_rms_deg_no_lag": _mean_sd([r["yaw_rms_deg_no_lag"] for r in these]),
                "precision_no_lag": _mean_sd([r["tf_no_lag"]["precision"] for r in these]),
                "recall_no_lag": _mean_sd([r["tf_no_lag"]["recall"] for r in these]),
            }
        rows.append(row)
    return rows


def _pm(value: list[float], digits: int) -> str:
    return f"{value[0]:.{digits}f} ± {value[1]:.{digits}f}"


def speed_table(result: dict) -> str:
    """The markdown tables of section 7, from the experiment's JSON."""
    seeds = ", ".join(str(s) for s in result["seeds"])
    lines = [
        f"Route `--route {result['route']}`, seeds {seeds} (one tour per seed, driven once at every limit), "
        "`--no-cloud`, grids at 5 cm.",
        "",
        "| max linear, angular | one loop [s] | scans per m | ground truth: precision | recall |",
        "|---|---|---|---|---|",
    ]
    for row in result["summary"]:
        lines.append(
            f"| {row['max_linear_mps']:.2f} m/s, {row['max_angular_radps']:.2f} rad/s | {_pm(row['duration_s'], 0)} "
            f"| {_pm(row['scans_per_m'], 0)} | {_pm(row['ground_truth']['precision'], 3)} "
            f"| {_pm(row['ground_truth']['recall'], 3)} |")
    lines += [
        "",
        "| max linear, angular | odometry noise | tf: position error [cm] | yaw error [deg] | precision | recall "
        "| without the lag: yaw error [deg] | precision | recall |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for noise in result["noises"]:
        for row in result["summary"]:
            m = row[noise]
            lines.append(
                f"| {row['max_linear_mps']:.2f} m/s, {row['max_angular_radps']:.2f} rad/s | {noise} "
                f"| {_pm(m['position_rms_cm'], 1)} | {_pm(m['yaw_rms_deg'], 2)} | {_pm(m['precision'], 3)} "
                f"| {_pm(m['recall'], 3)} | {_pm(m['yaw_rms_deg_no_lag'], 2)} | {_pm(m['precision_no_lag'], 3)} "
                f"| {_pm(m['recall_no_lag'], 3)} |")
    return "\n".join(lines)


def speed_plot(result: dict, target: Path) -> None:
    import matplotlib.pyplot as plt

    rows = result["summary"]
    x = np.array([row["max_linear_mps"] for row in rows])
    labels = [f"{row['max_linear_mps']:.2f}\n{row['max_angular_radps']:.2f}" for row in rows]
    fig, axes = plt.subplots(1, 2, figsize=(9, 4.2), sharey=True)
    for ax, measure in zip(axes, ("precision", "recall")):
        series = [("ground truth poses", [row["ground_truth"][measure] for row in rows], "k", "s", "-")]
        for noise, colour in zip(result["noises"], ("tab:blue", "tab:red")):
            series.append((f"tf, {noise} odometry", [row[noise][measure] for row in rows], colour, "o", "-"))
            series.append((f"tf without the lag, {noise}", [row[noise][f"{measure}_no_lag"] for row in rows],
                           colour, "^", "--"))
        for k, (label, values, colour, marker, style) in enumerate(series):
            mean, sd = np.array(values).T
            ax.errorbar(x + (k - 2) * 0.003, mean, yerr=sd, label=label, color=colour, marker=marker,
                        linestyle=style, capsize=3)
        ax.set_title(f"occupied {measure}")
        ax.set_xticks(x, labels)
        ax.set_xlabel("max linear [m/s], max angular [rad/s]")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel(f"mean ± sd over seeds {', '.join(str(s) for s in result['seeds'])}")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.14, 1, 1))
    fig.savefig(target, dpi=90)
    plt.close(fig)


def set_example_duration(text: str, result: dict) -> str:
    """The guide with the example run's --duration set to the one measured for its seed and limits."""
    match = EXAMPLE_LINE.search(text)
    if match is None:
        raise SystemExit("make_figures: the example 'bagtools simulate lab/speed/fast ...' line of lab.md changed")
    seed, linear, angular = int(match.group(2)), float(match.group(3)), float(match.group(4))
    durations = {r["duration_s"] for r in result["runs"]
                 if (r["seed"], r["max_linear_mps"], r["max_angular_radps"]) == (seed, linear, angular)}
    if len(durations) != 1:
        raise SystemExit(f"make_figures: the experiment has no run for seed {seed} at {linear} m/s, {angular} rad/s")
    return EXAMPLE_LINE.sub(lambda m: f"{m.group(1)}{durations.pop():g}{m.group(6)}", text, count=1)


# ---------------------------------------------------------------------- 4: the prose's claims

def check_claims(guide: str, workdir: Path, speed: dict | None) -> list[str]:
    """What the guide (with its fresh outputs) says about its numbers, checked; the sentences that no longer hold."""
    lab = workdir / "lab"

    def summary(name: str) -> dict:
        return json.loads((lab / name / "summary.json").read_text())

    failures = []

    def claim(ok: bool, sentence: str) -> None:
        if not ok:
            failures.append(sentence)

    cloud = {n: summary(n)["accuracy_vs_truth_m"] for n in ("cloud_map", "cloud_map_latest", "cloud_map_odom")}
    claim(cloud["cloud_map_odom"]["p95"] > 2 * cloud["cloud_map"]["p95"],
          "4: the odom-frame cloud map's p95 is about three times the map frame's")
    claim(abs(cloud["cloud_map_latest"]["mean"] - cloud["cloud_map"]["mean"]) < 0.005,
          "4: the latest transform barely changes the cloud map")
    chained = dict(re.findall(r"^(NDT|wheel odometry) +position error: end ([\d.]+) m", guide, re.M))
    claim(len(chained) == 2 and float(chained["NDT"]) < float(chained["wheel odometry"]),
          "5: chained scan to scan, NDT already ends closer to the truth than the wheels")
    lags = re.search(r"^latest transform newer than the cloud by (.*)$", guide, re.M)
    claim(lags is not None and all(float(ms) <= 34 for ms in re.findall(r"([\d.]+) ms", lags.group(1))),
          "4: the latest transform is at most one 30 Hz odometry step newer than the cloud")
    ndt = summary("ndt")
    claim(ndt["errors_ndt"]["ape_translation_m"]["rmse"] < 0.25 * ndt["errors_odometry"]["ape_translation_m"]["rmse"],
          "5: the NDT trajectory lies on the ground truth, the wheels curl away")
    claim("agrees with bagtools grid in 100.0% of its" in guide, "6: bagtools grid does the same as insert_ray by hand")
    grids = {n: summary(n)["accuracy_vs_truth"] for n in ("grid", "grid_truth", "grid_odom", "grid_ndt")}
    claim(grids["grid_odom"]["occupied_precision"] < grids["grid"]["occupied_precision"]
          < grids["grid_truth"]["occupied_precision"], "6: odom grid worse than tf grid, tf grid worse than the truth")
    claim(grids["grid_ndt"]["occupied_precision"] >= grids["grid_truth"]["occupied_precision"] - 0.01,
          "6: the NDT grid's walls are as thin as the ground truth's")
    if speed is not None:
        failures += speed_claims(speed)
    return failures


def speed_claims(speed: dict) -> list[str]:
    """The sentences of section 7 that the experiment's numbers no longer support."""
    rows = speed["summary"]
    failures = []

    def claim(ok: bool, sentence: str) -> None:
        if not ok:
            failures.append(sentence)

    def means(noise: str, key: str) -> list[float]:
        return [row[noise][key][0] for row in rows]

    truth_precision = [row["ground_truth"]["precision"][0] for row in rows]
    truth_recall = [row["ground_truth"]["recall"][0] for row in rows]
    claim(min(truth_precision) > 0.99, "7 scan rate: ground-truth grids have precision 1.000 at every limit")
    claim(max(truth_recall) - min(truth_recall) < 0.02, "7 scan rate: ground-truth recall is the same at every limit")
    claim(rows[0]["scans_per_m"][0] > 3.5 * rows[-1]["scans_per_m"][0],
          "7 scan rate: the crawl records four times as many scans per metre as full speed")
    positions = means("realistic", "position_rms_cm") + means("high", "position_rms_cm")
    claim(max(positions) - min(positions) < 0.5 and 4.0 <= min(positions) and max(positions) <= 5.0,
          "7 AMCL's error: tf's position error, 4-5 cm rms, is the same at every speed and noise level")
    for noise in ("realistic", "high"):
        yaw = means(noise, "yaw_rms_deg")
        claim(all(a < b for a, b in zip(yaw, yaw[1:])), f"7 AMCL's lag: tf's heading error grows with the turn rate ({noise})")
        yaw_no_lag = means(noise, "yaw_rms_deg_no_lag")
        claim(max(yaw_no_lag) - min(yaw_no_lag) < 0.25 * (yaw[-1] - yaw[0]) + 0.1,
              f"7 AMCL's lag: without the lag the heading error is the same at every speed ({noise})")
    high_yaw, realistic_yaw = means("high", "yaw_rms_deg"), means("realistic", "yaw_rms_deg")
    claim(high_yaw[-1] - high_yaw[0] > 2 * (realistic_yaw[-1] - realistic_yaw[0]),
          "7 AMCL's lag: the heading error grows much more with high odometry noise")
    high = [row["high"] for row in rows]
    claim(high[-1]["recall"][0] < high[0]["recall"][0] - high[0]["recall"][1],
          "7 AMCL's lag: the high-noise grids lose recall at speed")
    for noise in ("realistic", "high"):
        for key in ("precision_no_lag", "recall_no_lag"):
            crawl, top = rows[0][noise][key], rows[-1][noise][key]
            claim(top[0] > crawl[0] - crawl[1], f"7 AMCL's lag: without the lag {key[:-7]} no longer falls with speed ({noise})")
    realistic = [row["realistic"] for row in rows]
    for key in ("precision", "recall"):
        spread = max(m[key][0] for m in realistic) - min(m[key][0] for m in realistic)
        claim(spread < max(m[key][1] for m in realistic),
              f"7 AMCL's lag: with realistic odometry the effect on {key} is smaller than the scatter between seeds")
    return failures


# ---------------------------------------------------------------------- main

def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workdir", type=Path, default=REPO / "build" / "lab",
                        help="where the guide's commands run (emptied first)")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(SPEED_SEEDS), help="seeds of the speed experiment")
    parser.add_argument("--skip-speed", action="store_true",
                        help="keep docs/lab_speed.json and its table; only rerun the guide's blocks")
    args = parser.parse_args(argv)

    workdir = args.workdir.resolve()
    if workdir.exists():
        shutil.rmtree(workdir)
    workdir.mkdir(parents=True)
    text = labdoc.LAB_MD.read_text()

    if args.skip_speed:
        speed = json.loads(SPEED_JSON.read_text())
    else:
        log("speed experiment")
        speed = speed_experiment(workdir, tuple(args.seeds))
        SPEED_JSON.write_text(json.dumps(speed, indent=1) + "\n")
    speed_plot(speed, workdir / SPEED_PNG)
    save_small_png(workdir / SPEED_PNG, labdoc.IMG_DIR / SPEED_PNG)
    text = set_example_duration(text, speed)
    text = labdoc.replace_between(text, "speed-table", speed_table(speed))

    log("the guide's blocks")
    text = run_guide(text, workdir)
    copy_figures(workdir)
    labdoc.LAB_MD.write_text(text)

    failures = check_claims(text, workdir, speed)
    for sentence in failures:
        log(f"make_figures: lab.md no longer holds: {sentence}")
    sizes = {p.name: p.stat().st_size for p in sorted(labdoc.IMG_DIR.glob("*.png"))}
    log("figures: " + ", ".join(f"{name} {size // 1024} kB" for name, size in sizes.items())
        + f"; total {sum(sizes.values()) // 1024} kB")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
