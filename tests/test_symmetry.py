"""The fixture's symmetries, and the unlabelled search that takes one assignment of each orbit.

Independent answers: the templates' own design (the cube's three faces about its corner's diagonal, the
sphere-plate's three balls at 120 degrees, the quarter-sphere's flats under a half turn; the inclined plane and
the v-block have none), each symmetry checked on the patches' sample points rather than on the constraints it
was found from, and the search that takes every assignment.
"""

import dataclasses
import itertools

import numpy as np
import pytest

from fixturecad.registration import unlabelled
from fixturecad.registration.engine import register_touches
from fixturecad.registration.features import Extent
from fixturecad.registration.patches import patch_points
from fixturecad.registration.pose import fixture2meas_from_rt, pose_errors, random_rotation
from fixturecad.registration.symmetry import symmetries

templates = pytest.importorskip("fixturecad.templates")
build = pytest.importorskip("fixturecad.build")
from fixturecad.registration.features import features_from_json  # noqa: E402

TURNS_DEG = {"cube": [120, 120], "sphere-plate": [120, 120], "quarter-sphere": [180],
             "inclined-plane-cylinder": [], "v-block": []}


def _surfaces(name):
    features = features_from_json(build.features_document(templates.make(name)))
    return features, [f for f in features.values() if f.surface]


@pytest.mark.parametrize("name", sorted(TURNS_DEG))
def test_the_templates_symmetries_are_their_designs(name):
    features, surfaces = _surfaces(name)
    found = symmetries(surfaces)
    turns = sorted(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))) for R, _, _ in found)
    assert np.allclose(turns, TURNS_DEG[name], atol=1e-6)
    for R, t, image in found:
        assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)
        for f in surfaces:
            # Each patch's own sample points, moved, lie on the image's surface and patch.
            g = features[image[f.id]]
            moved = patch_points(f) @ R.T + t
            assert np.abs(g.signed_distance(moved)).max() < 1e-6
            assert g.contains(moved, 1e-3).all()


def test_a_ball_moved_a_micrometre_or_a_patch_grown_breaks_the_symmetry():
    features, surfaces = _surfaces("sphere-plate")
    moved = dataclasses.replace(surfaces[0], center=surfaces[0].center + [0.001, 0.0, 0.0])
    assert symmetries([moved] + surfaces[1:]) == []
    e = surfaces[1].extent
    grown = dataclasses.replace(surfaces[1], extent=Extent(e.halfspaces + [0, 0, 0, 0.01], e.balls, e.cylinders,
                                                          e.interval))
    assert symmetries([surfaces[0], grown, surfaces[2]]) == []
    # Two balls alone: one direction between them pins no rotation, so none is looked for (a search not saved).
    assert symmetries(surfaces[:2]) == []


@pytest.mark.parametrize("name, counts", [("sphere-plate", {"ball_1": 4, "ball_2": 4, "ball_3": 4}),
                                          ("cube", {"top": 4, "front": 4, "left": 4}),
                                          ("quarter-sphere", {"flat_a": 4, "flat_b": 4, "sphere": 4})])
def test_one_assignment_of_each_orbit_finds_what_all_of_them_find(name, counts, monkeypatch):
    features = features_from_json(build.features_document(templates.make(name)))
    rng = np.random.default_rng(11)
    for _ in range(6):
        R, t = random_rotation(rng), rng.uniform(-80.0, 80.0, 3)
        points = np.concatenate([patch_points(features[f])[rng.choice(len(patch_points(features[f])), n, replace=False)]
                                 for f, n in counts.items()]) @ R.T + t + rng.normal(0.0, 0.005, (12, 3))
        taken = register_touches(features, {}, unlabelled=points, sigma_mm=0.005)
        with monkeypatch.context() as m:
            m.setattr(unlabelled, "symmetries", lambda surfaces: [])
            every = register_touches(features, {}, unlabelled=points, sigma_mm=0.005)
        assert (taken["status"], taken["search"]) == (every["status"], every["search"]) == ("ambiguous", "complete")
        assert len(taken["solutions"]) == len(every["solutions"])
        for s in taken["solutions"]:
            assert min(pose_errors(np.array(s["pose"]), np.array(e["pose"]))[0] for e in every["solutions"]) < 1e-4
        truth = fixture2meas_from_rt(R, t)
        assert min(pose_errors(np.array(s["pose"]), truth)[0] for s in taken["solutions"]) < 0.05


@pytest.mark.parametrize("name", ["cube", "sphere-plate", "quarter-sphere", "v-block"])
def test_the_symmetries_found_are_a_group(name):
    """The search turns each orbit's least assignment by each symmetry once, which reaches the whole orbit only
    if every product of two symmetries is one of them (or the identity): on the sensing features and on every
    face of the solid (the cube's 24 turns)."""
    surfaces = [f for f in features_from_json(build.features_document(templates.make(name))).values() if f.surface]
    faces = symmetries(list(_faces(name).values()))
    assert len(faces) == {"cube": 23, "v-block": 1}.get(name, 0)
    for found in (symmetries(surfaces), faces):
        motions = [(np.eye(3), np.zeros(3))] + [(R, t) for R, t, _ in found]
        for (R1, t1), (R2, t2) in itertools.product(motions, motions):
            R, t = R1 @ R2, R1 @ t2 + t1
            assert any(np.allclose(R, Rk, atol=1e-7) and np.allclose(t, tk, atol=1e-5) for Rk, tk in motions)


def _faces(name):
    """Every face of the template's solid as a feature (features.json's ``faces``), by id."""
    cad = pytest.importorskip("fixturecad.cad.faces")
    from fixturecad.cad.solid import fixture_solid

    return {f.id: f for f in cad.face_features(fixture_solid(templates.make(name)))[0]}
