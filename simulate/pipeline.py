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
from bagtools.outputs import atomic_path, check_writable, mark_own_output
from bagtools.progress import progress_bar
from bagtools.transforms import pose2tform, se2_compose
from bagtools_simulate.robot.amcl import TRANSFORM_TOLERANCE_NS, amcl_map_to_odom
from bagtools_simulate.robot.controller import Limits, Motion, drive
from bagtools_simulate.robot.odometry import ODOM_NOISE_LEVELS, Odometry, wheel_odometry
from bagtools_simulate.robot.routes import ROUTE_NAMES, make_route
from bagtools_simulate.robot.waffle import (
    MAX_ANGULAR_RADPS,
    MAX_LINEAR_MPS,
    ROBOT_RADIUS_M,
    STATIC_TRANSFORMS,
    WHEEL_JOINT_MODELS,
    WHEEL_JOINTS,
    T_base_footprint_frame,
    urdf_text,
    wheel_quats_xyzw,
)
from bagtools_simulate.sensors import DepthCamera, Imu, Lidar
from bagtools_simulate.world import World, load_world
from bagtools_simulate.writer import DEFAULT_ROS_DISTRO, ROS_DISTROS, MessageBuilder, SimBagWriter, is_rosbag2_output

ODOM_RATE_HZ = 30
STEPS_PER_SCAN = 6  # 5 Hz scans at the 30 Hz odometry rate
CLICK_PERIOD_S = 20.0
MAX_CLOUD_PIXELS = 1280 * 960
# Transport latency ranges (ms) between a message's stamp and its bag time.
LATENCY_MS = {"tf": (1, 5), "odom": (1, 5), "truth": (1, 5), "scan": (10, 30), "cloud": (20, 60), "amcl": (5, 20),
              "click": (1, 5), "joints": (1, 5), "imu": (1, 3)}
WORLD_TOPIC = "/simulation/world"
CLOUD_TOPIC = "/camera/depth/points"
CAMERA_INFO_TOPIC = "/camera/depth/camera_info"
#: The frames the depth cloud may be published in (and seen from). The default is the lab's: the TurtleBot3
#: Waffle's Gazebo depth plugin publishes its points in camera_rgb_optical_frame; the R200's own depth optical
#: frame, 1 cm beside it, is the other.
CLOUD_FRAMES = ("camera_rgb_optical_frame", "camera_depth_optical_frame")
IMU_FRAME = "imu_link"
BATCH_BLOCK = 4096  # messages serialized at once per fixed-layout stream (bounds memory on long runs)


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
    cloud_frame: str = CLOUD_FRAMES[0]
    ros_distro: str = DEFAULT_ROS_DISTRO  # humble: metadata version 5, which Humble and Jazzy both read
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
        if self.cloud_frame not in CLOUD_FRAMES:
            raise BagtoolsError(f"unknown cloud frame {self.cloud_frame!r} (choose from {', '.join(CLOUD_FRAMES)})")
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
    # New streams go at the end: each child seed depends only on its position.
    names = ("odom", "amcl", "latency", "scan", "cloud", "click", "imu")
    children = np.random.SeedSequence([seed, 0x5151]).spawn(len(names))
    return {n: np.random.default_rng(c) for n, c in zip(names, children)}


def _latency_ns(rng: np.random.Generator, kind: str, n: int) -> np.ndarray:
    lo, hi = LATENCY_MS[kind]
    return np.round(rng.uniform(lo, hi, n) * 1e6).astype(np.int64)


class _BagSimulation:
    """One bag's messages: when each is stamped and logged, and how it is built.

    The random streams are drawn in a fixed order (AMCL estimates, clicks, latencies, then scan and cloud noise in bag order), so the same configuration gives the
    same bytes. The fixed-layout streams (odometry, tf, joint states, IMU) are serialized in
    blocks of ``BATCH_BLOCK`` messages as the writing reaches them (IMU noise is drawn block by
    block); scans and clouds are simulated one by one.
    """

    def __init__(self, config: SimConfig, world: World, traj: Trajectory, rngs: dict[str, np.random.Generator]) -> None:
        self.config, self.world, self.traj, self.rngs = config, world, traj, rngs
        motion, odom, step_ns = traj.motion, traj.odometry, traj.step_ns
        self.t0 = config.start_time_ns
        # Scans every 6th step; map->odom from the AMCL model at each scan.
        self.scan_steps = np.arange(0, len(step_ns), STEPS_PER_SCAN)
        self.scan_ns = step_ns[self.scan_steps]
        self.amcl = amcl_map_to_odom(motion.poses[self.scan_steps], odom.poses[self.scan_steps], rngs["amcl"])
        self.lidar = Lidar()
        self.T_base_scan = T_base_footprint_frame("base_scan")
        self.cloud_ns = np.zeros(0, dtype=np.int64)
        if config.cloud:
            self.camera = DepthCamera(width=config.cloud_size[0], height=config.cloud_size[1])
            n_clouds = int(np.floor(config.duration_s * config.cloud_rate_hz + 1e-9)) + 1
            cloud_ns = self.t0 + np.round(np.arange(n_clouds) * 1e9 / config.cloud_rate_hz).astype(np.int64)
            self.cloud_ns = cloud_ns[cloud_ns <= step_ns[-1]]
            self.cloud_poses = motion.pose_at_offset((self.cloud_ns - self.t0) / 1e9)
            self.T_base_optical = T_base_footprint_frame(config.cloud_frame)
        n_clicks = int(config.duration_s // CLICK_PERIOD_S)
        self.click_ns = self.t0 + np.arange(1, n_clicks + 1, dtype=np.int64) * int(CLICK_PERIOD_S * 1e9)
        self.click_points = _clicked_points(world, motion.pose_at_offset((self.click_ns - self.t0) / 1e9), rngs["click"])
        self.world_json = json.dumps(
            {"world": world.to_json(), "config": _config_json(config), "robot": "turtlebot3_waffle"}, sort_keys=True)
        # IMU readings at its own rate over the whole run.
        self.imu = Imu()
        n_imu = int((step_ns[-1] - self.t0) * self.imu.rate_hz // 1_000_000_000) + 1
        self.imu_ns = self.t0 + (np.arange(n_imu, dtype=np.int64) * 1_000_000_000) // int(self.imu.rate_hz)
        # Twists over the step that ended at each stamp.
        self.v_true, self.w_true = _previous_step(motion.v_mps), _previous_step(motion.w_radps)
        self.v_odom, self.w_odom = _previous_step(odom.v_mps), _previous_step(odom.w_radps)
        # Wheel joints: the encoder angles the odometry integrated, and their rates over the last step.
        self.wheel_rad = np.column_stack([odom.wheel_left_rad, odom.wheel_right_rad])
        self.wheel_radps = np.vstack([np.zeros((1, 2)), np.diff(self.wheel_rad, axis=0) / motion.dt_s])
        self._blocks: dict[str, tuple[int, np.ndarray]] = {}

    @property
    def topics(self) -> list[str]:
        topics = [WORLD_TOPIC, "/robot_description", "/tf_static", "/tf", "/odom", "/joint_states", "/imu",
                  "/ground_truth", "/scan", "/clicked_point"]
        return topics + [CAMERA_INFO_TOPIC, CLOUD_TOPIC] if self.config.cloud else topics

    def schedule(self) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
        """(kinds, kind index, message index, log time ns) of every message, in bag (log-time) order."""
        lat, step_ns = self.rngs["latency"], self.traj.step_ns
        scan_log = self.scan_ns + _latency_ns(lat, "scan", len(self.scan_ns))
        streams = [
            ("world", np.array([self.t0])),
            ("tf_static", np.array([self.t0])),
            ("tf_odom", step_ns + _latency_ns(lat, "tf", len(step_ns))),
            ("odom", step_ns + _latency_ns(lat, "odom", len(step_ns))),
            ("truth", step_ns + _latency_ns(lat, "truth", len(step_ns))),
            ("scan", scan_log),
            ("tf_map", scan_log + _latency_ns(lat, "amcl", len(self.scan_ns))),
            ("cloud", self.cloud_ns + _latency_ns(lat, "cloud", len(self.cloud_ns))),
            ("click", self.click_ns + _latency_ns(lat, "click", len(self.click_ns))),
        ]
        joints_log = step_ns + _latency_ns(lat, "joints", len(step_ns))
        streams += [
            ("robot_description", np.array([self.t0])),
            ("joints", joints_log),
            # robot_state_publisher turns each /joint_states into the wheels' /tf.
            ("tf_wheels", joints_log + _latency_ns(lat, "tf", len(step_ns))),
            ("imu", self.imu_ns + _latency_ns(lat, "imu", len(self.imu_ns))),
            ("camera_info", self.cloud_ns + _latency_ns(lat, "cloud", len(self.cloud_ns))),
        ]
        log_ns = np.concatenate([times for _, times in streams])
        kind = np.concatenate([np.full(len(times), i) for i, (_, times) in enumerate(streams)])
        index = np.concatenate([np.arange(len(times)) for _, times in streams])
        order = np.lexsort((index, kind, log_ns))
        return [name for name, _ in streams], kind[order], index[order], log_ns[order]

    def _batch(self, mb: MessageBuilder, name: str, j: int) -> bytes:
        """Message ``j`` of a fixed-layout stream, serialized with its block of ``BATCH_BLOCK`` neighbours."""
        block = j // BATCH_BLOCK
        cached = self._blocks.get(name)
        if cached is None or cached[0] != block:
            if name == "imu" and block != (cached[0] + 1 if cached else 0):
                raise ValueError("IMU blocks must be built in order (their noise is drawn block by block)")
            cached = (block, self._serialize_block(mb, name, slice(block * BATCH_BLOCK, (block + 1) * BATCH_BLOCK)))
            self._blocks[name] = cached
        return cached[1][j - block * BATCH_BLOCK].tobytes()

    def _serialize_block(self, mb: MessageBuilder, name: str, sl: slice) -> np.ndarray:
        step_ns, odom, motion = self.traj.step_ns, self.traj.odometry, self.traj.motion
        if name == "tf_odom":
            return mb.planar_tf_batch(step_ns[sl], "odom", "base_footprint", odom.poses[sl])
        if name == "odom":
            return mb.odometry_batch(step_ns[sl], "odom", "base_footprint", odom.poses[sl], self.v_odom[sl],
                                     self.w_odom[sl])
        if name == "truth":
            return mb.odometry_batch(step_ns[sl], "map", "base_footprint", motion.poses[sl], self.v_true[sl],
                                     self.w_true[sl], truth=True)
        if name == "joints":
            return mb.joint_state_batch(step_ns[sl], WHEEL_JOINTS, self.wheel_rad[sl], self.wheel_radps[sl])
        if name == "tf_wheels":
            wheel_rad = self.wheel_rad[sl]
            xyz = np.broadcast_to(np.array([j.xyz_m for j in WHEEL_JOINT_MODELS]), (len(wheel_rad), 2, 3))
            quats = np.stack([wheel_quats_xyzw(j, wheel_rad[:, i]) for i, j in enumerate(WHEEL_JOINT_MODELS)], axis=1)
            return mb.transforms_batch(step_ns[sl], tuple((j.parent, j.child) for j in WHEEL_JOINT_MODELS), xyz, quats)
        imu = self.imu  # name == "imu"
        samples = imu.samples(motion, (self.imu_ns[sl] - self.t0) / 1e9, self.rngs["imu"])
        return mb.imu_batch(self.imu_ns[sl], IMU_FRAME, samples.quat_xyzw, samples.angular_velocity_radps,
                            samples.linear_acceleration_mps2,
                            (imu.orientation_covariance, imu.angular_velocity_covariance,
                             imu.linear_acceleration_covariance))

    def message(self, mb: MessageBuilder, name: str, j: int) -> tuple[str, bytes]:
        """(topic, serialized message) number ``j`` of stream ``name``."""
        if name in _BATCH_TOPICS:
            return _BATCH_TOPICS[name], self._batch(mb, name, j)
        if name == "world":
            return WORLD_TOPIC, mb.string(self.world_json)
        if name == "robot_description":
            return "/robot_description", mb.string(urdf_text())
        if name == "tf_static":
            return "/tf_static", mb.tf_message([(self.t0, st.parent, st.child, st.xyz_m, st.quat_xyzw)
                                                for st in STATIC_TRANSFORMS])
        if name == "scan":
            return "/scan", self._scan(mb, j)
        if name == "tf_map":
            return "/tf", mb.planar_tf(int(self.scan_ns[j]) + TRANSFORM_TOLERANCE_NS, "map", "odom", *self.amcl.poses[j])
        if name == "cloud":
            T_map_optical = pose2tform(self.cloud_poses[j]) @ self.T_base_optical
            points = self.camera.points(self.world, T_map_optical, self.rngs["cloud"])
            return CLOUD_TOPIC, mb.point_cloud(int(self.cloud_ns[j]), self.config.cloud_frame, points)
        if name == "camera_info":
            cam = self.camera
            return CAMERA_INFO_TOPIC, mb.camera_info(int(self.cloud_ns[j]), self.config.cloud_frame, cam.width, cam.height,
                                                     cam.K, cam.P)
        if name == "click":
            return "/clicked_point", mb.point_stamped(int(self.click_ns[j]), "map", self.click_points[j])
        raise ValueError(f"unknown stream {name!r}")

    def _scan(self, mb: MessageBuilder, j: int) -> bytes:
        T_map_scan = pose2tform(self.traj.motion.poses[self.scan_steps[j]]) @ self.T_base_scan
        yaw = float(self.traj.motion.poses[self.scan_steps[j]][2])
        x, y, z = T_map_scan[:3, 3]
        lidar = self.lidar
        ranges = lidar.scan(self.world, (x, y, z, yaw), self.rngs["scan"])
        return mb.laser_scan(int(self.scan_ns[j]), "base_scan", ranges, lidar.angle_min_rad, lidar.angle_increment_rad,
                             lidar.range_min_m, lidar.range_max_m, 1.0 / lidar.rate_hz)


_BATCH_TOPICS = {"tf_odom": "/tf", "odom": "/odom", "truth": "/ground_truth", "joints": "/joint_states",
                 "tf_wheels": "/tf", "imu": "/imu"}


def _previous_step(values: np.ndarray) -> np.ndarray:
    """Per stamp, the value over the step that ended there (0 at the first stamp)."""
    return np.concatenate(([0.0], values))


def simulate_bag(out_path: str | Path, config: SimConfig, force: bool = False) -> SimSummary:
    """Simulate ``config`` and write the rosbag2 directory ``out_path`` atomically.

    Refuses an existing ``out_path`` unless ``force`` (OutputExistsError); on any error or
    Ctrl-C nothing is left behind. Returns counts per topic, distance driven and final drift.
    """
    config.validate()
    out_path = Path(out_path)
    check_writable(out_path, force, is_rosbag2_output)  # before the work, and again at the final rename
    world = load_world(config.world)
    traj = plan_trajectory(config, world)
    sim = _BagSimulation(config, world, traj, _rngs(config.seed))
    names, kinds, indices, log_ns = sim.schedule()
    with atomic_path(out_path, force, is_rosbag2_output) as staged:
        with SimBagWriter(staged, config.ros_distro, sim.topics) as bag:
            mb = MessageBuilder(bag.typestore)
            with progress_bar(total=round(config.duration_s, 3), desc="simulate", unit="s") as bar:
                shown_s = 0.0
                for k, j, t_log in zip(kinds.tolist(), indices.tolist(), log_ns.tolist()):
                    topic, data = sim.message(mb, names[k], j)
                    bag.write(topic, t_log, data)
                    sim_s = min((t_log - config.start_time_ns) / 1e9, config.duration_s)
                    if sim_s - shown_s >= 1.0:
                        bar.update(round(sim_s - shown_s, 3))
                        shown_s = sim_s
            counts = dict(bag.counts)
        mark_own_output(staged, "simulate")  # so that --force may replace this bag, and nothing else
    return _summary(out_path, config, traj, counts)


def _summary(out_path: Path, config: SimConfig, traj: Trajectory, counts: dict[str, int]) -> SimSummary:
    motion = traj.motion
    odom_in_map = se2_compose(traj.spawn_xyyaw, traj.odometry.poses[-1])
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
