"""Rigid poses: rotation vectors, twists and the 4x4 ``fixture2meas`` transform.

A pose maps the fixture frame to the measurement frame, ``p_meas = R p_fix + t``,
written ``fixture2meas`` as a 4x4 homogeneous matrix. A spatial twist
``(omega, v)`` (rad, mm) moves a pose by ``R <- exp(omega) R``,
``t <- exp(omega) t + v``, the convention of the contact model's Jacobians.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

from .elements import cross, perpendicular_basis

ORTHONORMAL_TOLERANCE = 1e-6  # largest |R^T R - I| entry accepted in a given 4x4


def skew(w):
    """The cross-product matrices (..., 3, 3) of ``w`` (..., 3): ``skew(w) @ x == cross(w, x)``."""
    w = np.asarray(w, dtype=np.float64)
    K = np.zeros(w.shape + (3,))  # filled in place: cheaper than stacking rows of parts
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = w[..., 2], -w[..., 1], w[..., 0]
    return K


def point_covariances(points, twist_covariance):
    """The covariances (n, 3, 3) of the points (n, 3) moved by a spatial twist ``(omega, v)`` of covariance
    (6, 6): a twist moves p by ``omega x p + v``."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    M = np.concatenate([-skew(points), np.broadcast_to(np.eye(3), (len(points), 3, 3))], axis=2)
    return M @ twist_covariance @ M.transpose(0, 2, 1)


def rotation_from_vector(omega):
    """Rodrigues: the rotation matrix exp([omega]) of a rotation vector (3,) rad, or matrices (K, 3, 3)
    of rotation vectors (K, 3)."""
    omega = np.asarray(omega, dtype=np.float64)
    if omega.ndim == 2:
        angle = np.linalg.norm(omega, axis=1)[:, None, None]
        K = skew(omega)
        small = angle < 1e-8
        a = np.where(small, 1.0, np.sin(angle) / np.where(small, 1.0, angle))
        b = np.where(small, 0.5, (1.0 - np.cos(angle)) / np.where(small, 1.0, angle) ** 2)
        return np.eye(3) + a * K + b * (K @ K)
    angle = float(np.linalg.norm(omega))
    K = skew(omega)
    if angle < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + (np.sin(angle) / angle) * K + ((1.0 - np.cos(angle)) / angle**2) * K @ K


def vector_from_rotation(rotation):
    """The rotation vector (..., 3) rad of rotation matrices (..., 3, 3) (inverse of ``rotation_from_vector``;
    its angle at most pi)."""
    R = np.asarray(rotation, dtype=np.float64)
    axis = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    cos = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0)
    angle = np.arctan2(0.5 * np.linalg.norm(axis, axis=-1), cos)[..., None]
    v = axis * np.where(angle < 1e-8, 0.5, angle / (2.0 * np.sin(np.maximum(angle, 1e-8))))
    # Near a half turn the skew part vanishes: u u^T from the symmetric part, the sign from the skew part.
    near = (np.pi - angle[..., 0]) < 1e-3
    if np.any(near):
        Rn, c = R[near], cos[near][:, None, None]
        outer = (0.5 * (Rn + np.swapaxes(Rn, -1, -2)) - c * np.eye(3)) / (1.0 - c)
        k = np.argmax(np.diagonal(outer, axis1=-2, axis2=-1), axis=-1)
        u = np.take_along_axis(outer, k[:, None, None], axis=-1)[..., 0]
        u = u * np.where(np.sum(axis[near] * u, axis=-1) < 0, -1.0, 1.0)[:, None]
        v[near] = angle[near] * u / np.linalg.norm(u, axis=-1, keepdims=True)
    return v


def rotation_angle(rotation):
    """Angle (rad) of a rotation matrix, or angles (...) of matrices (..., 3, 3), accurate near 0 (atan2 of sine
    and cosine parts)."""
    R = np.asarray(rotation, dtype=np.float64)
    axis = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    angle = np.arctan2(0.5 * np.linalg.norm(axis, axis=-1), 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0))
    return float(angle) if angle.ndim == 0 else angle


def fixture2meas_from_rt(rotation, translation):
    """The 4x4 ``fixture2meas`` of rotation (3, 3) and translation (3,) mm."""
    T = np.eye(4)
    T[:3, :3] = rotation
    T[:3, 3] = translation
    return T


def check_fixture2meas(fixture2meas):
    """Return a proper rigid 4x4 as float64; raise ValueError otherwise."""
    T = np.asarray(fixture2meas, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"fixture2meas must have shape (4, 4), got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError("fixture2meas must be finite, got NaN or inf")
    R = T[:3, :3]
    if np.max(np.abs(R.T @ R - np.eye(3))) > ORTHONORMAL_TOLERANCE or np.linalg.det(R) < 0:
        raise ValueError("fixture2meas must be rigid: its 3x3 block is not a rotation")
    if np.max(np.abs(T[3] - [0.0, 0.0, 0.0, 1.0])) > 1e-12:
        raise ValueError("fixture2meas must have last row [0, 0, 0, 1]")
    return T


def rt_from_fixture2meas(fixture2meas):
    """Rotation (3, 3) and translation (3,) of a checked 4x4 ``fixture2meas``."""
    T = check_fixture2meas(fixture2meas)
    return T[:3, :3].copy(), T[:3, 3].copy()


def motion_from_twist(twist):
    """The rigid motion (R, t) ``exp`` of a twist (omega rad, v mm): ``x -> R x + t``."""
    omega, v = np.asarray(twist[:3], float), np.asarray(twist[3:], float)
    theta = np.linalg.norm(omega)
    W = skew(omega)
    if theta < 1e-9:
        V = np.eye(3) + 0.5 * W
    else:
        V = np.eye(3) + (1 - np.cos(theta)) / theta**2 * W + (theta - np.sin(theta)) / theta**3 * (W @ W)
    return rotation_from_vector(omega), V @ v


def apply_twist(rotation, translation, twist):
    """Move a pose by a spatial twist (omega, v): ``R <- exp(omega) R``, ``t <- exp(omega) t + v``."""
    E = rotation_from_vector(twist[:3])
    return E @ rotation, E @ translation + twist[3:]


def origin_error_map(translation):
    """Matrix (6, 6) mapping a twist (omega, v) to (omega, change of the fixture origin).

    A spatial twist moves the fixture origin ``t`` by ``omega x t + v``.
    """
    A = np.eye(6)
    A[3:, :3] = -skew(translation)
    return A


def pose_errors(fixture2meas_est, fixture2meas_true):
    """Translation error (mm, of the fixture origin) and rotation error (rad) between two poses."""
    dt = float(np.linalg.norm(fixture2meas_est[:3, 3] - fixture2meas_true[:3, 3]))
    dr = rotation_angle(fixture2meas_est[:3, :3] @ fixture2meas_true[:3, :3].T)
    return dt, dr


def rotation_from_quaternion(quaternion_wxyz):
    """Rotation matrix of a quaternion (w, x, y, z), normalised first; ValueError if it is zero."""
    q = np.asarray(quaternion_wxyz, float)
    norm = np.linalg.norm(q)
    if not norm > 0:
        raise ValueError(f"a quaternion must be non-zero, got {q.tolist()}")
    w, x, y, z = q / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def random_rotation(rng):
    """A rotation drawn uniformly (Haar) with a ``numpy.random.Generator``."""
    return rotation_from_quaternion(rng.normal(size=4))


def rotation_aligning(a, b):
    """A rotation taking unit vector ``a`` onto unit vector ``b`` (the shortest one)."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) / np.linalg.norm(b)
    axis = cross(a, b)
    s = np.linalg.norm(axis)
    c = float(a @ b)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        return rotation_from_vector(np.pi * perpendicular_basis(a)[0])
    return rotation_from_vector(np.arctan2(s, c) * axis / s)
