"""The pose covariance: ``sigma^2 (J_w^T J_w)^-1`` of the whitened rows, the Cramer-Rao bound at the truth.

Covariances are over (rotation vector rad, fixture origin mm), both in the
measurement frame.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

from .pose import check_fixture2meas, origin_error_map

def covariance(jacobian, translation, sigma):
    """Pose covariance (6, 6) over (rotation vector rad, fixture origin mm); None if singular.

    ``jacobian`` (m, 6): whitened rows (covariance sigma^2 I, see :class:`Problem`).
    """
    return covariance_from_information(jacobian.T @ jacobian, translation, sigma)


def covariance_from_information(F, translation, sigma):
    """:func:`covariance` of the rows' information ``J^T J`` (6, 6)."""
    try:
        C = sigma**2 * np.linalg.inv(F)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(C)):
        return None
    A = origin_error_map(translation)
    return A @ C @ A.T


def cramer_rao_bound(problem, fixture2meas, sigma):
    """Cramer-Rao bound (6, 6) of the pose under the sensor noise model with placement noise sigma (mm).

    The sensors' placement error: translation sigma, rotation sigma / lever
    about each contact point (``problem.lever``), see :func:`row_whitening`.
    """
    T = check_fixture2meas(fixture2meas)
    _, J = problem.evaluate(T[:3, :3], T[:3, 3])
    return covariance(J, T[:3, 3], sigma)


def sigmas(cov):
    """RMS translation (mm) and rotation (deg) standard deviations of a covariance."""
    if cov is None:
        return None, None
    return float(np.sqrt(np.trace(cov[3:, 3:]))), float(np.degrees(np.sqrt(np.trace(cov[:3, :3]))))
