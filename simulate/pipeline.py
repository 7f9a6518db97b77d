"""The simulation loop: drive the route, simulate sensors and write one rosbag2 bag.

``simulate_bag(out_path, config, force)`` is the one entry point (the ``bagtools simulate``
command calls it). Everything is computed from ``config`` alone (fixed start time, seeded
random streams), so the same configuration gives the same messages.
"""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from bagtools.errors import BagtoolsError
from bagtools.outputs import atomic_path
from bagtools.progress import progress_bar
from simulate.robot.amcl import TRANSFORM_TOLERANCE_NS, amcl_map_to_odom
from simulate.robot.controller import Limits, Motion, drive
from simulate.robot.odometry import ODOM_NOISE_LEVELS, Odometry, se2_compose, wheel_odometry
from simulate.robot.routes import ROUTE_NAMES, make_route
from simulate.robot.waffle import (
    MAX_ANGULAR_RADPS,
    MAX_LINEAR_MPS,
    ROBOT_RADIUS_M,
    STATIC_TRANSFORMS,
    T_base_footprint_frame,
)
from simulate.sensors import DepthCamera, Lidar
from simulate.world import World, load_world
from simulate.writer import ROS_DISTROS, MessageBuilder, SimBagWriter

ODOM_RATE_HZ = 30
STEPS_PER_SCAN = 6  # 5 Hz scans at the 30 Hz odometry rate
CLICK_PERIOD_S = 20.0
MAX_CLOUD_PIXELS = 1280 * 960
# Transport latency ranges (ms) between a message's stamp and its bag time.
LATENCY_MS = {"tf": (1, 5), "odom": (1, 5), "truth": (1, 5), "scan": (10, 30), "cloud": (20, 60), "amcl": (5, 20), "click": (1, 5)}
WORLD_TOPIC = "/simulation/world"
CLOUD_TOPIC = "/camera/depth/points"


@dataclass(frozen=True)
class SimConfig:
    """Everything a simulated bag depends on. Speeds in m/s and rad/s, rates in Hz, sizes in pixels."""

    duration_s: float = 60.0
    seed: int = 0
    route: str = "lap"
    odom_noise: str = "realistic"
    max_linear_mps: float = MAX_LINEAR_MPS
    max_angular_radps: float = MAX_ANGULAR_RADPS
    cloud: bool = True
    cloud_rate_hz: float = 2.0
    cloud_size: tuple[int, int] = (160, 120)
    ros_distro: str = "jazzy"
    world: str = "turtlebot3_world"
    start_time_ns: int = 1_700_000_000_000_000_000

    def validate(self) -> None:
        """Raise BagtoolsError naming the first invalid setting."""
        if not (np.isfinite(self.duration_s) and 0.0 < self.duration_s <= 24 * 3600):
            raise BagtoolsError(f"--duration must be a positive number of seconds (at most a day), got {self.duration_s}")
        if self.seed < 0:
            raise BagtoolsError(f"--seed must be >= 0, got {self.seed}")
        if self.route not in ROUTE_NAMES:
            raise BagtoolsError(f"unknown route {self.route!r} (choose from {', '.join(ROUTE_NAMES)})")
        if self.odom_noise not in ODOM_NOISE_LEVELS:
            raise BagtoolsError(f"unknown odometry noise {self.odom_noise!r} (choose from {', '.join(ODOM_NOISE_LEVELS)})")
        Limits(self.max_linear_mps, self.max_angular_radps).check()
        if self.cloud and not (np.isfinite(self.cloud_rate_hz) and 0.0 < self.cloud_rate_hz <= 30.0):
            raise BagtoolsError(f"--cloud-rate must be in (0, 30] Hz, got {self.cloud_rate_hz}")
        w, h = self.cloud_size
        if w < 2 or h < 2 or w * h > MAX_CLOUD_PIXELS:
            raise BagtoolsError(f"--cloud-size must be at least 2x2 and at most {MAX_CLOUD_PIXELS} pixels, got {w}x{h}")
        if self.ros_distro not in ROS_DISTROS:
            raise BagtoolsError(f"unknown ROS distro {self.ros_distro!r} (choose from {', '.join(ROS_DISTROS)})")


def parse_cloud_size(text: str) -> tuple[int, int]:
    """Parse ``"WxH"`` (e.g. ``"160x120"``) into (width, height); BagtoolsError if malformed."""
    match = re.fullmatch(r"\s*(\d{1,5})\s*[xX]\s*(\d{1,5})\s*", text)
    if not match:
        raise BagtoolsError(f"--cloud-size must look like WIDTHxHEIGHT (e.g. 160x120), got {text!r}")
    return int(match.group(1)), int(match.group(2))


@dataclass
class SimSummary:
    """What a simulation wrote: message counts per topic, distance driven (m), final odometry drift."""

    path: Path
    duration_s: float
    counts: dict[str, int] = field(default_factory=dict)
    distance_m: float = 0.0
    final_drift_m: float = 0.0
    final_drift_rad: float = 0.0

    def lines(self) -> list[str]:
        """A short human-readable summary."""
        out = [f"wrote {self.path} ({self.duration_s:g} s simulated)"]
        out += [f"  {topic}: {n} messages" for topic, n in sorted(self.counts.items())]
        out.append(f"  distance driven: {self.distance_m:.2f} m")
        out.append(f"  final odometry drift: {self.final_drift_m:.3f} m, {np.rad2deg(self.final_drift_rad):.2f} deg")
        return out


@dataclass(frozen=True)
class Trajectory:
    """The simulated truth and odometry, before any sensor: the motion plan of one bag."""

    motion: Motion
    odometry: Odometry
    spawn_xyyaw: np.ndarray
    step_ns: np.ndarray


def plan_trajectory(config: SimConfig, world: World) -> Trajectory:
    """Drive ``config.route`` in ``world`` for the configured duration and simulate wheel odometry."""
    rngs = _rngs(config.seed)
    n_steps = int(round(config.duration_s * ODOM_RATE_HZ))
    if n_steps < 1:
        raise BagtoolsError(f"--duration {config.duration_s} s is shorter than one odometry step")
    route = make_route(config.route, world, config.seed)
    limits = Limits(config.max_linear_mps, config.max_angular_radps)
    path = route.path(config.duration_s * config.max_linear_mps + 1.0)
    motion = drive(path, world.spawn_xy_yaw, n_steps, 1.0 / ODOM_RATE_HZ, limits)
    clearance = world.clearance_m(motion.poses[:, :2])
    if np.min(clearance) < ROBOT_RADIUS_M:
        raise BagtoolsError(f"route {config.route!r} came within {np.min(clearance):.3f} m of an obstacle in world {world.name!r}")
    odometry = wheel_odometry(motion, config.odom_noise, rngs["odom"])
    step_ns = config.start_time_ns + (np.arange(n_steps + 1, dtype=np.int64) * 1_000_000_000) // ODOM_RATE_HZ
    return Trajectory(motion, odometry, np.asarray(world.spawn_xy_yaw, dtype=np.float64), step_ns)


def _rngs(seed: int) -> dict[str, np.random.Generator]:
    names = ("odom", "amcl", "latency", "scan", "cloud", "click")
    children = np.random.SeedSequence([seed, 0x5151]).spawn(len(names))
    return {n: np.random.default_rng(c) for n, c in zip(names, children)}


def _latency_ns(rng: np.random.Generator, kind: str, n: int) -> np.ndarray:
    lo, hi = LATENCY_MS[kind]
    return np.round(rng.uniform(lo, hi, n) * 1e6).astype(np.int64)


def _matrix_from_xyyaw(x: float, y: float, yaw: float, z: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = (x, y, z)
    return T


def simulate_bag(out_path: str | Path, config: SimConfig, force: bool = False) -> SimSummary:
    """Simulate ``config`` and write the rosbag2 directory ``out_path`` atomically.

    Refuses an existing ``out_path`` unless ``force`` (OutputExistsError); on any error or
    Ctrl-C nothing is left behind. Returns counts per topic, distance driven and final drift.
    """
    config.validate()
    out_path = Path(out_path)
    world = load_world(config.world)
    traj = plan_trajectory(config, world)
    rngs = _rngs(config.seed)
    motion, odom, step_ns = traj.motion, traj.odometry, traj.step_ns
    t0 = config.start_time_ns
    n_poses = len(step_ns)

    # Scans every 6th step; map->odom from the AMCL model at each scan.
    scan_steps = np.arange(0, n_poses, STEPS_PER_SCAN)
    scan_ns = step_ns[scan_steps]
    amcl = amcl_map_to_odom(motion.poses[scan_steps], odom.poses[scan_steps], rngs["amcl"])
    lidar = Lidar()
    T_base_scan = T_base_footprint_frame("base_scan")
    scan_offset_xy, scan_z = T_base_scan[:2, 3], float(T_base_scan[2, 3])

    if config.cloud:
        cloud_w, cloud_h = config.cloud_size
        camera = DepthCamera(width=cloud_w, height=cloud_h)
        n_clouds = int(np.floor(config.duration_s * config.cloud_rate_hz + 1e-9)) + 1
        cloud_ns = t0 + np.round(np.arange(n_clouds) * 1e9 / config.cloud_rate_hz).astype(np.int64)
        cloud_ns = cloud_ns[cloud_ns <= step_ns[-1]]
        cloud_poses = motion.pose_at_offset((cloud_ns - t0) / 1e9)
        T_base_optical = T_base_footprint_frame("camera_rgb_optical_frame")
    else:
        cloud_ns = np.zeros(0, dtype=np.int64)

    click_ns = t0 + np.arange(1, int(config.duration_s // CLICK_PERIOD_S) + 1, dtype=np.int64) * int(CLICK_PERIOD_S * 1e9)
    click_points = _clicked_points(world, motion.pose_at_offset((click_ns - t0) / 1e9), rngs["click"])

    # Every message as (log time, kind, index); written in log-time order.
    lat = rngs["latency"]
    scan_log = scan_ns + _latency_ns(lat, "scan", len(scan_ns))
    streams = [
        ("world", np.array([t0])),
        ("tf_static", np.array([t0])),
        ("tf_odom", step_ns + _latency_ns(lat, "tf", n_poses)),
        ("odom", step_ns + _latency_ns(lat, "odom", n_poses)),
        ("truth", step_ns + _latency_ns(lat, "truth", n_poses)),
        ("scan", scan_log),
        ("tf_map", scan_log + _latency_ns(lat, "amcl", len(scan_ns))),
        ("cloud", cloud_ns + _latency_ns(lat, "cloud", len(cloud_ns))),
        ("click", click_ns + _latency_ns(lat, "click", len(click_ns))),
    ]
    log_ns = np.concatenate([s[1] for s in streams])
    kind = np.concatenate([np.full(len(s[1]), i) for i, s in enumerate(streams)])
    index = np.concatenate([np.arange(len(s[1])) for s in streams])
    order = np.lexsort((index, kind, log_ns))

    topics = [WORLD_TOPIC, "/tf_static", "/tf", "/odom", "/ground_truth", "/scan", "/clicked_point"]
    if config.cloud:
        topics.append(CLOUD_TOPIC)
    world_json = json.dumps(
        {"world": world.to_json(), "config": _config_json(config), "robot": "turtlebot3_waffle"}, sort_keys=True
    )
    spawn = traj.spawn_xyyaw
    v_prev = np.concatenate(([0.0], motion.v_mps))  # twist over the step that ended at each stamp
    w_prev = np.concatenate(([0.0], motion.w_radps))
    vo_prev = np.concatenate(([0.0], odom.v_mps))
    wo_prev = np.concatenate(([0.0], odom.w_radps))

    with atomic_path(out_path, force) as staged, SimBagWriter(staged, config.ros_distro, topics) as bag:
        mb = MessageBuilder(bag.typestore)
        with progress_bar(total=round(config.duration_s, 3), desc="simulate", unit="s") as bar:
            shown_s = 0.0
            for i in order:
                k, j, t_log = int(kind[i]), int(index[i]), int(log_ns[i])
                name = streams[k][0]
                if name == "world":
                    bag.write(WORLD_TOPIC, t_log, mb.string(world_json))
                elif name == "tf_static":
                    tfs = [(t0, st.parent, st.child, st.xyz_m, st.quat_xyzw) for st in STATIC_TRANSFORMS]
                    bag.write("/tf_static", t_log, mb.tf_message(tfs))
                elif name == "tf_odom":
                    x, y, yaw = odom.poses[j]
                    bag.write("/tf", t_log, mb.planar_tf(int(step_ns[j]), "odom", "base_footprint", x, y, yaw))
                elif name == "odom":
                    x, y, yaw = odom.poses[j]
                    bag.write("/odom", t_log, mb.odometry(int(step_ns[j]), "odom", "base_footprint", x, y, yaw, vo_prev[j], wo_prev[j]))
                elif name == "truth":
                    x, y, yaw = motion.poses[j]
                    msg = mb.odometry(int(step_ns[j]), "map", "base_footprint", x, y, yaw, v_prev[j], w_prev[j], truth=True)
                    bag.write("/ground_truth", t_log, msg)
                elif name == "scan":
                    x, y, yaw = motion.poses[scan_steps[j]]
                    c, s = np.cos(yaw), np.sin(yaw)
                    sx = x + c * scan_offset_xy[0] - s * scan_offset_xy[1]
                    sy = y + s * scan_offset_xy[0] + c * scan_offset_xy[1]
                    ranges = lidar.scan(world, (sx, sy, scan_z, yaw), rngs["scan"])
                    msg = mb.laser_scan(
                        int(scan_ns[j]), "base_scan", ranges, lidar.angle_min_rad, lidar.angle_increment_rad,
                        lidar.range_min_m, lidar.range_max_m, 1.0 / lidar.rate_hz,
                    )
                    bag.write("/scan", t_log, msg)
                elif name == "tf_map":
                    x, y, yaw = amcl.poses[j]
                    bag.write("/tf", t_log, mb.planar_tf(int(scan_ns[j]) + TRANSFORM_TOLERANCE_NS, "map", "odom", x, y, yaw))
                elif name == "cloud":
                    T_map_optical = _matrix_from_xyyaw(*cloud_poses[j]) @ T_base_optical
                    points = camera.points(world, T_map_optical, rngs["cloud"])
                    bag.write(CLOUD_TOPIC, t_log, mb.point_cloud(int(cloud_ns[j]), "camera_rgb_optical_frame", points))
                else:
                    bag.write("/clicked_point", t_log, mb.point_stamped(int(click_ns[j]), "map", click_points[j]))
                sim_s = min((t_log - t0) / 1e9, config.duration_s)
                if sim_s - shown_s >= 1.0:
                    bar.update(round(sim_s - shown_s, 3))
                    shown_s = sim_s
        counts = dict(bag.counts)

    odom_in_map = se2_compose(spawn, odom.poses[-1])
    truth = motion.poses[-1]
    return SimSummary(
        path=out_path,
        duration_s=config.duration_s,
        counts=counts,
        distance_m=float(np.sum(np.abs(motion.v_mps)) * motion.dt_s),
        final_drift_m=float(np.hypot(*(odom_in_map[:2] - truth[:2]))),
        final_drift_rad=float(abs((odom_in_map[2] - truth[2] + np.pi) % (2 * np.pi) - np.pi)),
    )


def _config_json(config: SimConfig) -> dict:
    d = asdict(config)
    d["cloud_size"] = list(config.cloud_size)
    return d


def _clicked_points(world: World, poses: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Points (K, 3) in map a user might click in RViz near the robot: an obstacle surface ahead, else the floor."""
    points = np.zeros((len(poses), 3))
    click_z = 0.1  # within the height of every obstacle of the TurtleBot3 world
    for i, (x, y, yaw) in enumerate(poses):  # one click every 20 s
        angle = yaw + rng.uniform(-0.6, 0.6)
        dist = float(world.raycast_2d(np.array([x, y]), np.array([angle]), click_z, 3.0)[0])
        if np.isfinite(dist):
            points[i] = (x + dist * np.cos(angle), y + dist * np.sin(angle), click_z)
        else:
            reach = rng.uniform(0.5, 1.5)
            points[i] = (x + reach * np.cos(angle), y + reach * np.sin(angle), 0.0)
    return points
