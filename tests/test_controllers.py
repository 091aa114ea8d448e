"""The pose in each controller's convention: round trips through the printed text, an independent conversion
(scipy's Rotation), published worked examples, sigmas against a Monte Carlo, and the docs page's example."""

import ast
import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from fixturecad.registration import controllers
from fixturecad.registration.controllers import (FORMATS, format_pose, pose_from_format, sigmas_from_covariance,
                                                  values_from_pose)
from fixturecad.registration.pose import random_rotation, rotation_from_vector

ROOT = Path(__file__).resolve().parent.parent
NUMBER = re.compile(r"-?\d+\.\d+(?:e[-+]?\d+)?")
EULER = {"kuka": "ZYX", "fanuc": "XYZ", "yaskawa": "XYZ"}  # scipy intrinsic ZYX angles, in the printed order


def pose(rotation, translation_mm):
    T = np.eye(4)
    T[:3, :3] = rotation
    T[:3, 3] = translation_mm
    return T


def zyx_deg(a, b, c):
    return Rotation.from_euler("ZYX", [a, b, c], degrees=True).as_matrix()


def poses():
    """Seeded random poses and the singular cases: gimbal lock, half turns, an angle at +-180 deg."""
    rng = np.random.default_rng(20261122)
    cases = [pose(random_rotation(rng), rng.uniform(-2000, 2000, 3)) for _ in range(40)]
    singular = [zyx_deg(30, 90, 20), zyx_deg(-120, -90, 75), zyx_deg(0, 90, 0), zyx_deg(180, 0, 180),
                zyx_deg(-180, 45, -180), zyx_deg(179.9999999, 10, -179.9999999), np.diag([1.0, -1.0, -1.0]),
                np.diag([-1.0, -1.0, 1.0]), rotation_from_vector(np.pi * np.array([1.0, 1.0, 0.0]) / np.sqrt(2)),
                rotation_from_vector(np.pi * np.array([-0.3, 0.5, -0.8]) / np.linalg.norm([-0.3, 0.5, -0.8])),
                np.eye(3)]
    return cases + [pose(R, [812.5, -143.25, 96.0]) for R in singular]


POSES = poses()


def printed_numbers(name, text):
    """The pose's numbers parsed back from a format's text, in ``values_from_pose`` order."""
    if name == "json":
        document = json.loads(text)
        return document["translation_mm"] + document["quaternion_wxyz"]
    lines = [line for line in text.splitlines() if not line.startswith(("#", ";", "!", "'"))]
    if name == "ros":
        return [float(x) for x in NUMBER.findall(lines[0])]
    numbers = [float(x) for x in NUMBER.findall(" ".join(lines))]
    if name == "matrix":
        rows = np.reshape(numbers[:12], (3, 4))
        return list(rows[:, 3]) + list(rows[:, :3].ravel())
    return numbers


@pytest.mark.parametrize("name", FORMATS)
def test_the_printed_text_parses_back_to_the_same_pose(name):
    for T in POSES:
        text = format_pose(name, T, covariance=np.eye(6) * 1e-6)
        back = pose_from_format(name, printed_numbers(name, text))
        np.testing.assert_allclose(back, T, rtol=0, atol=1e-9)


def test_the_ros_yaml_is_the_same_transform_as_the_command():
    for T in POSES[:5]:
        text = format_pose("ros", T, frame_names=("world", "jig"))
        message = yaml.safe_load("\n".join(text.splitlines()[3:]))
        assert message["header"]["frame_id"] == "world" and message["child_frame_id"] == "jig"
        translation, rotation = message["transform"]["translation"], message["transform"]["rotation"]
        values = [translation[a] for a in "xyz"] + [rotation[a] for a in "xyzw"]
        np.testing.assert_allclose(pose_from_format("ros", values), T, rtol=0, atol=1e-9)
        assert "--frame-id world --child-frame-id jig" in text


def scipy_values(name, T):
    """The numbers of each format by scipy's Rotation, independently of the module."""
    r = Rotation.from_matrix(T[:3, :3])
    t = T[:3, 3]
    if name in EULER:
        angles = r.as_euler("ZYX", degrees=True)
        return np.concatenate([t, angles if name == "kuka" else angles[::-1]])
    if name in ("abb", "json"):
        return np.concatenate([t, r.as_quat(scalar_first=True)])
    if name == "ros":
        return np.concatenate([t / 1000, r.as_quat()])
    if name == "ur":
        return np.concatenate([t / 1000, r.as_rotvec()])
    return np.concatenate([t, T[:3, :3].ravel()])


def same_rotation_numbers(name, ours, theirs):
    """Equal up to the forms of one rotation: angles mod 360, the quaternion's sign, the rotation vector at pi."""
    if name in EULER:
        return np.allclose(((ours - theirs) + 180) % 360 - 180, 0, atol=1e-8)
    if name in ("abb", "json", "ros"):
        return np.allclose(ours, theirs, atol=1e-10) or np.allclose(ours, -theirs, atol=1e-10)
    if name == "ur" and abs(np.linalg.norm(theirs) - np.pi) < 1e-6:
        return np.allclose(ours, theirs, atol=1e-7) or np.allclose(ours, -theirs, atol=1e-7)
    return np.allclose(ours, theirs, atol=1e-10)


@pytest.mark.filterwarnings("ignore:Gimbal lock detected")
@pytest.mark.parametrize("name", FORMATS)
def test_the_numbers_agree_with_scipy(name):
    for T in POSES:
        ours, theirs = values_from_pose(name, T), scipy_values(name, T)
        np.testing.assert_allclose(ours[:3], theirs[:3], rtol=0, atol=1e-12)
        gimbal = name in EULER and abs(abs(theirs[4]) - 90) < 1e-6
        if gimbal:  # only A - C (or A + C) is defined there: compare the matrices, and the middle angle
            assert abs(ours[4] - theirs[4]) < 1e-6
            np.testing.assert_allclose(pose_from_format(name, ours), T, atol=1e-12)
        else:
            assert same_rotation_numbers(name, ours[3:], theirs[3:]), (name, ours, theirs)


@pytest.mark.parametrize("name", FORMATS)
def test_the_numbers_are_canonical(name):
    for T in POSES:
        v = values_from_pose(name, T)[3:]
        if name in EULER:
            first, middle, third = v if name == "kuka" else v[::-1]
            assert all(-180 < a <= 180 for a in v) and -90 <= middle <= 90
            if abs(abs(middle) - 90) < 1e-9:
                assert third == 0
        if name in ("abb", "json"):
            w, xyz = v[0], v[1:]
        elif name == "ros":
            w, xyz = v[3], v[:3]
        else:
            continue
        assert w >= 0
        if w == 0:
            assert xyz[np.abs(xyz) > 1e-12][0] > 0
    if name == "ur":
        assert all(np.linalg.norm(values_from_pose(name, T)[3:]) <= np.pi + 1e-12 for T in POSES)


def test_half_turn_about_x_is_canonical_in_every_quaternion_and_rotation_vector():
    T = pose(np.diag([1.0, -1.0, -1.0]), [0, 0, 0])
    assert list(values_from_pose("abb", T)[3:]) == [0.0, 1.0, 0.0, 0.0]
    assert list(values_from_pose("ros", T)[3:]) == [1.0, 0.0, 0.0, 0.0]
    np.testing.assert_allclose(values_from_pose("ur", T)[3:], [np.pi, 0, 0], atol=1e-15)
    np.testing.assert_allclose(values_from_pose("kuka", T)[3:], [0, 0, 180], atol=1e-12)
    assert "C 180.0}" in format_pose("kuka", T)


def test_gimbal_lock_puts_the_third_angle_to_zero_and_its_sigma_to_inf():
    T = pose(zyx_deg(30, 90, 20), [1.0, 2.0, 3.0])
    A, B, C = values_from_pose("kuka", T)[3:]
    assert (round(A, 9), B, C) == (10.0, 90.0, 0.0)  # at B = 90 only A - C is defined
    sigma = sigmas_from_covariance("kuka", T, np.eye(6) * 1e-6)
    assert np.isinf(sigma[3]) and np.isinf(sigma[5]) and np.isfinite(sigma[4])


# --- Published worked examples ---------------------------------------------------------------------------------

def test_ur_manual_rotvec2rpy_example():
    # URScript manual (SW 10.7), rotvec2rpy: "rotvec2rpy([3.14,1.57,0]) ... Returns [-2.80856, -0.16202, 0.9]
    # -> roll=-2.80856, pitch=-0.16202, yaw=0.9", with "Rrpy = Rz(yaw)Ry(pitch)Rx(roll)": FANUC's W, P, R.
    T = pose_from_format("ur", [0, 0, 0, 3.14, 1.57, 0])
    np.testing.assert_allclose(np.radians(values_from_pose("fanuc", T)[3:]), [-2.80856, -0.16202, 0.9], atol=1e-5)


def test_ur_manual_rpy2rotvec_example():
    # URScript manual (SW 5.21), rpy2rotvec: "rpy2rotvec([3.14,1.57,0]) ... Returns [2.22153, 0.00177, -2.21976]",
    # roll, pitch, yaw about the fixed X, Y, Z axes: Yaskawa's Rx, Ry, Rz.
    T = pose_from_format("yaskawa", [0, 0, 0, np.degrees(3.14), np.degrees(1.57), 0])
    np.testing.assert_allclose(values_from_pose("ur", T)[3:], [2.22153, 0.00177, -2.21976], atol=1e-5)


def test_ros_static_transform_publisher_example():
    # A published answer on ros2 static_transform_publisher (wenku.csdn.net/answer/xua3j5x0ww): a turn of 90 deg
    # about Z is "ros2 run tf2_ros static_transform_publisher 0 0 0 0 0 0.707 0.707 world base_link"
    # (x y z qx qy qz qw parent child); the ROS 2 flags name the same numbers.
    T = pose(zyx_deg(90, 0, 0), [0, 0, 0])
    text = format_pose("ros", T, frame_names=("world", "base_link"))
    numbers = [float(x) for x in NUMBER.findall(text.splitlines()[1])]
    np.testing.assert_allclose(numbers, [0, 0, 0, 0, 0, 0.707, 0.707], atol=1e-3)
    assert text.splitlines()[1].endswith("--frame-id world --child-frame-id base_link")


def test_abb_manual_orient_example():
    # RAPID Reference Manual, orient: "orient1 := [1, 0, 0, 0]; The orient1 orientation is assigned the value
    # q1=1, q2-q4=0; this corresponds to no rotation." No published numeric example with a rotation was found:
    # the quaternion order rests on scipy (test_the_numbers_agree_with_scipy) and Basler's (Q2, Q3, Q4, Q1) = (x, y, z, w).
    np.testing.assert_array_equal(pose_from_format("abb", [0, 0, 0, 1, 0, 0, 0]), np.eye(4))
    assert format_pose("abb", np.eye(4)).splitlines()[1] == "[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]]"


def basler_quaternion_xyzw(a_deg, b_deg, c_deg):
    """Basler rc_visard manual, "KUKA XYZ-ABC format" / "Yaskawa Pose Format" / "FANUC XYZ-WPR format":
    the published quaternion of angles about Z (A, Rz, R), Y (B, Ry, P) and X (C, Rx, W)."""
    A, B, C = np.radians([a_deg, b_deg, c_deg]) / 2
    return np.array([np.cos(A) * np.cos(B) * np.sin(C) - np.sin(A) * np.sin(B) * np.cos(C),
                     np.cos(A) * np.sin(B) * np.cos(C) + np.sin(A) * np.cos(B) * np.sin(C),
                     np.sin(A) * np.cos(B) * np.cos(C) - np.cos(A) * np.sin(B) * np.sin(C),
                     np.cos(A) * np.cos(B) * np.cos(C) + np.sin(A) * np.sin(B) * np.sin(C)])


@pytest.mark.parametrize("name", list(EULER))
def test_euler_angles_follow_basler_published_formulas(name):
    # No published numeric example of a KUKA, FANUC or Yaskawa frame was found; Basler publishes the conversion
    # formulas of each, which this checks against (as well as scipy above).
    for T in POSES:
        angles = values_from_pose(name, T)[3:]
        about_zyx = angles if name == "kuka" else angles[::-1]
        q = basler_quaternion_xyzw(*about_zyx)
        ours = values_from_pose("ros", T)[3:]
        assert np.allclose(q, ours, atol=1e-12) or np.allclose(q, -ours, atol=1e-12)


# --- Sigmas ----------------------------------------------------------------------------------------------------

def nearest_form(name, values, reference):
    """The test's own unwrapping of a sample's rotation numbers onto the reference's."""
    if name in EULER:
        return reference + ((values - reference) + 180) % 360 - 180
    if name in ("abb", "json", "ros"):
        return values if values @ reference >= 0 else -values
    if name == "ur":
        other = values - 2 * np.pi * values / np.linalg.norm(values)
        return other if np.linalg.norm(other - reference) < np.linalg.norm(values - reference) else values
    return values


def covariance(rng):
    """A correlated covariance: rotation about 1 mrad, origin about 0.05 mm."""
    L = rng.normal(size=(6, 6)) * np.array([1e-3] * 3 + [0.05] * 3)[:, None]
    return L @ L.T


@pytest.mark.parametrize("name", FORMATS)
def test_sigmas_match_a_monte_carlo(name):
    rng = np.random.default_rng(7)
    cases = [POSES[0], pose(zyx_deg(179.95, 30, -179.95), [500, 20, -30]),
             pose(rotation_from_vector(3.1405 * np.array([0.6, 0.0, 0.8])), [10, 20, 30])]
    for T in cases:
        C = covariance(rng)
        sigma = sigmas_from_covariance(name, T, C)
        reference = values_from_pose(name, T)
        samples = rng.multivariate_normal(np.zeros(6), C, size=5000)  # std within about 1 %
        spread = []
        for s in samples:
            v = values_from_pose(name, pose(rotation_from_vector(s[:3]) @ T[:3, :3], T[:3, 3] + s[3:]))
            v[3:] = nearest_form(name, v[3:], reference[3:])
            spread.append(v)
        # A number at an extremum (a matrix entry of +-1) moves at second order only: beyond a first-order sigma.
        first_order = sigma > 10 * np.trace(C[:3, :3])
        assert first_order.sum() >= sigma.size - 3
        np.testing.assert_allclose(np.std(spread, axis=0)[first_order], sigma[first_order], rtol=0.05)


def test_sigmas_need_a_6x6_covariance():
    with pytest.raises(ValueError, match=r"shape \(6, 6\)"):
        sigmas_from_covariance("kuka", np.eye(4), np.eye(3))


# --- API -------------------------------------------------------------------------------------------------------

def test_every_format_names_its_convention_first():
    for name in FORMATS:
        text = format_pose(name, POSES[0], covariance=np.eye(6) * 1e-6)
        if name == "json":
            assert "translation mm" in json.loads(text)["convention"]
        else:
            comment = controllers.CONVENTIONS[name].comment
            first = text.splitlines()[0]
            assert first.startswith(comment + " ") and (" mm" in first or " m;" in first)
            assert text.splitlines()[-1 if name != "ros" else 2].startswith(comment + " sigma:")


def test_bad_input_is_a_value_error():
    with pytest.raises(ValueError, match="unknown pose format 'staubli'"):
        format_pose("staubli", np.eye(4))
    with pytest.raises(ValueError, match=r"kuka takes 6 numbers \(X, Y, Z, A, B, C\)"):
        pose_from_format("kuka", [1, 2, 3])
    with pytest.raises(ValueError, match="must be rigid"):
        format_pose("kuka", np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match="non-zero"):
        pose_from_format("abb", [0, 0, 0, 0, 0, 0, 0])


def test_the_module_imports_numpy_and_its_siblings_only():
    tree = ast.parse((ROOT / "registration" / "controllers.py").read_text())
    imported = {alias.name for node in tree.body if isinstance(node, ast.Import) for alias in node.names}
    imported |= {"." * node.level + (node.module or "") for node in tree.body if isinstance(node, ast.ImportFrom)}
    assert imported <= {"json", "dataclasses", "numpy", ".pose"}


# --- The docs page ---------------------------------------------------------------------------------------------

DOCS_POSE = pose(zyx_deg(30, -20, 45), [812.5, -143.25, 96.0])
DOCS_COVARIANCE = np.diag([1e-4**2] * 3 + [0.01**2] * 3)  # 0.1 mrad per axis, 0.01 mm per axis


def docs_blocks():
    """The docs page's example blocks: ```text blocks preceded by a <!-- format: NAME --> marker."""
    text = (ROOT / "docs" / "robot-frames.md").read_text()
    return dict(re.findall(r"<!-- format: (\w+) -->\n```\w*\n(.*?)\n```", text, flags=re.S))


def test_the_docs_show_every_format_as_the_module_writes_it():
    blocks = docs_blocks()
    assert sorted(blocks) == sorted(FORMATS)
    for name, block in blocks.items():
        assert block == format_pose(name, DOCS_POSE, DOCS_COVARIANCE), name
