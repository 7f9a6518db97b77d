"""Laser odometry: the front end that slam, ndt-odom and localize share.

``LaserOdometry`` registers scans in order (:mod:`bagtools.odometry.frontend`, its settings in
:mod:`bagtools.odometry.options`), each step one objective: the scan's fit less the motion prior's cost
(:mod:`bagtools.odometry.prior`); what it hands on is a
``FrontEndRun`` of ``ScanStep`` (:mod:`bagtools.odometry.steps`). The motion model it predicts each step with,
which the localizer shares, is :mod:`bagtools.odometry.motion`.
"""

from bagtools.odometry.frontend import LaserOdometry
from bagtools.odometry.options import FrontEndOptions, cell_size_for, normalized_score
from bagtools.odometry.steps import FrontEndRun, ScanStep

__all__ = ["FrontEndOptions", "FrontEndRun", "LaserOdometry", "ScanStep", "cell_size_for", "normalized_score"]
