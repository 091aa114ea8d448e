"""Where the features of a designed fixture go, and the touch plan they carry (no CAD).

Fixture frame: a square base block, side ``size_mm``, its top face in z = 0
(origin at its centre, Z up). Up to three planes, the most touched first, are
the block's top, front and left faces; every other fixture-side element is
the head of a round stalk that rises from inside the block along a direction
``w`` at least ``MIN_ELEVATION_DEG`` above the horizon:

* PL: the stalk's flat end face (normal ``w``);
* S: a ball on the stalk's end;
* C: the stalk itself, a boss whose lateral face is the feature (axis ``w``);
* L: a chisel end, two roof faces meeting in a straight ridge across ``w``;
* P: a cone tip on the stalk's end (its apex).

The stalks cross z = 0 at their feet and stay apart above it, so the solid is
the block plus one piece per feature and its volume is exact: a cylinder cut
obliquely by z = 0 keeps ``pi a^2`` times its axial length above the plane.
Touch points on pieces face upwards (the sensor comes from above, the block
cannot be in its way) and their approach rays stay clear of the other pieces;
those on the block's sides are approached from outside it.

The minimal touch plan holds one touch per contact; its mobility at the real
geometry is the rank of the contact model's rows
(:mod:`fixturecad.registration.problem`). Among seeded random layouts that
locate, the one whose default plan carries the most information (the D
criterion of ``fixturecad plan``) is kept and then refined by nudging one
piece at a time (:func:`refined`).
"""

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from fixturecad.registration.contacts import ContactType
from fixturecad.registration.elements import cross, perpendicular_basis
from fixturecad.registration.features import Cylinder, Extent, Line, Plane, Point, Sphere
from fixturecad.registration.mobility import matrix_rank
from fixturecad.registration.problem import Problem
from fixturecad.registration.synthetic import plan_touches
from fixturecad.registration.touches import build_groups, laid_sensor
from fixturecad.registration.planning import criterion_values
from fixturecad.registration.uncertainty import cramer_rao_bound, sigmas
from fixturecad.templates.base import box_halfspaces

MIN_ELEVATION_DEG = 45.0  # stalks rise at least this steeply: seen from above, printed without support
MIN_APPROACH_Z = 0.15  # a touch's outward normal climbs at least this much: the sensor comes from above
CLEARANCE_MM = 2.0  # gap kept between pieces above the base, and between an approach ray and a piece
BASE_THICKNESS = 0.25  # of the size
STALK_RADIUS = {"PL": 0.07, "S": 0.04, "C": 0.05, "L": 0.06, "P": 0.05}  # of the size
SHARED_PLANE_RADIUS = 0.12  # of the size: a face touched several times gets a wider disc
BALL_RADIUS = 0.1  # of the size
HEAD_LENGTH = 0.22  # axial length of a stalk above the base top, of the size
BALL_TILT_DEG = 50.0  # touches on a ball this far from its stalk's direction (half that for a lone touch)
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0  # steps of a sequence that fills an interval evenly
MAX_GROWTH = 2.5  # pieces' radii are drawn up to this many times the sizes above
MAX_LENGTH_GROWTH = 5.0  # and their lengths up to this many times
FOOT_RING = 0.28  # feet on a circle of this radius, of the size
BOSS_SENSOR_TILT_DEG = 35.0  # a sensor laid round a boss turns at most this far off across it
ROOF_HALF_ANGLE_DEG = 45.0  # a chisel's roof faces leave its ridge this far from the stalk direction
CONE_HEIGHT = 1.0  # a cone tip's height, of its stalk radius
MIN_SIZE_MM = 20.0
DEGENERATE_MM2 = 1e-12  # a segment whose squared length is below this is a point (a ball's capsule)
LAYOUTS_COMPARED = 64  # locating layouts a design chooses the best of
LAYOUT_TRIALS = 400  # random layouts tried at most
REFINE_STEPS = 200  # nudges tried on each layout refined
REFINED_STARTS = 3  # the best random layouts refined: one alone often sits in a poorer basin
NUDGE = 0.03  # a nudge's standard deviation: of the size for feet
NUDGE_RAD = 0.08  # and for directions, phases and sensor turns
NUDGE_GROWTH_LOG = 0.3  # and of the logarithm of radii and lengths: pieces grow or shrink boldly, as in the pool
NUDGE_GROWTH = 1.5  # a nudge kept grows the next ones this many times; one not kept shrinks them by its 4th root
MIN_NUDGE_SCALE, MAX_NUDGE_SCALE = 0.1, 4.0  # the nudges stay within these multiples of the sizes above
MAX_STALK_OF_BALL = 0.8  # a ball's stalk is at most this fraction of its radius
MIN_MARGIN = 1e-3  # smallest normalised singular value of the plan's Jacobian a design accepts
FEATURE_NAMES = {"PL": "face", "S": "ball", "C": "boss", "L": "edge", "P": "tip"}
# The block's own faces a plane of the combination takes, most touched first: as far apart and as
# large as the block allows (the datum faces, named datum_<face> when no plane takes them).
BLOCK_FACES = {"top": 2, "front": 1, "left": 0}  # face -> the axis of its normal
BLOCK_NORMALS = {"top": (0.0, 0.0, 1.0), "front": (0.0, -1.0, 0.0), "left": (-1.0, 0.0, 0.0)}
# Touch spots on a block face, as fractions of its half-sides, spread first: corners, then edge middles.
TOP_SPOTS = ((-1, -1), (1, -1), (-1, 1), (1, 1), (0, -1), (-1, 0), (1, 0), (0, 1))
SIDE_SPOTS = ((-1, 0.0), (1, 0.0), (-1, 0.6), (1, -0.6), (-1, -0.6), (1, 0.6), (0, 0.6), (0, -0.6))


@dataclass
class Piece:
    """One feature on its stalk: foot in z = 0, direction ``w``, stalk radius, length above the foot."""

    id: str
    element: str
    foot: np.ndarray
    w: np.ndarray
    radius: float
    length: float
    ridge: np.ndarray | None = None  # a chisel's ridge direction (perpendicular to w)
    head_radius: float = 0.0  # a ball's radius
    phase: float = 0.0  # rad: where round the feature its touches start (they spread evenly from there)

    @property
    def top(self) -> np.ndarray:
        return self.foot + self.length * self.w

    @property
    def reach(self) -> float:
        """Radius of the capsule from the foot to the top that holds the piece."""
        return max(self.radius, self.head_radius)

    @property
    def tilt(self) -> float:
        """Half the vertical extent of the stalk's cross-section, per unit radius."""
        return math.sqrt(max(0.0, 1.0 - self.w[2] ** 2))

    def below(self) -> float:
        """Axial length of the stalk below the foot (inside the block), its end disc under z = 0."""
        return (self.radius * self.tilt + 0.02 * self.length) / self.w[2]

    def feature(self):
        """The analytic sensing feature with its patch."""
        top, w = self.top, self.w
        if self.element == "PL":
            return Plane(self.id, top, w, Extent(cylinders=[[*top, *w, self.radius]]))
        if self.element == "S":
            # the patch ends at the circle where the stalk enters the ball
            cut = self.foot @ w + self.length - math.sqrt(self.head_radius**2 - self.radius**2)
            return Sphere(self.id, top, self.head_radius, Extent(halfspaces=[[*(-w), -cut]]))
        if self.element == "C":
            return Cylinder(self.id, self.foot, w, self.radius, Extent(interval=(self.boss_start(), self.length)))
        if self.element == "L":
            return Line(self.id, self.top, self.ridge, Extent(interval=(-self.radius, self.radius)))
        return Point(self.id, self.top + CONE_HEIGHT * self.radius * w)

    def boss_start(self) -> float:
        """Axial parameter from which a boss's lateral face stands clear of the block."""
        return (self.radius * self.tilt + CLEARANCE_MM) / self.w[2]

    def roof_drop(self) -> float:
        """How far a chisel's roof falls from its ridge to the stalk's rim, along w."""
        return self.radius * math.tan(math.radians(ROOF_HALF_ANGLE_DEG))

    def roof_normals(self) -> list:
        """Outward normals of a chisel's two roof faces, each leaving the ridge."""
        beta = math.radians(ROOF_HALF_ANGLE_DEG)
        across = cross(self.w, self.ridge)
        return [math.cos(beta) * self.w + side * math.sin(beta) * across for side in (1.0, -1.0)]

    def volume(self) -> float:
        """Volume of the piece above z = 0, mm^3 (exact: see the module doc)."""
        a, L = self.radius, self.length
        stalk = math.pi * a**2 * L
        if self.element == "S":
            r = self.head_radius
            h0 = math.sqrt(r**2 - a**2)
            cap = r - h0
            return 4.0 / 3.0 * math.pi * r**3 + math.pi * a**2 * (L - h0) - math.pi * cap**2 * (3 * r - cap) / 3.0
        if self.element == "L":
            return stalk - 4.0 / 3.0 * a**3 * math.tan(math.radians(ROOF_HALF_ANGLE_DEG))
        if self.element == "P":
            return stalk + math.pi * a**2 * CONE_HEIGHT * a / 3.0
        return stalk

    def lowest_above(self) -> float:
        """The lowest z of the piece's head (a ball's bottom, a roof's rim, the end disc's rim)."""
        if self.element == "S":
            return self.top[2] - self.head_radius
        if self.element == "L":
            return (self.length - self.roof_drop()) * self.w[2] - self.radius * self.tilt
        return self.length * self.w[2] - self.radius * self.tilt

    def to_json(self) -> dict:
        out = {"id": self.id, "element": self.element, "foot": self.foot.tolist(), "direction": self.w.tolist(),
               "stalk_radius_mm": self.radius, "length_mm": self.length}
        if self.ridge is not None:
            out["ridge"] = self.ridge.tolist()
        if self.head_radius:
            out["ball_radius_mm"] = self.head_radius
        return out


@dataclass
class Layout:
    """A placed design: the block, its pieces and the touch plan."""

    size: float
    pieces: list
    touches: list  # touch-plan entries (templates.base.touch form): one per contact
    checks: list  # a second touch of each contact elsewhere on its feature: what makes the pose unique
    faces: dict = field(default_factory=dict)  # block face -> the id of the combination's plane on it
    turns: dict = field(default_factory=dict)  # (feature id, touch index) -> its sensor's turn, rad (sensor_turn)
    margin: float = 0.0
    mobility: int = 6
    information: float = -math.inf  # log det of the default plan's scaled information (the D criterion)
    # What the refinement reuses of the features a nudge leaves alone: each touch's (point, normal, approached
    # from above) by (feature id, index), and each feature's touches' scaled information (6, 6).
    spots: dict = field(default_factory=dict, repr=False)
    blocks: dict = field(default_factory=dict, repr=False)

    @property
    def thickness(self) -> float:
        return BASE_THICKNESS * self.size

    def face_ids(self) -> dict:
        """Block face -> feature id: a plane of the combination's, or the datum's own name."""
        return {face: self.faces.get(face, f"datum_{face}") for face in BLOCK_FACES}

    def block_features(self) -> list:
        """The block's top, front and left faces as planes, their whole rectangles the patches."""
        return list(_block_planes(self.size, tuple(self.face_ids().items())))

    def features(self) -> list:
        return [piece.feature() for piece in self.pieces] + self.block_features()

    def volume(self) -> float:
        return self.size**2 * self.thickness + sum(piece.volume() for piece in self.pieces)


@functools.lru_cache(maxsize=16)
def _block_planes(size, face_ids) -> tuple:
    """:meth:`Layout.block_features` of a block of ``size`` whose faces carry ``face_ids`` ((face, id) pairs),
    made once: the layout search asks for them at every step; read-only, as they are shared."""
    t = BASE_THICKNESS * size
    low, high = np.array([-size / 2, -size / 2, -t]), np.array([size / 2, size / 2, 0.0])
    planes = tuple(Plane(fid, _face_point(face, size, t), BLOCK_NORMALS[face],
                         Extent(halfspaces=box_halfspaces(low, high, BLOCK_FACES[face]))) for face, fid in face_ids)
    for plane in planes:
        for array in (plane.point, plane.normal, plane.extent.halfspaces):
            array.flags.writeable = False
    return planes


def plan_problem(features, entries) -> Problem:
    """The stacked contact rows of a touch plan made at the nominal pose."""
    touches, contacts = plan_touches(entries, np.eye(4))
    return Problem(build_groups({f.id: f for f in features}, touches, contacts=contacts))


def plan_jacobian(features, entries) -> np.ndarray:
    """The twist Jacobian (m, 6) of a touch plan at its nominal pose: the contact model's rows."""
    return plan_problem(features, entries).sensor_rows(np.eye(3), np.zeros(3))[1]


def plan_bound(features, entries) -> tuple:
    """The Cramer-Rao bound of a plan at its nominal pose with the default touch noise (5 um): RMS
    translation (mm) and rotation (deg) standard deviations, None each when it does not locate."""
    problem = plan_problem(features, entries)
    return sigmas(cramer_rao_bound(problem, np.eye(4), problem.sigma))


def plan_information(features, entries, length_mm) -> float:
    """The D criterion of a plan as ``fixturecad plan`` takes it: log det of its rows' information with
    rotations scaled by ``length_mm`` (-inf when it does not locate)."""
    return float(criterion_values(_scaled_information(features, entries, length_mm), "d"))


def _scaled_information(features, entries, length_mm) -> np.ndarray:
    """The information (6, 6) of a plan's rows, rotations scaled by ``length_mm``: a sum over its touches."""
    J = plan_jacobian(features, entries) * np.array([1.0 / length_mm] * 3 + [1.0] * 3)
    return J.T @ J


def plan_mobility(features, entries, length_mm) -> tuple[int, float]:
    """(mobility, margin) of a plan: 6 - rank of its rows, and the smallest singular value of the
    Jacobian with rotations scaled by ``length_mm`` over the largest (0 when it does not locate)."""
    J = plan_jacobian(features, entries)
    rank = matrix_rank(J, length_mm)
    s = np.linalg.svd(J / np.array([length_mm] * 3 + [1.0] * 3), compute_uv=False)
    return 6 - rank, float(s[5] / s[0]) if rank == 6 and len(s) >= 6 else 0.0


def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _rotate(v, axis, angle):
    """``v`` turned by ``angle`` rad about unit ``axis`` (Rodrigues)."""
    return v * math.cos(angle) + cross(axis, v) * math.sin(angle) + axis * (axis @ v) * (1 - math.cos(angle))


def _direction(rng, outward=None) -> np.ndarray:
    """A random stalk direction; leaning away from the centre (azimuth ``outward``, rad) when given."""
    elevation = math.radians(rng.uniform(MIN_ELEVATION_DEG, 85.0))
    azimuth = rng.uniform(0.0, 2 * math.pi) if outward is None else outward + rng.uniform(-1.2, 1.2)
    return np.array([math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth),
                     math.sin(elevation)])


def _upward(axis) -> np.ndarray:
    """The unit direction perpendicular to ``axis`` that climbs most."""
    up = np.array([0.0, 0.0, 1.0])
    return _unit(up - (up @ axis) * axis)


def touch_spot(piece: Piece, index: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``index``-th of ``count`` touch points on a piece's feature and the outward normal there, spread
    evenly round it from the piece's phase."""
    w = piece.w
    turn = piece.phase + 2 * math.pi * index / count
    if piece.element == "PL":
        e1, e2 = perpendicular_basis(w)
        spread = 0.65 * piece.radius if count > 1 else 0.3 * piece.radius
        return piece.top + spread * (math.cos(turn) * e1 + math.sin(turn) * e2), w
    if piece.element == "S":
        # within 55 deg of the stalk's end direction, never on its underside
        e1, e2 = perpendicular_basis(w)
        tilt = math.radians(BALL_TILT_DEG if count > 1 else BALL_TILT_DEG / 2)
        normal = math.cos(tilt) * w + math.sin(tilt) * (math.cos(turn) * e1 + math.sin(turn) * e2)
        return piece.top + piece.head_radius * normal, normal
    if piece.element == "C":
        # spread round the boss as far as the approach still climbs, and along it by the golden-ratio
        # sequence from its foot to its end
        up = _upward(w)
        side = math.acos(min(1.0, 1.5 * MIN_APPROACH_Z / up[2]))
        normal = _rotate(up, w, side * math.cos(turn))
        lo = piece.boss_start() + 0.05 * (piece.length - piece.boss_start())
        t = lo + (index * GOLDEN % 1.0) * 0.9 * (piece.length - lo)
        return piece.foot + t * w + piece.radius * normal, normal
    if piece.element == "L":
        s = (-0.6 + 1.2 * (index + 0.5) / count) * piece.radius
        return piece.top + s * piece.ridge, w
    return piece.feature().point, w


def _face_point(face, size, thickness) -> np.ndarray:
    """The middle of a block face, mm."""
    return {"top": np.zeros(3), "front": np.array([0.0, -size / 2, -thickness / 2]),
            "left": np.array([-size / 2, 0.0, -thickness / 2])}[face]


def face_spot(face, index, size, thickness) -> tuple[np.ndarray, np.ndarray]:
    """The ``index``-th touch on a block face (corners first, an inset off its edges) and its normal."""
    normal = np.array(BLOCK_NORMALS[face])
    if face == "top":
        corner = 0.45 * size - CLEARANCE_MM  # as the point-probe plan's rim touches
        u, v = TOP_SPOTS[index % len(TOP_SPOTS)]
        return np.array([u * corner, v * corner, 0.0]), normal
    u, v = SIDE_SPOTS[index % len(SIDE_SPOTS)]
    across = 0.42 * size * u
    z = -thickness / 2 + v * (thickness / 2 - CLEARANCE_MM)
    point = np.array([across, -size / 2, z]) if face == "front" else np.array([-size / 2, across, z])
    return point, normal


def sensor_turn(ctype: ContactType, feature, rng) -> float | None:
    """A random turn of a touch's sensor (rad) for :func:`sensor_entry`: about the normal when nothing fixes
    its direction, off across a boss within ``BOSS_SENSOR_TILT_DEG``; None for a plain probe and across an
    edge, which have none."""
    if (ctype.sensor == "P" and not ctype.fixture_fixed) or feature.kind == "line":
        return None
    if feature.kind == "cylinder":
        return math.radians(rng.uniform(-BOSS_SENSOR_TILT_DEG, BOSS_SENSOR_TILT_DEG))
    return rng.uniform(0, 2 * math.pi)


def sensor_entry(ctype: ContactType, feature, point, normal, ball_mm: float, turn: float | None) -> dict:
    """One touch-plan entry: a sensor element of ``ctype`` touching ``feature`` at ``point`` from the
    outward ``normal``'s side (:func:`~fixturecad.registration.touches.laid_sensor`); a line or a
    cylinder sensor lies across an edge, round a boss turned by ``turn`` (rad, :func:`sensor_turn`), or
    in any direction ``turn`` gives in a face or on a ball."""
    entry = {"contact": ctype.name, "feature": feature.id, "points": [[float(v) for v in point]]}
    if ctype.sensor == "P" and not ctype.fixture_fixed:
        return entry  # a plain probe touch
    axis = feature.axis if feature.kind == "cylinder" else feature.direction if feature.kind == "line" else None
    if axis is None:
        tangent = _rotate(perpendicular_basis(normal)[0], normal, turn)
    else:
        tangent = _unit(cross(axis, normal))  # across the edge, or round the boss
        if feature.kind == "cylinder":
            tilt = math.radians(BOSS_SENSOR_TILT_DEG)
            tangent = _rotate(tangent, normal, min(tilt, max(-tilt, turn)))
    sensor = laid_sensor(ctype.sensor, point, normal, tangent, ball_mm)
    if ctype.sensor == "PL" and ctype.sensor_fixed and axis is not None:
        sensor["line"] = axis  # where on the plane the line or the boss lies is known
    entry["sensor"] = {key: value if isinstance(value, (str, float)) else [float(v) for v in value]
                       for key, value in sensor.items()}
    return entry


def _segment_distances(a0, a1, b0, b1) -> np.ndarray:
    """Smallest distances (n,) between the segments a0-a1 and b0-b1 ((n, 3) each, mm), any of them possibly a
    point: the closest points' parameters, each clamped to its segment (Ericson, Real-Time Collision
    Detection, 5.1.9)."""
    d1, d2, r = a1 - a0, b1 - b0, a0 - b0
    a, e, f = np.sum(d1 * d1, axis=-1), np.sum(d2 * d2, axis=-1), np.sum(d2 * r, axis=-1)
    c, b = np.sum(d1 * r, axis=-1), np.sum(d1 * d2, axis=-1)
    point_a, point_b = a <= DEGENERATE_MM2, e <= DEGENERATE_MM2
    a, e = np.where(point_a, 1.0, a), np.where(point_b, 1.0, e)
    denominator = a * e - b * b  # 0 for parallel segments: any s will do, take 0
    skew = denominator > DEGENERATE_MM2 * a
    s = np.where(skew, np.clip((b * f - c * e) / np.where(skew, denominator, 1.0), 0.0, 1.0), 0.0)
    t = (b * s + f) / e
    s = np.where(t < 0.0, np.clip(-c / a, 0.0, 1.0), np.where(t > 1.0, np.clip((b - c) / a, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    s = np.where(point_a, 0.0, np.where(point_b, np.clip(-c / a, 0.0, 1.0), s))
    t = np.where(point_b, 0.0, np.where(point_a, np.clip(f / e, 0.0, 1.0), t))
    return np.linalg.norm(r + s[..., None] * d1 - t[..., None] * d2, axis=-1)


def _capsules(piece: Piece) -> list:
    """Segments with radii (start, end, radius mm) that hold the piece above the block: its stalk, from
    where its rim leaves z = 0 (a leaning stalk's uphill side rises before its foot on the axis: two
    stalks that met there made a solid short of the analytic volume), and a ball apart."""
    tip = CONE_HEIGHT * piece.radius if piece.element == "P" else 0.0
    stalk = (piece.foot - piece.radius * piece.tilt / piece.w[2] * piece.w, piece.top + tip * piece.w, piece.radius)
    return [stalk, (piece.top, piece.top, piece.head_radius)] if piece.element == "S" else [stalk]


def _stalk_radius(element, touches, size) -> float:
    """The smallest stalk radius :func:`_place` draws for a piece touched ``touches`` times, mm."""
    return (SHARED_PLANE_RADIUS if element == "PL" and touches > 1 else STALK_RADIUS[element]) * size


def _as_drawn(piece: Piece, touches, size) -> bool:
    """Whether the piece's radii and length lie within the ranges :func:`_place` draws them from: the
    refinement moves pieces about, but does not grow them past what the block was given."""
    base = _stalk_radius(piece.element, touches, size)
    ball = BALL_RADIUS * size if piece.element == "S" else 0.0
    return (base <= piece.radius <= MAX_GROWTH * base and ball <= piece.head_radius <= MAX_GROWTH * ball
            and 0.8 * HEAD_LENGTH * size <= piece.length <= (0.8 + MAX_LENGTH_GROWTH) * HEAD_LENGTH * size)


def _place(groups, size, rng) -> list:
    """Random pieces for the feature groups ``[(id, element, touch count)]``; None if they collide."""
    count = len(groups)
    phase = rng.uniform(0, 2 * math.pi)
    bold = rng.uniform(0.0, 1.0)  # how far this layout grows its pieces: crowded ones fit only small
    pieces = []
    for index, (fid, element, touches) in enumerate(groups):
        angle = phase + 2 * math.pi * index / count + rng.uniform(-0.2, 0.2)
        # a piece alone may stand anywhere and lean across the block, the longer for it
        ring = FOOT_RING * size * (rng.uniform(0.8, 1.4) if count > 1 else rng.uniform(0.0, 1.2))
        foot = np.array([ring * math.cos(angle), ring * math.sin(angle), 0.0])
        w = _direction(rng, angle if count > 1 else None)
        grow = rng.uniform(1.0, 1.0 + bold * (MAX_GROWTH - 1.0))  # larger pieces carry more information
        radius = grow * _stalk_radius(element, touches, size)
        head = grow * BALL_RADIUS * size if element == "S" else 0.0
        length = HEAD_LENGTH * size * rng.uniform(0.8, 0.8 + bold * MAX_LENGTH_GROWTH)
        if element == "S":
            length = max(length, (head + CLEARANCE_MM) / w[2] + 0.01 * size)
        ridge = _unit(_rotate(perpendicular_basis(w)[0], w, rng.uniform(0, 2 * math.pi))) if element == "L" else None
        piece = Piece(fid, element, foot, w, radius, length, ridge, head, rng.uniform(0, 2 * math.pi))
        if element == "L":
            piece.length = max(length, (piece.roof_drop() * w[2] + radius * piece.tilt + CLEARANCE_MM) / w[2])
        pieces.append(piece)
    return pieces if _fits(pieces, size) else None


def rim_points(size) -> np.ndarray:
    """Three points on the block's top face near its corners (the point-probe plan's primary touches), mm."""
    corner = 0.45 * size - CLEARANCE_MM
    return np.array([[-corner, -corner, 0.0], [corner, -corner, 0.0], [-corner, corner, 0.0]])


def _fits(pieces, size, moved=None) -> bool:
    """Every piece inside the block's footprint, clear of the others and of the rim touches seen from
    above, its head above the block; or, given the id of the one piece ``moved`` since they fitted, that one."""
    thickness = BASE_THICKNESS * size
    mine = [piece for piece in pieces if moved is None or piece.id == moved]
    for piece in mine:
        w_xy = math.hypot(piece.w[0], piece.w[1])
        below = piece.below()
        if np.abs(piece.foot[:2]).max() + piece.reach + below * w_xy > size / 2 - CLEARANCE_MM:
            return False
        if below * piece.w[2] + piece.radius * piece.tilt > thickness - CLEARANCE_MM:
            return False
        if piece.lowest_above() < CLEARANCE_MM:
            return False
    rim = rim_points(size)
    if not _reachable(rim, np.broadcast_to([0.0, 0.0, 1.0], rim.shape), [None] * len(rim), mine, size):
        return False
    capsules = [(piece.id, capsule) for piece in pieces for capsule in _capsules(piece)]
    pairs = [(first, second) for i, first in enumerate(capsules) for second in capsules[i + 1:]
             if first[0] != second[0] and moved in (None, first[0], second[0])]
    if not pairs:
        return True
    (a0, a1, ra), (b0, b1, rb) = ([np.array(part) for part in zip(*(pair[side][1] for pair in pairs))]
                                  for side in (0, 1))
    return bool(np.all(_segment_distances(a0, a1, b0, b1) >= ra + rb + CLEARANCE_MM))


def _reachable(points, normals, owners, pieces, size) -> bool:
    """Whether every touch's approach ray (points and outward normals (n, 3), the ids of the pieces they lie
    on) climbs and clears every other piece."""
    if not len(points):
        return True
    if np.min(normals[:, 2]) < MIN_APPROACH_Z:
        return False
    pairs = [(k, capsule) for k, owner in enumerate(owners) for piece in pieces if piece.id != owner
             for capsule in _capsules(piece)]
    if not pairs:
        return True
    touch = np.array([k for k, _ in pairs])
    a0, a1, r = (np.array(part) for part in zip(*(capsule for _, capsule in pairs)))
    ends = points + 3.0 * size * normals
    return bool(np.all(_segment_distances(points[touch], ends[touch], a0, a1) > r + CLEARANCE_MM))


def layout_plan(contacts, labels, size, ball_mm, rng, block_faces=True):
    """One random layout and its touch plan, or None when the pieces collide or a touch is hidden.

    ``contacts``: ContactTypes, sensor first; ``labels``: the feature id of each. With ``block_faces``
    the most touched planes are the block's top, front and left faces, the rest stand on stalks.
    """
    order = list(dict.fromkeys(labels))
    groups = [(fid, contacts[labels.index(fid)].fixture, labels.count(fid)) for fid in order]
    planes = sorted((g for g in groups if g[1] == "PL"), key=lambda g: -g[2]) if block_faces else []
    faces = {face: fid for face, (fid, _, _) in zip(BLOCK_FACES, planes)}
    pieces = _place([g for g in groups if g[0] not in faces.values()], size, rng)
    return None if pieces is None else planned(contacts, labels, size, ball_mm, pieces, faces, rng)


def planned(contacts, labels, size, ball_mm, pieces, faces, rng, turns=None, previous=None, moved=None):
    """The layout of these pieces and block faces with its touch plan, or None when a touch is hidden. Its
    sensors are turned as ``turns`` ((feature id, touch index) -> rad) says, the rest by ``rng``
    (:func:`sensor_turn`), and the layout keeps every turn. Given the ``previous`` layout, of which only the
    feature ``moved`` (a piece, or its sensors' turns) has changed, the other features' touches are its."""
    order = list(dict.fromkeys(labels))
    on_faces = {fid: face for face, fid in faces.items()}
    layout = Layout(size, pieces, [], [], faces)
    by_id = {piece.id: piece for piece in pieces}
    features = {f.id: f for f in layout.block_features()}
    features.update({piece.id: piece.feature() for piece in pieces if previous is None or piece.id == moved})
    seen = {fid: 0 for fid in order}
    for i, (ctype, fid) in enumerate(zip(contacts, labels)):
        count = labels.count(fid)
        for index, plan, kept in ((seen[fid], layout.touches, previous and previous.touches),
                                  (seen[fid] + count, layout.checks, previous and previous.checks)):
            key = (fid, index)
            if previous is not None and fid != moved:
                layout.spots[key], layout.turns[key] = previous.spots[key], previous.turns[key]
                plan.append(kept[i])
                continue
            if fid in on_faces:
                point, normal = face_spot(on_faces[fid], index, size, layout.thickness)
            else:
                point, normal = touch_spot(by_id[fid], index, 2 * count)
            feature = features[fid]
            layout.spots[key] = (point, normal, fid not in on_faces or normal[2] >= 1)  # a side: from outside
            turn = turns[key] if turns is not None else sensor_turn(ctype, feature, rng)
            layout.turns[key] = turn
            plan.append(sensor_entry(ctype, feature, point, normal, ball_mm, turn))
        seen[fid] += 1
    above = [(point, normal, key[0]) for key, (point, normal, up) in layout.spots.items() if up]
    if previous is not None:
        # Only the moved piece's touches and the rays that pass it can have changed.
        near = [spot for spot in above if spot[2] == moved]
        others = [spot for spot in above if spot[2] != moved]
        return layout if (_reached(near, pieces, size)
                          and _reached(others, [by_id[moved]] if moved in by_id else [], size)) else None
    return layout if _reached(above, pieces, size) else None


def _reached(spots, pieces, size) -> bool:
    """:func:`_reachable` of touches given as (point, normal, the id of the piece they lie on)."""
    points, normals, owners = zip(*spots) if spots else ((), (), ())
    return _reachable(np.array(points).reshape(-1, 3), np.array(normals).reshape(-1, 3), owners, pieces, size)


def best_layout(contacts, labels, size, ball_mm, seed, keep=LAYOUTS_COMPARED, trials=LAYOUT_TRIALS,
                steps=REFINE_STEPS, starts=REFINED_STARTS):
    """The layout whose default plan carries the most information (:func:`plan_information`): the
    ``starts`` best of the first ``keep`` locating ones of up to ``trials`` seeded random layouts (the
    planes on the block's faces, or on stalks when no layout locates so), each :func:`refined` by
    ``steps`` nudges; None if none locates; and the smallest mobility met (what remains when none
    locates)."""
    lowest = 6
    for block_faces in (True, False):
        rng = np.random.default_rng(seed)
        pool = []
        for _ in range(trials):
            layout = layout_plan(contacts, labels, size, ball_mm, rng, block_faces)
            if layout is None:
                continue
            features = layout.features()
            layout.mobility, layout.margin = plan_mobility(features, layout.touches, size)
            lowest = min(lowest, layout.mobility)
            if layout.mobility or layout.margin < MIN_MARGIN:
                continue
            layout.information = plan_information(features, layout.touches + layout.checks, size)
            pool.append(layout)
            if len(pool) == keep:
                break
        if pool:
            pool.sort(key=lambda layout: -layout.information)
            return max((refined(layout, contacts, labels, ball_mm, rng, steps) for layout in pool[:starts]),
                       key=lambda layout: layout.information), lowest
    return None, lowest


FOOT, DIRECTION, RADIUS, LENGTH, BALL, PHASE, TURNS = range(7)  # what a nudge moves (:func:`refined`)


def _nudged(piece: Piece, size, rng, scale, aspect) -> Piece:
    """The piece with one ``aspect`` moved a little, ``scale`` times the nudge (a step of :func:`refined`)."""
    step = lambda k: scale if aspect == k else 0.0  # noqa: E731
    w = _unit(piece.w + rng.normal(0.0, step(DIRECTION) * NUDGE_RAD, 3))
    foot = piece.foot + np.r_[rng.normal(0.0, step(FOOT) * NUDGE * size, 2), 0.0]
    ridge = None if piece.ridge is None else _unit(piece.ridge - (piece.ridge @ w) * w)
    grow = np.exp(rng.normal(0.0, NUDGE_GROWTH_LOG, 3) * np.array([step(RADIUS), step(LENGTH), step(BALL)]))
    return Piece(piece.id, piece.element, foot, w, piece.radius * grow[0], piece.length * grow[1], ridge,
                 piece.head_radius * grow[2], piece.phase + rng.normal(0.0, step(PHASE) * NUDGE_RAD))


def _better(layout, contacts, labels, ball_mm, rng, pieces, turns, moved):
    """The layout of these pieces and sensor turns when the feature ``moved`` (a piece or its sensors' turns)
    still prints, the pieces fit and are reached, the default plan carries more information than
    ``layout``'s and the minimal plan locates; else None. Only what the moved feature changes is redone, and
    the information is tested before the mobility: most nudges fail there."""
    if not (all(_prints(piece, labels.count(piece.id), layout.size) for piece in pieces if piece.id == moved)
            and _fits(pieces, layout.size, moved)):
        return None
    candidate = planned(contacts, labels, layout.size, ball_mm, pieces, layout.faces, rng, turns, layout, moved)
    if candidate is None:
        return None
    candidate.blocks = {**layout.blocks, **_blocks(candidate, [moved])}
    candidate.information = float(criterion_values(sum(candidate.blocks.values()), "d"))
    if not candidate.information > layout.information:
        return None
    candidate.mobility, candidate.margin = plan_mobility(candidate.features(), candidate.touches, layout.size)
    return candidate if not candidate.mobility and candidate.margin >= MIN_MARGIN else None


def _prints(piece, touches, size) -> bool:
    """Whether a nudged piece still prints without support (its stalk steep enough, a ball's stalk thinner
    than the ball) and lies within the ranges its sizes are drawn from."""
    return (math.degrees(math.asin(min(1.0, piece.w[2]))) >= MIN_ELEVATION_DEG
            and (piece.element != "S" or piece.radius <= MAX_STALK_OF_BALL * piece.head_radius)
            and _as_drawn(piece, touches, size))


def _blocks(layout, fids) -> dict:
    """The scaled information (6, 6) of each of these features' touches in the layout's default plan."""
    features = [piece.feature() for piece in layout.pieces if piece.id in fids] + layout.block_features()
    return {fid: _scaled_information(features, [entry for entry in layout.touches + layout.checks
                                                if entry["feature"] == fid], layout.size) for fid in fids}


def refined(layout, contacts, labels, ball_mm, rng, steps=REFINE_STEPS):
    """The layout improved by random nudges of one aspect of one feature at a time (a piece's foot,
    direction, stalk radius, length, ball radius or phase, or the turns of the line and cylinder sensors laid
    on a feature), each kept when the pieces still fit, print and are reached, the default plan's information
    grows and the minimal plan still locates. The nudges grow after one kept and shrink after one not (the
    one-fifth rule), so that they stay large while they pay. (Nudges of every aspect at once, 120 a start,
    left 12 classes of Table V behind the best of 1,000 random layouts.)"""
    size = layout.size
    laid = {fid for ctype, fid in zip(contacts, labels) if ctype.sensor in ("L", "C")}  # turns that matter
    aspects = {piece.id: [FOOT, DIRECTION, RADIUS, LENGTH] + [BALL] * (piece.element == "S")
               + [PHASE] * (piece.element in ("PL", "S", "C")) for piece in layout.pieces}
    for fid in laid:
        aspects.setdefault(fid, []).append(TURNS)
    units = sorted(aspects)
    scale = 1.0
    layout.blocks = _blocks(layout, sorted(set(labels)))  # one order: a sum in another rounds otherwise
    for _ in range(steps if units else 0):
        fid = units[int(rng.integers(len(units)))]
        aspect = aspects[fid][int(rng.integers(len(aspects[fid])))]
        pieces = [_nudged(piece, size, rng, scale, aspect) if piece.id == fid and aspect != TURNS else piece
                  for piece in layout.pieces]
        turns = {key: turn + rng.normal(0.0, scale * NUDGE_RAD) if key[0] == fid and aspect == TURNS
                 and turn is not None else turn for key, turn in layout.turns.items()}
        candidate = _better(layout, contacts, labels, ball_mm, rng, pieces, turns, fid)
        if candidate is not None:
            layout, scale = candidate, min(MAX_NUDGE_SCALE, scale * NUDGE_GROWTH)
        else:
            scale = max(MIN_NUDGE_SCALE, scale * NUDGE_GROWTH ** -0.25)
    return layout
