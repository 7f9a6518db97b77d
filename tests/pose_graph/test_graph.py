"""The GTSAM pose graph: optimization closes a loop, the outlier check finds a wrong loop, g2o round trip."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from bagtools.pose_graph.graph import LOOP, ODOMETRY, Constraint, PoseGraph, check_covariance
from bagtools.transforms import se2_between, se2_compose

ODOM_COV = np.diag([0.02**2, 0.02**2, 0.01**2])
LOOP_COV = np.diag([0.03**2, 0.03**2, 0.01**2])


def _square(n_side: int = 10, step_m: float = 1.0) -> np.ndarray:
    """True poses (4 n_side + 1, 3) around a square, back at the start."""
    motions = []
    for _ in range(4):
        motions += [np.array([step_m, 0.0, 0.0])] * (n_side - 1) + [np.array([step_m, 0.0, np.pi / 2])]
    poses = [np.zeros(3)]
    for m in motions:
        poses.append(se2_compose(poses[-1], m))
    return np.array(poses)


def _drifting_graph(truth: np.ndarray, kernel: str = "huber", seed: int = 0) -> PoseGraph:
    """The chain of ``truth`` with noisy odometry (a heading bias: the end misses the start)."""
    rng = np.random.default_rng(seed)
    graph = PoseGraph(truth[0], loop_kernel=kernel)
    for k in range(1, len(truth)):
        m = se2_between(truth[k - 1], truth[k]) + np.r_[rng.normal(0, 0.02, 2), 0.01 + rng.normal(0, 0.005)]
        graph.add_node(se2_compose(graph.poses[k - 1], m))
        graph.add(Constraint(k - 1, k, m, ODOM_COV, ODOMETRY))
    return graph


def _position_error(graph: PoseGraph, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((graph.poses[:, :2] - truth[:, :2]) ** 2, axis=1))))


@pytest.mark.parametrize("kernel", ["huber", "cauchy", "none"])
def test_loop_closure_removes_most_of_the_drift(kernel: str) -> None:
    truth = _square()
    graph = _drifting_graph(truth, kernel)
    before = _position_error(graph, truth)
    n = len(truth) - 1
    for a, b in ((0, n), (1, n - 1), (2, 30)):  # the end sees the start, and a cross check mid-way
        graph.add(Constraint(a, b, se2_between(truth[a], truth[b]), LOOP_COV, LOOP))
    result = graph.optimize()
    after = _position_error(graph, truth)
    assert before > 0.8 and after < 0.25 * before, (before, after)
    assert result.final_error < result.initial_error and result.iterations >= 1 and result.time_s > 0
    assert np.allclose(graph.poses[0], truth[0], atol=1e-3)  # the prior holds the first node
    loops, chi2 = graph.loop_chi2()
    assert len(loops) == 3 and (chi2 < 16.27).all()


def test_wrong_loop_stands_out_by_chi2_and_its_removal_restores_the_result() -> None:
    truth = _square()
    n = len(truth) - 1
    graph = _drifting_graph(truth)
    graph.add(Constraint(0, n, se2_between(truth[0], truth[n]), LOOP_COV, LOOP))
    graph.add(Constraint(5, 25, se2_between(truth[5], truth[25]), LOOP_COV, LOOP))
    wrong = graph.add(Constraint(10, 30, np.array([2.0, 1.5, 0.3]), LOOP_COV, LOOP))  # a corridor look-alike
    graph.optimize()
    loops, chi2 = graph.loop_chi2()
    assert loops[int(np.argmax(chi2))] == wrong and chi2.max() > 100
    graph.remove([wrong])
    graph.optimize()
    assert _position_error(graph, truth) < 0.15
    assert graph.loop_chi2()[1].max() < 16.27


def test_the_graph_judges_doubtful_loops_by_graduated_non_convexity() -> None:
    """Loops handed to the graph unconfirmed: GNC keeps the ones the accepted constraints agree with (a right loop
    across the square, another later) and drops a look-alike 2 m off, and the estimate is left as it was."""
    truth = _square()
    n = len(truth) - 1
    graph = _drifting_graph(truth)
    graph.add(Constraint(0, n, se2_between(truth[0], truth[n]), LOOP_COV, LOOP))
    graph.optimize()
    before = graph.poses.copy()
    doubtful = [Constraint(5, 25, se2_between(truth[5], truth[25]), LOOP_COV, LOOP),
                Constraint(10, 30, np.array([2.0, 1.5, 0.3]), LOOP_COV, LOOP),
                Constraint(12, 38, se2_between(truth[12], truth[38]), LOOP_COV, LOOP)]
    assert graph.judge(doubtful, 16.27).tolist() == [True, False, True]
    assert np.array_equal(graph.poses, before) and len(graph.constraints) == n + 1
    assert graph.judge([], 16.27).shape == (0,)


def test_g2o_text_reads_back_with_gtsam(tmp_path) -> None:
    truth = _square(n_side=3)
    graph = _drifting_graph(truth)
    cov = np.array([[0.001, 0.0002, 0.0], [0.0002, 0.002, 0.0001], [0.0, 0.0001, 0.0005]])
    graph.add(Constraint(0, len(truth) - 1, np.array([0.01, -0.02, 0.03]), cov, LOOP))
    graph.optimize()
    text = graph.g2o_text()
    lines = text.strip().splitlines()
    assert sum(line.startswith("VERTEX_SE2 ") for line in lines) == graph.n_nodes
    assert sum(line.startswith("EDGE_SE2 ") for line in lines) == len(graph.constraints)
    path = tmp_path / "graph.g2o"
    path.write_text(text)
    factors, values = gtsam.readG2o(str(path), False)
    assert values.size() == graph.n_nodes and factors.size() == len(graph.constraints)
    assert lines[-1] == "FIX 0"  # the first vertex fixed, as g2o expects
    for k in range(graph.n_nodes):
        p = values.atPose2(k)
        assert np.allclose([p.x(), p.y(), p.theta()], graph.poses[k], rtol=0, atol=1e-12)  # full precision
    loop = factors.at(factors.size() - 1)
    assert np.allclose(loop.measured().translation(), [0.01, -0.02], atol=1e-6)
    information = loop.noiseModel().R().T @ loop.noiseModel().R()
    assert np.allclose(information, np.linalg.inv(cov), rtol=1e-9)


def test_g2o_text_keeps_far_coordinates_exact() -> None:
    """Coordinates near 576 m (the CSAIL log's) keep every digit: 6 significant digits would be a millimetre."""
    graph = PoseGraph(np.array([576.123456789, -312.987654321, 1.23456789]))
    graph.add_node(np.array([577.000000001, -312.5, 1.3]))
    graph.add(Constraint(0, 1, np.array([0.876543211, 0.1, 0.06543211]), np.diag([1e-4, 1e-4, 1e-5]), ODOMETRY))
    vertex = graph.g2o_text().splitlines()[0].split()
    assert [float(v) for v in vertex[2:]] == [576.123456789, -312.987654321, 1.23456789]


def test_bad_constraints_are_refused() -> None:
    graph = PoseGraph(np.zeros(3))
    graph.add_node(np.array([1.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="positive definite"):
        graph.add(Constraint(0, 1, np.array([1.0, 0, 0]), np.diag([1.0, -1.0, 1.0]), ODOMETRY))
    with pytest.raises(ValueError, match="finite"):
        graph.add(Constraint(0, 1, np.array([np.nan, 0, 0]), ODOM_COV, ODOMETRY))
    with pytest.raises(ValueError, match="between nodes"):
        graph.add(Constraint(0, 2, np.array([1.0, 0, 0]), ODOM_COV, ODOMETRY))
    with pytest.raises(ValueError, match="kind"):
        graph.add(Constraint(0, 1, np.array([1.0, 0, 0]), ODOM_COV, "gps"))
    with pytest.raises(ValueError, match="loop_kernel"):
        PoseGraph(np.zeros(3), loop_kernel="tukey")
    assert np.allclose(check_covariance([[1, 0.5, 0], [0.3, 1, 0], [0, 0, 1]], "x"), [[1, 0.4, 0], [0.4, 1, 0], [0, 0, 1]])
