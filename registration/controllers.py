"""The fixture's pose in each robot controller's own convention and units, with its standard deviations.

A pose ``fixture2meas`` (4x4, ``p_meas = R p_fix + t``, mm) is the frame of the
child (the fixture) expressed in the parent (the measurement frame), which is
what every controller below stores as a user / base / work-object frame. Its
covariance is over (rotation vector rad of a left perturbation
``R <- exp(omega) R`` in the measurement frame, fixture origin mm).

Conventions, each checked against the source named on its line:

- KUKA FRAME / BASE_DATA: X, Y, Z mm; A about Z, B about Y, C about X, deg, R = Rz(A) Ry(B) Rx(C):
  Basler rc_visard manual "KUKA XYZ-ABC format" (docs.baslerweb.com/stereovisard/rc_cube/en/pose_format_kuka).
- ABB RAPID pose ``[[x, y, z], [q1, q2, q3, q4]]`` mm, q1 the scalar part: RAPID Reference Manual "orient"
  (``[1, 0, 0, 0]`` is no rotation) and Basler "ABB pose format" ((x, y, z, w) = (Q2, Q3, Q4, Q1)).
- FANUC W, P, R deg about the fixed X, Y, Z axes, R = Rz(R) Ry(P) Rx(W): Basler "FANUC XYZ-WPR format"
  (docs.baslerweb.com/stereovisard/rc_visard/en/pose_format_fanuc.html).
- UR URScript ``p[x, y, z, rx, ry, rz]`` m and rotation vector rad: URScript manual ``rotvec2rpy`` /
  ``rpy2rotvec`` (universal-robots.com/manuals/EN/HTML/SW10_7/.../rotvec2rpy_rotation_vector.htm).
- ROS 2 ``static_transform_publisher --x --y --z --qx --qy --qz --qw --frame-id --child-frame-id``, m, child
  pose in the parent: ros2/geometry2 ``tf2_ros/src/static_transform_broadcaster_program.cpp``.
- Yaskawa Rx, Ry, Rz deg, R = Rz(Rz) Ry(Ry) Rx(Rx): Basler "Yaskawa Pose Format"
  (docs.baslerweb.com/stereovisard/rc_cube/en/pose_format_yaskawa).

Canonical forms: Euler angles in (-180, 180] with the middle one in [-90, 90]
(at +-90 the third angle is 0); quaternions with w >= 0 (at w = 0 the first
non-zero component positive); rotation vectors of angle in [0, pi] (from that
quaternion). The sigmas are the covariance pushed through the conversion's
Jacobian (central differences over the rotation-vector perturbation).

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import json
from dataclasses import dataclass

import numpy as np

from .pose import check_fixture2meas, fixture2meas_from_rt, rotation_from_quaternion, rotation_from_vector

GIMBAL_LOCK_COS = 1e-10  # cos of the middle Euler angle below which it is +-90 deg and the third angle is set to 0
GIMBAL_SIGMA_COS = 1e-5  # below this the first and third angles have no first-order sigma: reported as inf
HALF_TURN_W = 1e-12  # |w| of a quaternion taken as 0 (a half turn) for the sign rule
JACOBIAN_STEP_RAD = 1e-7  # central-difference step of the rotation perturbation
# Printed decimals per unit: enough that format -> parse -> 4x4 agrees to 1e-9 (mm and unitless entries).
DECIMALS = {"mm": 9, "m": 12, "deg": 10, "rad": 12, "": 12}


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(b):
    c, s = np.cos(b), np.sin(b)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rx(c_):
    c, s = np.cos(c_), np.sin(c_)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _wrap_deg(angle_deg):
    """Angles (deg) wrapped into (-180, 180]."""
    return 180.0 - np.mod(180.0 - np.asarray(angle_deg, float), 360.0)


def zyx_from_rotation(rotation):
    """Angles (a, b, c) rad with ``R = Rz(a) Ry(b) Rx(c)``, a and c in [-pi, pi], b in [-pi/2, pi/2].

    b comes from ``Rz(a)^T R = Ry(b) Rx(c)``, well conditioned at any b; at
    gimbal lock (b = +-pi/2) only a -+ c is defined and c is set to 0.
    """
    R = np.asarray(rotation, float)
    if np.hypot(R[0, 0], R[1, 0]) > GIMBAL_LOCK_COS:
        a = np.arctan2(R[1, 0], R[0, 0])
        M = _rz(a).T @ R
        return np.array([a, np.arctan2(-M[2, 0], M[0, 0]), np.arctan2(-M[1, 2], M[1, 1])])
    a = np.arctan2(-R[0, 1], R[1, 1])
    M = _rz(a).T @ R
    return np.array([a, np.copysign(np.pi / 2, -M[2, 0]), np.arctan2(-M[1, 2], M[1, 1])])


def rotation_from_zyx(angles_rad):
    """``Rz(a) Ry(b) Rx(c)`` of angles (a, b, c) rad."""
    a, b, c = angles_rad
    return _rz(a) @ _ry(b) @ _rx(c)


def quaternion_from_rotation(rotation):
    """Unit quaternion (w, x, y, z) of a rotation matrix, canonical: w >= 0, at w = 0 the first non-zero part > 0."""
    R = np.asarray(rotation, float)
    # Shepperd: solve from the largest of the four diagonal combinations, never dividing by a small number.
    k = int(np.argmax([np.trace(R), R[0, 0], R[1, 1], R[2, 2]]))
    if k == 0:
        w = 0.5 * np.sqrt(max(1.0 + np.trace(R), 0.0))
        q = np.array([w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)])
    else:
        i, j, m = k - 1, k % 3, (k + 1) % 3
        v = np.zeros(3)
        v[i] = 0.5 * np.sqrt(max(1.0 + R[i, i] - R[j, j] - R[m, m], 0.0))
        v[j] = (R[j, i] + R[i, j]) / (4 * v[i])
        v[m] = (R[m, i] + R[i, m]) / (4 * v[i])
        q = np.array([(R[m, j] - R[j, m]) / (4 * v[i]), *v])
    q /= np.linalg.norm(q)
    if abs(q[0]) <= HALF_TURN_W:
        q[0] = 0.0
        first = q[1:][np.abs(q[1:]) > HALF_TURN_W][0]
        return q if first > 0 else np.array([0.0, *-q[1:]])
    return q if q[0] > 0 else -q


def rotvec_from_rotation(rotation):
    """Rotation vector (3,) rad of angle in [0, pi], from the canonical quaternion (so a half turn is canonical)."""
    q = quaternion_from_rotation(rotation)
    s = np.linalg.norm(q[1:])
    if s < 1e-12:
        return 2.0 * q[1:] / q[0]
    return 2.0 * np.arctan2(s, q[0]) * q[1:] / s


@dataclass(frozen=True)
class _Rotation:
    """One way to write a rotation as numbers: forward, inverse and the nearest equal form (for differences)."""

    from_matrix: object
    to_matrix: object
    nearest: object  # (values, reference) -> values of the same rotation nearest the reference


def _nearest_euler(values_deg, reference_deg):
    return reference_deg + _wrap_deg(values_deg - reference_deg)


def _nearest_sign(values, reference):
    return values if values @ reference >= 0 else -values


def _nearest_rotvec(values, reference):
    angle = np.linalg.norm(values)
    if angle == 0:
        return values
    other = values - 2 * np.pi * values / angle
    return other if np.linalg.norm(other - reference) < np.linalg.norm(values - reference) else values


_ROTATIONS = {
    "matrix": _Rotation(lambda R: R.ravel(), lambda v: np.reshape(v, (3, 3)), lambda v, ref: v),
    "zyx_deg": _Rotation(lambda R: _wrap_deg(np.degrees(zyx_from_rotation(R))),
                         lambda v: rotation_from_zyx(np.radians(v)), _nearest_euler),
    "xyz_deg": _Rotation(lambda R: _wrap_deg(np.degrees(zyx_from_rotation(R)[::-1])),
                         lambda v: rotation_from_zyx(np.radians(v[::-1])), _nearest_euler),
    "wxyz": _Rotation(quaternion_from_rotation, rotation_from_quaternion, _nearest_sign),
    "xyzw": _Rotation(lambda R: np.roll(quaternion_from_rotation(R), -1),
                      lambda v: rotation_from_quaternion(np.roll(v, 1)), _nearest_sign),
    "rotvec": _Rotation(rotvec_from_rotation, rotation_from_vector, _nearest_rotvec),
}


@dataclass(frozen=True)
class Convention:
    """A controller's convention: its numbers (translation first), their labels and units, how it is written."""

    translation_unit: str  # "mm" or "m"
    rotation: str  # key of _ROTATIONS
    labels: tuple
    rotation_unit: str  # "deg", "rad" or "" (unitless)
    comment: str  # the language's line comment ("" when it has none)
    header: str  # the convention in words; {parent} and {child} are the frame names

    def units(self):
        return (self.translation_unit,) * 3 + (self.rotation_unit,) * (len(self.labels) - 3)


CONVENTIONS = {
    "matrix": Convention("mm", "matrix", ("tx", "ty", "tz", "r11", "r12", "r13", "r21", "r22", "r23", "r31", "r32",
                                          "r33"), "", "#",
                         "{child}2{parent} 4x4: p_{parent} = R p_{child} + t; t mm, R unitless"),
    "json": Convention("mm", "wxyz", ("x", "y", "z", "qw", "qx", "qy", "qz"), "", "",
                       "{child}2{parent}: p_{parent} = R p_{child} + t; translation mm; quaternion w, x, y, z "
                       "(w >= 0)"),
    "kuka": Convention("mm", "zyx_deg", ("X", "Y", "Z", "A", "B", "C"), "deg", ";",
                       "KUKA FRAME (BASE_DATA): X,Y,Z mm; A,B,C deg, R = Rz(A) Ry(B) Rx(C); {child} in {parent}"),
    "abb": Convention("mm", "wxyz", ("x", "y", "z", "q1", "q2", "q3", "q4"), "", "!",
                      "ABB wobjdata uframe (pose): [[x,y,z] mm, [q1,q2,q3,q4]] quaternion, q1 = w scalar first; "
                      "{child} in {parent}"),
    "fanuc": Convention("mm", "xyz_deg", ("X", "Y", "Z", "W", "P", "R"), "deg", "!",
                        "FANUC user frame: X,Y,Z mm; W,P,R deg about fixed X,Y,Z, R = Rz(R) Ry(P) Rx(W); "
                        "{child} in {parent}"),
    "ur": Convention("m", "rotvec", ("x", "y", "z", "rx", "ry", "rz"), "rad", "#",
                     "UR pose p[x,y,z,rx,ry,rz]: x,y,z m; rx,ry,rz rotation vector rad; {child} in {parent}"),
    "ros": Convention("m", "xyzw", ("x", "y", "z", "qx", "qy", "qz", "qw"), "", "#",
                      "ROS tf2: translation m; rotation quaternion x,y,z,w; child {child} in parent {parent}"),
    "yaskawa": Convention("mm", "xyz_deg", ("X", "Y", "Z", "Rx", "Ry", "Rz"), "deg", "'",
                          "Yaskawa user frame: X,Y,Z mm; Rx,Ry,Rz deg about fixed X,Y,Z, R = Rz(Rz) Ry(Ry) Rx(Rx); "
                          "{child} in {parent}"),
}
FORMATS = tuple(CONVENTIONS)
_SCALE = {"mm": 1.0, "m": 1e-3}  # per mm


def _convention(name):
    if name not in CONVENTIONS:
        raise ValueError(f"unknown pose format {name!r}; choose one of {', '.join(FORMATS)}")
    return CONVENTIONS[name]


def _values(convention, rotation, translation_mm):
    return np.concatenate([translation_mm * _SCALE[convention.translation_unit],
                           _ROTATIONS[convention.rotation].from_matrix(rotation)])


def values_from_pose(name, fixture2meas):
    """The numbers a format prints (its ``labels`` order and units, unrounded), shape (6,), (7,) or (12,)."""
    T = check_fixture2meas(fixture2meas)
    return _values(_convention(name), T[:3, :3], T[:3, 3])


def pose_from_format(name, values):
    """The 4x4 ``fixture2meas`` (mm) of a format's numbers (as :func:`values_from_pose` gives them)."""
    convention = _convention(name)
    v = np.asarray(values, dtype=np.float64)
    if v.shape != (len(convention.labels),):
        raise ValueError(f"{name} takes {len(convention.labels)} numbers ({', '.join(convention.labels)}), "
                         f"got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} numbers must be finite, got {v.tolist()}")
    rotation = _ROTATIONS[convention.rotation].to_matrix(v[3:])
    return check_fixture2meas(fixture2meas_from_rt(rotation, v[:3] / _SCALE[convention.translation_unit]))


def sigmas_from_covariance(name, fixture2meas, covariance):
    """Standard deviations (same shape and units as :func:`values_from_pose`) of a format's numbers.

    ``covariance`` (6, 6): over (rotation vector rad, left perturbation in the
    measurement frame; fixture origin mm). Within ``GIMBAL_SIGMA_COS`` of an
    Euler gimbal lock the first and third angles are inf.
    """
    convention = _convention(name)
    T = check_fixture2meas(fixture2meas)
    C = np.asarray(covariance, dtype=np.float64)
    if C.shape != (6, 6):
        raise ValueError(f"covariance must have shape (6, 6), got shape {C.shape}")
    R, t = T[:3, :3], T[:3, 3]
    rotation = _ROTATIONS[convention.rotation]
    reference = _values(convention, R, t)
    jacobian = np.zeros((reference.size, 6))
    for k in range(6):
        step = np.zeros(6)
        step[k] = JACOBIAN_STEP_RAD if k < 3 else 1.0  # the translation enters linearly
        ends = []
        for sign in (1.0, -1.0):
            v = _values(convention, rotation_from_vector(sign * step[:3]) @ R, t + sign * step[3:])
            v[3:] = rotation.nearest(v[3:], reference[3:])
            ends.append(v)
        jacobian[:, k] = (ends[0] - ends[1]) / (2 * step[k])
    sigma = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", jacobian, C, jacobian), 0.0))
    if convention.rotation.endswith("_deg") and np.hypot(R[0, 0], R[1, 0]) < GIMBAL_SIGMA_COS:
        sigma[[3, 5]] = np.inf
    return sigma


def _number(value, unit):
    """A printed number: fixed decimals for its unit, trailing zeros dropped, never ``-0.0`` nor ``-180.0``."""
    text = f"{value:.{DECIMALS[unit]}f}".rstrip("0")
    text = text + "0" if text.endswith(".") else text
    if float(text) == 0:
        return "0.0"
    return "180.0" if unit == "deg" and text == "-180.0" else text


def _labelled(convention, values):
    return ", ".join(f"{label} {n}" for label, n in zip(convention.labels, _numbers(convention, values)))


def _sigma_line(convention, sigmas):
    parts = [f"{label} {s:.3g}" + (f" {unit}" if unit else "")
             for label, s, unit in zip(convention.labels, sigmas, convention.units())]
    return f"{convention.comment} sigma: " + ", ".join(parts)


def _numbers(convention, values):
    return [_number(v, unit) for v, unit in zip(values, convention.units())]


def _matrix_text(convention, values, frames):
    n = _numbers(convention, values)
    return [" ".join(n[3 + 3 * i:6 + 3 * i] + [n[i]]) for i in range(3)] + ["0.0 0.0 0.0 1.0"], []


def _json_text(convention, fixture2meas, values, sigmas, frames):
    """JSON has no comments: the convention is a key of the object, the sigmas another.

    Numbers carry the same decimals as the other formats, the sigmas 3 significant digits.
    """
    parent, child = frames
    T = np.asarray(fixture2meas, dtype=np.float64)
    n = [float(x) for x in _numbers(convention, values)]
    document = {
        "convention": convention.header.format(parent=parent, child=child),
        "frame_id": parent,
        "child_frame_id": child,
        f"{child}2{parent}": [[float(_number(x, "" if j < 3 else "mm")) for j, x in enumerate(row)] for row in T],
        "translation_mm": n[:3],
        "quaternion_wxyz": n[3:],
        "sigma": None if sigmas is None else {"translation_mm": [float(f"{x:.3g}") for x in sigmas[:3]],
                                             "quaternion_wxyz": [float(f"{x:.3g}") for x in sigmas[3:]]},
    }
    return json_lines(document)


def json_lines(document: dict) -> str:
    """One key a line, each value on its line: readable, and still one JSON object."""
    return "{\n" + ",\n".join(f"  {json.dumps(key)}: {json.dumps(value)}" for key, value in document.items()) + "\n}"


def _kuka_text(convention, values, frames):
    return ["{" + _labelled(convention, values) + "}"], []


def _abb_text(convention, values, frames):
    n = _numbers(convention, values)
    return [f"[[{', '.join(n[:3])}], [{', '.join(n[3:])}]]"], []


def _pendant_text(convention, values, frames):
    return [_labelled(convention, values)], []


def _ur_text(convention, values, frames):
    return ["p[" + ", ".join(_numbers(convention, values)) + "]"], []


def _ros_text(convention, values, frames):
    parent, child = frames
    n = dict(zip(convention.labels, _numbers(convention, values)))
    command = ("ros2 run tf2_ros static_transform_publisher "
               + " ".join(f"--{label} {n[label]}" for label in convention.labels)
               + f" --frame-id {parent} --child-frame-id {child}")
    yaml = ["# geometry_msgs/msg/TransformStamped", "header:", f"  frame_id: {parent}", f"child_frame_id: {child}",
            "transform:", "  translation:"] + [f"    {axis}: {n[axis]}" for axis in "xyz"] + ["  rotation:"]
    yaml += [f"    {axis}: {n['q' + axis]}" for axis in "xyzw"]
    return [command], yaml


_WRITERS = {"matrix": _matrix_text, "kuka": _kuka_text, "abb": _abb_text,
            "fanuc": _pendant_text, "ur": _ur_text, "ros": _ros_text, "yaskawa": _pendant_text}


def format_pose(name, fixture2meas, covariance=None, frame_names=("meas", "fixture")):
    """The text a user pastes into the controller: the convention in a comment, the pose, its sigmas.

    Parameters
    ----------
    name : str, one of :data:`FORMATS`
    fixture2meas : array-like, shape (4, 4), mm
    covariance : array-like, shape (6, 6), optional: over (rotation vector rad, fixture origin mm)
    frame_names : (parent, child), the measurement frame's and the fixture's names
    """
    convention = _convention(name)
    values = values_from_pose(name, fixture2meas)
    sigmas = None if covariance is None else sigmas_from_covariance(name, fixture2meas, covariance)
    parent, child = frame_names
    if name == "json":
        return _json_text(convention, fixture2meas, values, sigmas, (parent, child))
    pose_lines, trailer = _WRITERS[name](convention, values, (parent, child))
    lines = [f"{convention.comment} " + convention.header.format(parent=parent, child=child)] + pose_lines
    if sigmas is not None:
        lines.append(_sigma_line(convention, sigmas))
    return "\n".join(lines + trailer)
