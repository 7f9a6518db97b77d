"""What ``bagtools batch`` can run on each bag: one :class:`Job` per command, in :data:`JOBS`.

A job does what the single command does, through the same library calls: it
builds the command's options from the command's own parsed parameters (the
CLI parses COMMAND OPTIONS with the command's click command, so options and
their checks are the same), refuses existing outputs before the work, runs the
pipeline and publishes the files with the command's writer, all or nothing.
It returns the command's summary; :class:`Column` picks the headline numbers
of the fleet table out of it.

Adding a command is one entry in :data:`JOBS` (its adapter is a few lines
beside the others): the options from the parameters, the run, the columns.
Heavy modules are imported inside the adapters, once per worker process.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bagtools.errors import BagtoolsError
from bagtools.outputs import OutputDir, check_outputs
from bagtools.results import run_outputs

#: What ``batch info`` writes in each bag's directory: ``bagtools info BAG --json`` output.
INFO_FILES = ["info.json"]


@dataclass(frozen=True)
class Column:
    """A headline number of the fleet table, read from a command's summary.json.

    ``path``: keys from the top of the summary. ``reduce``: 'count' for the
    length of a list, 'total' for the sum of a dict's values (e.g. scans
    skipped by reason). Absent values are None (an empty CSV cell, a Parquet null).
    """

    name: str
    path: tuple[str, ...]
    kind: str = "float"
    reduce: str | None = None

    def value(self, summary: Mapping[str, Any]) -> float | int | None:
        """This column's value in ``summary``, as ``kind``, or None."""
        node: Any = summary
        for key in self.path:
            if not isinstance(node, Mapping) or key not in node:
                return None
            node = node[key]
        if self.reduce == "count":
            node = len(node) if isinstance(node, (list, dict)) else None
        elif self.reduce == "total":
            node = sum(node.values()) if isinstance(node, Mapping) else None
        if node is None or isinstance(node, bool) or not isinstance(node, (int, float)):
            return None
        return int(node) if self.kind == "int" else float(node)


@dataclass(frozen=True)
class JobOutput:
    """What a job's run returns: the command's summary, the files it wrote, the bag's message count (if known)."""

    summary: dict
    written: list[str]
    messages: int | None = None


@dataclass(frozen=True)
class WriterConfig:
    """A job's configuration: the library's options object and whether the writer adds results.mcap (--no-mcap)."""

    options: Any
    mcap: bool = True


@dataclass(frozen=True)
class Job:
    """One command as a batch job.

    ``options(params)``: the command's parsed parameters (click's names, less
    ``bag``, ``out_dir`` and ``force``) to the job's configuration (picklable:
    it travels to the workers), built as the command builds it, so it raises
    :class:`BagtoolsError` for a bad value before any work.
    ``run(bag, out_dir, config, force)``: the command's library calls and
    writer. ``ignored``: parameters that mean nothing in a batch. ``plots``: panels of
    fleet.png, each a title and the columns it draws.
    """

    command: str
    options: Callable[[Mapping[str, Any]], Any]
    run: Callable[[str, Path, Any, bool], JobOutput]
    columns: tuple[Column, ...]
    plots: tuple[tuple[str, tuple[str, ...]], ...] = ()
    ignored: frozenset[str] = field(default_factory=frozenset)
    counts_messages: bool = False


# -- info ---------------------------------------------------------------------


def _info_options(params: Mapping[str, Any]) -> None:
    return None


def _info(bag: str, out_dir: Path, options: None, force: bool) -> JobOutput:
    from bagtools.commands.info import describe_bag

    check_outputs(out_dir, INFO_FILES, force)
    desc = describe_bag(bag)
    data = desc.to_json()
    with OutputDir(out_dir, INFO_FILES, force) as staged:
        # Byte for byte what `bagtools info BAG --json > info.json` writes.
        (staged / "info.json").write_text(json.dumps(data, indent=2) + "\n")
    return JobOutput(data, list(INFO_FILES), desc.message_count)


# -- map-cloud ----------------------------------------------------------------


def _map_cloud_options(p: Mapping[str, Any]) -> WriterConfig:
    from bagtools.commands.map_cloud import CloudMapOptions

    return WriterConfig(CloudMapOptions.from_params(p), mcap=not p["no_mcap"])


def _map_cloud(bag: str, out_dir: Path, config: WriterConfig, force: bool) -> JobOutput:
    from bagtools.commands.map_cloud import CloudMapPipeline, write_cloud_map
    from bagtools.commands.map_cloud.writer import cloud_map_outputs

    check_outputs(out_dir, cloud_map_outputs(config.mcap, config.options.refine), force)
    result = CloudMapPipeline(bag, config.options, keep_inputs=config.mcap).run()
    written = write_cloud_map(result, out_dir, force, mcap=config.mcap)
    return JobOutput(result.summary, [p.name for p in written])


# -- grid ---------------------------------------------------------------------


def _grid_options(p: Mapping[str, Any]) -> WriterConfig:
    from bagtools.commands.grid import GridMapOptions
    from bagtools.trajectory import read_tum

    if p["poses"] not in ("tf", "ground-truth"):
        read_tum(p["poses"])  # a missing or bad trajectory file is one error before any work, not one per bag

    return WriterConfig(GridMapOptions.from_params(p), mcap=not p["no_mcap"])


def _grid(bag: str, out_dir: Path, config: WriterConfig, force: bool) -> JobOutput:
    from bagtools.commands.grid import GRID_MAP_FILES, GridMapPipeline, write_grid_map

    check_outputs(out_dir, run_outputs(GRID_MAP_FILES, config.mcap), force)
    result = GridMapPipeline(bag, config.options, keep_scans=config.mcap).run()
    written = write_grid_map(result, out_dir, force, mcap=config.mcap)
    return JobOutput(result.summary, [p.name for p in written])


# -- ndt-odom -----------------------------------------------------------------


def _ndt_odom_options(p: Mapping[str, Any]) -> WriterConfig:
    from bagtools.commands.ndt_odom import NdtOdomOptions

    return WriterConfig(NdtOdomOptions.from_params(p), mcap=not p["no_mcap"])


def _ndt_odom(bag: str, out_dir: Path, config: WriterConfig, force: bool) -> JobOutput:
    from bagtools.commands.ndt_odom import NDT_ODOM_FILES, NdtOdomPipeline, write_ndt_odom

    check_outputs(out_dir, run_outputs(NDT_ODOM_FILES, config.mcap), force)
    result = NdtOdomPipeline(bag, config.options, keep_scans=config.mcap).run()
    if result.problem is not None:  # as the command: a failed run changes nothing in its directory
        raise BagtoolsError(result.problem, bag)
    written = write_ndt_odom(result, out_dir, force, mcap=config.mcap)
    return JobOutput(result.summary, [p.name for p in written])


# -- slam ---------------------------------------------------------------------


def _slam_options(p: Mapping[str, Any]) -> WriterConfig:
    from bagtools.commands.slam import SlamOptions
    from bagtools.trajectory import read_relations

    if p["relations"]:
        read_relations(p["relations"])  # a missing or bad relations file is one error before any work

    return WriterConfig(SlamOptions.from_params(p), mcap=not p["no_mcap"])


def _slam(bag: str, out_dir: Path, config: WriterConfig, force: bool) -> JobOutput:
    from bagtools.commands.slam import SLAM_FILES, SlamPipeline, write_slam

    check_outputs(out_dir, run_outputs(SLAM_FILES, config.mcap), force)
    result = SlamPipeline(bag, config.options).run()
    written = write_slam(result, out_dir, force, mcap=config.mcap)
    return JobOutput(result.summary, [p.name for p in written])


# -- localize -----------------------------------------------------------------


def _localize_options(p: Mapping[str, Any]) -> WriterConfig:
    from bagtools.grid import read_nav2_map
    from bagtools.commands.localize import LocalizeOptions

    read_nav2_map(p["map_yaml"])  # a missing or bad map is one error before any work
    return WriterConfig((str(p["map_yaml"]), LocalizeOptions.from_params(p)), mcap=not p["no_mcap"])


def _localize(bag: str, out_dir: Path, config: WriterConfig, force: bool) -> JobOutput:
    from bagtools.commands.localize import LOCALIZE_FILES, LocalizePipeline, write_localize

    check_outputs(out_dir, run_outputs(LOCALIZE_FILES, config.mcap), force)
    map_yaml, options = config.options
    result = LocalizePipeline(bag, map_yaml, options, keep_scans=config.mcap).run()
    written = write_localize(result, out_dir, force, mcap=config.mcap)
    return JobOutput(result.summary, [p.name for p in written])


_WARN = Column("warnings", ("warnings",), "int", "count")

#: command name -> its job. A command is batchable when it is here and in ``bagtools.cli.COMMANDS``.
JOBS: dict[str, Job] = {
    "info": Job(
        "info", _info_options, _info,
        (Column("bag_duration_s", ("duration_s",)), Column("topics", ("topics",), "int", "count"),
         Column("tf_frames", ("tf_frames",), "int", "count"), _WARN),
        plots=(("messages", ("messages",)), ("bag duration [s]", ("bag_duration_s",))),
        ignored=frozenset({"as_json"}), counts_messages=True),
    "map-cloud": Job(
        "map-cloud", _map_cloud_options, _map_cloud,
        (Column("clouds_used", ("clouds_used",), "int"), Column("clouds_skipped", ("clouds_skipped",), "int", "total"),
         Column("points_out", ("points_out",), "int"), Column("dist_mean_m", ("accuracy_vs_truth_m", "mean")),
         Column("dist_median_m", ("accuracy_vs_truth_m", "median")), Column("dist_p95_m", ("accuracy_vs_truth_m", "p95")),
         _WARN),
        plots=(("points in the map", ("points_out",)),
               ("distance to the true surfaces [m]", ("dist_mean_m", "dist_p95_m")))),
    "grid": Job(
        "grid", _grid_options, _grid,
        (Column("scans_used", ("scans_used",), "int"), Column("scans_skipped", ("scans_skipped",), "int", "total"),
         Column("occupied_cells", ("grid", "occupied_cells"), "int"),
         Column("precision", ("accuracy_vs_truth", "occupied_precision")),
         Column("recall", ("accuracy_vs_truth", "occupied_recall")),
         Column("free_share", ("accuracy_vs_truth", "free_share")), _WARN),
        plots=(("occupied cells vs the true world", ("precision", "recall")), ("scans mapped", ("scans_used",)))),
    "ndt-odom": Job(
        "ndt-odom", _ndt_odom_options, _ndt_odom,
        (Column("scans_used", ("scans_used",), "int"), Column("pairs_matched", ("pairs_matched",), "int"),
         Column("searched", ("searched",), "int"), Column("fallbacks", ("fallbacks",), "int"),
         Column("odometry_rejected", ("odometry_rejected",), "int"),
         Column("ape_ndt_m", ("errors_ndt", "ape_translation_m", "rmse")),
         Column("rpe_ndt_m_per_m", ("errors_ndt", "rpe_translation_m_per_1m", "rmse")),
         Column("ape_odometry_m", ("errors_odometry", "ape_translation_m", "rmse")),
         Column("rpe_odometry_m_per_m", ("errors_odometry", "rpe_translation_m_per_1m", "rmse")), _WARN),
        plots=(("APE rmse [m]", ("ape_ndt_m", "ape_odometry_m")),
               ("pairs", ("searched", "fallbacks", "odometry_rejected")))),
    "slam": Job(
        "slam", _slam_options, _slam,
        (Column("scans", ("scans",), "int"), Column("keyframes", ("keyframes",), "int"),
         Column("loops_accepted", ("loop_closure", "accepted"), "int"),
         Column("loops_rejected", ("loop_closure", "rejected"), "int"),
         Column("ape_slam_m", ("errors_slam", "ape_aligned_m", "rmse")),
         Column("ape_front_end_m", ("errors_front_end", "ape_aligned_m", "rmse")),
         Column("gap20_slam_m", ("errors_slam", "relative_gap_20", "trans_mean_m")),
         Column("optimize_s", ("optimization", "time_s")), _WARN),
        plots=(("APE after alignment [m]", ("ape_slam_m", "ape_front_end_m")),
               ("loop closures", ("loops_accepted", "loops_rejected")))),
    "localize": Job(
        "localize", _localize_options, _localize,
        (Column("scans", ("scans",), "int"), Column("scans_localized", ("scans_localized",), "int"),
         Column("first_fix_s", ("first_fix", "seconds_after_first_scan")), Column("lost", ("lost",), "int"),
         Column("recovered", ("recovered",), "int"), Column("corrected", ("corrected",), "int"),
         Column("unmapped", ("scans_by_state", "unmapped"), "int"), Column("score_mean", ("score", "mean")),
         Column("vs_bag_localizer_m", ("bag_localizer", "translation_m", "mean")),
         Column("ape_m", ("ground_truth", "ours", "ape_m", "rmse")),
         Column("ape_bag_localizer_m", ("ground_truth", "bag_localizer", "ape_m", "rmse")), _WARN),
        plots=(("scans", ("scans", "scans_localized")), ("lost and recovered", ("lost", "recovered")),
               ("APE against the ground truth [m]", ("ape_m", "ape_bag_localizer_m")))),
}


def get_job(command: str, available: set[str] | None = None) -> Job:
    """The job of ``command``; BagtoolsError naming the batchable commands if there is none."""
    names = sorted(JOBS if available is None else set(JOBS) & available)
    if command not in names:
        raise BagtoolsError(f"'{command}' is not a command batch can run (choose from {', '.join(names)})")
    return JOBS[command]
