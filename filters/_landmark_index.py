"""Candidate landmarks for nearest-neighbour association from a k-d tree over the map, built once.

The Gaussian filters associate a (range, bearing) sighting with the map landmark of smallest squared
Mahalanobis distance d2 = nu^T S^-1 nu, S = H P H^T + R, among those inside the chi-square gate d2 <= g.
Testing every landmark costs time linear in the map's size. This module bounds, from P, R and g alone,
how far from the sighted point a landmark inside the gate can lie, so only the landmarks of the k-d tree
within that distance need the exact test; the winner is the same (the exact test is unchanged, and the
candidates come in row order, so ties fall to the same row).

The bound. For a landmark at predicted range d and bearing pb from the pose estimate, with nu = (vr, vb):
d2 <= g implies vr^2 <= g S_00 and vb^2 <= g S_11. The range row of H is a unit vector in (x, y), so
S_00 <= p_xx + p_yy + sigma_r^2; the bearing row is (dy / d^2, -dx / d^2, -1), of squared norm
1 + 1 / d^2, so S_11 <= tr(P) (1 + 1 / d^2) + sigma_b^2. The landmark lies at most |vr| + d |vb| from the
point at range r and bearing b (a radial step and an arc; |vb| <= pi as it is wrapped), with d <= r + |vr|.
The bearing bound grows without limit as d -> 0, so landmarks within ``near_m`` of the pose are always
candidates, and the others use the bound with d = near_m.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

FloatArray = npt.NDArray[np.float64]

#: Maps with at least this many landmarks take their candidates from the index; below it the filters test
#: every landmark (faster there than a query of the tree).
INDEX_MIN_LANDMARKS = 48
#: Landmarks within this distance of the pose estimate (m) are always candidates (module docstring).
NEAR_M = 1.0
#: Relative and absolute slack (m) on the search radii, far above the rounding of the bound's arithmetic.
_SLACK_REL = 1e-9
_SLACK_ABS = 1e-9


def gate_radius(
    r: float, p: list[list[float]], var_range: float, var_bearing: float, gate: float, near_m: float = NEAR_M
) -> float:
    """The largest distance (m) from the sighted point at which a landmark farther than ``near_m`` from the
    pose can pass the gate ``gate`` (module docstring); ``p`` the (3, 3) pose covariance as nested lists."""
    tr_xy = p[0][0] + p[1][1]
    vr_max = math.sqrt(gate * (tr_xy + var_range))
    vb_max = min(math.pi, math.sqrt(gate * ((tr_xy + p[2][2]) * (1.0 + 1.0 / (near_m * near_m)) + var_bearing)))
    return vr_max + (r + vr_max) * vb_max


class LandmarkIndex:
    """A k-d tree over the map's landmark positions (M, 2), m, world frame, built once per reset."""

    def __init__(self, xy: FloatArray) -> None:
        self._tree = cKDTree(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        self.size = int(self._tree.n)

    def candidates(
        self,
        pose: tuple[float, float, float] | list[float],
        r: float,
        b: float,
        radius_m: float,
        near_m: float = NEAR_M,
    ) -> list[int]:
        """Rows, ascending, of the landmarks within ``radius_m`` of the point at range ``r`` (m) and bearing
        ``b`` (rad, robot frame) from ``pose`` (x, y, theta), or within ``near_m`` of the pose itself."""
        x, y, th = pose[0], pose[1], pose[2]
        px, py = x + r * math.cos(th + b), y + r * math.sin(th + b)
        far = self._tree.query_ball_point((px, py), radius_m * (1.0 + _SLACK_REL) + _SLACK_ABS)
        near = self._tree.query_ball_point((x, y), near_m * (1.0 + _SLACK_REL) + _SLACK_ABS)
        return sorted(set(far).union(near))
