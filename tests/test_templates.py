"""Templates: solids, analytic volumes, features read back from the BREP, plans, validation, base."""

import math

import numpy as np
import pytest

from fixturecad.cad.brep import match_features, read_faces
from fixturecad.cad.solid import base_solid, fixture_solid
from fixturecad.errors import InputError
from fixturecad.fixture_commands import class_members
from fixturecad.registration.contacts import ContactType
from fixturecad.templates import TEMPLATES, make
from fixturecad.templates.base import BASE_CLEARANCE_MM
from fixturecad.theory.enumeration import class_of_contacts

cq = pytest.importorskip("cadquery")

NAMES = list(TEMPLATES)
RNG_SEED = 8
ON_FACE_MM = 1e-5


@pytest.fixture(scope="module")
def instances():
    """(template, solid) per (name, base), built once."""
    cache = {}
    for name in NAMES:
        for base in (False, True):
            fixture = make(name, base=base)
            cache[name, base] = (fixture, fixture_solid(fixture))
    return cache


def test_required_templates_are_registered():
    assert {"cube", "quarter-sphere", "inclined-plane-cylinder"} <= set(TEMPLATES)
    assert len(TEMPLATES) >= 5


@pytest.mark.parametrize("base", [False, True], ids=["bare", "base"])
@pytest.mark.parametrize("name", NAMES)
def test_solid_is_one_valid_solid_with_the_analytic_volume(instances, name, base):
    fixture, solid = instances[name, base]
    assert solid.isValid()
    assert len(solid.Solids()) == 1
    assert solid.Volume() == pytest.approx(fixture.volume(), rel=1e-6)


def test_analytic_volumes_of_the_paper_fixtures():
    assert make("quarter-sphere", radius=40).volume() == pytest.approx(math.pi * 40**3 / 3)
    assert make("cube", size=50).volume() == pytest.approx(50**3)
    cylinder = make("inclined-plane-cylinder", radius=20, angle=45, length=40)
    assert cylinder.volume() == pytest.approx(math.pi * 20**2 * (20 + 40))


def _sample_patch(feature, solid, count, rng):
    """Points on the feature's finite patch: random points near the solid projected on the feature."""
    box = solid.BoundingBox()
    low = np.array([box.xmin, box.ymin, box.zmin]) - 1.0
    high = np.array([box.xmax, box.ymax, box.zmax]) + 1.0
    points = feature.closest_point(rng.uniform(low, high, size=(20 * count, 3)))
    return points[feature.contains(points, 0.0)][:count]


def _distance(shape, point) -> float:
    return shape.distance(cq.Vertex.makeVertex(*point))


@pytest.mark.parametrize("base", [False, True], ids=["bare", "base"])
@pytest.mark.parametrize("name", NAMES)
def test_features_are_faces_and_edges_of_the_solid(instances, name, base):
    fixture, solid = instances[name, base]
    matches = match_features(solid, fixture.features())
    faces = solid.Faces()
    edges = solid.Edges()
    rng = np.random.default_rng(RNG_SEED)
    for feature in fixture.features():
        shapes = [edges[i] for i in matches[feature.id]] if feature.kind == "line" else [faces[i] for i in matches[feature.id]]
        # every point of the sensing patch lies on the solid's own face or edge
        patch = _sample_patch(feature, solid, 40, rng)
        assert len(patch) >= 10, feature.id
        for point in patch:
            assert min(_distance(s, point) for s in shapes) < ON_FACE_MM, (feature.id, point)


@pytest.mark.parametrize("name", NAMES)
def test_bare_faces_lie_inside_their_feature_extent(instances, name):
    """Without a base, the patch is the whole face: every tessellation node of it is inside the extent."""
    from fixturecad.cad.mesh import triangulate

    fixture, solid = instances[name, False]
    features = fixture.features()
    matches = match_features(solid, features)
    parts = triangulate(solid, 0.05)
    for feature in features:
        if feature.kind == "line":
            ends = np.array([[e.startPoint().toTuple(), e.endPoint().toTuple()] for e in
                             (solid.Edges()[i] for i in matches[feature.id])]).reshape(-1, 3)
            t = (ends - feature.point) @ feature.direction
            assert t.min() == pytest.approx(feature.extent.interval[0]) and t.max() == pytest.approx(feature.extent.interval[1])
            continue
        for index in matches[feature.id]:
            nodes = parts[index][1]
            assert np.all(np.abs(feature.signed_distance(nodes)) < 1e-6), feature.id
            if feature.id == "end":  # v-block: the sensing patch is the rectangle below the groove
                continue
            assert feature.contains(nodes, 1e-6).all(), feature.id


@pytest.mark.parametrize("name", NAMES)
def test_brep_surface_parameters_match_features(instances, name):
    fixture, solid = instances[name, False]
    faces = read_faces(solid)
    matches = match_features(solid, fixture.features())
    for feature in fixture.features():
        for index in matches[feature.id] if feature.kind != "line" else []:
            info = faces[index]
            if feature.kind == "sphere":
                assert info.geom_type == "SPHERE"
                assert np.allclose(info.params["center"], feature.center) and info.params["radius"] == pytest.approx(feature.radius)
            elif feature.kind == "cylinder":
                assert info.geom_type == "CYLINDER" and info.params["radius"] == pytest.approx(feature.radius)
            else:
                assert info.geom_type == "PLANE" and np.allclose(info.normal, feature.normal)


@pytest.mark.parametrize("name", NAMES)
def test_touch_plans_lie_on_their_features_and_match_their_class(name):
    fixture = make(name)
    features = fixture.feature_map()
    plans = fixture.touch_plans()
    assert "default" in plans
    assert plans["default"].contact_class == fixture.contact_class
    for plan_name, plan in plans.items():
        contacts = []
        for entry in plan.touches:
            feature = features[entry["feature"]]
            ctype = ContactType.parse(entry["contact"])
            assert ctype.fixture == feature.element, (plan_name, entry)
            points = np.array(entry["points"])
            assert np.allclose(feature.signed_distance(points), 0.0, atol=1e-9), (plan_name, entry)
            assert feature.contains(points).all(), (plan_name, entry)
            if ctype.sensor != "P":
                assert entry["sensor"]["kind"] == {"PL": "plane", "L": "line"}[ctype.sensor]
            contacts += [entry["contact"]] * (len(points) if ctype.sensor == "P" else 1)
        # the plan's class is realised by its touches (extra touches only remove finite solutions)
        realised = list(class_of_contacts(contacts))
        for member in class_members(plan.contact_class):
            assert member in realised, (plan_name, member, realised)
            realised.remove(member)


def test_quarter_sphere_has_the_papers_features_and_a_point_probe_plan():
    fixture = make("quarter-sphere", radius=40)
    kinds = {f.id: f.kind for f in fixture.features()}
    assert kinds == {"flat_a": "plane", "flat_b": "plane", "sphere": "sphere", "edge": "line"}
    plans = fixture.touch_plans()
    assert {entry["contact"] for entry in plans["paper"].touches} == {"PL/F-PL/F", "P/F-S/M", "P/F-PL/M", "L/M-L/M"}
    probe = plans["point-probe"].touches
    assert all(entry["contact"].startswith("P/F-") for entry in probe)
    sphere_points = sum(len(e["points"]) for e in probe if e["feature"] == "sphere")
    assert sphere_points >= 2  # one sphere touch leaves two solutions along the edge


def test_inclined_plane_cylinder_frame_follows_the_paper():
    fixture = make("inclined-plane-cylinder", radius=20, angle=30)
    plane, cylinder = fixture.features()
    s, n = cylinder.axis, plane.normal
    assert np.allclose(s, [0, 0, 1])
    assert np.degrees(np.arccos(n @ s)) == pytest.approx(90 - 30)  # plane at 30 deg to the axis
    y = np.cross(n, s)
    assert np.allclose(y / np.linalg.norm(y), [0, 1, 0])
    assert np.allclose(np.cross([0, 1, 0], s), [1, 0, 0])  # X = Y x Z
    assert np.allclose(plane.point, 0) and plane.signed_distance([0, 0, 0])[0] == 0  # origin on the axis and plane
    cylinder_touches = [e for e in fixture.touch_plans()["minimal"].touches if e["feature"] == "cylinder"]
    assert sum(len(e["points"]) for e in cylinder_touches) == 4


@pytest.mark.parametrize("name", NAMES)
def test_base_never_touches_a_sensing_feature(instances, name):
    fixture, solid = instances[name, True]
    base = base_solid(fixture.anchor())
    rng = np.random.default_rng(RNG_SEED)
    for feature in fixture.features():
        patch = _sample_patch(feature, solid, 60, rng)
        if feature.kind == "line":
            patch = np.vstack([patch, feature.point + np.outer(feature.extent.interval, feature.direction)])
        gap = min(_distance(base, p) for p in patch)
        assert gap >= BASE_CLEARANCE_MM - 1e-6, (feature.id, gap)


@pytest.mark.parametrize(
    "name, values, words",
    [
        ("quarter-sphere", {"radius": "nan"}, ["--radius", "finite"]),
        ("quarter-sphere", {"radius": "inf"}, ["--radius", "finite"]),
        ("quarter-sphere", {"radius": "0"}, ["--radius", "between"]),
        ("cube", {"size": "-5"}, ["--size", "between"]),
        ("cube", {"size": "abc"}, ["--size", "number"]),
        ("cube", {"radius": "5"}, ["--radius", "--size"]),
        ("inclined-plane-cylinder", {"angle": "90"}, ["--angle", "rotation about the axis"]),
        ("inclined-plane-cylinder", {"angle": "0"}, ["--angle"]),
        ("inclined-plane-cylinder", {"angle": "89.5"}, ["--angle"]),
        ("sphere-plate", {"spacing": "6", "radius": "10"}, ["--spacing"]),
        ("v-block", {"depth": "40", "size": "40"}, ["groove"]),
    ],
)
def test_bad_parameters_raise_input_error(name, values, words):
    with pytest.raises(InputError) as error:
        make(name, **values)
    message = str(error.value)
    assert "\n" not in message
    for word in words:
        assert word in message


def test_slug_names_the_parameters():
    assert make("quarter-sphere", radius=40).slug() == "quarter-sphere-r40"
    assert make("cube", size=50).slug() == "cube-s50"
    assert make("inclined-plane-cylinder", radius=20, angle=30).slug() == "inclined-plane-cylinder-r20-a30"
    assert make("quarter-sphere", base=True, radius=12.5).slug() == "quarter-sphere-r12.5-base"


def _random_instances(count_per_template: int, seed: int):
    """Seeded random valid parameter sets across each template's ranges (with and without base)."""
    rng = np.random.default_rng(seed)
    out = []
    for name, cls in TEMPLATES.items():
        found = 0
        while found < count_per_template:
            values = {}
            for p in cls.PARAMS:
                if p.unit == "mm":
                    values[p.name] = float(np.exp(rng.uniform(np.log(p.minimum), np.log(min(p.maximum, 50 * p.minimum)))))
                else:
                    values[p.name] = float(rng.uniform(p.minimum, p.maximum))
            try:
                cls(base=bool(found % 2), **values)
            except InputError:
                continue
            out.append((name, bool(found % 2), values))
            found += 1
    return out


@pytest.mark.parametrize("name, base, values", _random_instances(2, seed=516))
def test_random_valid_parameters_give_valid_solids_meshes_and_plans(name, base, values):
    from fixturecad.cad.mesh import mesh_from_shape, mesh_volume

    fixture = make(name, base=base, **values)
    solid = fixture_solid(fixture)
    assert solid.isValid() and len(solid.Solids()) == 1
    assert solid.Volume() == pytest.approx(fixture.volume(), rel=1e-6)
    match_features(solid, fixture.features())
    vertices, faces = mesh_from_shape(solid, 0.01)
    assert mesh_volume(vertices, faces) == pytest.approx(fixture.volume(), rel=1e-2)
    features = fixture.feature_map()
    for plan in fixture.touch_plans().values():
        for entry in plan.touches:
            assert features[entry["feature"]].contains(entry["points"]).all()


@pytest.mark.parametrize("name", NAMES)
def test_default_plans_locate_the_fixture_uniquely(name):
    """The registration engine, given the default plan's exact touches at a random pose, finds one pose."""
    from fixturecad.registration.engine import register_touches
    from fixturecad.registration.pose import fixture2meas_from_rt, random_rotation
    from fixturecad.registration.synthetic import plan_touches

    fixture = make(name)
    rng = np.random.default_rng(RNG_SEED)
    for _ in range(2):
        truth = fixture2meas_from_rt(random_rotation(rng), rng.uniform(-100.0, 100.0, 3))
        touches, contacts = plan_touches(fixture.touch_plans()["default"].touches, truth)
        result = register_touches(fixture.feature_map(), touches, contacts=contacts)
        assert result["status"] == "unique", result["status"]
        assert np.allclose(result["pose"], truth, atol=1e-6)
