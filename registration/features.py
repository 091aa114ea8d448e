"""Touch-sensing features of a fixture: analytic planes, spheres, cylinders, lines, points.

Every feature lives in the fixture frame, in millimetres. Surfaces (plane,
sphere, cylinder) bound the material: their normal points OUT of the
material and ``signed_distance`` is positive outside. Spheres and cylinders
are convex (material inside). Lines and points have no inside: their
``signed_distance`` is the unsigned distance.

Finite extent
-------------
A feature is only present on the solid over a finite patch. The patch is the
part of the infinite feature that satisfies every constraint of its
:class:`Extent`, all of them convex:

``halfspaces``
    ``[{"normal": n, "offset": h}]``: points with ``n . x <= h`` (n unit).
``balls``
    ``[{"center": c, "radius": r}]``: points with ``|x - c| <= r``.
``cylinders``
    ``[{"point": p, "axis": a, "radius": r}]``: points within distance r of
    the infinite line through p along a (a unit).
``interval``
    ``[t0, t1]`` or ``null``: for cylinders and lines, the parameter
    ``t = (x - point) . axis`` (or ``. direction``) lies in ``[t0, t1]``.

``contains(points)`` projects each point on the feature (closest point) and
tests the projection against the extent. A point feature has no extent.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

from dataclasses import dataclass, field

import numpy as np

from .elements import KINDS, closest_point, element, outward, signed_distance

SENSING = ("mobile", "fixed")
UNIT_TOLERANCE = 1e-9  # how far from 1 a given "unit" vector may be before it is refused


def check_points(points, name="points"):
    """Return ``points`` as a float64 array of shape (n, 3); raise ValueError otherwise.

    A single point of shape (3,) becomes shape (1, 3).
    """
    array = np.asarray(points, dtype=np.float64)
    if array.ndim == 1 and array.shape == (3,):
        array = array[None, :]
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3) in mm, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite, got NaN or inf")
    return array


def check_vector(vector, name="vector"):
    """Return ``vector`` as a finite float64 array of shape (3,); raise ValueError otherwise."""
    array = np.asarray(vector, dtype=np.float64)
    if array.shape != (3,):
        raise ValueError(f"{name} must have shape (3,), got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite, got {array.tolist()}")
    return array


def check_unit(vector, name="direction"):
    """Return ``vector`` normalised to unit length; raise ValueError if it is (near) zero."""
    array = check_vector(vector, name)
    length = np.linalg.norm(array)
    if length < 1e-12:
        raise ValueError(f"{name} must be a non-zero vector, got {array.tolist()}")
    return array / length


def check_radius(radius, name="radius"):
    value = float(radius)
    if not np.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be a positive finite number of mm, got {radius!r}")
    return value


@dataclass
class Extent:
    """The finite patch of a feature: an intersection of convex constraints (see module doc).

    ``halfspaces`` (m, 4) rows ``[nx, ny, nz, h]``; ``balls`` (k, 4) rows
    ``[cx, cy, cz, r]``; ``cylinders`` (j, 7) rows ``[px, py, pz, ax, ay, az, r]``;
    ``interval`` ``(t0, t1)`` or None.
    """

    halfspaces: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    balls: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    cylinders: np.ndarray = field(default_factory=lambda: np.zeros((0, 7)))
    interval: tuple | None = None

    def __post_init__(self):
        self.halfspaces = np.asarray(self.halfspaces, dtype=np.float64).reshape(-1, 4)
        self.balls = np.asarray(self.balls, dtype=np.float64).reshape(-1, 4)
        self.cylinders = np.asarray(self.cylinders, dtype=np.float64).reshape(-1, 7)
        for vectors, name in ((self.halfspaces[:, :3], "halfspace normal"), (self.cylinders[:, 3:6], "cylinder axis")):
            lengths = np.linalg.norm(vectors, axis=1)
            if np.any(np.abs(lengths - 1.0) > 1e-6):
                raise ValueError(f"extent {name}s must be unit vectors, got lengths {lengths.tolist()}")
        if not (
            np.all(np.isfinite(self.halfspaces))
            and np.all(np.isfinite(self.balls))
            and np.all(np.isfinite(self.cylinders))
        ):
            raise ValueError("extent constraints must be finite")
        if self.interval is not None:
            t0, t1 = (float(v) for v in self.interval)
            if not (np.isfinite(t0) and np.isfinite(t1) and t0 <= t1):
                raise ValueError(f"extent interval must be finite with t0 <= t1, got {self.interval!r}")
            self.interval = (t0, t1)

    @classmethod
    def from_json(cls, data) -> "Extent":
        data = data or {}
        return cls(
            halfspaces=[list(h["normal"]) + [h["offset"]] for h in data.get("halfspaces", [])],
            balls=[list(b["center"]) + [b["radius"]] for b in data.get("balls", [])],
            cylinders=[list(c["point"]) + list(c["axis"]) + [c["radius"]] for c in data.get("cylinders", [])],
            interval=data.get("interval"),
        )

    def to_json(self) -> dict:
        return {
            "halfspaces": [{"normal": row[:3].tolist(), "offset": float(row[3])} for row in self.halfspaces],
            "balls": [{"center": row[:3].tolist(), "radius": float(row[3])} for row in self.balls],
            "cylinders": [
                {"point": row[:3].tolist(), "axis": row[3:6].tolist(), "radius": float(row[6])}
                for row in self.cylinders
            ],
            "interval": None if self.interval is None else [self.interval[0], self.interval[1]],
        }

    def margin(self, points, parameter=None):
        """Smallest slack over all constraints, shape (n,) mm: >= 0 inside the patch.

        ``parameter`` (n,) is the axial parameter t, needed when ``interval`` is set.
        """
        points = check_points(points)
        slack = np.full(len(points), np.inf)
        if len(self.halfspaces):
            slack = np.minimum(slack, np.min(self.halfspaces[:, 3] - points @ self.halfspaces[:, :3].T, axis=1))
        for row in self.balls:
            slack = np.minimum(slack, row[3] - np.linalg.norm(points - row[:3], axis=1))
        for row in self.cylinders:
            r = points - row[:3]
            w = r - np.outer(r @ row[3:6], row[3:6])
            slack = np.minimum(slack, row[6] - np.linalg.norm(w, axis=1))
        if self.interval is not None:
            if parameter is None:
                raise ValueError("this extent has an axial interval: give the parameter t")
            slack = np.minimum(slack, np.minimum(parameter - self.interval[0], self.interval[1] - parameter))
        return slack


def _extent(extent):
    if extent is None:
        return Extent()
    if isinstance(extent, Extent):
        return extent
    return Extent.from_json(extent)


def _check_sensing(sensing):
    if sensing not in SENSING:
        raise ValueError(f"sensing must be one of {', '.join(SENSING)}, got {sensing!r}")
    return sensing


class _Feature:
    """Shared behaviour: the distances of the element table, the patch, the JSON entry.

    A subclass names its element (``kind``) and holds its features.json geometry keys as attributes.
    """

    kind = ""
    surface = False  # a plane, a sphere or a cylinder: a surface a probe touches at a point

    @property
    def element(self) -> str:
        """The paper's element letter: PL, S, C, L or P."""
        return element(self.kind).letter

    def core(self):
        """(core, anchor, direction, radius) of the element table's distances."""
        return element(self.kind).core_of(self)

    def signed_distance(self, points):
        core, anchor, direction, radius = self.core()
        return signed_distance(core, anchor, direction, radius, check_points(points))

    def normal_at(self, points):
        core, anchor, direction, _ = self.core()
        return outward(core, anchor, direction, check_points(points))

    def closest_point(self, points):
        core, anchor, direction, radius = self.core()
        return closest_point(core, anchor, direction, radius, check_points(points))

    def contains(self, points, tol_mm=1e-6):
        """Whether each point, projected on the feature, lies on its finite patch, shape (n,) bool."""
        projected = self.closest_point(points)
        return self.extent.margin(projected, self._parameter(projected)) >= -tol_mm

    def _parameter(self, points):
        return None

    def to_json(self) -> dict:
        """The ``features[]`` entry of features.json: id, kind, element, sensing, geometry, extent."""
        out = {"id": self.id, "kind": self.kind, "element": self.element, "sensing": self.sensing}
        for key in element(self.kind).json_keys:
            value = getattr(self, key)
            out[key] = value.tolist() if isinstance(value, np.ndarray) else float(value)
        if self.kind != "point":
            out["extent"] = self.extent.to_json()
        return out


class _Axial(_Feature):
    """Cylinders and lines: the axial parameter t along the axis through ``point``."""

    def _parameter(self, points):
        return (check_points(points) - self.point) @ self.core()[2]


@dataclass
class Plane(_Feature):
    """A planar face: ``point`` on it, unit ``normal`` out of the material."""

    id: str
    point: np.ndarray
    normal: np.ndarray
    extent: Extent = field(default_factory=Extent)
    sensing: str = "mobile"
    kind = "plane"
    surface = True

    def __post_init__(self):
        self.point = check_vector(self.point, "plane point")
        self.normal = check_unit(self.normal, "plane normal")
        self.extent = _extent(self.extent)
        self.sensing = _check_sensing(self.sensing)


@dataclass
class Sphere(_Feature):
    """A convex spherical face: ``center``, ``radius`` mm; material inside."""

    id: str
    center: np.ndarray
    radius: float
    extent: Extent = field(default_factory=Extent)
    sensing: str = "mobile"
    kind = "sphere"
    surface = True

    def __post_init__(self):
        self.center = check_vector(self.center, "sphere center")
        self.radius = check_radius(self.radius, "sphere radius")
        self.extent = _extent(self.extent)
        self.sensing = _check_sensing(self.sensing)


@dataclass
class Cylinder(_Axial):
    """A convex cylindrical face: axis through ``point`` along unit ``axis``, ``radius`` mm."""

    id: str
    point: np.ndarray
    axis: np.ndarray
    radius: float
    extent: Extent = field(default_factory=Extent)
    sensing: str = "mobile"
    kind = "cylinder"
    surface = True

    def __post_init__(self):
        self.point = check_vector(self.point, "cylinder point")
        self.axis = check_unit(self.axis, "cylinder axis")
        self.radius = check_radius(self.radius, "cylinder radius")
        self.extent = _extent(self.extent)
        self.sensing = _check_sensing(self.sensing)


@dataclass
class Line(_Axial):
    """An edge: through ``point`` along unit ``direction``; ``signed_distance`` is unsigned."""

    id: str
    point: np.ndarray
    direction: np.ndarray
    extent: Extent = field(default_factory=Extent)
    sensing: str = "mobile"
    kind = "line"

    def __post_init__(self):
        self.point = check_vector(self.point, "line point")
        self.direction = check_unit(self.direction, "line direction")
        self.extent = _extent(self.extent)
        self.sensing = _check_sensing(self.sensing)


@dataclass
class Point(_Feature):
    """A point element (e.g. a vertex or a probe-able tip): no extent beyond itself."""

    id: str
    point: np.ndarray
    sensing: str = "fixed"
    kind = "point"

    def __post_init__(self):
        self.point = check_vector(self.point, "point")
        self.sensing = _check_sensing(self.sensing)
        self.extent = Extent()


FEATURE_CLASSES = {cls.kind: cls for cls in (Plane, Sphere, Cylinder, Line, Point)}


def feature_from_json(data: dict):
    """Build a feature from its ``to_json`` dict (the ``features[]`` entries of features.json)."""
    kind = data.get("kind")
    if kind not in FEATURE_CLASSES:
        raise ValueError(f"unknown feature kind {kind!r}; choose from {', '.join(KINDS)}")
    keys = element(kind).json_keys
    missing = [key for key in ("id",) + keys if key not in data]
    if missing:
        raise ValueError(f"{kind} feature is missing {', '.join(missing)}")
    kwargs = {key: data[key] for key in keys}
    if kind != "point":
        kwargs["extent"] = Extent.from_json(data.get("extent"))
    if "sensing" in data:
        kwargs["sensing"] = data["sensing"]
    return FEATURE_CLASSES[kind](id=data["id"], **kwargs)


def features_from_json(document: dict) -> dict:
    """All features of a features.json document, by id."""
    return {entry["id"]: feature_from_json(entry) for entry in document["features"]}


def faces_from_json(document: dict) -> dict:
    """Every face of the part (features.json's ``faces``, written by a build), by id: where an unlabelled
    touch made anywhere on the part may lie. ValueError (one line) when the build wrote none."""
    faces = document.get("faces")
    if faces is None:
        raise ValueError("features.json has no faces (built before touches anywhere were read): rebuild the fixture")
    if isinstance(faces, dict):
        raise ValueError(f"touches anywhere are not read on this part: {faces['unsupported']} "
                         "(a face is taken when it is a plane, a convex sphere or a convex cylinder)")
    return features_from_json({"features": faces})
