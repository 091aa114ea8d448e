"""The verdict on a candidate pose: its rank, the residual test and whether its touches could happen.

A candidate passes when its residual passes a chi-square test and its touches
are admissible: inside their features' finite patches, touched from outside
when the probe's approach is known.

This module imports numpy only and nothing of fixturecad: it is
inlined into the generated standalone ``register.py``.
"""

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from .mobility import matrix_rank
from .pose import fixture2meas_from_rt, point_covariances, rotation_angle

CHI2_CONFIDENCE = 0.999  # residual test: a correct pose passes 999 times in 1000
EXTENT_TOLERANCE_MM = 0.2  # how far outside a feature's patch a touch may be judged to lie
EXTENT_SIGMAS = 3.0  # ... plus this many standard deviations of the touch's position under the pose ...
EXTENT_WIDENING_MAX_MM = 1.0  # ... but never more than this: a pose known worse is not judged on its patches
SAME_POSE_ROTATION_RAD = 1e-4
SAME_POSE_TRANSLATION_MM = 1e-3


def same_as_which(pose, others):
    """The index of the first of ``others`` [(R, t)] that a pose (R, t) is, or None: turned less than
    ``SAME_POSE_ROTATION_RAD`` and moved less than ``SAME_POSE_TRANSLATION_MM`` from it (all compared at once)."""
    if not len(others):
        return None
    rotations, translations = (np.array(x) for x in zip(*others))
    same = np.flatnonzero((rotation_angle(pose[0] @ rotations.transpose(0, 2, 1)) < SAME_POSE_ROTATION_RAD)
                          & (np.linalg.norm(translations - pose[1], axis=1) < SAME_POSE_TRANSLATION_MM))
    return int(same[0]) if len(same) else None


def same_as_any(pose, others):
    """Whether a pose (R, t) is one of ``others`` [(R, t)] (:func:`same_as_which`)."""
    return same_as_which(pose, others) is not None


def distinct(solutions):
    """The solutions with repeats of one pose left out, the first of each kept."""
    out = []
    for s in solutions:
        if not same_as_any((s.rotation, s.translation), [(o.rotation, o.translation) for o in out]):
            out.append(s)
    return out


@dataclass
class Solution:
    rotation: np.ndarray
    translation: np.ndarray
    residuals: np.ndarray
    jacobian: np.ndarray
    rank: int = 6
    passes: bool = True
    admissible: bool = True
    outside: list = field(default_factory=list)
    spread_mm: float = 0.0  # the largest of the touches' spreads (:func:`touch_spreads`)
    wide: bool = False  # from a region of poses that may pass reaching farther than the patches' widening
    assignment: object = None  # each unlabelled touch's feature id under this pose (:mod:`.unlabelled`) ...
    problem: object = None  # ... and the labelled problem it gives; None where a pose was refitted without them

    @property
    def good(self):
        """A pose the verdict counts: it passes the residual test, its touches on their patches, at rank 6."""
        return self.passes and self.admissible and self.rank == 6

    @property
    def weak(self):
        """Determined, but too poorly to judge its touches on their patches."""
        return self.rank == 6 and self.spread_mm > EXTENT_WIDENING_MAX_MM

    @property
    def fixture2meas(self):
        return fixture2meas_from_rt(self.rotation, self.translation)

    @property
    def cost(self):
        return float(self.residuals @ self.residuals)

    @property
    def rms(self):
        return float(np.sqrt(np.mean(self.residuals**2))) if len(self.residuals) else 0.0


def chi_square_tail(x, dof):
    """P(X > x) for X chi-square with an integer ``dof``: the closed forms of the integer cases
    (a Poisson sum for even dof, with erfc for odd), summed in logs so large dof do not overflow."""
    half = 0.5 * x
    if half <= 0.0:
        return 1.0
    if dof % 2 == 0:
        terms = [j * math.log(half) - math.lgamma(j + 1.0) for j in range(dof // 2)]
        tail = 0.0
    else:
        terms = [(j + 0.5) * math.log(half) - math.lgamma(j + 1.5) for j in range(dof // 2)]
        tail = math.erfc(math.sqrt(half))
    return tail + sum(math.exp(t - half) for t in terms)


@lru_cache(maxsize=None)
def chi_square_quantile(probability, dof):
    """The chi-square quantile of an integer ``dof`` (scipy.stats.chi2.ppf), by bisection on the tail:
    exact to 1e-12 relative, without the import time of scipy.special."""
    low, high = 0.0, 1.0
    while chi_square_tail(high, dof) > 1.0 - probability:
        high *= 2.0
    for _ in range(200):
        middle = 0.5 * (low + high)
        if chi_square_tail(middle, dof) > 1.0 - probability:
            low = middle
        else:
            high = middle
        if high - low <= 1e-12 * high:
            break
    return 0.5 * (low + high)


SAME_POSE_CHI2 = chi_square_quantile(CHI2_CONFIDENCE, 6)  # poses closer than this (Mahalanobis^2) are one


def chi_square_passes(cost, rows, rank, sigma):
    dof = max(rows - rank, 1)
    return cost / sigma**2 <= chi_square_quantile(CHI2_CONFIDENCE, dof)


def touch_spreads(problem, jacobian):
    """How far (mm) each point touch's place on the fixture is unsure under the pose: three standard
    deviations, {touch index: mm}; None when the pose leaves motions free."""
    F = jacobian.T @ jacobian
    if np.linalg.cond(F) >= 1e14:
        return None
    twist_cov = problem.sigma**2 * np.linalg.inv(F)
    spreads = {}
    for g in _placed(problem):
        variances = np.trace(point_covariances(g.centre, twist_cov), axis1=1, axis2=2)
        for index, variance in zip(g.index, variances):
            spreads[int(index)] = EXTENT_SIGMAS * np.sqrt(max(variance, 0.0))
    return spreads


def inadmissible(problem, rotation, translation, spreads=None, tolerance=EXTENT_TOLERANCE_MM, approaches=True):
    """Touch indices that cannot have happened at this pose.

    A touch is inadmissible when its contact (a probe's point, a ball's
    centre, a sensor's known contact point), mapped into the fixture frame,
    lies off the feature's finite patch, or (``approaches``) when the probe's
    approach direction (if known) points along the outward surface normal
    there. With the touches' ``spreads`` (:func:`touch_spreads`), the patch is
    widened by each, at most by ``EXTENT_WIDENING_MAX_MM``, so a poorly
    determined pose is not refused for its own uncertainty.
    """
    bad = set()
    for g in _placed(problem):
        local = (g.centre - translation) @ rotation
        slack = tolerance
        if spreads is not None:
            slack = tolerance + np.minimum([spreads[int(i)] for i in g.index], EXTENT_WIDENING_MAX_MM)
        inside = np.asarray(g.feature.contains(local, slack))
        bad.update(int(i) for i in g.index[~inside])
        if approaches and g.approach is not None and g.feature.surface:
            outward = g.feature.normal_at(local) @ rotation.T
            away = np.einsum("ij,ij->i", outward, g.approach) > 0.0
            bad.update(int(i) for i in g.index[away & np.all(np.isfinite(g.approach), axis=1)])
    return sorted(bad)


def _placed(problem):
    """The touch groups whose places on the fixture are known: point and ball touches, and sensors whose
    contact point is given (a pose that puts it off its patch cannot have happened)."""
    return [g for g in problem.groups if g.points is not None or g.located]


def judged(problem, candidate, length):
    """A solution with its rank, residual test, extent check and touch spread filled in."""
    candidate.rank = matrix_rank(candidate.jacobian, length)
    candidate.passes = chi_square_passes(candidate.cost, len(candidate.residuals), candidate.rank, problem.sigma)
    spreads = touch_spreads(problem, candidate.jacobian)
    candidate.spread_mm = max(spreads.values(), default=0.0) if spreads is not None else np.inf
    candidate.outside = inadmissible(problem, candidate.rotation, candidate.translation, spreads)
    candidate.admissible = not candidate.outside
    return candidate
