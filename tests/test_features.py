"""Analytic features: distances, projections, extents, JSON round trip, no cadquery."""

import subprocess
import sys

import numpy as np
import pytest

from fixturecad.registration.features import (
    Cylinder,
    Extent,
    Line,
    Plane,
    Point,
    Sphere,
    check_points,
    feature_from_json,
)

RNG_SEED = 20261121


def _examples():
    half_disc = Extent(halfspaces=[[0, -1, 0, 0]], balls=[[0, 0, 0, 40]])
    return [
        Plane("flat", [0, 0, 0], [0, 0, -1], extent=half_disc),
        Sphere("ball", [1, 2, 3], 40, extent=Extent(halfspaces=[[0, 0, -1, 0]])),
        Cylinder("pin", [0, 0, 0], [0, 0, 1], 20, extent=Extent(interval=(-60, 0))),
        Line("edge", [0, 0, 0], [1, 0, 0], extent=Extent(interval=(-40, 40))),
        Point("tip", [5, 5, 5]),
    ]


@pytest.mark.parametrize("feature", _examples(), ids=lambda f: f.kind)
def test_closest_point_lies_on_feature_and_distance_matches(feature):
    rng = np.random.default_rng(RNG_SEED)
    points = rng.uniform(-80, 80, size=(50, 3))
    closest = feature.closest_point(points)
    assert np.allclose(feature.signed_distance(closest), 0.0, atol=1e-9) or feature.kind == "point"
    gap = np.linalg.norm(points - closest, axis=1)
    assert np.allclose(np.abs(feature.signed_distance(points)), gap, atol=1e-9)
    normals = feature.normal_at(points)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
    if feature.kind in ("plane", "sphere", "cylinder"):
        # outward normal: stepping along it increases the signed distance
        assert np.all(feature.signed_distance(closest + 0.1 * normals) > 0)


@pytest.mark.parametrize("feature", _examples(), ids=lambda f: f.kind)
def test_json_round_trip(feature):
    again = feature_from_json(feature.to_json())
    assert again.to_json() == feature.to_json()
    assert again.element == {"plane": "PL", "sphere": "S", "cylinder": "C", "line": "L", "point": "P"}[
        feature.kind
    ]


def test_contains_respects_extent():
    plane, sphere, cylinder, line, _ = _examples()
    assert plane.contains([[0, 10, 3], [0, -10, 3], [0, 39.9, 0], [0, 41, 0]]).tolist() == [
        True,
        False,
        True,
        False,
    ]
    assert sphere.contains([[1, 2, -100], [1, 2, 100]]).tolist() == [False, True]
    assert cylinder.contains([[20, 0, -1], [20, 0, 1]]).tolist() == [True, False]
    assert line.contains([[39, 3, 0], [41, 0, 0]]).tolist() == [True, False]


def test_normals_are_normalised_and_sensing_default():
    plane = Plane("p", [0, 0, 0], [0, 0, -3])
    assert np.allclose(plane.normal, [0, 0, -1])
    assert plane.sensing == "mobile"
    with pytest.raises(ValueError, match="sensing"):
        Plane("p", [0, 0, 0], [0, 0, 1], sensing="maybe")


def test_bad_shapes_raise_value_error_naming_the_shape():
    with pytest.raises(ValueError, match=r"\(3, 2\)"):
        check_points(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="non-zero"):
        Plane("p", [0, 0, 0], [0, 0, 0])
    with pytest.raises(ValueError, match="positive"):
        Sphere("s", [0, 0, 0], -1)
    with pytest.raises(ValueError, match="kind"):
        feature_from_json({"id": "x", "kind": "torus"})


def test_features_module_does_not_import_cadquery():
    code = (
        "import sys, fixturecad.registration.features\n"
        "assert 'cadquery' not in sys.modules and 'OCP' not in sys.modules\n"
        "assert not any(m.startswith('fixturecad.') and not m.startswith('fixturecad.registration')"
        " for m in sys.modules if m != 'fixturecad')\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_one_element_table():
    """The schema's feature kinds, the feature classes and the contact letters are the element table's;
    an unknown kind is an error, never a point."""
    import json
    from pathlib import Path

    from fixturecad.registration.elements import ELEMENTS, KINDS, element
    from fixturecad.registration.features import FEATURE_CLASSES
    from fixturecad.registration.touches import fixture_side

    schema = json.loads((Path(__file__).parent.parent / "fixturecad" / "schema" / "features.schema.json").read_text())
    # The kinds a features.json may hold, read from the schema's list of feature entries.
    entries = [schema["$defs"][ref["$ref"].split("/")[-1]] for ref in schema["properties"]["features"]["items"]["oneOf"]]
    kinds = {entry["properties"]["kind"]["const"] for entry in entries}
    assert kinds == set(KINDS) == set(FEATURE_CLASSES)
    for e in ELEMENTS:
        assert schema["$defs"][e.kind]["properties"]["element"]["const"] == e.letter
        assert set(e.json_keys) <= set(schema["$defs"][e.kind]["required"])
    with pytest.raises(ValueError, match="unknown element 'torus'"):
        element("torus")

    class Torus:
        kind = "torus"

    with pytest.raises(ValueError, match="unknown element"):
        fixture_side(Torus(), False)


def test_distances_are_the_contact_rows():
    """A point probe's row on a mobile element is the feature's signed distance (one geometry)."""
    from fixturecad.registration.contacts import ContactType, make_side, residuals_and_jacobian
    from fixturecad.registration.touches import fixture_side

    rng = np.random.default_rng(3)
    points = rng.uniform(-30, 30, size=(20, 3))
    for feature in (Plane("p", [1, 2, 3], [0, 0.6, 0.8]), Sphere("s", [1, 2, 3], 7.0),
                    Cylinder("c", [1, 2, 3], [0.6, 0, 0.8], 5.0)):
        ctype = ContactType("P", True, feature.element, False)
        rows, _ = residuals_and_jacobian(ctype, make_side("P", True, c=points, o=points),
                                         fixture_side(feature, False), np.eye(3), np.zeros(3))
        assert np.allclose(rows[:, 0], feature.signed_distance(points), atol=1e-12)


def test_ball_tip_rows_are_the_distance_less_both_radii():
    """A ball tip's row (two mobile elements) is the distance from the feature's core less the feature's
    and the ball's radii, against the distances written out for a plane, a sphere and a cylinder."""
    from fixturecad.registration.contacts import residuals_and_jacobian
    from fixturecad.registration.touches import point_touches

    rng = np.random.default_rng(RNG_SEED)
    centres = rng.uniform(-30, 30, size=(20, 3))
    ball_mm = 1.5
    q, n = np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.6, 0.8])
    axial = (centres - q) - np.outer((centres - q) @ n, n)
    expected = {
        "plane": (centres - q) @ n - ball_mm,
        "sphere": np.linalg.norm(centres - q, axis=1) - 7.0 - ball_mm,
        "cylinder": np.linalg.norm(axial, axis=1) - 5.0 - ball_mm,
    }
    for feature in (Plane("p", q, n), Sphere("s", q, 7.0), Cylinder("c", q, n, 5.0)):
        group = point_touches(feature, centres, np.arange(len(centres)), ball_mm)
        rows, _ = residuals_and_jacobian(group.ctype, group.sensor, group.fixture, np.eye(3), np.zeros(3), group.rho)
        assert np.allclose(rows[:, 0], expected[feature.kind], atol=1e-12)


@pytest.mark.parametrize("name", ["cube", "inclined-plane-cylinder", "quarter-sphere", "sphere-plate", "v-block"])
def test_a_patch_s_box_holds_every_point_of_the_patch(name):
    """Every feature of each template (and of :func:`_examples`): 50,000 points drawn in the patch's box grown by
    20 mm, moved onto the feature (``closest_point``) and kept where its patch holds them (``contains``), a sampler
    other than the grid the box comes from, lie in :func:`.patches.patch_box`: the search's bounds and first cells
    take a touch that passes to lie near it (docs/registration.md, the complete search, 2)."""
    from fixturecad.build import features_document
    from fixturecad.registration.features import features_from_json
    from fixturecad.registration.patches import patch_box
    from fixturecad.templates import make

    rng = np.random.default_rng(RNG_SEED)
    for feature in list(features_from_json(features_document(make(name))).values()) + _examples():
        low, high = patch_box(feature)
        if not np.all(np.isfinite(low) & np.isfinite(high)):
            continue
        points = feature.closest_point(rng.uniform(low - 20.0, high + 20.0, (50000, 3)))
        points = points[feature.contains(points, 0.0)]
        assert len(points) > 0
        assert np.all((points >= low - 1e-9) & (points <= high + 1e-9)), feature.id
