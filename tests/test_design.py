"""fixturecad design: every class of Table V laid out to locate at its real geometry, built samples, bad input."""

import json
import os
import re

import numpy as np
import pytest

from cli import assert_bad_input, run
from solid_files import assert_the_files_hold
from fixturecad.design.combination import for_class, parse
from fixturecad.design.fixture import design
from fixturecad.design.layout import best_layout, plan_problem
from fixturecad.registration.mobility import matrix_rank
from fixturecad.theory.catalogue import lookup
from fixturecad.theory.enumeration import enumerate_classes

SIZE_MM, BALL_MM = 100.0, 3.0


def test_every_class_of_table_five_gets_a_layout_that_locates_minimally():
    """All 579 classes: the plan's rows have rank 6 at the concrete geometry, each contact gives the rows
    of its dimension in Table III, and, as Table V says of its classes, no contact can be left out."""
    found = enumerate_classes().found
    assert len(found) == 579
    for item in found:
        combination = for_class(item.members)
        assert tuple(combination.members) == item.members
        layout, _ = best_layout(combination.contacts, combination.labels, SIZE_MM, BALL_MM, seed=1, keep=1, steps=0)
        assert layout is not None and layout.mobility == 0, item.name
        problem = plan_problem(layout.features(), layout.touches)
        J = problem.sensor_rows(np.eye(3), np.zeros(3))[1]
        rows = problem.row_feature
        for ctype, label in zip(combination.contacts, combination.labels):
            assert np.sum(rows == label) == 6 - lookup(ctype.name).dim, (item.name, ctype.name)
            assert matrix_rank(J[rows != label], SIZE_MM) < 6, (item.name, f"{ctype.name} is redundant")


def test_labels_share_a_feature_as_on_a_cube():
    """3-2-1 on three faces locates, on the block's own faces, the most touched on top; 4-1-1 leaves one
    rotation, six touches on one face the planar motion."""
    layout, _ = best_layout(*_parsed("a a a b b c"), SIZE_MM, BALL_MM, seed=1)
    assert layout.mobility == 0 and not layout.pieces
    assert layout.faces == {"top": "a", "front": "b", "left": "c"}
    assert best_layout(*_parsed("a a a a b c"), SIZE_MM, BALL_MM, seed=1, trials=30)[1] == 1
    assert best_layout(*_parsed("a a a a a a"), SIZE_MM, BALL_MM, seed=1, trials=30)[1] == 3


def _parsed(labels):
    combination = parse([f"P/F-PL/M@{label}" for label in labels.split()])
    return combination.contacts, combination.labels


@pytest.mark.parametrize("contact_class", ["{S-C}{S-C}{S-C}{S-T2}{S-T2}{S-T2}", "{S}{S-R}{G3-R}", "{R}{R}"])
def test_a_designed_fixture_builds_and_registers(contact_class, tmp_path):
    """One valid solid whose BREP carries every feature (checked by the build), its STEP, STL and 3MF
    holding the layout's analytic volume, features.json naming the class, and the folder's register.py
    recovers a pose from the plan's touches made at that pose."""
    result = run("design", "--class", contact_class, "--out", tmp_path / "fixture", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    folder = tmp_path / "fixture"
    document = json.loads((folder / "features.json").read_text())
    assert document["template"] == "design" and document["design"]["mobility"] == 0
    assert document["contact_class"] == contact_class == document["design"]["contact_class"]
    assert set(document["design"]["combination"]) <= set(result.stdout.split())
    assert_the_files_hold(folder, design(parse(document["design"]["combination"])).volume())

    from fixturecad.registration.pose import random_rotation
    from fixturecad.registration.synthetic import plan_touches
    from fixturecad.registration.touchfile import touch_json

    rng = np.random.default_rng(5)
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = random_rotation(rng), rng.uniform(-200, 200, 3)
    (tmp_path / "touches.json").write_text(touch_json(*plan_touches(document["plans"]["default"]["touch_plan"], pose)))
    import subprocess
    import sys

    out = subprocess.run([sys.executable, folder / "register.py", tmp_path / "touches.json", "--json"],
                         capture_output=True, text=True)
    solutions = [np.array(s["pose"]) for s in json.loads(out.stdout)["solutions"]]
    assert min(np.abs(s - pose).max() for s in solutions) < 1e-3
    _the_csv_template_checks_each_touch(folder)


def _the_csv_template_checks_each_touch(folder):
    """Issue 22: the design's touches.template.csv (a point probe on the block when the plan needs sensors)
    registers unique at its nominal pose with every touch checked, and a touch 0.5 mm off is flagged."""
    from fixturecad.registration.engine import register_touches
    from fixturecad.registration.features import features_from_json
    from fixturecad.registration.touchfile import read_touch_csv

    features = features_from_json(json.loads((folder / "features.json").read_text()))
    touches, _, _ = read_touch_csv((folder / "touches.template.csv").read_text(), list(features))
    result = register_touches(features, touches)
    assert result["status"] == "unique" and result["redundancy"]["unchecked"] == []
    fid = next(iter(touches))
    touches[fid][0] += 0.5 * features[fid].normal_at(touches[fid][:1])[0]
    result = register_touches(features, touches)
    assert result["status"] == "inconsistent" and 0 in {flag["touch"] for flag in result["flagged"]}


@pytest.mark.parametrize("tokens", [["P/F-S/M"] * 6, ["--class", "{S}{S-S}{S-S}{S-S}"]])
def test_balls_on_stalks_write_the_solid(tokens, tmp_path):
    """The two designs whose STEP once read back 6 % and 3.1 % short (balls on stalks, a stalk across a
    ball's seam): the files the kernel writes hold the layout's analytic volume."""
    from fixturecad.build import DEFAULT_STL_TOLERANCE_MM
    from fixturecad.cad.export import export
    from fixturecad.cad.solid import fixture_solid

    combination = parse(tokens) if tokens[0] != "--class" else for_class(re.findall(r"{([^}]*)}", tokens[1]))
    fixture = design(combination)
    export(fixture_solid(fixture), [tmp_path / f"fixture.{kind}" for kind in ("step", "stl", "3mf")],
           DEFAULT_STL_TOLERANCE_MM)
    assert_the_files_hold(tmp_path, fixture.volume())


RANDOM_LAYOUTS = 300


@pytest.mark.parametrize("contact_class", ["{T1}{S-R}", "{S-T1}{G3-R}{S-C}{S-C}", "{S-R}{S-R}{C-R-C}{C-R-C}"])
def test_a_design_carries_more_information_than_random_layouts(contact_class):
    """Three classes whose designs once lost in D (by 0.51, 1.15 and 0.86) to the best of 1,000 random
    layouts in bench_design: the design's default plan carries at least the information of the best of
    300 seeded random feasible layouts of the same kind (the layout search's own draws), and the
    information it records is its default plan's."""
    from fixturecad.design.layout import layout_plan, plan_information

    combination = for_class(re.findall(r"{([^}]*)}", contact_class))
    fixture = design(combination)
    layout = fixture.layout
    assert layout.information == pytest.approx(
        plan_information(fixture.features(), fixture.touch_plans()["default"].touches, layout.size), abs=1e-9)
    rng = np.random.default_rng(20)
    best = -np.inf
    for _ in range(RANDOM_LAYOUTS):
        other = layout_plan(combination.contacts, combination.labels, layout.size, fixture.sensor_ball, rng,
                            bool(layout.faces))
        if other is not None:
            best = max(best, plan_information(other.features(), other.touches + other.checks, layout.size))
    assert np.isfinite(best) and layout.information >= best


def test_segment_distances_are_the_least_over_sampled_points():
    """The clearance between pieces and approach rays: against the least distance over 401 points along
    each segment (never below it, within the sampling's step above it), points and parallel segments
    among them."""
    from fixturecad.design.layout import _segment_distances

    rng = np.random.default_rng(3)
    a0, a1, b0, b1 = (rng.normal(0.0, 10.0, (400, 3)) for _ in range(4))
    a1[:50], b1[50:100] = a0[:50], b0[50:100]
    b1[100:150] = b0[100:150] + (a1[100:150] - a0[100:150]) * rng.uniform(-2.0, 2.0, (50, 1))
    s = np.linspace(0.0, 1.0, 401)[:, None]
    sampled = np.array([np.linalg.norm((p + s * (q - p))[:, None] - (u + s * (v - u))[None], axis=2).min()
                        for p, q, u, v in zip(a0, a1, b0, b1)])
    step = np.maximum(np.linalg.norm(a1 - a0, axis=1), np.linalg.norm(b1 - b0, axis=1)) / 400
    distances = _segment_distances(a0, a1, b0, b1)
    assert np.all(distances <= sampled + 1e-9) and np.all(sampled - distances <= step)


def test_a_design_is_the_same_in_every_process():
    """The layout search is seeded and sums its information in one order: two processes with other string
    hashes (the order of a set of feature ids) design the same layout. A sum taken in a set's order once
    rounded differently from process to process and tipped nudges that change nothing either way."""
    import subprocess
    import sys

    code = ("from fixturecad.design.combination import for_class; from fixturecad.design.fixture import design; "
            "print(repr(design(for_class(['G3', 'R-R-C', 'S-C'])).layout.information))")
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                           env={**os.environ, "PYTHONHASHSEED": seed}).stdout for seed in ("1", "2")]
    assert runs[0] == runs[1] and runs[0].strip()


@pytest.mark.parametrize("contact_class", ["{S-S}{S-S}{S-C}{C-R-C}{C-R-C}{C-R-C}", "{G3-R}{S-S}{S-S}{S-C}{S-C}",
                                           "{R}{S-T1}"])
def test_a_nudge_is_judged_as_the_whole_layout_would_be(contact_class):
    """The refinement redoes only what a nudge changes (the moved piece's fit, the rays it may block, its
    touches and their information): over 150 bold nudges of a design, each is kept or refused as the whole
    checks (every piece's fit, every touch's ray, the whole plan's information) keep or refuse it, with
    the same plan."""
    from fixturecad.design.layout import (_blocks, _fits, _nudged, _prints, criterion_values, planned,
                                          plan_information, refined, TURNS)

    combination = for_class(re.findall(r"{([^}]*)}", contact_class))
    layout = design(combination).layout
    layout = refined(layout, combination.contacts, combination.labels, BALL_MM, np.random.default_rng(0), steps=0)
    rng = np.random.default_rng(5)
    units = sorted({piece.id for piece in layout.pieces} | {fid for ctype, fid in zip(combination.contacts,
                                                                                       combination.labels)
                                                             if ctype.sensor in ("L", "C")})
    outcomes = []
    for _ in range(150):
        fid = units[int(rng.integers(len(units)))]
        aspect = int(rng.integers(TURNS + 1))
        pieces = [_nudged(piece, layout.size, rng, 4.0, aspect) if piece.id == fid else piece
                  for piece in layout.pieces]
        if not all(_prints(piece, combination.labels.count(piece.id), layout.size) for piece in pieces):
            continue
        turns = {key: turn + rng.normal(0.0, 0.5) if key[0] == fid and aspect == TURNS and turn is not None
                 else turn for key, turn in layout.turns.items()}
        args = (combination.contacts, combination.labels, layout.size, BALL_MM, pieces, layout.faces, rng, turns)
        part = planned(*args, layout, fid) if _fits(pieces, layout.size, fid) else None
        whole = planned(*args) if _fits(pieces, layout.size) else None
        assert (part is None) == (whole is None)
        outcomes.append(part is not None)
        if part is not None:
            assert json.dumps(part.touches + part.checks) == json.dumps(whole.touches + whole.checks)
            blocks = {**layout.blocks, **_blocks(part, [fid])}
            assert float(criterion_values(sum(blocks.values()), "d")) == pytest.approx(
                plan_information(whole.features(), whole.touches + whole.checks, layout.size), abs=1e-9)
    assert 10 <= sum(outcomes) <= 140  # both kept and refused nudges were judged


@pytest.mark.parametrize("args, words", [
    (["P/F-XL/M"], ["cannot read contact"]),
    (["P/F-PL/M@a", "P/F-S/M@a"], ["label 'a'", "one fixture element"]),
    (["P/F-PL/M@a"] * 6, ["does not locate", "3 freedoms", "planar motion {G_P} in the plane of a"]),
    (["--class", "{S-S}x3 {S-T2}x3", "--size", "5"], ["--size"]),
    (["--class", "{S-S}"], ["not a class of Table V"]),
    (["C/M-PL/F"], ["contact line", "PL/F-C/M"]),
    ([], ["give either contacts"]),
])
def test_bad_input_is_one_line_and_writes_nothing(args, words, tmp_path):
    assert_bad_input(run("design", *args, cwd=tmp_path), *words)
    assert not (tmp_path / "out").exists()


def test_every_contact_a_plan_can_make_holds_at_the_pose_it_was_made_at():
    """Both orientations of the 41 contacts (those a plan can make): the touch, made by its sensor at a
    random pose, has zero rows at that pose and the rank of its dimension in Table III."""
    from fixturecad.design.combination import plan_gap
    from fixturecad.design.layout import layout_plan
    from fixturecad.registration.pose import random_rotation
    from fixturecad.registration.problem import Problem
    from fixturecad.registration.synthetic import plan_touches
    from fixturecad.registration.touches import build_groups
    from fixturecad.theory.catalogue import catalogue

    rng = np.random.default_rng(3)
    for entry in catalogue():
        for ctype in {entry.ctype, entry.ctype.swapped()}:
            if plan_gap(ctype):
                continue
            layout = None
            while layout is None:
                layout = layout_plan([ctype], ["f"], SIZE_MM, BALL_MM, rng)
            R, t = random_rotation(rng), rng.uniform(-300, 300, 3)
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = R, t
            touches, contacts = plan_touches(layout.touches, pose)
            problem = Problem(build_groups({f.id: f for f in layout.features()}, touches, contacts=contacts))
            values, J = problem.sensor_rows(R, t)
            assert np.abs(values).max() < 1e-9, ctype.name
            assert matrix_rank(J, SIZE_MM) == 6 - entry.dim, ctype.name


# Each template's class as a combination on its features, and the side of the square block that holds the
# template (its footprint, mm; sphere-plate: its plate's diameter).
TEMPLATE_COMBINATIONS = {
    "cube": ("P/F-PL/M@top " * 3 + "P/F-PL/M@front " * 2 + "P/F-PL/M@left", 50),
    "v-block": ("P/F-PL/M@groove_a " * 3 + "P/F-PL/M@groove_b " * 2 + "P/F-PL/M@end", 60),
    "quarter-sphere": ("PL/F-PL/F@flat_a P/F-S/M@sphere P/F-PL/M@flat_b L/M-L/M@edge", 80),
    "inclined-plane-cylinder": ("P/F-PL/M@plane " * 3 + "P/F-C/M@cylinder " * 3, 40),
    "sphere-plate": ("P/F-S/M@ball_1 " * 2 + "P/F-S/M@ball_2 " * 2 + "P/F-S/M@ball_3 " * 2, 130),
}
AS_GOOD_AS_A_TEMPLATE = 1.25


def _bounds(features, entries):
    """A plan's Cramer-Rao bound at 5 um (nominal pose): the RMS translation (mm) of the point it fixes best
    and the RMS rotation (rad). The origin's translation is ``delta t``; a point p's, ``delta t + delta omega x
    p``, whose mean square ``tr S_tt + 2 p.c + p^T M p`` (``c = E[delta t x delta omega]``, ``M = tr S_rr I -
    S_rr``) is least at ``p = -M^-1 c``: unlike the origin's, it does not depend on where the frame's origin
    lies."""
    from fixturecad.design.layout import plan_problem
    from fixturecad.registration.uncertainty import cramer_rao_bound

    problem = plan_problem(features, entries)
    C = cramer_rao_bound(problem, np.eye(4), problem.sigma)
    rr, tt, tr = C[:3, :3], C[3:, 3:], C[3:, :3]
    c = np.array([tr[1, 2] - tr[2, 1], tr[2, 0] - tr[0, 2], tr[0, 1] - tr[1, 0]])
    M = np.trace(rr) * np.eye(3) - rr
    return np.sqrt(np.trace(tt) - c @ np.linalg.solve(M, c)), np.sqrt(np.trace(rr))


@pytest.mark.parametrize("name", sorted(TEMPLATE_COMBINATIONS))
def test_a_design_of_a_templates_class_is_nearly_as_accurate_as_the_template(name):
    """The template's class designed on a block of the template's size: the default plan's Cramer-Rao
    bound at 5 um is at most 1.25 x the template's default plan's, in rotation and in translation where each
    plan fixes a point best (:func:`_bounds`). (At the origin, the sphere-plate's design's translation is 1.15
    to 1.73 x the template's over ten seeds, as the block's origin lies farther from its balls than the
    plate's: the rotation's error carried to the origin, the design's rotation bound about half the
    template's.)"""
    from fixturecad.templates import make

    template = make(name)
    tokens, size = TEMPLATE_COMBINATIONS[name]
    fixture = design(parse(tokens.split()), size=size)
    assert fixture.contact_class == template.contact_class
    ours = _bounds(fixture.features(), fixture.touch_plans()["default"].touches)
    theirs = _bounds(template.features(), template.touch_plans()["default"].touches)
    assert np.all(np.array(ours) <= AS_GOOD_AS_A_TEMPLATE * np.array(theirs)), (ours, theirs)
