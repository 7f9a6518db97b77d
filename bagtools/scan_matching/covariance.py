"""What a scan match's precision says of its pose: one covariance floor and one inverse for the odometry's steps and
the loop closures alike.

Covariances are (3,3) over [x, y, theta] (m^2, m rad, rad^2); informations (inverse covariances) likewise.
"""

from __future__ import annotations

import numpy as np

#: Added to the covariance of every scan match (m^2, m^2, rad^2): 1 cm and 0.3 degrees. The points of a scan are
#: not independent (the beams of one wall move together), so the precision summed over them says too much.
COVARIANCE_FLOOR = np.diag([1e-4, 1e-4, 3e-5])


def information_inverse(information: np.ndarray) -> np.ndarray:
    """The covariance (3,3) of a symmetric ``information`` (3,3), inverted on its positive eigenvalues: a direction
    with no information (eigenvalue at most 1e-6, as along a corridor) gets a variance of 1e2."""
    values, vectors = np.linalg.eigh(information)
    inverse = np.where(values > 1e-6, 1.0 / np.maximum(values, 1e-6), 1e2)
    return (vectors * inverse) @ vectors.T


__all__ = ["COVARIANCE_FLOOR", "information_inverse"]
