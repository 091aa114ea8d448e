"""Contacts that share a feature (issue 9, part 1): the concrete structure's mobility, redundancy,
special positions and symmetry, against the cube's known cases and the paper's Fig. 5."""

import json

import numpy as np
import pytest

from cli import assert_bad_input, run
from fixturecad.registration.contacts import ContactType
from fixturecad.theory.analysis import analyze
from fixturecad.theory.structure import Structure, parse_labelled

CUBE_321 = ["P/F-PL/M@a"] * 3 + ["P/F-PL/M@b"] * 2 + ["P/F-PL/M@c"]
CUBE_411 = ["P/F-PL/M@a"] * 4 + ["P/F-PL/M@b", "P/F-PL/M@c"]
ONE_FACE = ["P/F-PL/M@a"] * 6
FIG_5 = ["L/M-C/M@cyl"] * 4


def test_the_labels_decide_the_mobility_of_six_point_plane_contacts():
    """The catalogue's generic answer for six P-PL contacts is 'locates, minimal'; on features it depends."""
    generic = analyze(["P/F-PL/M"] * 6)
    assert generic.mobility == 0 and generic.minimal
    assert analyze(CUBE_321).mobility == 0 and analyze(CUBE_321).minimal
    four = analyze(CUBE_411)
    assert four.mobility == 1 and not four.minimal
    # Named by the features, not by the coordinates of the random placement.
    assert four.freedom == ["rotation {R_u} about an axis parallel to the normal of a"]
    assert analyze(CUBE_321[:5]).freedom == ["translation {T_u} parallel to the line where a and b meet"]
    assert sorted(set(four.redundant)) == ["P/F-PL/M@a"] and len(four.redundant) == 4
    face = analyze(ONE_FACE)
    assert face.mobility == 3
    assert face.freedom == ["planar motion {G_P} in the plane of a"]
    assert face.target.startswith("the freedom is exactly the symmetry of a")


def test_the_paper_fig_5_leaves_the_cylinders_own_symmetry():
    result = analyze(FIG_5)
    assert result.mobility == 2
    assert result.freedom == ["cylindrical motion {C_u} along the axis of cyl"]
    assert result.target == ("the freedom is exactly the symmetry of cyl: "
                             "cylindrical motion {C_u} along the axis of cyl")
    # Three lines leave a third freedom: no longer the symmetry.
    three = analyze(FIG_5[:3])
    assert three.mobility == 3 and three.target.startswith("the freedom is not the symmetry")


def test_special_positions_are_found_and_each_loses_rank():
    structure = Structure.generic(parse_labelled(CUBE_321))
    special = structure.special_positions()
    for words in ("the touches on a are collinear", "the touches on a coincide", "the touches on b coincide",
                  "the normal of b is parallel to the normal of a", "the normal of c is parallel to the normal of b"):
        assert words in special
    # Perpendicular normals are the cube itself: no loss.
    assert not any("perpendicular" in words for words in special)
    for words, moved in structure._degenerations():
        assert (moved.rank() < structure.rank()) == (words in special)


def test_the_structure_rows_agree_with_the_cube_templates_plan():
    """The cube's default plan at its real geometry and the labelled structure agree on the mobility."""
    from fixturecad.registration.features import features_from_json
    from fixturecad.registration.mobility import matrix_rank
    from fixturecad.registration.problem import Problem
    from fixturecad.registration.synthetic import plan_touches
    from fixturecad.registration.touches import build_groups
    from fixturecad.build import features_document
    from fixturecad.templates import make

    document = features_document(make("cube"))
    features = features_from_json(document)
    entries = document["plans"]["default"]["touch_plan"]
    touches, contacts = plan_touches(entries, np.eye(4))
    _, jacobian = Problem(build_groups(features, touches, 0.0, contacts)).evaluate(np.eye(3), np.zeros(3))
    labelled = [f"{e['contact']}@{e['feature']}" for e in entries for _ in e["points"]]
    assert 6 - matrix_rank(jacobian, 50.0) == analyze(labelled).mobility == 0


def test_the_touch_rows_of_a_structure_lie_on_its_features():
    structure = Structure.generic(parse_labelled(["PL/F-PL/F@f", "P/F-S/M@s", "L/M-L/M@e", "S/M-C/M@c",
                                                  "C/M-PL/M@f", "PL/M-C/M@c"]))
    from fixturecad.registration.problem import Problem

    residuals, _ = Problem(structure.groups()).evaluate(np.eye(3), np.zeros(3))
    assert np.abs(residuals).max() < 1e-9


def test_labels_are_checked():
    with pytest.raises(ValueError, match="one label names one fixture element"):
        parse_labelled(["P/F-PL/M@a", "P/F-S/M@a"])
    with pytest.raises(ValueError, match="a label follows @"):
        parse_labelled(["P/F-PL/M@"])
    assert parse_labelled(["P/F-PL/M@a", "L/M-C/M"]) == [(ContactType.parse("P/F-PL/M"), "a"),
                                                         (ContactType.parse("L/M-C/M"), None)]


def test_analyze_command_with_labels():
    out = run("analyze", *CUBE_411, "--format", "json")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert result["mobility"] == 1 and "the touches on a are collinear" in result["special_positions"]
    assert json.loads(run("analyze", *CUBE_321, "--target-dim", "0", "--format", "json").stdout)["target"] == \
        "leaves 0 freedoms, as asked"
    assert_bad_input(run("analyze", "P/F-PL/M@a", "P/F-S/M@a"), "label 'a'")
    assert_bad_input(run("analyze", "P/F-XX/M@a"), "cannot read contact")
    assert_bad_input(run("analyze", *CUBE_321, "--target-dim", "7"), "--target-dim")


@pytest.mark.parametrize("sensor, fixture", [("C", "L"), ("PL", "P"), ("S", "PL")])
def test_catalog_expand_writes_contacts_in_the_filters_orientation(sensor, fixture):
    out = run("catalog", "--sensor", sensor, "--fixture", fixture, "--expand", "--max-contacts", "3",
              "--format", "json")
    assert out.returncode == 0, out.stderr
    rows = json.loads(out.stdout)["combinations"]
    assert rows
    for row in rows:
        for name in row["contacts"]:
            ctype = ContactType.parse(name)
            assert (ctype.sensor, ctype.fixture) == (sensor, fixture), name
