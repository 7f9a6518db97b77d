"""``bagtools eval``: a trajectory's errors against a reference trajectory or a log's relations."""

from __future__ import annotations

import json

import click

_STATS = ("max", "mean", "median", "min", "rmse", "sse", "std")


def _stats_block(title: str, stats: dict) -> list[str]:
    if "unavailable" in stats:
        return [f"{title}: {stats['unavailable']}"]
    return [title, *(f"{name:>10}  {stats[name]:.6f}" for name in _STATS), f"{'pairs':>10}  {stats['count']}"]


@click.command("eval")
@click.argument("estimate", type=click.Path(path_type=str))
@click.argument("reference", required=False, type=click.Path(path_type=str))
@click.option("--align", is_flag=True, help="Also the APE after the best SE(2) alignment (evo_ape --align).")
@click.option("--gap", type=click.IntRange(min=1), default=1, show_default=True,
              help="Poses apart for the relative error (1: scan to scan; 20: the drift over 20 scans).")
@click.option("--relations", type=click.Path(path_type=str), default=None,
              help="Score the estimate against this .relations file (Kuemmerle et al. 2009) at exact stamps.")
@click.option("--t-max-diff", "t_max_diff", type=click.FloatRange(min=0, min_open=True, max=3600), default=None,
              help="Largest difference of stamps (s) at which two poses pair, as evo's --t_max_diff  [default: 0.01 "
                   "for trajectories, 1e-4 for relations]")
@click.option("--json", "as_json", is_flag=True, help="Print the results as one JSON object.")
def evaluate(estimate: str, reference: str | None, align: bool, gap: int, relations: str | None,
             t_max_diff: float | None, as_json: bool) -> None:
    """Errors of the TUM trajectory ESTIMATE against the TUM trajectory REFERENCE (and/or --relations).

    As evo computes them (equal to evo's numbers): the APE of the translation
    (no alignment, `evo_ape tum REFERENCE ESTIMATE`), with --align also after
    the best planar rigid alignment, and the RPE per metre of path
    (`evo_rpe ... --delta 1 --delta_unit m`); then the error of the motion over
    --gap poses (mean, median, max, mean rotation, how many over 0.2 m). Poses
    are paired by nearest stamp within 0.01 s. With --relations, the relations
    metric of the classic benchmarks (mean +- std of the translation and
    rotation errors), each relation at the estimate's poses at its very stamps.
    When no pose pairs at all (trajectories of other clocks, relations of
    another log), nothing is scored: one line says so with the nearest stamps'
    offset, and the exit status is 2.

    \b
    Example:
      bagtools eval out/slam/trajectory.tum out/slam/ground_truth.tum --align --gap 20
      bagtools eval out/intel/trajectory.tum --relations intel.relations
      bagtools eval ndt/trajectory.tum ndt/ground_truth.tum --json
    """
    from bagtools.errors import BagtoolsError
    from bagtools.trajectory.evaluate import evaluate as evaluate_trajectory
    from bagtools.trajectory import read_relations, read_tum

    if reference is None and relations is None:
        raise click.UsageError("give a REFERENCE trajectory, --relations FILE, or both")
    est = read_tum(estimate)
    if len(est) == 0:
        raise BagtoolsError("holds no pose", estimate)
    ref = read_tum(reference) if reference is not None else None
    rel = read_relations(relations) if relations is not None else None
    max_diff_ns = None if t_max_diff is None else int(round(t_max_diff * 1e9))
    result = evaluate_trajectory(est, ref, rel, gap=gap, align=align, max_diff_ns=max_diff_ns)
    for name, file in (("ape_translation_m", reference), ("relations", relations)):  # nothing paired: nothing scored
        if "unavailable" in result.get(name, {}) and not result[name].get("used"):
            raise BagtoolsError(result[name]["unavailable"], file)
    if as_json:
        click.echo(json.dumps(result))
        return
    lines: list[str] = []
    if ref is not None:
        lines += _stats_block("APE w.r.t. translation part (m), no alignment", result["ape_translation_m"])
        if align:
            lines += _stats_block("APE w.r.t. translation part (m), after SE(2) alignment", result["ape_aligned_m"])
        lines += _stats_block("RPE w.r.t. translation part (m) for delta = 1 (m)", result["rpe_translation_m_per_1m"])
        g = result[f"relative_gap_{gap}"]
        if "unavailable" in g:
            lines.append(f"error over {gap} pose(s): {g['unavailable']}")
        else:
            lines.append(f"error over {gap} pose(s): mean {g['trans_mean_m']:.4f} m, median {g['trans_median_m']:.4f} m, "
                         f"max {g['trans_max_m']:.4f} m, rotation {g['rot_mean_deg']:.3f} deg (mean); "
                         f"{g['over_0_2_m']} of {g['pairs']} over 0.2 m")
    if rel is not None:
        scored = result["relations"]
        if "trans_mean_m" not in scored:
            lines.append(f"relations: {scored['unavailable']}")
        else:
            lines.append(f"relations error {scored['trans_mean_m']:.4f} +- {scored['trans_std_m']:.4f} m "
                         f"(max {scored['trans_max_m']:.3f}), {scored['rot_mean_deg']:.2f} +- "
                         f"{scored['rot_std_deg']:.2f} deg over {scored['used']} of {scored['relations']} relations"
                         + (f" ({scored['missing']} without a pose at both stamps)" if scored["missing"] else ""))
    click.echo("\n".join(lines))
