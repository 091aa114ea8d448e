"""The search's bounds on sensors with no stand-in (registration/sensor_bounds.py): a line sensor across an edge
or round a boss, a plane sensor on a plane or a boss, a line or a cylinder sensor lying on a plane.

The bounds are checked against the contact model's own whitened rows (the cost the residual test takes) at poses
sampled in cells, not against the formulas they are made of."""

import functools

import numpy as np
import pytest

from fixturecad.build import features_document
from fixturecad.registration.defaults import SENSOR_LEVER_MM
from fixturecad.registration.deviations import deviation_rows
from fixturecad.registration.tolerance import deviated
from fixturecad.registration.verdict import EXTENT_TOLERANCE_MM, EXTENT_WIDENING_MAX_MM
from fixturecad.registration.engine import register_touches
from fixturecad.registration.features import features_from_json
from fixturecad.registration.pose import pose_errors, random_rotation, rotation_from_vector, vector_from_rotation
from fixturecad.registration.problem import Problem
from fixturecad.registration.elements import perpendicular_basis
from fixturecad.registration.search import stand_in_tree, threshold_mm2
from fixturecad.registration.sensor_bounds import Printed, SensorBounds
from fixturecad.registration.stand_ins import stand_ins
from fixturecad.registration.synthetic import perturb_touches, plan_touches
from fixturecad.registration.touches import build_groups
from fixturecad.templates import make

from search_cases import _features, _fixture, _tolerance

CUBE = 50.0  # mm
LONG_LEVER_MM = 1e3  # mm: far longer than the default, short enough for the whitening's regularisation


def _cube_plan(face):
    """Point touches on two faces of the cube, a line sensor and a cylinder sensor lying on the third: its top (the
    printed part's datum, which does not deviate) or its left (which does)."""
    s = CUBE
    if face == "top":
        return [
            {"feature": "front", "points": [[0.2 * s, 0.0, 0.3 * s], [0.8 * s, 0.0, 0.6 * s]]},
            {"feature": "left", "points": [[0.0, 0.3 * s, 0.2 * s], [0.0, 0.7 * s, 0.7 * s], [0.0, 0.5 * s, 0.5 * s]]},
            {"feature": "top", "contact": "L/M-PL/M", "points": [[0.3 * s, 0.4 * s, s]],
             "sensor": {"kind": "line", "point": [0.3 * s, 0.4 * s, s], "direction": [0.6, 0.8, 0.0]}},
            {"feature": "top", "contact": "C/M-PL/M", "points": [[0.6 * s, 0.5 * s, s + 4.0]], "rho": 4.0,
             "sensor": {"kind": "cylinder", "point": [0.6 * s, 0.5 * s, s + 4.0], "axis": [0.8, -0.6, 0.0],
                        "radius": 4.0}},
        ]
    return [
        {"feature": "front", "points": [[0.2 * s, 0.0, 0.3 * s], [0.8 * s, 0.0, 0.6 * s]]},
        {"feature": "top", "points": [[0.3 * s, 0.2 * s, s], [0.7 * s, 0.7 * s, s], [0.5 * s, 0.5 * s, s]]},
        {"feature": "left", "contact": "L/M-PL/M", "points": [[0.0, 0.4 * s, 0.3 * s]],
         "sensor": {"kind": "line", "point": [0.0, 0.4 * s, 0.3 * s], "direction": [0.0, 0.8, 0.6]}},
        {"feature": "left", "contact": "C/M-PL/M", "points": [[-4.0, 0.5 * s, 0.6 * s]], "rho": 4.0,
         "sensor": {"kind": "cylinder", "point": [-4.0, 0.5 * s, 0.6 * s], "axis": [0.0, 0.6, -0.8],
                    "radius": 4.0}},
    ]


def _cube_plane_plan():
    """Point touches on the cube's front and top, and a plane sensor lying on its left face (which deviates on the
    printed part)."""
    s = CUBE
    point = [0.0, 0.4 * s, 0.3 * s]
    return [
        {"feature": "front", "points": [[0.2 * s, 0.0, 0.3 * s], [0.8 * s, 0.0, 0.6 * s]]},
        {"feature": "top", "points": [[0.3 * s, 0.2 * s, s], [0.7 * s, 0.7 * s, s], [0.5 * s, 0.5 * s, s]]},
        {"feature": "left", "contact": "PL/F-PL/F", "points": [point],
         "sensor": {"kind": "plane", "point": point, "normal": [-1.0, 0.0, 0.0]}},
    ]


def _boss_plan():
    """Point touches on the inclined plane and the boss, a line sensor across the boss and a plane sensor lying on
    it (both at the boss's radius)."""
    return [
        {"feature": "plane", "points": [[0.0, 12.0, 0.0], [-10.4, -6.0, -10.4], [10.4, -6.0, 10.4]]},
        {"feature": "cylinder", "points": [[18.79385, 6.84040, -32.0], [-15.32089, 12.85575, -44.0]]},
        {"feature": "cylinder", "contact": "L/M-C/M", "points": [[20.0, 0.0, -40.0]], "rho": 20.0,
         "sensor": {"kind": "line", "point": [20.0, 0.0, -40.0], "direction": [0.0, 1.0, 0.0]}},
        {"feature": "cylinder", "contact": "PL/M-C/M", "points": [[0.0, -20.0, -30.0]], "rho": 20.0,
         "sensor": {"kind": "plane", "point": [0.0, -20.0, -30.0], "normal": [0.0, 1.0, 0.0]}},
    ]


@functools.lru_cache(maxsize=None)
def _case(name):
    """(features, touch plan) of a case: a template's named plan, a design's default plan, or the cube's above."""
    if name == CUBE_PLANE:
        return features_from_json(features_document(make("cube", size=CUBE))), _cube_plane_plan()
    if name.startswith("cube, line and cylinder lying on the "):
        return features_from_json(features_document(make("cube", size=CUBE))), _cube_plan(name.split()[-1])
    if name == BOSS:
        return features_from_json(features_document(make("inclined-plane-cylinder"))), _boss_plan()
    if name.startswith("{"):
        return _features(name), _fixture(name).touch_plans()["default"].touches
    template, plan = name.split(" ")
    return features_from_json(features_document(make(template))), make(template).touch_plans()[plan].touches


BOSS = "inclined-plane-cylinder, line across and plane lying on the boss"
CUBE_PLANE = "cube, plane sensor lying on the left"
BOSSES = "{C-R-C}" * 6  # six leaning bosses, two line sensors round each, their contact points given: no point touch
PLANES_ON_BOSSES = "{G3-R}" * 3  # three bosses, two plane sensors lying on each (two axes near parallel): the same
CASES = ("quarter-sphere paper", "quarter-sphere minimal", "{R}{C-R-C}", "{R}{G3-R}",
         "cube, line and cylinder lying on the top", BOSS, BOSSES, PLANES_ON_BOSSES)
# The cases whose bounds are checked on a printed part too, against the test's own rows: not the designs, whose
# stand-ins lie off their features (the test's deviations are not known over them; tests/search_cases.py judges them).
PRINTED = ("quarter-sphere paper", "quarter-sphere minimal", "cube, line and cylinder lying on the top", BOSS)


def _touches(name, truth, rng, noise_mm):
    """The case's touches made at the pose ``truth``, each sensor placed with ``noise_mm`` of the noise model."""
    touches, contacts = plan_touches(_case(name)[1], truth)
    return perturb_touches(touches, contacts, rng, noise_mm) if noise_mm else (touches, contacts)


@functools.lru_cache(maxsize=None)
def _printed(name):
    """The case's part as printed: the recorded tolerance of its template."""
    return _tolerance(name.split(",")[0].split(" ")[0], _case(name)[0])


def _problem(name, rng, noise_mm=0.0, lever_mm=SENSOR_LEVER_MM, printed=False):
    """The case's touches at a random pose: (problem, truth)."""
    truth = np.eye(4)
    truth[:3, :3], truth[:3, 3] = random_rotation(rng), rng.uniform(-80, 80, 3)
    touches, contacts = _touches(name, truth, rng, noise_mm)
    return Problem(build_groups(_case(name)[0], touches, contacts=contacts), max(noise_mm, 0.005), lever_mm,
                   _printed(name) if printed else None), truth


def _passing(tree, v_true, y_true):
    """The least-squares pose from the truth (v, y), where its cost passes the search's threshold (else None): the
    truth itself need not (the sensors' placement noise is drawn at the default lever)."""
    R = rotation_from_vector(v_true[None])
    Rs, ts = tree.refined(R, (tree.centroid - R[0] @ y_true)[None])
    r = tree.full.evaluate_batch(Rs, ts)[0]
    points = tree.problem.size
    cost = np.sum(r[0, :points] ** 2) + tree.sensors.weight * np.sum(r[0, points:] ** 2)
    return (vector_from_rotation(Rs)[0], Rs[0].T @ (tree.centroid - ts[0])) if cost <= tree.root**2 else None


def _cells(rng, count, v_true, y_true):
    """Cells (v0, w, y centre, y half-widths) anywhere, about the truth, and beside it (where a bound's slack is
    least): rotation half-widths from 0.1 mrad to 0.4 rad, y half-widths from 3 um to 30 mm."""
    for k in range(count):
        w = np.exp(rng.uniform(np.log(1e-4), np.log(0.4)))
        half = np.exp(rng.uniform(np.log(0.003), np.log(30.0), 3))
        beside = rng.choice([-1.0, 1.0], 6) * rng.uniform(1.0, 10.0, 6) if k % 3 == 2 else rng.uniform(-1, 1, 6)
        yield (v_true if k % 3 else rng.uniform(-2, 2, 3)) + beside[:3] * w, w, y_true + beside[3:] * half, half


def _samples(rng, v0, w, centre, half, count=64, truth=None):
    """Poses of a cell (R (count, 3, 3), y (count, 3)), half of them at corners of its rotation box and y box; and
    ``truth`` (v, y), a pose that passes, where the cell holds it (the rows' models hold at the poses that pass)."""
    corner = np.arange(count) % 2 == 0
    v = v0 + np.where(corner[:, None], rng.choice([-1.0, 1.0], (count, 3)), rng.uniform(-1, 1, (count, 3))) * w
    y = centre + np.where(corner[:, None], rng.choice([-1.0, 1.0], (count, 3)), rng.uniform(-1, 1, (count, 3))) * half
    if truth is not None and np.all(np.abs(truth[0] - v0) <= w) and np.all(np.abs(truth[1] - centre) <= half):
        v, y = np.vstack([v, truth[0]]), np.vstack([y, truth[1]])
    return rotation_from_vector(v), y


def _setting(name, lever_mm=SENSOR_LEVER_MM, printed=False):
    rng = np.random.default_rng(7)
    problem, truth = _problem(name, rng, 0.005, lever_mm, printed)
    tree = stand_in_tree(problem, threshold_mm2(problem))[0]
    assert tree.sensors is not None and tree.fixes_pose
    v_true = vector_from_rotation(truth[:3, :3])
    return rng, tree, v_true, truth[:3, :3].T @ (tree.centroid - truth[:3, 3])


@pytest.mark.parametrize("lever_mm", [SENSOR_LEVER_MM, LONG_LEVER_MM], ids=["lever", "long lever"])
@pytest.mark.parametrize("name", CASES)
def test_the_sensor_bounds_hold_within_a_cell(name, lever_mm):
    """On 300 random cells a case (:func:`_cells`), 64 poses each (:func:`_samples`): no pose has the bounded
    sensors' cost (their whitened rows, times their weight) below the cells' bound of it, nor below their
    first-order rows there less the rows' remainders; the bound is positive in some. With a long lever the
    sensors' turn hardly whitens their distance rows, so these bounds are tight: it fails when a line's swing
    over the cell is taken a third smaller, or its model's remainder without the common normal's turn. The model
    is checked at the poses that pass (the least-squares pose among them, in the cells that hold it: 40 at least
    where it passes); it fails when a line round a boss is modelled where the other sign of its distance comes
    within 1.5 times the boss's radius of where it started (or anywhere)."""
    rng, tree, v_true, y_true = _setting(name, lever_mm)
    fit = _passing(tree, v_true, y_true)
    positive = passing = 0
    for v0, w, centre, half in _cells(rng, 300, v_true, y_true):
        R0 = rotation_from_vector(v0[None])
        bound, value, Jw, m, remainder = tree.sensors.cells(R0, np.array([np.sqrt(3) * w]), centre[None],
                                                               np.array([np.linalg.norm(half)]), tree.root)[:5]
        Rs, y = _samples(rng, v0, w, centre, half, truth=fit)
        r = tree.full.evaluate_batch(Rs, tree.centroid - np.einsum("kij,kj->ki", Rs, y))[0]
        sensed = tree.sensors.weight * np.sum(r[:, tree.problem.size:] ** 2, axis=1)
        assert sensed.min() >= bound[0] * (1 - 1e-9) - 1e-12, (sensed.min(), bound[0])
        omega = vector_from_rotation(np.einsum("ji,kjl->kil", R0[0], Rs))  # R = R0 exp(omega)
        model = value[0] + np.einsum("ri,ki->kr", Jw[0], omega) + np.einsum("ri,ki->kr", m[0], y)
        passes = sensed <= tree.root**2
        assert np.all(np.sqrt(sensed) >= np.linalg.norm(model, axis=1) - np.linalg.norm(remainder[0]) - 1e-9,
                      where=passes)
        positive += bound[0] > 0.0
        passing += passes.any()
    assert positive >= 20 and (fit is None or passing >= 40), (positive, passing)


@pytest.mark.parametrize("lever_mm", [SENSOR_LEVER_MM, LONG_LEVER_MM], ids=["lever", "long lever"])
@pytest.mark.parametrize("name", PRINTED)
def test_the_sensor_bounds_hold_on_a_printed_part(name, lever_mm):
    """On the part as printed (its recorded tolerance), 150 such cells with 32 poses each, each pose with a
    deviation of the sensors' features that a pose that passes allows (``z = L u``, ``|u|^2 = q``, half along
    the direction that moves one row most): the sensors' rows as the test takes them at the pose, ``r - J_d
    z`` (the contact model's whitened rows and their change with the modes, :func:`.deviations.deviation_rows`),
    are never below the cells' bound, nor below the first-order rows with the modes, ``value + Jw.omega + m.y -
    Jz u``, less their remainders. It fails when a row's change with the modes has the wrong sign (a line's, a
    plane's offset, either side the plane, or a radius's); the bound's deviation terms taken half as large are
    caught by the next test, the remainders' by :func:`test_a_locus_rows_model_is_off_by_its_deviation_remainder_at_worst`
    and :func:`test_two_lines_model_is_off_by_its_deviation_remainder_at_worst`. The model at the poses that pass."""
    rng, tree, v_true, y_true = _setting(name, lever_mm, printed=True)
    fit = _passing(tree, v_true, y_true)
    tolerance = tree.judge.tolerance
    q = tree.root**2 / tree.problem.sigma**2
    singles = Problem(tree.full.groups[len(tree.problem.groups):], tree.problem.sigma, tree.problem.lever)
    rows = tree.sensors.row_touch
    positive = 0
    for v0, w, centre, half in _cells(rng, 150, v_true, y_true):
        R0 = rotation_from_vector(v0[None])
        bound, value, Jw, m, remainder, _, twist, radius = tree.sensors.cells(
            R0, np.array([np.sqrt(3) * w]), centre[None], np.array([np.linalg.norm(half)]), tree.root)
        Jz = np.einsum("si,sij->sj", twist[0], tree.sensor_twists[rows]) + radius[0][:, None] * tree.sensor_radius[rows]
        Rs, y = _samples(rng, v0, w, centre, half, 32, truth=fit)
        # Deviations along one row's largest change (that row moved as far as the modes allow), or at random.
        along = Jz[rng.integers(len(Jz), size=len(Rs))]
        u = np.where((np.arange(len(Rs)) % 2 == 1)[:, None] & np.any(along != 0.0, axis=1, keepdims=True), along,
                     rng.normal(size=(len(Rs), tree.L.shape[1])))
        u *= rng.choice([-1.0, 1.0], (len(u), 1)) * np.sqrt(q) / np.linalg.norm(u, axis=1, keepdims=True)
        z = np.zeros((len(u), tolerance.size))
        z[:, tree.mode_index] = u @ tree.L.T
        ts = tree.centroid - np.einsum("kij,kj->ki", Rs, y)
        cost = np.empty(len(Rs))
        for k, (R, t) in enumerate(zip(Rs, ts)):
            r, J = singles.sensor_rows(R, t)
            cost[k] = np.sum((r - deviation_rows(singles, tolerance, R, t, J) @ z[k]) ** 2)
        assert cost.min() >= bound[0] * (1 - 1e-9) - 1e-12, (cost.min(), bound[0])
        omega = vector_from_rotation(np.einsum("ji,kjl->kil", R0[0], Rs))  # R = R0 exp(omega)
        model = value[0] + np.einsum("ri,ki->kr", Jw[0], omega) + np.einsum("ri,ki->kr", m[0], y) - u @ Jz.T
        assert np.all(np.sqrt(cost) >= np.linalg.norm(model, axis=1) - np.linalg.norm(remainder[0]) - 1e-9,
                      where=tree.sensors.weight * cost <= tree.root**2)
        positive += bound[0] > 0.0
    assert positive >= 20, positive


@pytest.mark.parametrize("name", ["quarter-sphere paper", "quarter-sphere minimal", BOSS,
                                  "cube, line and cylinder lying on the left"])
def test_the_printed_sensor_bound_takes_off_what_the_part_can_move_a_row(name):
    """The bounds' deviation terms are as large as they need to be, and not twice that: touches made exactly on the
    part as drawn, at three random poses, registered against the drawing moved by a deviation of the sensors'
    features that a pose that passes allows (``z = L u``, ``|u|^2 = q``, along one row's largest change, either
    sign; a radius mode grows the contacts' offsets with it). At the true pose (a cell of one pose) the test's
    cost with that deviation is nil, and so must the sensors' bound be; and on some rows the bound with the
    deviation terms taken half as large (``Printed`` halved) is not: halving those terms in
    :mod:`.sensor_bounds` fails this test (each of its four deviation terms: a plane's offset row at the fixture's
    point and at the sensor's, the turn rows, two lines' distance). The cube's sensors lie on its left here:
    its top, under them in the other printed case, is the printed part's datum, which does not deviate.)"""
    features, _ = _case(name)
    tolerance = _printed(name)
    tight = 0
    for seed in range(3):
        rng = np.random.default_rng(seed)
        truth = np.eye(4)
        truth[:3, :3], truth[:3, 3] = random_rotation(rng), rng.uniform(-80, 80, 3)
        touches, contacts = _touches(name, truth, rng, 0.0)

        def tree_on(drawing, grow=None):
            grown = [{**c, "rho": c["rho"] + (grow or {}).get(c["feature"], 0.0)} if "rho" in c else c
                     for c in contacts]
            problem = Problem(build_groups(drawing, touches, contacts=grown), 0.005, SENSOR_LEVER_MM, tolerance)
            return stand_in_tree(problem, threshold_mm2(problem))[0]

        tree = tree_on(features)
        R, t = truth[:3, :3], truth[:3, 3]
        pose = (R[None], np.zeros(1), (R.T @ (tree.centroid - t))[None], np.zeros(1))
        twist, radius = tree.sensors.cells(*pose, tree.root)[6:]
        rows = tree.sensors.row_touch
        Jz = np.einsum("si,sij->sj", twist[0], tree.sensor_twists[rows]) + radius[0][:, None] * tree.sensor_radius[rows]
        q = tree.root**2 / tree.problem.sigma**2
        fids = {tree.full.groups[len(tree.problem.groups) + g].feature.id for g in np.unique(rows)}
        for j in np.flatnonzero(np.linalg.norm(Jz, axis=1) > 1e-9 * max(np.abs(Jz).max(), 1e-300)):
            for sign in (1.0, -1.0):
                z = np.zeros(tolerance.size)
                z[tree.mode_index] = tree.L @ (sign * np.sqrt(q) * Jz[j] / np.linalg.norm(Jz[j]))
                moved = {f: deviated(tolerance.modes[f], z[tolerance.slices[f]]) for f in fids}
                drawn = tree_on({**features, **moved},
                                {f: z[tolerance.slices[f]] @ tolerance.modes[f].radius for f in fids})
                singles = Problem(drawn.full.groups[len(drawn.problem.groups):], drawn.problem.sigma,
                                  drawn.problem.lever)
                r, J = singles.sensor_rows(R, t)
                cost = np.sum((r - deviation_rows(singles, tolerance, R, t, J) @ z) ** 2)
                scale = np.sum(r**2)  # the rows' squares off the moved drawing: what the deviation terms take off
                assert cost <= 1e-6 * scale, (j, cost, scale)  # the rows to first order in the deviation
                bound = drawn.sensors.cells(*pose, drawn.root)[0][0]
                assert bound <= cost + 1e-6 * scale, (j, bound, cost)
                drawn.sensors.printed = [Printed(p.tilt / 2, p.dev / 2, p.centre) for p in drawn.sensors.printed]
                tight += drawn.sensors.cells(*pose, drawn.root)[0][0] > 1e-3 * scale
    assert tight >= 2, tight


@pytest.mark.parametrize("name", ["quarter-sphere paper", "{R}{C-R-C}", BOSS])
def test_a_line_rows_model_holds_on_a_turning_feature(name):
    """Two lines' distance on a fixture line that turns by 0.05 rad about a point 200 mm off it (its move there
    zero), computed here from the lines themselves: at 32 poses of each of 300 cells, the row as the test takes
    it, the distance less ``rho`` less ``u.D(p*)`` (``u`` the common normal signed as at the cell's centre,
    ``p*`` the closest point on the fixture's line, ``D`` the feature's move), lies within its remainder of the
    cell's model ``value + Jw.omega + m.y + twist.(omega_f, v_f)``, row by row. A lever of 1e9 mm leaves the row
    unscaled by the whitening. It fails when the closest point's move over the cell is taken as zero."""
    rng, tree, v_true, y_true = _setting(name)
    lines = [(g, k) for g, k in stand_ins(tree.full, tree.root**2)[4] if not g.ctype.is_locus]
    assert lines
    checked = 0
    for g, k in lines:
        bounds = SensorBounds([(g, k)], 1e9, tree.centroid)
        _, s, f, rho, _ = bounds.touches[0]
        centre = f["p"] + 200.0 * perpendicular_basis(f["d"])[0]
        bounds.printed = [Printed(0.05, 0.0, centre)]
        for v0, w, y_centre, half in _cells(rng, 300, v_true, y_true):
            R0 = rotation_from_vector(v0[None])
            _, value, Jw, m, remainder, usable, twist, _ = bounds.cells(
                R0, np.array([np.sqrt(3) * w]), y_centre[None], np.array([np.linalg.norm(half)]), tree.root)
            if not usable[0]:
                continue
            Rs, y = _samples(rng, v0, w, y_centre, half, 32)
            omega_f = rng.normal(size=(len(Rs), 3))
            omega_f *= 0.05 / np.linalg.norm(omega_f, axis=1, keepdims=True)
            v_f = -np.cross(omega_f, centre)
            # The sensor's line on the fixture at each pose, its closest point on the fixture's line, the normal.
            p = np.einsum("i,kij->kj", s["p"] - tree.centroid, Rs) + y
            d = np.einsum("i,kij->kj", s["d"], Rs)
            normal = np.cross(d, f["d"])
            normal /= np.linalg.norm(normal, axis=1, keepdims=True)
            u_centre = -twist[0, 0, 3:]  # the model's twist column of v is -u at the cell's centre
            normal *= np.sign(normal @ u_centre)[:, None]
            w_ = p - f["p"]
            cosine = d @ f["d"]
            along = (w_ @ f["d"] - cosine * np.einsum("ki,ki->k", w_, d)) / (1.0 - cosine**2)
            closest = f["p"] + along[:, None] * f["d"]
            move = np.cross(omega_f, closest) + v_f
            row = np.einsum("ki,ki->k", p - f["p"], normal) - rho - np.einsum("ki,ki->k", normal, move)
            omega = vector_from_rotation(np.einsum("ji,kjl->kil", R0[0], Rs))  # R = R0 exp(omega)
            model = value[0, 0] + omega @ Jw[0, 0] + y @ m[0, 0] + np.concatenate([omega_f, v_f], axis=1) @ twist[0, 0]
            assert np.all(np.abs(model - row) <= remainder[0, 0] + 1e-9), (np.abs(model - row).max(), remainder[0, 0])
            checked += 1
    assert checked >= 100, checked


def _unit(v):
    return v / np.linalg.norm(v)


@pytest.mark.parametrize("name", ["quarter-sphere paper", "cube, line and cylinder lying on the left", BOSS])
def test_a_locus_rows_model_is_off_by_its_deviation_remainder_at_worst(name):
    """A plane sensor lying on a plane or a boss, a line or a cylinder sensor lying on a plane, on a fixture
    feature that turns by up to 1 mrad and moves its mode centre (200 mm off the fixture's point) by up to 50 um:
    in 60 small cells (turns of 1 urad to 0.1 mrad, where the deviation's share of each row's remainder is nearly
    all of it), at the pose and feature move that make each row's change with the move differ most from the
    model's at the cell's centre (the cell turns a plane's normal, a tangent or a line's direction across the
    feature's move, or moves the line's point across the feature's turn), each row, computed here from the sensor
    and the feature, lies within its remainder of the model, and comes within 10 % of it: the remainder's
    deviation terms (``delta * tilt`` of a turn row, ``delta * dev`` of a plane sensor's offset, ``tilt * swing``
    of a line's) are as large as needed and no larger; halving any one fails this test. A lever of 1e9 mm leaves
    the rows unscaled by the whitening but for the model's common 1/sqrt(2). (Two lines': the next test.)"""
    rng, tree, v_true, y_true = _setting(name)
    loci = [(g, k) for g, k in stand_ins(tree.full, tree.root**2)[4] if g.ctype.is_locus]
    assert loci
    tilt, dev = 1e-3, 0.05  # rad, mm
    rows_checked = 0
    for g, k in loci:
        bounds = SensorBounds([(g, k)], 1e9, tree.centroid)
        ctype, s, f, rho, _ = bounds.touches[0]
        c = tree.centroid
        plane_sensor = ctype.sensor == "PL"
        q = f["q"] if ctype.fixture == "PL" else f["p"]  # where a plane sensor's offset takes the feature's move
        centre = q + 200.0 * _unit(rng.normal(size=3))
        bounds.printed = [Printed(tilt, dev, centre)]

        # The turn rows: the sensor's directions (a plane's tangents on a plane, else its normal or the line's) along
        # the fixture's (the plane's normal, the line's direction).
        turning = [s["t1"], s["t2"]] if ctype.sensor == ctype.fixture else [s["n"] if plane_sensor else s["d"]]
        fixed = f["d"] if plane_sensor and ctype.fixture != "PL" else f["n"]

        def rows(R, y, omega_f, v_f):
            """The sensor's rows at the pose (R, y) on the feature moved by the twist, to first order in it: the
            turn rows times the lever, then the offset."""
            move = lambda p: np.cross(omega_f, p) + v_f  # noqa: E731
            if plane_sensor:
                n = s["n"] @ R
                offset = n @ (q - y) - (s["n"] @ (s["q"] - c) + rho) + n @ move(q)
            else:
                x = (s["p"] - c) @ R + y
                offset = (x - f["q"]) @ f["n"] - rho - f["n"] @ move(x)
            turn = [(t @ R) @ (fixed + np.cross(omega_f, fixed)) for t in turning]
            return np.array([1e9 * t for t in turn] + [offset]) / np.sqrt(2.0)

        worst = np.zeros(len(turning) + 1)
        for _ in range(60):
            R0 = rotation_from_vector(v_true + rng.uniform(-0.01, 0.01, 3))
            yc = y_true + rng.uniform(-1.0, 1.0, 3)
            delta, h = np.exp(rng.uniform(np.log(1e-6), np.log(1e-4))), 1e-6
            _, value, Jw, m, remainder, usable, twist, _ = bounds.cells(R0[None], np.array([delta]), yc[None],
                                                                        np.array([h]), tree.root)
            assert usable[0]
            for row in range(len(worst)):
                if row < len(worst) - 1:  # a turn row: turn its direction a across the fixture's b as far as it goes
                    a = turning[row] @ R0
                    e = _unit(np.cross(a, fixed))
                    omega, y = delta * _unit(np.cross(e, a)), yc
                    omega_f, v_f = tilt * _unit(np.cross(fixed, e)), np.zeros(3)
                elif plane_sensor:  # the offset: turn the normal along the feature's largest move at q
                    n = s["n"] @ R0
                    e = _unit(np.cross(n, q - centre))
                    omega, y = delta * _unit(np.cross(e, n)), yc
                    omega_f = tilt * _unit(np.cross(q - centre, e))
                    v_f = (dev + tilt * np.linalg.norm(q - centre)) * e - np.cross(omega_f, q)
                else:  # the offset: move the line's point across the feature's turn
                    a = (s["p"] - c) @ R0
                    e = _unit(np.cross(a, f["n"]))
                    omega, y = delta * _unit(np.cross(e, a)), yc + h * e
                    omega_f, v_f = -tilt * _unit(np.cross(e, f["n"])), dev * _unit(rng.normal(size=3))
                for sign in (1.0, -1.0):
                    R = R0 @ rotation_from_vector(sign * omega)
                    model = (value[0] + Jw[0] @ (sign * omega) + m[0] @ (yc + sign * (y - yc))
                             + twist[0] @ np.concatenate([omega_f, v_f]))
                    off = np.abs(model - rows(R, yc + sign * (y - yc), omega_f, v_f))
                    assert np.all(off <= remainder[0] + 1e-9), (row, off, remainder[0])
                    worst[row] = max(worst[row], off[row] / remainder[0, row])
        assert np.all(worst >= 0.9), worst
        rows_checked += len(worst)
    assert rows_checked >= 2


@pytest.mark.parametrize("name", ["quarter-sphere paper", "{R}{C-R-C}", BOSS])
def test_two_lines_model_is_off_by_its_deviation_remainder_at_worst(name):
    """Two lines' distance on a fixture line that moves by up to 50 um: in 60 small cells (turns of 1 urad to
    0.1 mrad), at the turn that swings the common normal farthest (the sensor's direction turned along the normal)
    and the move along the normal's change, the row, computed here from the lines, lies within its remainder of the
    model, and comes within 10 % of it: the normal's turn bound, ``2 sin(asin(delta / s) / 2)``, is what a small
    turn reaches (the chord bound ``2 delta / s`` came within 50 % here), and halving the deviation's term ``du *
    dev`` fails this test. A lever of 1e9 mm leaves the row unscaled by the whitening."""
    rng, tree, v_true, y_true = _setting(name)
    lines = [(g, k) for g, k in stand_ins(tree.full, tree.root**2)[4] if not g.ctype.is_locus]
    assert lines
    dev = 0.05  # mm
    for g, k in lines:
        bounds = SensorBounds([(g, k)], 1e9, tree.centroid)
        _, s, f, rho, _ = bounds.touches[0]
        bounds.printed = [Printed(0.0, dev, f["p"])]
        worst = 0.0
        for _ in range(60):
            R0 = rotation_from_vector(v_true + rng.uniform(-0.01, 0.01, 3))
            yc = y_true + rng.uniform(-1.0, 1.0, 3)
            delta = np.exp(rng.uniform(np.log(1e-6), np.log(1e-4)))
            _, value, Jw, m, remainder, usable, twist, _ = bounds.cells(R0[None], np.array([delta]), yc[None],
                                                                        np.array([1e-6]), tree.root)
            assert usable[0]
            u_c = -twist[0, 0, 3:]  # the model's twist column of v is -u at the cell's centre
            d_c = s["d"] @ R0
            for sign in (1.0, -1.0):
                # The sensor's direction turned by delta along u_c: the common normal swings by delta / s.
                omega = sign * delta * _unit(np.cross(u_c, d_c))
                R = R0 @ rotation_from_vector(omega)
                d = s["d"] @ R
                u = _unit(np.cross(d, f["d"]))
                u *= np.sign(u @ u_c)
                v_f = -dev * _unit(u - u_c)  # the fixture line's move along the normal's change
                p = (s["p"] - tree.centroid) @ R + yc
                row = (p - f["p"]) @ u - rho - u @ v_f
                model = value[0, 0] + Jw[0, 0] @ omega + m[0, 0] @ yc + twist[0, 0] @ np.concatenate([np.zeros(3), v_f])
                off = abs(model - row)
                assert off <= remainder[0, 0] + 1e-9, (off, remainder[0, 0])
                worst = max(worst, off / remainder[0, 0])
        assert worst >= 0.9, worst


@pytest.mark.parametrize("name", PRINTED)
def test_the_sensor_rows_move_with_their_printed_feature_as_modelled(name):
    """Each sensor row's change with each mode of its feature, as the search models it (``twist`` and
    ``radius`` at a cell of one pose), matches the rows of the same touches on the feature moved by that mode
    (:func:`.tolerance.deviated`, an exact rigid motion and radius), by central differences, within 0.1 %: the
    rows' scale, which the model holds fixed over a cell, moves with the feature too (times rows of a few um)."""
    rng = np.random.default_rng(3)
    truth = np.eye(4)
    truth[:3, :3], truth[:3, 3] = random_rotation(rng), rng.uniform(-80, 80, 3)
    touches, contacts = _touches(name, truth, rng, 0.005)
    features, tolerance = _case(name)[0], _printed(name)

    def sensors(features, printed, grow=0.0, fid=None):
        # A grown feature's contacts' offsets grow with it (as the test's radius derivative takes them).
        grown = [{**c, "rho": c["rho"] + grow} if c["feature"] == fid and "rho" in c else c for c in contacts]
        problem = Problem(build_groups(features, touches, contacts=grown), 0.005, SENSOR_LEVER_MM,
                          tolerance if printed else None)
        return stand_in_tree(problem, threshold_mm2(problem))[0]

    tree = sensors(features, True)
    R0, yc = truth[:3, :3][None], (truth[:3, :3].T @ (tree.centroid - truth[:3, 3]))[None]
    zero = np.zeros(1)
    twist, radius = tree.sensors.cells(R0, zero, yc, zero, tree.root)[6:]
    rows = tree.sensors.row_touch
    step = 1e-6
    checked = 0
    for group in np.unique(rows):
        fid = tree.full.groups[len(tree.problem.groups) + group].feature.id
        modes = tolerance.modes[fid]
        for j in range(len(modes.names)):
            moved = []
            for sign in (1.0, -1.0):
                coordinates = np.zeros(len(modes.names))
                coordinates[j] = sign * step
                # The rows at the cell's pose: value + m.y.
                grow = coordinates @ modes.radius
                _, value, _, m, *_ = sensors({**features, fid: deviated(modes, coordinates)}, False, grow,
                                             fid).sensors.cells(R0, zero, yc, zero, tree.root)
                moved.append((value + np.einsum("ksi,ki->ks", m, yc))[0, rows == group])
            measured = (moved[0] - moved[1]) / (2 * step)
            modelled = twist[0, rows == group] @ modes.twists[j] + radius[0, rows == group] * modes.radius[j]
            assert np.allclose(measured, modelled, rtol=0.0, atol=1e-3 * max(1.0, np.abs(modelled).max())), (fid, j)
            checked += 1
    assert checked >= 3


@pytest.mark.parametrize("name", CASES)
def test_the_search_bounds_hold_with_sensors(name):
    """The same cells through the search's own (which shrinks their y boxes first): no pose sampled in a cell
    left has a cost (the touches' rows and the bounded sensors') below its zeroth-order bound, nor, if it passes,
    below its first-order one (the least-squares pose among them where the cell holds it)."""
    rng, tree, v_true, y_true = _setting(name)
    fit = _passing(tree, v_true, y_true)
    checked = 0
    for v0, w, centre, half in _cells(rng, 300, v_true, y_true):
        cells = tree.cells(v0[None], np.array([w]), (centre @ tree.Q - half)[None], (centre @ tree.Q + half)[None])
        if not np.isfinite(cells.bound[0]):
            continue
        middle, side = 0.5 * (cells.ylo[0] + cells.yhi[0]), 0.5 * (cells.yhi[0] - cells.ylo[0])
        Rs, y = _samples(rng, v0, w, middle, side, truth=fit and (fit[0], fit[1] @ tree.Q))
        y = y @ tree.Q.T
        r = tree.full.evaluate_batch(Rs, tree.centroid - np.einsum("kij,kj->ki", Rs, y))[0]
        points = tree.problem.size
        cost = np.sum(r[:, :points] ** 2, axis=1) + tree.sensors.weight * np.sum(r[:, points:] ** 2, axis=1)
        assert cost.min() >= cells.zeroth[0] * (1 - 1e-9) - 1e-12, (cost.min(), cells.zeroth[0])
        assert np.all(cost >= cells.first[0] * (1 - 1e-9) - 1e-12, where=cost <= tree.root**2), cells.first[0]
        checked += 1
    assert checked >= 40, checked


@pytest.mark.parametrize("name", CASES)
def test_plans_with_bounded_sensors_are_searched_completely(name):
    """Noise-free and with 5 um of placement noise, at three random poses each: register_touches says the
    search is complete, and its best pose is the truth (within 0.1 um and 0.1 urad noise-free; 50 um and 1 mrad
    with noise, a sanity check: bench_search judges the noisy answers)."""
    for seed in range(3):
        for noise_mm in (0.0, 0.005):
            rng = np.random.default_rng(seed)
            truth = np.eye(4)
            truth[:3, :3], truth[:3, 3] = random_rotation(rng), rng.uniform(-80, 80, 3)
            touches, contacts = _touches(name, truth, rng, noise_mm)
            result = register_touches(_case(name)[0], touches, sigma_mm=max(noise_mm, 0.005), contacts=contacts)
            assert result["search"] == "complete", result["search_reason"]
            error_mm, error_rad = pose_errors(np.array(result["solutions"][0]["pose"]), truth)
            assert error_mm <= (0.05 if noise_mm else 1e-4) and error_rad <= (1e-3 if noise_mm else 1e-7)


@pytest.mark.parametrize("printed", [False, True], ids=["exact", "printed"])
def test_flat_touches_beside_line_sensors_are_searched_completely(printed):
    """A design whose touches are flat (balls on planes: their bound takes its least over the y box itself) beside
    line sensors round four bosses (their bound holds the box's half-diagonal): the search splits the y box too, or
    the sensors never bound a cell and the turn is split until the cell limit. Until the split rule counted the
    bounded sensors, this design's search stopped there (exit 6) on an exact part and a printed one; now it is
    complete, ``unique`` and right at three random poses."""
    name = "{S-T1}{C-R-C}{C-R-C}{C-R-C}{C-R-C}"
    features = _features(name)
    tolerance = _tolerance(name, features) if printed else None
    for seed in range(3):
        rng = np.random.default_rng(seed)
        truth = np.eye(4)
        truth[:3, :3], truth[:3, 3] = random_rotation(rng), rng.uniform(-80, 80, 3)
        touches, contacts = plan_touches(_fixture(name).touch_plans()["default"].touches, truth)
        result = register_touches(features, touches, contacts=contacts, tolerance=tolerance)
        assert result["search"] == "complete", result["search_reason"]
        assert result["status"] == "unique"
        error_mm, error_rad = pose_errors(np.array(result["solutions"][0]["pose"]), truth)
        assert error_mm <= 1e-4 and error_rad <= 1e-7


def _edge_poses(tree, truth, rng, count, judge=None, turn=1.0):
    """Poses (R (count, 3, 3), y (count, 3)) on the edge of passing: the truth moved along random twists (their
    turn scaled by ``turn``) until the test's cost reaches T: ``judge``'s (a :class:`.problem.Problem`, deviations
    and all on a printed part, times the sensors' weight), by default the tree's own (the touches' and the bounded
    sensors')."""
    from test_search import _edge_of_passing

    R, t = truth[:3, :3], truth[:3, 3]
    scale = np.concatenate([np.full(3, turn / (tree.rho if len(tree.rho) else tree.marker_rho).max()), np.ones(3)])
    weight = 1.0 if judge is None else tree.sensors.weight
    judge = tree.judge if judge is None else judge

    def cost(twist):
        r = judge.evaluate(R @ rotation_from_vector(twist[:3]), t + twist[3:])[0]
        return weight * (r @ r)

    twists = np.array([_edge_of_passing(cost, rng.normal(size=6) * scale, tree.root**2) for _ in range(count)])
    Rs = R @ rotation_from_vector(twists[:, :3])
    return Rs, np.einsum("kji,kj->ki", Rs, tree.centroid - (t + twists[:, 3:]))


@pytest.mark.parametrize("printed", [False, True], ids=["exact", "printed"])
@pytest.mark.parametrize("name", ["quarter-sphere paper", CUBE_PLANE])
def test_a_plane_sensor_s_normal_starts_the_search_in_boxes_that_hold_every_pose_that_passes(name, printed):
    """Example One's paper plan (a plane sensor lying on a flat, the datum; a line sensor on the edge, a point on
    the sphere and one on the other flat) and the cube's (a plane sensor lying on its left face, which deviates
    on the printed part; points on two other faces), each at 20 random poses, sensors placed with 5 um of noise:
    the search starts from the boxes the sensor's normal leaves (:meth:`.search.Tree.normals`; on the quarter
    sphere the tube about it, :func:`.search.tube_turns`; on the cube beside the top's three touches'), which
    hold the rotation vector of each of 30 poses on the edge of passing; and 20 poses on the edge of the plane
    sensor's own cost passing turn the fixture's normal to within the cone the search draws about the
    sensor's (phi: its turn rows' ``sqrt(T) / L``, plus the printed feature's largest turn), some of them past 0.9
    of it (0.5 printed: the feature's largest turn is a bound these poses do not reach). It fails when the tube's
    boxes are half as wide, or phi is taken two thirds as wide, or on the printed cube without the feature's
    turn."""
    from test_search import in_boxes

    rng = np.random.default_rng(19)
    reached = 0.0
    for _ in range(20):
        problem, truth = _problem(name, rng, 0.005, printed=printed)
        tree = stand_in_tree(problem, threshold_mm2(problem))[0]
        plane = next(k for k, (ctype, *_) in enumerate(tree.sensors.touches) if ctype.is_locus)
        sensed = tree.sensors.touches[plane][1]["n"]
        f, n, phi, _ = next(normal for normal in tree.normals if np.array_equal(normal[1], sensed))
        v0, w0 = tree.first_cells()[:2]
        assert np.max(w0) < 0.2  # (a first-level cell of every rotation: 0.39 rad)
        Rs, _ = _edge_poses(tree, truth, rng, 30)
        assert np.all(in_boxes(vector_from_rotation(Rs), v0, w0))
        judge = Problem([tree.full.groups[len(tree.problem.groups) + plane]], problem.sigma, problem.lever,
                        problem.tolerance)
        Rs, ys = _edge_poses(tree, truth, rng, 20, judge)
        # (Where the sensor's placement noise fails its test at the truth itself, no pose is on the edge.)
        passing = [np.sum(judge.evaluate(R, tree.centroid - R @ y)[0] ** 2) <= tree.root**2 for R, y in zip(Rs, ys)]
        angle = np.arccos(np.clip(np.abs(Rs[passing] @ f @ n), -1.0, 1.0))
        assert np.all(angle <= phi * (1 + 1e-9)), (angle.max(), phi)
        reached = max(reached, angle.max(initial=0.0) / phi)
    assert reached > (0.5 if printed else 0.9), reached


@pytest.mark.parametrize("name,printed", [pytest.param(name, printed, id=f"{name}-{'printed' if printed else 'exact'}")
                                           for name in PRINTED + (BOSSES, PLANES_ON_BOSSES)
                                           for printed in (False, True)])
def test_the_sensors_slabs_hold_every_pose_that_passes(name, printed):
    """Plane sensors lying on planes and bosses, line and cylinder sensors lying on planes, and line sensors round
    bosses, at a random pose, exact and printed (a long lever, so that a shift moves the offset row alone): for
    each such sensor, 20 poses on the edge of its own cost passing (half of them moved mostly by a shift,
    :func:`_edge_poses`), each in 25 cells about it (rotation half-widths from 0.1 mrad to 0.4 rad, y half-widths
    from 3 um to 30 mm, the pose anywhere in the cell), lie in the slab :meth:`.SensorBounds.slabs` draws for y.
    It fails when a slab's reach leaves out the cell's turn, or the printed boss's deviation bound, or is taken
    0.7 times as wide (not 0.9: the slab holds the offset row's share of the sensor's cost by its whitening's
    largest eigenvalue, a little loose)."""
    rng = np.random.default_rng(23)
    problem, truth = _problem(name, rng, 0.0, LONG_LEVER_MM, printed)
    tree = stand_in_tree(problem, threshold_mm2(problem))[0]
    singles = tree.full.groups[len(tree.problem.groups):]
    least, cut = np.inf, 0
    touches = tree.sensors.loci + tree.sensors.crossings  # the slabs' order
    for slab, k in enumerate(touches):
        judge = Problem([singles[k]], problem.sigma, problem.lever, problem.tolerance)
        Rs, ys = (np.concatenate(pair) for pair in zip(_edge_poses(tree, truth, rng, 10, judge),
                                                        _edge_poses(tree, truth, rng, 10, judge, 1e-3)))
        for R, y in zip(Rs, ys):
            v = vector_from_rotation(R)
            for _ in range(25):
                w = np.exp(rng.uniform(np.log(1e-4), np.log(0.4)))
                half = np.exp(rng.uniform(np.log(0.003), np.log(30.0), 3))
                v0, centre = v + rng.uniform(-w, w, 3), y + rng.uniform(-1, 1, 3) * half
                g, low, high = (x[0, slab] for x in tree.sensors.slabs(
                    rotation_from_vector(v0[None]), np.array([np.sqrt(3) * w]), centre[None],
                    np.array([np.linalg.norm(half)]), tree.root))
                assert low <= g @ y + 1e-9 and g @ y <= high + 1e-9, (low, g @ y, high)
                if high - low < np.inf:
                    least = min(least, min(g @ y - low, high - g @ y) / (high - low))
                cut += high - low < 2.0 * np.abs(g) @ half
    # The slabs narrow many cells' boxes, and some pose lies within a fifth of a slab's width of its side.
    assert cut >= 100 * len(touches) and least < 0.2, (cut, least)


@pytest.mark.parametrize("side", ["high", "low"])
def test_a_located_contact_point_s_slab_holds_every_pose_the_verdict_admits(side):
    """The six-boss design's line sensors, their contact points given: at 20 poses a boss (turned up to 0.3 rad
    from a random one and shifted along the boss's axis until one of its contact points lies on the edge of what
    the verdict admits, its patch widened as far as :func:`.verdict.inadmissible` widens it: each point judged by
    the feature's own ``contains``), each in 25 cells about it (as above), y lies in the slab across the boss's
    axis that :meth:`.SensorBounds.located` draws. It fails without the widening or the cell's turn; some pose
    lies within a tenth of the slab's width of its side."""
    rng = np.random.default_rng(29)
    problem, truth = _problem(BOSSES, rng)
    tree = stand_in_tree(problem, threshold_mm2(problem))[0]
    widened = EXTENT_TOLERANCE_MM + EXTENT_WIDENING_MAX_MM
    features = {g.feature.id: g.feature for g in tree.full.groups}
    least = np.inf
    for slab, (x, p, d, *_) in enumerate(tree.sensors.axial):
        feature = next(f for f in features.values() if np.array_equal(f.point, p) and np.array_equal(f.core()[2], d))
        for _ in range(20):
            R = truth[:3, :3] @ rotation_from_vector(rng.normal(size=3) * 0.1)
            y = R.T @ (tree.centroid - truth[:3, 3]) + rng.normal(size=3)
            along = (x - tree.centroid) @ R @ d + (y - p) @ d  # each point's axial parameter at (R, y)
            # ... shifted along the axis so that the farthest point lies on the widened patch's edge.
            if side == "high":
                y = y + (feature.extent.interval[1] + widened - 1e-9 - along.max()) * d
            else:
                y = y + (feature.extent.interval[0] - widened + 1e-9 - along.min()) * d
            local = (x - tree.centroid) @ R + y
            assert np.all(feature.contains(local, widened)) and not np.all(feature.contains(local, 0.9 * widened))
            v = vector_from_rotation(R)
            for _ in range(25):
                w = np.exp(rng.uniform(np.log(1e-4), np.log(0.4)))
                v0 = v + rng.uniform(-w, w, 3)
                low, high = (b[0, slab] for b in tree.sensors.located(rotation_from_vector(v0[None]),
                                                                      np.array([np.sqrt(3) * w])))
                assert low <= d @ y + 1e-9 and d @ y <= high + 1e-9, (low, d @ y, high)
                least = min(least, min(d @ y - low, high - d @ y) / (high - low))
    assert least < 0.1, least
