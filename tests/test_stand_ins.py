"""The sensors' stand-ins: each point touch's squared distance, times its factor, is at most its sensor touch's
cost wherever that cost passes (the assumption the complete search rests on for sensors), checked on the
contact model's own rows at poses near and far, for every contact with a stand-in."""

import itertools
import zlib

import numpy as np
import pytest

from fixturecad.registration.contacts import ContactType
from fixturecad.registration.elements import LETTERS, perpendicular_basis
from fixturecad.registration.features import Cylinder, Line, Plane, Point, Sphere
from fixturecad.registration.patches import patch_points
from fixturecad.registration.pose import motion_from_twist, random_rotation, rotation_from_vector
from fixturecad.registration.problem import Problem
from fixturecad.registration.search import deviation_bound
from fixturecad.registration.stand_ins import deviation_bound_mm, stand_in
from fixturecad.registration.touches import contact_touch, laid_sensor, point_touches

THRESHOLD_MM2 = 0.05**2 * 20  # a passing cost: sigma 0.05 mm, 20 degrees of freedom
POSES = 120  # poses per placement of a contact (two placements), turned 1 mrad to 1 rad and shifted 10 um to 10 mm
BALL_MM = 4.0


def _feature(letter, rng):
    point, direction = rng.uniform(-30.0, 30.0, 3), perpendicular_basis(rng.normal(size=3))[0]
    return {"PL": lambda: Plane("f", point, direction), "S": lambda: Sphere("f", point, rng.uniform(5.0, 20.0)),
            "C": lambda: Cylinder("f", point, direction, rng.uniform(5.0, 20.0)),
            "L": lambda: Line("f", point, direction), "P": lambda: Point("f", point)}[letter]()


def _touch(ctype, rng):
    """A touch of the contact at the identity pose: its sensor laid on a random feature (a random place on a
    sphere, a cylinder or a plane, across a line)."""
    feature = _feature(ctype.fixture, rng)
    core, anchor, direction, radius = feature.core()
    if core == "point":
        normal = perpendicular_basis(rng.normal(size=3))[0] if radius else perpendicular_basis(rng.normal(size=3))[1]
        point = anchor + radius * normal
    elif core == "line":
        normal = perpendicular_basis(direction)[0] @ rotation_from_vector(direction * rng.uniform(0, 2 * np.pi))
        point = anchor + rng.uniform(-20, 20) * direction + radius * normal
    else:
        normal, point = direction, anchor + perpendicular_basis(direction)[0] * rng.uniform(-20, 20)
    tangent = np.cross(normal, direction) if core == "line" else perpendicular_basis(normal)[0]
    sensor = laid_sensor(ctype.sensor, point, normal, tangent / np.linalg.norm(tangent), BALL_MM)
    if ctype.sensor == "PL" and ctype.sensor_fixed and core == "line":
        sensor["line"] = direction  # where on the plane the axis or the edge lies is known, as designs say
    fixture = {"o": point} if ctype.fixture_fixed else None
    return contact_touch(feature, ctype.name, sensor, 0, fixture=fixture, contact_point=point)


def _poses(rng):
    for _ in range(POSES):
        turn = 10.0 ** rng.uniform(-3, 0)
        shift = 10.0 ** rng.uniform(-2, 1)
        vector = rng.normal(size=3)
        yield rotation_from_vector(turn * vector / np.linalg.norm(vector)), shift * rng.normal(size=3) / np.sqrt(3)


CONTACTS = [ContactType(a, fa, b, fb) for a, b in itertools.product(LETTERS, LETTERS)
            for fa, fb in itertools.product((True, False), repeat=2)
            if not (a == "P" and not fa) and not (b == "P" and not fb)]


def _with_stand_in():
    rng = np.random.default_rng(3)
    out = []
    for ctype in CONTACTS:
        try:
            group = _touch(ctype, rng)
        except ValueError:
            continue  # not a contact a touch plan makes
        if group.points is None and stand_in(group, 0, THRESHOLD_MM2, 20.0) is not None:
            out.append(ctype.name)
    return out


STANDING_IN = _with_stand_in()


def test_the_contacts_with_a_stand_in():
    """Fixed sensors on mobile features, both points known, a ball on a known point, and a plane sensor with its
    contact line known under a cylinder or an edge; not sensors that move on both sides, nor plane on plane."""
    assert {"P/F-PL/F", "S/F-PL/M", "S/F-C/M", "S/F-S/M", "L/F-C/M", "L/F-S/M", "S/F-L/F", "S/M-L/F", "S/M-PL/F",
            "C/F-S/M", "PL/F-S/M", "PL/F-C/M", "PL/F-C/F", "PL/F-L/M", "PL/F-L/F"} <= set(STANDING_IN)
    assert not {"L/M-C/M", "L/M-L/M", "PL/F-PL/M", "PL/M-C/M", "PL/F-PL/F"} & set(STANDING_IN)


@pytest.mark.parametrize("name", STANDING_IN)
def test_a_stand_in_costs_no_more_than_its_sensor(name):
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    worst = 0.0
    for _ in range(2):
        group = _touch(ContactType.parse(name), rng)
        one = stand_in(group, 0, THRESHOLD_MM2, 20.0)
        feature, point, kappa2 = one.feature, one.point, one.kappa2
        sensor, proxy = Problem([group]), Problem([point_touches(feature, point, group.index)])
        for R, t in _poses(rng):
            R = R @ random_rotation(rng) if rng.uniform() < 0.1 else R  # now and then far off
            cost = float(np.sum(sensor.evaluate(R, t)[0] ** 2))
            d2 = float(np.sum(proxy.evaluate(R, t)[0] ** 2))
            assert cost > THRESHOLD_MM2 or kappa2 * d2 <= cost * (1 + 1e-9) + 1e-18, (name, cost, d2, kappa2)
            if cost <= THRESHOLD_MM2 and cost > 1e-12:
                worst = max(worst, d2 / cost)
    # Where the factor is well below 1 it is needed: at some pose that passes the stand-in costs more than the
    # sensor (the test would fail with the factor taken as 1); the plane on an axis's bound is looser than these
    # poses show (its gap form holds the anchor's turn, which they rarely reach).
    assert kappa2 > 0.99 or worst > 1.0 or ContactType.parse(name).is_locus


def _printed(template):
    from fixturecad.build import features_document
    from fixturecad.registration.deviations import tolerance_from_document
    from fixturecad.registration.features import features_from_json
    from fixturecad.templates import make

    document = features_document(make(template))
    features = features_from_json(document)
    return features, tolerance_from_document(features, document)


PRINTED = [("quarter-sphere", "sphere", ("S/F-S/M", "C/F-S/M", "PL/F-S/M", "L/F-S/M", "P/F-S/F", "S/M-S/F")),
           ("quarter-sphere", "flat_b", ("S/F-PL/M", "P/F-PL/F", "S/F-PL/F", "S/M-PL/F")),
           ("quarter-sphere", "edge", ("S/F-L/M", "S/M-L/F", "S/F-L/F", "PL/F-L/M")),
           ("inclined-plane-cylinder", "cylinder", ("S/F-C/M", "C/F-C/M", "L/F-C/M", "S/M-C/F", "PL/F-C/M",
                                                    "PL/F-C/F"))]


def _laid(ctype, feature, point, normal, tangent):
    """A sensor of the contact laid on the feature at ``point`` (a plane sensor told where an axis or an edge lies)."""
    sensor = laid_sensor(ctype.sensor, point, normal, tangent / np.linalg.norm(tangent), BALL_MM)
    if ctype.sensor == "PL" and feature.kind in ("cylinder", "line"):
        sensor["line"] = feature.axis if feature.kind == "cylinder" else feature.direction
    return sensor


@pytest.mark.parametrize("template,fid,names", PRINTED)
def test_a_printed_stand_in_moves_no_farther_than_its_deviation_bound(template, fid, names):
    """Sensors laid exactly on a feature of the drawing, the feature printed with mode coordinates on the edge of
    what a pose that passes allows (``z^T S^-1 z = q``, 210 directions): each stand-in's distance on the printed
    feature stays within its deviation bound (a point touch's own on the sensor's feature, else
    :func:`deviation_bound_mm`), and comes near it (the bound is not vacuous). Where the stand-in is not the
    sensor's own point, the bound also holds the whole move of its element (``|omega x x + v|`` at its places,
    plus the radius's change): the search takes it so for the turn of a round row's direction
    (:meth:`.search.Tree.mode_moves`)."""
    from fixturecad.registration.tolerance import deviated

    features, tolerance = _printed(template)
    feature, q, rng = features[fid], 30.0, np.random.default_rng(8)
    s = tolerance.slices[fid]
    root = np.linalg.cholesky(tolerance.covariance[s, s] + 1e-18 * np.eye(s.stop - s.start))
    places = patch_points(feature)
    for name in names:
        ctype = ContactType.parse(name)
        worst = 0.0
        for k in rng.choice(len(places), 3, replace=False):
            point, normal = places[k], feature.normal_at(places[k][None])[0]
            axis = {"cylinder": "axis", "line": "direction"}.get(feature.kind)
            tangent = perpendicular_basis(normal)[0] if axis is None else np.cross(getattr(feature, axis), normal)
            if feature.kind == "line":
                normal = perpendicular_basis(feature.direction)[0]
            sensor = _laid(ctype, feature, point, normal, tangent)
            fixture = {"o": point} if ctype.fixture_fixed else None
            group = contact_touch(feature, name, sensor, 0, fixture=fixture, contact_point=point)
            nominal = stand_in(group, 0, THRESHOLD_MM2, 20.0)
            bound = deviation_bound(tolerance, feature, q) if nominal.own else \
                deviation_bound_mm(tolerance, feature, nominal.places, q)
            for _ in range(70):
                u = rng.normal(size=s.stop - s.start)
                z = root @ (np.sqrt(q) * u / np.linalg.norm(u))
                printed = deviated(tolerance.modes[fid], z)
                if ctype.fixture_fixed:  # the known point is the feature's: it moves with the print
                    R, t = motion_from_twist(z @ tolerance.modes[fid].twists)
                    on = R @ point + t
                    fixture = {"o": on + z @ tolerance.modes[fid].radius * printed.normal_at(on[None])[0]}
                moved = contact_touch(printed, name, sensor, 0, fixture=fixture, contact_point=point)
                proxy = stand_in(moved, 0, THRESHOLD_MM2, 20.0)
                distance = float(np.linalg.norm(Problem([point_touches(proxy.feature, proxy.point, moved.index)])
                                                .evaluate(np.eye(3), np.zeros(3))[0]))
                assert distance <= bound * (1 + 1e-6) + 1e-9, (name, distance, bound)
                worst = max(worst, distance / bound)
                if not nominal.own:
                    modes = tolerance.modes[fid]
                    twist = z @ np.where(modes.radius[:, None], 0.0, modes.twists)
                    move = np.linalg.norm(np.cross(twist[:3], nominal.places) + twist[3:], axis=1).max()
                    assert move + abs(z @ modes.radius) <= bound * (1 + 1e-6) + 1e-9, (name, move, bound)
        assert worst > 0.3, (name, worst)


@pytest.mark.parametrize("template,fid,names", PRINTED)
def test_the_search_moves_a_printed_stand_in_as_the_print_does(template, fid, names):
    """The search's first-order model of the deviations (:meth:`Tree.deviation_rows`): a stand-in's rows change
    with the feature's mode coordinates as the stand-in made on the printed feature does (its twist, and a radius
    mode along the sensor's normal or the feature's), at the identity pose, to within second order."""
    from fixturecad.registration.elements import core_offset
    from fixturecad.registration.search import Tree
    from fixturecad.registration.tolerance import deviated

    features, tolerance = _printed(template)
    feature, rng = features[fid], np.random.default_rng(9)
    s = tolerance.slices[fid]
    root = np.linalg.cholesky(tolerance.covariance[s, s] + 1e-18 * np.eye(s.stop - s.start))
    point = patch_points(feature)[7]
    normal = feature.normal_at(point[None])[0]
    axis = {"cylinder": "axis", "line": "direction"}.get(feature.kind)
    tangent = perpendicular_basis(normal)[0] if axis is None else np.cross(getattr(feature, axis), normal)
    if feature.kind == "line":
        normal = perpendicular_basis(feature.direction)[0]
    for name in names:
        ctype = ContactType.parse(name)
        sensor = _laid(ctype, feature, point, normal, tangent)
        fixture = {"o": point} if ctype.fixture_fixed else None
        group = contact_touch(feature, name, sensor, 0, fixture=fixture, contact_point=point)
        one = stand_in(group, 0, THRESHOLD_MM2, 20.0)
        tree = Tree(Problem([point_touches(one.feature, one.point, group.index)], 0.005, tolerance=tolerance),
                    THRESHOLD_MM2, [one])
        unit, touch = tree.row_unit[None], tree.row_touch
        if not tree.flat[0]:
            unit, touch = one.feature.normal_at(one.point)[None], np.array([0])  # a round stand-in's one row
        J = tree.deviation_rows(unit, touch, one.point[None], np.eye(3)[None])[0]  # (rows, k')
        columns = np.concatenate([np.arange(tolerance.slices[f].start, tolerance.slices[f].stop)
                                  for f in [fid]])
        assert tree.L.shape[0] == len(columns)
        for _ in range(20):
            z = root @ (rng.normal(size=s.stop - s.start) * 0.1)  # small: the model is first-order
            printed = deviated(tolerance.modes[fid], z)
            if ctype.fixture_fixed:
                R, t = motion_from_twist(z @ tolerance.modes[fid].twists)
                on = R @ point + t
                fixture = {"o": on + z @ tolerance.modes[fid].radius * printed.normal_at(on[None])[0]}
            moved = stand_in(contact_touch(printed, name, sensor, 0, fixture=fixture, contact_point=point), 0,
                             THRESHOLD_MM2, 20.0)
            core, anchor, direction, radius = moved.feature.core()
            offset = core_offset(core, anchor, direction, moved.point)[0]
            if not tree.flat[0]:
                offset = np.linalg.norm(offset) - radius
                actual = np.array([offset])
            else:
                actual = unit[0] @ offset
            predicted = J @ np.linalg.lstsq(tree.L, z, rcond=None)[0]
            assert np.allclose(actual, predicted, atol=1e-7 + 3e-2 * np.abs(actual).max()), (name, actual, predicted)
