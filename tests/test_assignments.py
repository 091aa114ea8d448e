"""The assignments unlabelled touches' shape admits (registration/assignments.py): none under which a pose may
pass is left out.

Independent answers: touches drawn on each feature's patch and moved off its surface by their whole reach, in
or out, at a random pose, so that each test's premise holds at its edge: their own assignment must be admitted.
Each quad test alone against quads drawn the same way, and against quads that plainly cannot lie on the element;
the boxes' distances against sampled points; the axis search against touches on a cylinder or a line, with and
without a plane's touches among them or beside them, and its ranges against the exact distance from a tilted line.
"""

import numpy as np
import pytest

from fixturecad.registration import assignments
from fixturecad.registration.assignments import admitted
from fixturecad.registration.elements import perpendicular_basis
from fixturecad.registration.patches import patch_points
from fixturecad.registration.pose import random_rotation
from fixturecad.registration.touches import point_touches

templates = pytest.importorskip("fixturecad.templates")
build = pytest.importorskip("fixturecad.build")
from fixturecad.registration.features import features_from_json  # noqa: E402

REACH_MM = 0.03
LAYOUTS = 200


def _features(name):
    return features_from_json(build.features_document(templates.make(name)))


def _drawn(features, counts, rng, ball_mm=0.0, reach_mm=REACH_MM):
    """Touches (ball centres) on the features' patches, each moved off its surface by +-reach_mm, at a random
    pose, in a random order: (points (n, 3), their feature ids)."""
    R, t = random_rotation(rng), rng.uniform(-80.0, 80.0, 3)
    points, ids = [], []
    for fid, n in counts.items():
        on = patch_points(features[fid])
        on = on[rng.choice(len(on), n, replace=False)]
        off = ball_mm + reach_mm * rng.choice([-1.0, 1.0], n)
        points.append(on + off[:, None] * features[fid].normal_at(on))
        ids += [fid] * n
    order = rng.permutation(len(ids))
    return (np.concatenate(points) @ R.T + t)[order], [ids[k] for k in order]


@pytest.mark.parametrize("name,counts,ball_mm", [
    ("cube", {"top": 4, "front": 4, "left": 4}, 0.0),
    ("v-block", {"groove_a": 4, "groove_b": 4, "end": 4}, 1.5),
    ("quarter-sphere", {"flat_a": 4, "flat_b": 4, "sphere": 4}, 1.5),
    ("sphere-plate", {"ball_1": 4, "ball_2": 4, "ball_3": 4}, 0.0),
    ("inclined-plane-cylinder", {"plane": 6, "cylinder": 6}, 1.5),
])
def test_the_touches_own_assignment_is_admitted(name, counts, ball_mm):
    """200 layouts a template, every touch off its surface by its whole reach: the true assignment is among the
    admitted ones every time, point probes and balls, and with two touches labelled (which go first)."""
    features = _features(name)
    surfaces = [f for f in features.values() if f.surface]
    rng = np.random.default_rng(11)
    for layout in range(LAYOUTS):
        points, ids = _drawn(features, counts, rng, ball_mm)
        groups = []
        if layout % 2:
            groups = [point_touches(features[ids[k]], points[k:k + 1], np.array([k]), ball_mm) for k in range(2)]
            points, ids = points[2:], ids[2:]
        leaves, reason, _ = admitted(groups, surfaces, points, ball_mm, None, 1.0, REACH_MM)
        assert not reason and tuple(ids) in leaves, (name, layout)


def _quads(feature, count, rng, off_mm):
    """``count`` quads of touches on the feature's patch, each moved off its surface by one of ``off_mm``."""
    on = patch_points(feature)
    on = on[rng.choice(len(on), (count, 4))]
    off = rng.choice(off_mm, (count, 4))
    return on + off[..., None] * feature.normal_at(on.reshape(-1, 3)).reshape(count, 4, 3)


@pytest.mark.parametrize("name,fid", [("cube", "top"), ("quarter-sphere", "sphere"),
                                      ("inclined-plane-cylinder", "cylinder")])
def test_each_quad_test_passes_every_quad_within_reach(name, fid):
    """2,000 quads on the element, each touch off it by its whole reach in or out: every one passes. (A plane's
    slab made 10 % narrower fails 16 % of them, a sphere's 0.1 %.)"""
    feature = _features(name)[fid]
    core, _, _, radius = feature.core()
    quads = _quads(feature, 2000, np.random.default_rng(5), [-REACH_MM, REACH_MM])
    assert assignments.QUAD_TESTS[core](quads, radius, REACH_MM).all()


@pytest.mark.parametrize("name,fid,radius_mm,share", [("cube", "top", None, 0.9),
                                                       ("quarter-sphere", "sphere", None, 0.75),
                                                       ("inclined-plane-cylinder", "plane", 5.0, 0.5)])
def test_each_quad_test_fails_most_quads_that_cannot_lie_on_its_element(name, fid, radius_mm, share):
    """2,000 quads that cannot lie on the element: two touches of a plane's or a sphere's 1.2 mm (40 reaches)
    off it, and a plane's touches taken for a cylinder of radius 5 mm. The test fails most of them (what share
    it catches is what it prunes: the cylinder's only where touches lie farther apart than its diameter)."""
    feature = _features(name)[fid]
    core, _, _, radius = feature.core()
    quads = _quads(feature, 2000, np.random.default_rng(6), [0.0])
    if radius_mm is None:
        moved = quads[:, :2].reshape(-1, 3)
        quads[:, :2] += 40 * REACH_MM * feature.normal_at(moved).reshape(-1, 2, 3)
        test = assignments.QUAD_TESTS[core]
    else:
        radius, test = radius_mm, assignments.QUAD_TESTS["line"]
    assert (~test(quads, radius, REACH_MM)).mean() > share


def test_box_distances_are_the_least_and_greatest_between_the_boxes_points():
    """Random boxes, overlapping or apart, one unbounded: 20,000 points of each pair's boxes (their corners
    among them) lie between the least and the greatest distance, which the corners and the nearest points
    reach."""
    rng = np.random.default_rng(3)
    low = rng.uniform(-50.0, 50.0, (6, 3))
    high = low + rng.uniform(0.0, 40.0, (6, 3))
    low[5, 0] = -np.inf
    least, most = assignments.box_distances(low, high)
    assert np.isinf(most[5]).all() and np.isinf(most[:, 5]).all()
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)])
    for s in range(5):
        for t in range(5):
            a = low[s] + rng.uniform(0.0, 1.0, (20000, 3)) * (high[s] - low[s])
            b = low[t] + rng.uniform(0.0, 1.0, (20000, 3)) * (high[t] - low[t])
            d = np.linalg.norm(a - b, axis=1)
            assert d.min() >= least[s, t] - 1e-9 and d.max() <= most[s, t] + 1e-9
            ends_s, ends_t = low[s] + corners * (high[s] - low[s]), low[t] + corners * (high[t] - low[t])
            assert np.isclose(np.linalg.norm(ends_s[:, None] - ends_t[None], axis=2).max(), most[s, t])
            # The nearest points: each axis's overlap, or the facing faces.
            near_s = np.clip(0.5 * (low[t] + high[t]), low[s], high[s])
            near_t = np.clip(near_s, low[t], high[t])
            near_s = np.clip(near_t, low[s], high[s])
            assert np.isclose(np.linalg.norm(near_s - near_t), least[s, t])


def test_a_cylinders_quad_at_the_edge_of_its_cones_passes():
    """Touches on alternate sides of the cylinder, each its reach outside it, zig-zag along its axis: each
    pair's difference makes exactly its cone's angle with the axis, so the cones only just meet; the quad passes
    (a cone computed from the bare diameter fails it), turned anywhere."""
    rng = np.random.default_rng(8)
    feature = _features("inclined-plane-cylinder")["cylinder"]
    _, anchor, axis, radius = feature.core()
    across = np.cross(axis, [1.0, 0.0, 0.0])
    across /= np.linalg.norm(across)
    for _ in range(50):
        step = rng.uniform(5.0, 40.0)
        quad = np.array([anchor + (-1) ** k * (radius + REACH_MM) * across + k * step * axis for k in range(4)])
        R = random_rotation(rng)
        assert assignments.QUAD_TESTS["line"](quad[None] @ R.T, radius, REACH_MM).all()


def _on_cylinder(feature, count, rng, reach_mm=REACH_MM):
    """``count`` touches on the cylinder's patch, each off it by +-reach_mm, at a random pose."""
    on = patch_points(feature)
    on = on[rng.choice(len(on), count, replace=False)]
    on = on + reach_mm * rng.choice([-1.0, 1.0], count)[:, None] * feature.normal_at(on)
    return on @ random_rotation(rng).T + rng.uniform(-80.0, 80.0, 3)


def test_touches_on_a_cylinder_fit_an_axis():
    """200 sets of 5 to 12 touches on the inclined plane's cylinder, each off it by its whole reach, at random
    poses: every one fits an axis; so does every set on a line (radius 0) of a boss, touched by a point probe
    on its axis."""
    feature = _features("inclined-plane-cylinder")["cylinder"]
    rng = np.random.default_rng(12)
    sets = [_on_cylinder(feature, rng.integers(5, 13), rng) for _ in range(200)]
    radius = feature.core()[3]
    assert assignments.fit_an_axis(sets, radius, REACH_MM).all()
    _, anchor, axis, _ = feature.core()
    # Each off the line by up to its reach (a normal draw's tail would put some beyond it: no axis then).
    across = np.stack(perpendicular_basis(axis))

    def off(n):
        angle = rng.uniform(0.0, 2.0 * np.pi, n)
        return REACH_MM * rng.uniform(0.0, 1.0, (n, 1)) * np.column_stack([np.cos(angle), np.sin(angle)]) @ across

    lines = [(anchor + rng.uniform(-60.0, 20.0, (n, 1)) * axis + off(n)) @ random_rotation(rng).T
             for n in rng.integers(5, 13, 50)]
    assert assignments.fit_an_axis(lines, 0.0, REACH_MM).all()


def test_a_cylinders_touches_with_the_planes_fit_no_axis():
    """The same cylinder's touches (six) with one or two of the inclined plane's that lie 1 mm or more off the
    cylinder (200 sets): the search finds no axis for most of them. (The plane's touches alone it does not
    refute: seen along the plane, their images lie nearly on a line, and the parallelogram its two slabs leave
    is too long to tell.)"""
    features = _features("inclined-plane-cylinder")
    cylinder, plane = features["cylinder"], features["plane"]
    _, anchor, axis, radius = cylinder.core()
    flat = patch_points(plane)
    off = np.abs(np.linalg.norm(np.cross(flat - anchor, axis), axis=1) - radius) >= 1.0
    flat = flat[off]
    rng = np.random.default_rng(13)
    sets = []
    for _ in range(200):
        on = patch_points(cylinder)
        on = on[rng.choice(len(on), 6, replace=False)]
        sets.append(np.vstack([on, flat[rng.choice(len(flat), rng.integers(1, 3), replace=False)]])
                    @ random_rotation(rng).T)
    assert (~assignments.fit_an_axis(sets, radius, REACH_MM)).mean() > 0.9


def test_an_axis_keeps_its_angle_to_a_planes_normal():
    """200 layouts of the inclined plane and cylinder, 5 to 8 touches on the cylinder and 3 to 6 on the plane,
    each off its surface by its whole reach, at a random pose: the cylinder's touches fit an axis in the band the
    plane's touches leave (:meth:`.assignments.Tables.bands`) every time, and in most layouts none in the band
    turned by 0.3 rad from the fixture's angle (the band, not the touches alone, rules those out)."""
    features = _features("inclined-plane-cylinder")
    cylinder, plane = features["cylinder"], features["plane"]
    rng = np.random.default_rng(23)
    sets, bands = [], []
    for _ in range(LAYOUTS):
        counts = {"cylinder": int(rng.integers(5, 9)), "plane": int(rng.integers(3, 7))}
        points, ids = _drawn(features, counts, rng)
        on = np.array(ids) == "plane"
        tables = assignments.Tables([cylinder, plane], np.array([cylinder.core()[3], 0.0]), points, None, 1.0,
                                    REACH_MM)
        sets.append(points[~on])
        bands.append(tables.bands(0, np.array([1]), on[None]))
    normal, width, angle = (np.concatenate(b) for b in zip(*bands))
    radius = cylinder.core()[3]
    assert np.isfinite(width).all()
    assert assignments.fit_an_axis(sets, radius, REACH_MM, (normal, width, angle)).all()
    assert (~assignments.fit_an_axis(sets, radius, REACH_MM, (normal, width, angle + 0.3))).mean() > 0.9


def test_planes_touches_keep_their_normals_angle():
    """200 layouts of the v-block's three faces, 3 to 6 touches each, each off its face by its whole reach, at
    a random pose: the true assignment keeps every two faces' normals at their angle (:meth:`.assignments.Tables.
    at_angles`) every time; with one touch of a groove and one of the end swapped (no test but the angles
    applied), most do not."""
    features = _features("v-block")
    ids = ["groove_a", "groove_b", "end"]
    rng = np.random.default_rng(24)
    kept, swapped = 0, 0
    for _ in range(LAYOUTS):
        counts = {fid: int(rng.integers(3, 7)) for fid in ids}
        points, drawn = _drawn(features, counts, rng)
        tables = assignments.Tables([features[f] for f in ids], np.zeros(3), points, None, 1.0, REACH_MM)
        row = np.array([ids.index(f) for f in drawn])
        kept += len(tables.at_angles(row[None]))
        wrong = row.copy()
        a, b = rng.choice(np.flatnonzero(row == rng.integers(0, 2))), rng.choice(np.flatnonzero(row == 2))
        wrong[a], wrong[b] = row[b], row[a]
        swapped += len(tables.at_angles(wrong[None]))
    assert kept == LAYOUTS
    assert swapped < 0.1 * LAYOUTS


def test_a_touchs_distance_from_a_tilted_axis_lies_in_its_range():
    """2,000 sets of six touches on a cylinder (radius 20 mm, 80 mm long, about a random axis through the
    origin), each off it by its whole reach, and a direction a0 turned from its axis by up to 0.3 rad towards a
    random side: each touch's distance from the line along a0 through the axis's point nearest their centroid
    lies in its range. Ranges 20 % narrower miss on some sets."""
    rng = np.random.default_rng(21)
    radius, count = 20.0, 2000
    axis = np.array([random_rotation(rng)[:, 0] for _ in range(count)])
    across = np.cross(axis, rng.normal(size=(count, 3)))
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    tilt = np.cross(axis, across)
    beta = rng.uniform(0.0, 0.3, (count, 1))
    a0 = np.cos(beta) * axis + np.sin(beta) * tilt
    angle = rng.uniform(0.0, 2.0 * np.pi, (count, 6, 1))
    off = radius + REACH_MM * rng.choice([-1.0, 1.0], (count, 6, 1))
    points = (off * (np.cos(angle) * across[:, None] + np.sin(angle) * tilt[:, None])
              + rng.uniform(-40.0, 40.0, (count, 6, 1)) * axis[:, None])
    centre = points.mean(axis=1)
    nearest = np.einsum("ki,ki->k", centre, axis)[:, None] * axis
    rel = points - nearest[:, None]
    seen = np.linalg.norm(rel - np.einsum("kmi,ki->km", rel, a0)[..., None] * a0[:, None], axis=2)
    centred = points - centre[:, None]
    lo, hi = assignments.axis_ranges(centred, np.linalg.norm(centred, axis=2), a0, beta, radius, REACH_MM)
    assert np.all((seen >= lo - 1e-9) & (seen <= hi + 1e-9))
    slack = hi - radius
    narrow = (seen < radius - 0.8 * slack) | (seen > radius + 0.8 * slack)
    assert narrow.any(axis=1).mean() > 0.01
