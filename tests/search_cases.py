"""Issue 12's random touch layouts, and register_touches judged on each against the brute force.

A layout is touches drawn uniformly on the features' finite patches (the grid of
:func:`patch_points`) at a random true pose, noise-free or with Gaussian noise of ``SIGMA_MM``
on each axis. The judge (:func:`judge`) runs the engine and the brute force
(:mod:`brute_force`) on the same touches and records what the engine got wrong:

* ``wrong_unique``: ``unique`` with a pose off the truth by more than the tolerance;
* ``unique_missed``: ``unique`` although the brute force finds another admissible pose, beyond the tolerance;
* ``unique_none``: ``unique`` although the brute force finds no admissible pose at all;
* ``ambiguous_missing``: ``ambiguous`` without one of the brute force's poses in ``solutions``;
* ``false_inconsistent``: ``inconsistent`` although the brute force finds an admissible pose;
* ``false_underdetermined``: ``underdetermined`` on an exact part although the touches plainly fix the
  pose (:func:`_plainly_determined`; its brute force runs only where the spread is that small). The brute
  force runs for the other checks only where the engine claims a pose;
* ``separating``: on ``ambiguous``, whether the separating touch lies on the real part (probed where
  it says, the probe moving along the feature's normal at the true pose) and, added, gives
  ``unique`` at the true pose.

Poses are compared by the largest displacement of the fixture's patch points (mm), within
``max(10 sigma, 0.01 mm)``, sigma the largest standard deviation of a patch point under the
Cramer-Rao bound at the true pose (the brute force's own Jacobian).
"""

import functools
import time
import zlib
from dataclasses import dataclass, field

import numpy as np

from brute_force import PATCH_TOLERANCE_MM, TouchResiduals, admissible_poses, random_rotations, rotations
from fixturecad.build import features_document
from fixturecad.registration.defaults import DEFAULT_SIGMA_MM
from fixturecad.registration.deviations import tolerance_from_document
from fixturecad.registration.engine import register_touches
from fixturecad.registration.features import features_from_json
from fixturecad.registration.patches import patch_points
from fixturecad.registration.synthetic import perturb_touches, plan_touches
from fixturecad.templates import make

SIGMA_MM = 0.005  # a touch probe's repeatability, the noisy layouts' noise on each axis
FAULT_MM = 0.5  # how far the faulty touch is off its surface
TOLERANCE_SIGMAS = 10.0  # a pose this many standard deviations off the truth is wrong ...
EXACT_TOLERANCE_MM = 0.01  # ... or this far, noise-free
TRUE_POSE_RANGE_MM = 100.0  # true fixture origins are uniform in this cube about the measurement origin
NOMINAL_TWIST = np.concatenate([np.radians(5.0) * np.array([0.6, 0.0, 0.8]), [3.0, 4.0, 0.0]])  # rad, mm
DISPLACEMENT_POINTS = 400  # patch points over which two poses are compared
PLAIN_SPREAD_MM = 1.0 / 30.0  # a pose determined this well (each touch's standard deviation) is not weak
BOSSES = "{C-R-C}" * 6  # a design of six bosses (line sensors in its plan; touched by a point probe or those)


@functools.lru_cache(maxsize=None)
def _fixture(name):
    """A template by name, or the design of a Table V class written as its members ("{C-R-C}...")."""
    if name.startswith("{"):
        from fixturecad.design.combination import for_class
        from fixturecad.design.fixture import design
        from fixturecad.fixture_commands import table_five_class

        return design(for_class(table_five_class(name)))
    return make(name)


def _features(template):
    return features_from_json(features_document(_fixture(template)))


def _tolerance(template, features):
    return tolerance_from_document(features, features_document(_fixture(template)))


def _on_patch(features, counts, rng):
    return {fid: _draw(features[fid], n, rng) for fid, n in counts.items()}


def _draw(feature, count, rng):
    points = patch_points(feature)
    return points[rng.choice(len(points), count, replace=False)]


def _collinear(features, rng):
    """4-3-2 cube: the four top touches on the segment between two random top patch points."""
    ends = _draw(features["top"], 2, rng)
    touches = _on_patch(features, {"front": 3, "left": 2}, rng)
    touches["top"] = ends[0] + rng.uniform(0.0, 1.0, (4, 1)) * (ends[1] - ends[0])
    return touches


def _diagonal(features, rng):
    """3-2-1 cube: the three top touches on the top face's diagonal, x = y."""
    size = features["top"].point[2]
    along = rng.uniform(0.0, size, 3)
    touches = _on_patch(features, {"front": 2, "left": 1}, rng)
    touches["top"] = np.column_stack([along, along, np.full(3, size)])
    return touches


def _offset_touch(features, rng):
    """Cube 3-3-3 with one touch FAULT_MM off its face (in or out)."""
    touches = _on_patch(features, {"top": 3, "front": 3, "left": 3}, rng)
    fid = rng.choice(sorted(touches))
    k = rng.integers(3)
    touches[fid][k] += rng.choice([-1.0, 1.0]) * FAULT_MM * features[fid].normal
    return touches


def _mislabelled_touch(features, rng):
    """Cube 3-3-3 with one touch made on another face and labelled with this one."""
    touches = _on_patch(features, {"top": 3, "front": 3, "left": 3}, rng)
    fid, other = rng.choice(sorted(touches), 2, replace=False)
    touches[fid][rng.integers(3)] = _draw(features[other], 1, rng)[0]
    return touches


def _counts(counts):
    return lambda features, rng: _on_patch(features, counts, rng)


@functools.lru_cache(maxsize=None)
def _faces(template):
    """Every face of the template's solid as a feature (features.json's ``faces``), by id, and each face's
    triangles (m, 3, 3) of its tessellation."""
    from fixturecad.cad.faces import FACE_CHORD_MM, face_features
    from fixturecad.cad.mesh import triangulate
    from fixturecad.cad.solid import fixture_solid

    shape = fixture_solid(_fixture(template))
    faces, _ = face_features(shape)
    return {f.id: f for f in faces}, [nodes[triangles] for _, nodes, triangles in triangulate(shape, FACE_CHORD_MM)]


def _anywhere(template, count):
    """``count`` touches uniform by area anywhere on the solid (its faces' triangles, put on the face's surface),
    by the face each lies on."""
    def draw(features, rng):
        triangles = _faces(template)[1]
        face = np.concatenate([np.full(len(t), k) for k, t in enumerate(triangles)])
        triangles = np.concatenate(triangles)
        a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        pick = rng.choice(len(triangles), count, p=area / area.sum())
        u, v = rng.random((2, count))
        u, v = np.where(u + v > 1, 1 - u, u), np.where(u + v > 1, 1 - v, v)
        points = a[pick] + u[:, None] * (b - a)[pick] + v[:, None] * (c - a)[pick]
        ids = list(features)
        return {ids[k]: features[ids[k]].closest_point(points[face[pick] == k]) for k in np.unique(face[pick])}
    return draw


@dataclass(frozen=True)
class Case:
    """A kind of layout: its template, the noise levels it runs at (mm) and how its touches are drawn
    (fixture frame, by feature id); or a fixed touch plan of the template, sensors included."""

    name: str
    template: str
    noise_mm: tuple
    draw: object = None
    plan: str = ""
    printed: bool = False  # registered on a printed part: the fixture's recorded tolerance, as register.py does
    unlabelled: bool = False  # the touches given without their features, to the engine and the brute force
    symmetric: bool = False  # its poses are images of one another under the fixture's symmetry: none separates them
    anywhere: bool = False  # unlabelled touches anywhere on the solid: its faces are the features, on both sides


CASES = [
    Case("cube 2-2-2", "cube", (0.0, SIGMA_MM), _counts({"top": 2, "front": 2, "left": 2})),
    Case("cube 2-2-2, printed", "cube", (0.0, SIGMA_MM), _counts({"top": 2, "front": 2, "left": 2}), printed=True),
    Case("v-block 2-2-2", "v-block", (0.0, SIGMA_MM), _counts({"groove_a": 2, "groove_b": 2, "end": 2})),
    Case("v-block 2-2-2, printed", "v-block", (0.0, SIGMA_MM), _counts({"groove_a": 2, "groove_b": 2, "end": 2}),
         printed=True),
    Case("quarter-sphere 2-2-2 and the sphere", "quarter-sphere", (0.0, SIGMA_MM),
         _counts({"flat_a": 2, "flat_b": 2, "sphere": 2})),
    Case("inclined-plane-cylinder 2+4", "inclined-plane-cylinder", (0.0, SIGMA_MM),
         _counts({"plane": 2, "cylinder": 4})),
    Case("inclined-plane-cylinder 2+4, printed", "inclined-plane-cylinder", (0.0, SIGMA_MM),
         _counts({"plane": 2, "cylinder": 4}), printed=True),
    Case("Example Two 3+3", "inclined-plane-cylinder", (0.0, SIGMA_MM), _counts({"plane": 3, "cylinder": 3})),
    Case("sphere-plate 2 per ball", "sphere-plate", (0.0, SIGMA_MM), _counts({"ball_1": 2, "ball_2": 2, "ball_3": 2})),
    # The paper's plane sensor on a plane and line sensor across an edge: bounded by their own rows.
    Case("Example One (paper plan)", "quarter-sphere", (0.0, SIGMA_MM), plan="paper"),
    Case("Example One (paper plan), printed", "quarter-sphere", (0.0, SIGMA_MM), plan="paper", printed=True),
    Case("v-block 4-4-4, unlabelled", "v-block", (SIGMA_MM,), _counts({"groove_a": 4, "groove_b": 4, "end": 4}),
         unlabelled=True),
    # Its three poses are the images of the corner's symmetry: no touch tells them apart.
    Case("cube 4-4-4, unlabelled", "cube", (SIGMA_MM,), _counts({"top": 4, "front": 4, "left": 4}),
         unlabelled=True, symmetric=True),
    # Its three equal balls on a circle: the poses are the turns that swap them.
    Case("sphere-plate 4-4-4, unlabelled", "sphere-plate", (SIGMA_MM,),
         _counts({"ball_1": 4, "ball_2": 4, "ball_3": 4}), unlabelled=True, symmetric=True),
    # Its flats swap under a half turn: the two poses are images of each other.
    Case("quarter-sphere 4-4-4, unlabelled", "quarter-sphere", (SIGMA_MM,),
         _counts({"flat_a": 4, "flat_b": 4, "sphere": 4}), unlabelled=True, symmetric=True),
    Case("inclined-plane-cylinder 6+6, unlabelled", "inclined-plane-cylinder", (SIGMA_MM,),
         _counts({"plane": 6, "cylinder": 6}), unlabelled=True),
    # Six bosses leaning every way, touched by a point probe: no box axis follows their axes.
    Case("{C-R-C}x6 design's bosses 2 each", BOSSES, (0.0, SIGMA_MM),
         _counts({f"boss_{k}": 2 for k in range(1, 7)})),
    # Designs of Table V classes whose sensors' contact points are known (stand-ins in the complete search) and
    # whose stand-ins fix the pose by themselves: balls on two faces, both sides fixed (R); a ball on a face, a
    # line sensor on a boss, probe points on a face (G3, R-R-C, S-T2); balls on two edges, both mobile, probe
    # points on balls (S-R, S-S). ({G3}{R-R-C}{S-C} and {S-R}{S-R}{S-S}{S-C} served until the layout search of
    # ad9683b laid them out so that their stand-ins leave the pose too weak to search without the rows they
    # leave out, the line's tangency and the ball's normal: issue 18.)
    Case("{R}{R} design (default plan)", "{R}{R}", (0.0, SIGMA_MM), plan="default"),
    Case("{G3}{R-R-C}{S-T2} design (default plan)", "{G3}{R-R-C}{S-T2}", (0.0, SIGMA_MM), plan="default"),
    Case("{S-R}{S-R}{S-S}{S-S} design (default plan)", "{S-R}{S-R}{S-S}{S-S}", (0.0, SIGMA_MM), plan="default"),
    # Designs whose sensors know no point on either side, bounded by their own rows: balls on a face (R) and line
    # sensors round a boss, or a plane sensor lying on it.
    Case("{R}{C-R-C} design (default plan)", "{R}{C-R-C}", (0.0, SIGMA_MM), plan="default"),
    Case("{R}{G3-R} design (default plan)", "{R}{G3-R}", (0.0, SIGMA_MM), plan="default"),
    # The same on the printed part, beside the balls' stand-ins (off their faces, at the balls' centres).
    Case("{R}{C-R-C} design (default plan), printed", "{R}{C-R-C}", (0.0, SIGMA_MM), plan="default", printed=True),
    Case("{R}{G3-R} design (default plan), printed", "{R}{G3-R}", (0.0, SIGMA_MM), plan="default", printed=True),
    # Line sensors alone, two round each of six leaning bosses, their contact points given: no point touch bounds
    # the translation, their slabs across the bosses' axes do.
    Case("{C-R-C}x6 design (default plan)", BOSSES, (0.0, SIGMA_MM), plan="default"),
    Case("{C-R-C}x6 design (default plan), printed", BOSSES, (0.0, SIGMA_MM), plan="default", printed=True),
    # Plane sensors alone, two lying on each of three bosses, two of whose axes are near parallel: the slabs across
    # the axes bound y loosely (1 / |det| = 21 times their width), the sensors' own slabs narrow it.
    Case("{G3-R}x3 design (default plan)", "{G3-R}" * 3, (0.0, SIGMA_MM), plan="default"),
    Case("{G3-R}x3 design (default plan), printed", "{G3-R}" * 3, (0.0, SIGMA_MM), plan="default", printed=True),
    Case("collinear 4-3-2 cube", "cube", (SIGMA_MM,), _collinear),
    Case("near-degenerate 3-2-1 cube", "cube", (0.0, SIGMA_MM), _diagonal),
    Case("one touch 0.5 mm off, cube 3-3-3", "cube", (SIGMA_MM,), _offset_touch),
    Case("one touch mislabelled, cube 3-3-3", "cube", (SIGMA_MM,), _mislabelled_touch),
    # Three balls touched four times each, or three planes: their centres, or their normals (either sign), fix the
    # turn, and the search starts from the rotation boxes they leave (search.first_turns).
    Case("sphere-plate 4 per ball", "sphere-plate", (0.0, SIGMA_MM), _counts({"ball_1": 4, "ball_2": 4, "ball_3": 4})),
    Case("sphere-plate 4 per ball, printed", "sphere-plate", (0.0, SIGMA_MM),
         _counts({"ball_1": 4, "ball_2": 4, "ball_3": 4}), printed=True),
    Case("cube 4-4-4", "cube", (0.0, SIGMA_MM), _counts({"top": 4, "front": 4, "left": 4})),
    Case("cube 4-4-4, printed", "cube", (0.0, SIGMA_MM), _counts({"top": 4, "front": 4, "left": 4}), printed=True),
    Case("v-block 4-4-4", "v-block", (0.0, SIGMA_MM), _counts({"groove_a": 4, "groove_b": 4, "end": 4})),
    Case("v-block 4-4-4, printed", "v-block", (0.0, SIGMA_MM), _counts({"groove_a": 4, "groove_b": 4, "end": 4}),
         printed=True),
    # One plane touched three times or more fixes its normal, either sign, and the turn about it is searched along
    # the circle it leaves, cut by pairs of touches on another plane (search.tube_turns): the quarter-sphere's and
    # the inclined plane's point-probe plans.
    Case("quarter-sphere 3-2-2", "quarter-sphere", (0.0, SIGMA_MM), _counts({"flat_a": 3, "flat_b": 2, "sphere": 2})),
    Case("quarter-sphere 3-2-2, printed", "quarter-sphere", (0.0, SIGMA_MM),
         _counts({"flat_a": 3, "flat_b": 2, "sphere": 2}), printed=True),
    Case("inclined-plane-cylinder 6+8", "inclined-plane-cylinder", (0.0, SIGMA_MM), _counts({"plane": 6, "cylinder": 8})),
    Case("inclined-plane-cylinder 6+8, printed", "inclined-plane-cylinder", (0.0, SIGMA_MM),
         _counts({"plane": 6, "cylinder": 8}), printed=True),
    # Twelve unlabelled touches anywhere on the solid (--anywhere): every face may hold each. (The quarter-sphere's
    # poses are the half turn that swaps its flats: none separates them.)
    Case("quarter-sphere 12 anywhere", "quarter-sphere", (SIGMA_MM,), _anywhere("quarter-sphere", 12),
         unlabelled=True, symmetric=True, anywhere=True),
    Case("inclined-plane-cylinder 12 anywhere", "inclined-plane-cylinder", (SIGMA_MM,),
         _anywhere("inclined-plane-cylinder", 12), unlabelled=True, anywhere=True),
    # Parts of many alike faces, told apart by poses (registration.face_search): the cube's 24 turns and the
    # v-block's half turn fit touches anywhere alike, none separates them.
    Case("cube 12 anywhere", "cube", (SIGMA_MM,), _anywhere("cube", 12), unlabelled=True, symmetric=True,
         anywhere=True),
    Case("v-block 12 anywhere", "v-block", (SIGMA_MM,), _anywhere("v-block", 12), unlabelled=True, symmetric=True,
         anywhere=True),
]
VARIANTS = [(case, noise) for case in CASES for noise in case.noise_mm]


def variant_id(case, noise_mm):
    return f"{case.name}, {'noise-free' if noise_mm == 0.0 else f'{noise_mm * 1000:g} um'}"


@dataclass
class Layout:
    """One random layout: features, touches (measurement frame), contacts and the true fixture2meas."""

    features: dict
    touches: dict
    contacts: list
    truth: np.ndarray
    tolerance: object = None


def layout(case, noise_mm, index):
    """The seeded layout ``index`` of a case at a noise level."""
    rng = np.random.default_rng([zlib.crc32(case.name.encode()), int(noise_mm * 1e6), index])
    features = _faces(case.template)[0] if case.anywhere else _features(case.template)
    truth = np.eye(4)
    truth[:3, :3] = random_rotations(rng, 1)[0]
    truth[:3, 3] = rng.uniform(-TRUE_POSE_RANGE_MM, TRUE_POSE_RANGE_MM, 3)
    if case.plan:
        touches, contacts = plan_touches(_fixture(case.template).touch_plans()[case.plan].touches, truth)
    else:
        touches, contacts = {fid: p @ truth[:3, :3].T + truth[:3, 3] for fid, p in case.draw(features, rng).items()}, []
    touches = {fid: p + rng.normal(scale=noise_mm, size=p.shape) for fid, p in touches.items()}
    if contacts and noise_mm:
        # Each sensor placed with the noise model's random rigid error (translation and turn).
        _, contacts = perturb_touches({}, contacts, rng, noise_mm)
    return Layout(features, touches, contacts, truth, _tolerance(case.template, features) if case.printed else None)


@dataclass
class Outcome:
    """What the engine said on one layout and what it got wrong (see the module doc)."""

    status: str
    found: int  # admissible poses the brute force finds (-1: not run, the engine claimed no pose)
    search: str = "complete"
    wrong_unique: bool = False
    unique_missed: bool = False
    unique_none: bool = False
    ambiguous_missing: bool = False
    false_inconsistent: bool = False
    false_underdetermined: bool = False
    separating: str = ""  # "", "separates", "missing", "off the part", "does not separate"
    seconds: dict = field(default_factory=dict)  # CPU s: engine, brute force and (timed) engine with a nominal pose


def displacement_mm(a, b, points):
    """The largest distance (mm) between where two ``fixture2meas`` put fixture ``points`` (n, 3)."""
    return float(np.max(np.linalg.norm(points @ (a[:3, :3] - b[:3, :3]).T + a[:3, 3] - b[:3, 3], axis=1)))


def spread_mm(problem, truth, sigma_mm, points):
    """The largest standard deviation (mm) of where the pose puts a fixture point, under the Cramer-Rao
    bound of touches with iid noise ``sigma_mm`` at the true pose; inf when the touches leave a motion
    free."""
    if sigma_mm == 0.0:
        return 0.0
    A, b = problem.pose_of(truth)
    _, J = problem.jacobians(A[None], b[None])
    information = J[0].T @ J[0]
    if np.linalg.matrix_rank(information) < 6:
        return np.inf
    covariance = sigma_mm**2 * np.linalg.inv(information)
    # Where a fixture point x lands, p = A^T (x - b) + c, moved by each parameter of (w, b).
    step = 1e-6
    moved = []
    for k in range(6):
        dx = step * np.eye(6)[k]
        A_k, b_k = rotations(dx[None, :3])[0] @ A, b + dx[3:]
        moved.append(((points - b_k) @ A_k - (points - b) @ A) / step)
    G = np.stack(moved, axis=2)  # (n, 3, 6)
    return float(np.sqrt(np.max(np.einsum("nij,jk,nik->n", G, covariance, G))))


def judge(case, noise_mm, index, timed=False):
    """The :class:`Outcome` of register_touches on layout ``index`` of a case; ``timed``: also time the
    engine from a nominal pose (``NOMINAL_TWIST`` off the truth)."""
    lay = layout(case, noise_mm, index)
    # Noise-free touches are registered at the engine's default sigma, as a user would.
    kwargs = {"contacts": lay.contacts, "tolerance": lay.tolerance, **({"sigma_mm": noise_mm} if noise_mm else {})}
    given = lay.touches
    if case.unlabelled:
        given, kwargs["unlabelled"] = {}, np.vstack(list(lay.touches.values()))
    if case.anywhere:
        kwargs["faces"] = lay.features
    seconds = {}
    clock = time.process_time()
    result = register_touches(lay.features, given, **kwargs)
    seconds["engine"] = time.process_time() - clock
    if timed:
        nominal = np.eye(4)
        nominal[:3, :3] = rotations(NOMINAL_TWIST[None, :3])[0] @ lay.truth[:3, :3]
        nominal[:3, 3] = lay.truth[:3, 3] + NOMINAL_TWIST[3:]
        clock = time.process_time()
        register_touches(lay.features, given, nominal, **kwargs)
        seconds["engine, nominal pose"] = time.process_time() - clock
    status = result["status"]
    if status == "underdetermined":
        # No pose claimed (exit 4), but not where the touches plainly fix the pose (below).
        return Outcome(status, -1, result["search"], seconds=seconds,
                       false_underdetermined=_plainly_determined(case, lay, noise_mm, index))
    if result["search"] != "complete":
        return Outcome(status, -1, result["search"], seconds=seconds)  # no claim (exit 6): counted apart
    clock = time.process_time()
    found = admissible_poses(lay.features, lay.touches, lay.contacts, noise_mm, lay.truth, seed=index,
                             unlabelled=case.unlabelled)
    seconds["brute force"] = time.process_time() - clock

    points = np.vstack([patch_points(f) for f in lay.features.values()])
    points = points[np.random.default_rng(0).choice(len(points), min(len(points), DISPLACEMENT_POINTS), replace=False)]
    problem = TouchResiduals(lay.features, lay.touches, lay.contacts)
    tolerance = max(TOLERANCE_SIGMAS * spread_mm(problem, lay.truth, noise_mm, points), EXACT_TOLERANCE_MM)

    def close(a, b):
        return displacement_mm(np.asarray(a), np.asarray(b), points) <= tolerance

    out = Outcome(status, len(found), result["search"], seconds=seconds)
    listed = [s["pose"] for s in result["solutions"]]
    if status == "unique":
        out.wrong_unique = not close(result["pose"], lay.truth)
        # Another pose: a brute-force one farther from the answer than the tolerance (minima within it are one
        # pose with its uncertainty, as the engine reports it).
        out.unique_missed = any(not close(p.fixture2meas, result["pose"]) for p in found)
        out.unique_none = not found
    elif status == "ambiguous":
        out.ambiguous_missing = any(not any(close(p.fixture2meas, s) for s in listed) for p in found)
        out.separating = "" if case.symmetric else _separating(lay, given, result, kwargs, noise_mm, index, close)
    elif status == "inconsistent":
        out.false_inconsistent = bool(found)
    return out


def _plainly_determined(case, lay, noise_mm, index):
    """Whether the touches plainly fix the pose on an exact part: at the true pose each touch's place on the
    fixture has a standard deviation under ``PLAIN_SPREAD_MM`` (the touch-noise Cramer-Rao bound, at the
    engine's default sigma when noise-free), and the brute force finds one admissible pose. The engine's
    line for too weak to judge is ten times that (1 mm at three standard deviations). Printed parts are not
    judged: their deviations widen the spread beyond this model."""
    if case.printed:
        return False
    problem = TouchResiduals(lay.features, lay.touches, lay.contacts)
    R, t = lay.truth[:3, :3], lay.truth[:3, 3]
    points = (np.vstack(list(lay.touches.values())) - t) @ R
    if spread_mm(problem, lay.truth, noise_mm or DEFAULT_SIGMA_MM, points) >= PLAIN_SPREAD_MM:
        return False
    return len(admissible_poses(lay.features, lay.touches, lay.contacts, noise_mm, lay.truth, seed=index,
                                unlabelled=case.unlabelled)) == 1


def _separating(lay, given, result, kwargs, noise_mm, index, close):
    """Probe where the separating touch says, on the real part; whether it then gives the true pose (added,
    labelled, to the touches ``given``)."""
    touch = result["separating_touch"]
    if touch is None:
        return "missing"
    feature = lay.features[touch["feature"]]
    R, t = lay.truth[:3, :3], lay.truth[:3, 3]
    # The probe goes to point_meas_mm and moves along the surface normal until it touches the real part.
    on_part = feature.closest_point((np.asarray(touch["point_meas_mm"]) - t) @ R)
    if not feature.contains(on_part, PATCH_TOLERANCE_MM)[0]:
        return "off the part"
    point = on_part[0] @ R.T + t + np.random.default_rng(index).normal(scale=noise_mm, size=3)
    touches = {fid: p.copy() for fid, p in given.items()}
    touches[feature.id] = np.vstack([touches.get(feature.id, np.zeros((0, 3))), point])
    again = register_touches(lay.features, touches, **kwargs)
    return "separates" if again["status"] == "unique" and close(again["pose"], lay.truth) else "does not separate"


def judge_all(case, noise_mm, layouts, timed=False, first=0):
    return [judge(case, noise_mm, index, timed) for index in range(first, first + layouts)]
