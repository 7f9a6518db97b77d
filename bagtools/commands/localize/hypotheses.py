"""What the map localizer (:mod:`bagtools.commands.localize.tracker`) keeps: its hypotheses of where the robot is
(:class:`Hypothesis`), a scan matched on the map (:class:`Fit`), what it did (:class:`Event`), the recent scores
that say what is typical (:class:`RecentScores`) and where an unbroken motion bounds the robot (:class:`Bound`).
Poses are [x, y, theta] of the base in the map frame."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from bagtools.commands.localize.settings import BOUND_SIGMAS
from bagtools.odometry.motion import ODOM_NOISE_RATIO
from bagtools.transforms import se2_between


@dataclass
class Hypothesis:
    """One place the robot may be: its pose now, the poses and scores of the scans it matched, its misses."""

    pose: np.ndarray
    since: int  # the scan it was born at
    poses: dict[int, np.ndarray] = field(default_factory=dict)
    matched: set[int] = field(default_factory=set)  # the scans it matched well on the map
    scores: list[float] = field(default_factory=list)
    evidence: list[float] = field(default_factory=list)  # score x share of beams not through walls, per scan
    misses: int = 0
    anchor: tuple[np.ndarray, np.ndarray] | None = None  # (map pose, odometry pose) at its last good match
    recent: deque = field(default_factory=lambda: deque(maxlen=50))  # (stamp_ns, map pose) of its good matches
    stamp_ns: int = 0
    continued: bool = False  # where the robot was before it was lost, moved by the motion since
    unbroken: bool = False  # the odometry since its last good match was continuous throughout
    loose_m: float = 0.0  # path (m) from its last match that fixed the position in every direction to its anchor
    loose_dir: np.ndarray | None = None  # the direction (map frame) the matches since did not fix
    coasting: int = 0  # scans in a row carried by the motion (off the map, or a map lacking what it sees)
    searched_at: np.ndarray | None = None  # odometry pose of its last search that found nothing, while carried


class Fit(NamedTuple):
    """A scan matched on the map: base pose [x, y, theta], raster score, and the direction (unit (2,), map frame)
    along which the map does not fix the position there (a bare corridor's), None where it fixes it in every one."""

    pose: np.ndarray
    score: float
    loose: np.ndarray | None


@dataclass
class Event:
    """Something the localizer did: ``kind`` 'fix' (committed), 'lost', 'recovered' or 'corrected' (the map moved
    the pose by more than WINDOW where the motion was known to be unbroken), at scan ``index`` (stamp ``stamp_ns``)
    and map pose ``pose`` (the last good pose for 'lost')."""

    kind: str
    index: int
    stamp_ns: int
    pose: np.ndarray


class RecentScores:
    """The last ``n`` scores of well matched scans and their median (0.0 for none), kept until the next score:
    the tracker asks for it several times a scan."""

    def __init__(self, n: int) -> None:
        self.values: deque[float] = deque(maxlen=n)
        self._median: float | None = None

    def append(self, score: float) -> None:
        self.values.append(score)
        self._median = None

    def extend(self, scores: list[float]) -> None:
        self.values.extend(scores)
        self._median = None

    def median(self) -> float:
        if self._median is None:
            self._median = float(np.median(self.values)) if self.values else 0.0
        return self._median


class Bound(NamedTuple):
    """Where a robot whose motion went on unbroken since its last good match can be: within BOUND_SIGMAS of the
    ``prior`` [x, y, theta] with standard deviations ``sd`` (3,), widened along ``loose_dir`` (unit, map frame: a
    corridor the matches since did not fix the position along) by ODOM_NOISE_RATIO of the ``loose_m`` travelled."""

    prior: np.ndarray
    sd: np.ndarray
    loose_m: float
    loose_dir: np.ndarray | None

    def covariance(self) -> np.ndarray:
        """(2, 2) of the position, map frame (m^2)."""
        P = self.sd[0] ** 2 * np.eye(2)
        if self.loose_dir is not None:
            P = P + (ODOM_NOISE_RATIO * self.loose_m) ** 2 * np.outer(self.loose_dir, self.loose_dir)
        return P

    def holds(self, pose: np.ndarray) -> bool:
        """Is ``pose`` [x, y, theta] within the bound?"""
        d = np.asarray(pose[:2], dtype=np.float64) - self.prior[:2]
        turn = abs(se2_between(self.prior, pose)[2])
        return bool(d @ np.linalg.solve(self.covariance(), d) <= BOUND_SIGMAS**2 and turn <= BOUND_SIGMAS * self.sd[2])

    def reach(self) -> np.ndarray:
        """The search window (x, y, theta half-widths, the prior's frame) that covers the bound."""
        extent = BOUND_SIGMAS * math.sqrt(float(np.linalg.eigvalsh(self.covariance())[1]))
        return np.array([extent, extent, BOUND_SIGMAS * self.sd[2]])
