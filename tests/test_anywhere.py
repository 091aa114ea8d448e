"""Touches anywhere on the part (``--anywhere``): every face of the solid a feature, the unlabelled touches on any.

Independent answers: a finer tessellation of the solid by the CAD kernel (each triangle must lie on its own
face's feature, inside its patch), the true pose the touches were made at, and the brute force (the search_cases
rows "... 12 anywhere", judged in test_solution_search.py and, on 200 layouts, in benchmarks/bench_search.py;
the cube's and the v-block's told by poses, tests/test_face_search.py).
"""

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from cli import assert_bad_input, run
from fixturecad.registration.engine import register_touches
from fixturecad.registration.features import faces_from_json, features_from_json
from fixturecad.registration.pose import pose_errors
from fixturecad.registration.unlabelled import faces_holding

cq = pytest.importorskip("cadquery")
from fixturecad.build import features_document  # noqa: E402
from fixturecad.cad.faces import FACE_CHORD_MM, GROWTH, face_features, faces_record  # noqa: E402
from fixturecad.cad.mesh import labelled_mesh  # noqa: E402
from fixturecad.cad.solid import fixture_solid  # noqa: E402
from fixturecad.templates import TEMPLATES, make  # noqa: E402
from brute_force import TouchResiduals  # noqa: E402
from search_cases import VARIANTS, displacement_mm, layout, spread_mm  # noqa: E402

FINE_CHORD_MM = 0.01  # the STL's tessellation: the independent reader of the faces


@pytest.mark.parametrize("name", sorted(TEMPLATES))
def test_every_triangle_of_the_solid_lies_on_its_face_inside_its_patch(name):
    """Each triangle of the kernel's fine tessellation lies on the feature of the face it tessellates (within
    the fine chord) and its corners and middle inside that face's patch; every face is one of the features."""
    shape = fixture_solid(make(name))
    faces, reason = face_features(shape)
    assert reason == "" and len(faces) == len(shape.Faces())
    vertices, triangles, owner = labelled_mesh(shape, FINE_CHORD_MM)
    for k, face in enumerate(faces):
        corners = vertices[triangles[owner == k]].reshape(-1, 3)
        middles = vertices[triangles[owner == k]].mean(axis=1)
        assert np.abs(face.signed_distance(corners)).max() < 1e-6, face.id
        assert np.abs(face.signed_distance(middles)).max() < FINE_CHORD_MM, face.id
        assert face.contains(np.vstack([corners, middles]), 0.0).all(), face.id


@pytest.mark.parametrize("name", sorted(TEMPLATES))
def test_every_sensing_patch_lies_on_a_face(name):
    """Touches anywhere hold the touches on the sensing features: each surface feature's patch points lie on
    a face of the same surface, inside its patch."""
    from fixturecad.registration.patches import patch_points

    faces, _ = face_features(fixture_solid(make(name)))
    for feature in features_from_json(features_document(make(name))).values():
        if not feature.surface:
            continue
        points = patch_points(feature)
        on = np.zeros(len(points), bool)
        for face in faces:
            if face.kind == feature.kind:
                on |= (np.abs(face.signed_distance(points)) < 1e-6) & face.contains(points, 0.0)
        assert on.all(), (name, feature.id)
        # ... and the face a touch is put on names it: the faces whose surface it lies on hold it.
        holding = [f.id for f in faces if feature.id in faces_holding({f.id: f for f in faces}, {feature.id: feature})
                   .get(f.id, [])]
        assert holding and all(np.abs(faces_by_id[k].signed_distance(points)).max() < 1e-6
                               for faces_by_id in [{f.id: f for f in faces}] for k in holding), (name, feature.id)


def test_a_hull_not_grown_leaves_the_face_out():
    """The growth is needed: the sphere's hull of its coarse tessellation alone misses the face's fine
    triangles (the surface bulges past the chords)."""
    shape = fixture_solid(make("quarter-sphere"))
    faces, _ = face_features(shape)
    sphere = next(f for f in faces if f.kind == "sphere")
    vertices, triangles, owner = labelled_mesh(shape, FINE_CHORD_MM)
    corners = vertices[triangles[owner == int(sphere.id.split("_")[1])]].reshape(-1, 3)
    sphere.extent.halfspaces[:, 3] -= GROWTH * FACE_CHORD_MM
    assert not sphere.contains(corners, 0.0).all()


@pytest.mark.parametrize("solid, words", [
    (lambda: cq.Workplane().box(20, 20, 10).faces(">Z").workplane().hole(6).val(), "hollow cylinder"),
    (lambda: cq.Solid.makeCone(10, 0, 20), "cone"),
])
def test_a_face_no_feature_takes_is_named(solid, words):
    record = faces_record(solid())
    assert set(record) == {"unsupported"} and words in record["unsupported"]
    with pytest.raises(ValueError, match=words):
        faces_from_json({"faces": record})


@pytest.mark.parametrize("name", ["quarter-sphere 12 anywhere", "inclined-plane-cylinder 12 anywhere",
                                  "cube 12 anywhere", "v-block 12 anywhere"])
def test_touches_anywhere_give_the_true_pose_among_their_answers(name):
    """On the first layouts of the judged rows: the search completes and the truth is among the poses, each
    touch on the face it was drawn on (or on one as near: a touch where two faces meet)."""
    case, noise = next((c, z) for c, z in VARIANTS if c.name == name)
    for index in range(3):
        lay = layout(case, noise, index)
        points = np.vstack(list(lay.touches.values()))
        result = register_touches(lay.features, {}, unlabelled=points, sigma_mm=noise, faces=lay.features)
        if result["status"] == "underdetermined":
            continue  # touches that leave a motion free: no pose claimed, judged in test_solution_search
        assert result["search"] == "complete"
        # Within ten standard deviations of where the truth puts the touches (the bound of the touches labelled).
        places = (points - lay.truth[:3, 3]) @ lay.truth[:3, :3]
        within = max(10 * spread_mm(TouchResiduals(lay.features, lay.touches), lay.truth, noise, places), 0.01)
        best = min(result["solutions"], key=lambda s: displacement_mm(np.array(s["pose"]), lay.truth, places))
        assert displacement_mm(np.array(best["pose"]), lay.truth, places) < within
        assert max(abs(a["residual_mm"]) for a in best["assignment"]) < 5 * noise


def _anywhere_csv(folder, path, seed=3):
    """A touch file of twelve unlabelled touches anywhere a probe reaches on the folder's part, and the truth."""
    from fixturecad.registration.sampling import TouchSampler, load_mesh

    document = json.loads((folder / "features.json").read_text())
    sampler = TouchSampler(document, load_mesh(folder / "fixture.stl", document["volume_mm3"]), anywhere=True)
    touches, _, truth = sampler.draw(np.random.default_rng(seed), 0.0)
    path.write_text("feature,x,y,z\n" + "".join(f",{x:.9f},{y:.9f},{z:.9f}\n"
                                                for points in touches.values() for x, y, z in points))
    return truth


def test_register_and_register_py_take_touches_anywhere(built, tmp_path):
    folder = built("inclined-plane-cylinder")
    truth = _anywhere_csv(folder, tmp_path / "anywhere.csv")
    csv = tmp_path / "anywhere.csv"
    for out in (run("register", folder, csv, "--anywhere", "--json"),
                subprocess.run([sys.executable, str(folder / "register.py"), str(csv), "--anywhere", "--json"],
                               capture_output=True, text=True)):
        assert out.returncode == 0, out.stderr
        result = json.loads(out.stdout)
        assert result["status"] == "unique" and result["search"] == "complete"
        errors = pose_errors(np.array(result["pose"]), truth)
        assert errors[0] < 0.01 and np.degrees(errors[1]) < 0.01
        assert all(a["feature"].startswith("face_") for a in result["assignment"])
        # A touch on the face that holds the plane or the cylinder is named by it too: it lies on that surface
        # (within the STL's chord, where the touches were drawn).
        features = features_from_json(json.loads((folder / "features.json").read_text()))
        local = (np.loadtxt(csv, delimiter=",", skiprows=1, usecols=(1, 2, 3)) - truth[:3, 3]) @ truth[:3, :3]
        named = [a for a in result["assignment"] if a.get("holds")]
        assert named and all(np.abs(features[a["holds"][0]].signed_distance(local[a["touch"]][None]))[0] < 0.02
                             for a in named)
    text = run("register", folder, csv, "--anywhere").stdout
    assert any(line.startswith("assigned:") and "(plane)" in line for line in text.splitlines())


def test_anywhere_without_faces_or_unlabelled_touches_is_one_line(built, tmp_path):
    folder = tmp_path / "old"
    shutil.copytree(built("inclined-plane-cylinder"), folder)
    _anywhere_csv(folder, tmp_path / "anywhere.csv")
    labelled = folder / "touches.template.csv"
    assert_bad_input(run("register", folder, labelled, "--anywhere"), "--anywhere", "none")
    document = json.loads((folder / "features.json").read_text())
    del document["faces"]
    (folder / "features.json").write_text(json.dumps(document))
    assert_bad_input(run("register", folder, tmp_path / "anywhere.csv", "--anywhere"), "no faces", "rebuild")


def test_simulate_anywhere_draws_on_the_whole_part(built, tmp_path):
    """simulate --anywhere on the inclined plane (exact part, 2 trials): every touch on some face, the
    summary says so, the plot drawn."""
    out = run("simulate", built("inclined-plane-cylinder"), "--anywhere", "--trials", 2, "--fixture-tolerance", 0,
              "--out", tmp_path / "sim")
    assert out.returncode == 0, out.stderr
    summary = json.loads((tmp_path / "sim" / "simulation.json").read_text())
    assert summary["anywhere"] and summary["unlabelled"] and sum(summary["statuses"].values()) == 2
    assert (tmp_path / "sim" / "simulation.png").stat().st_size > 10_000


def test_more_assignments_than_are_searched_say_incomplete(monkeypatch):
    """Past MAX_SEARCHED assignments (here 5: the quarter-sphere's first layout leaves more) the poses tell them;
    where they stop too (here past 1,000 cells), or leave more than MAX_SEARCHED (the cube's first layout: 3 of
    its 24 turns' orbits, more than 1), the search stops and says so; nothing is claimed (exit 6 or
    underdetermined)."""
    from fixturecad.registration import face_search, unlabelled
    from fixturecad.registration.touchfile import exit_code

    for name, searched, cells, reason in [("quarter-sphere 12 anywhere", 5, 1000, "not told within 1000 cells"),
                                          ("cube 12 anywhere", 1, face_search.MAX_CELLS, "more than the 1 searched")]:
        monkeypatch.setattr(unlabelled, "MAX_SEARCHED", searched)
        monkeypatch.setattr(face_search, "MAX_CELLS", cells)
        case, noise = next((c, z) for c, z in VARIANTS if c.name == name)
        lay = layout(case, noise, 0)
        result = register_touches(lay.features, {}, unlabelled=np.vstack(list(lay.touches.values())), sigma_mm=noise,
                                  faces=lay.features)
        assert result["search"] == "incomplete" and reason in result["search_reason"], name
        assert exit_code(result) in (4, 6)
