"""``bagtools simulate``: write a realistic TurtleBot3 bag in the TurtleBot3 world."""

from __future__ import annotations

import click


@click.command("simulate")
@click.argument("out", type=click.Path(path_type=str))
@click.option("--duration", type=float, default=60.0, show_default=True, help="Simulated seconds.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of every random draw (noise, random route).")
@click.option("--route", type=click.Choice(["lap", "figure8", "random"]), default="lap", show_default=True,
              help="Lap around the pillars, figure eight, or a seeded random tour.")
@click.option("--odom-noise", type=click.Choice(["none", "realistic", "high"]), default="realistic", show_default=True,
              help="Wheel odometry errors (calibration and slip).")
@click.option("--max-linear", type=float, default=0.26, show_default=True, help="Speed limit [m/s], at most 0.26.")
@click.option("--max-angular", type=float, default=1.82, show_default=True, help="Turn rate limit [rad/s], at most 1.82.")
@click.option("--cloud-rate", type=float, default=2.0, show_default=True, help="Depth cloud rate [Hz].")
@click.option("--cloud-size", default="160x120", show_default=True, help="Depth image size WIDTHxHEIGHT.")
@click.option("--no-cloud", is_flag=True, help="Do not simulate the depth camera.")
@click.option("--cloud-frame", type=click.Choice(["camera_rgb_optical_frame", "camera_depth_optical_frame"]),
              default="camera_rgb_optical_frame", show_default=True,
              help="Frame of the depth cloud (the Waffle's Gazebo plugin, and the lab, use camera_rgb_optical_frame).")
@click.option("--ros-distro", type=click.Choice(["humble", "jazzy"]), default="humble", show_default=True,
              help="Write the bag as this distro's rosbag2 does. humble: metadata version 5, which Humble and "
                   "Jazzy both read; jazzy: version 9 as Jazzy writes it, which Humble cannot open.")
@click.option("--world", default="turtlebot3_world", show_default=True, help="Packaged world name or a world JSON file.")
@click.option("--force", is_flag=True, help="Overwrite OUT if it exists.")
def simulate(out: str, duration: float, seed: int, route: str, odom_noise: str, max_linear: float, max_angular: float,
             cloud_rate: float, cloud_size: str, no_cloud: bool, cloud_frame: str, ros_distro: str, world: str,
             force: bool) -> None:
    """Simulate a TurtleBot3 Waffle and write the rosbag2 (MCAP) directory OUT.

    Topics: /tf, /tf_static, /robot_description, /joint_states, /odom, /imu, /scan,
    /camera/depth/points, /camera/depth/camera_info, /ground_truth, /clicked_point and
    /simulation/world (the world and settings, for scoring). The tf tree is the one a real
    Waffle's robot_state_publisher gives (ROBOTIS' URDF).

    The default bag (--ros-distro humble) opens in Humble and in Jazzy; use --ros-distro
    jazzy for the metadata Jazzy writes (Humble's rosbag2 rejects it).

    \b
    Example:
      bagtools simulate out/sim --duration 120 --route figure8 --odom-noise high
      bagtools simulate out/sim_jazzy --ros-distro jazzy --no-cloud --force
    """
    from bagtools_simulate.pipeline import SimConfig, parse_cloud_size, simulate_bag

    config = SimConfig(duration_s=duration, seed=seed, route=route, odom_noise=odom_noise, max_linear_mps=max_linear,
                       max_angular_radps=max_angular, cloud=not no_cloud, cloud_rate_hz=cloud_rate,
                       cloud_size=parse_cloud_size(cloud_size), cloud_frame=cloud_frame, ros_distro=ros_distro,
                       world=world)
    summary = simulate_bag(out, config, force)
    click.echo("\n".join(summary.lines()))
