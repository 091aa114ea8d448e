"""Synthetic touches on the fixture's STL: the test bench of the registration routine.

Touches are sampled on the mesh triangles that belong to each sensing
feature (so they carry the tessellation's chordal error), moved by a random
pose, and perturbed by the engine's sensor noise model. Line and point features and non-point
sensors are placed analytically. trimesh is imported here only, never by the
engine.
"""

from pathlib import Path

import numpy as np

from .defaults import SENSOR_LEVER_MM
from .synthetic import perturb_touches, plan_touches
from .deviations import entry_on
from .elements import cross, element
from .features import faces_from_json, feature_from_json
from .reach import reachable
from .tolerance import coordinates, modes
from .pose import fixture2meas_from_rt, random_rotation

VERTEX_ON_SURFACE_MM = 1e-3  # a feature's triangles have all three vertices this close to it
NORMAL_AGREEMENT = 0.9  # cosine between a triangle normal and the feature normal at its centroid
POSE_TRANSLATION_RANGE_MM = 100.0  # random poses: translation uniform in +- this per axis


MESH_VOLUME_TOLERANCE = 0.01  # relative: the tessellation's chords change the volume by far less
# A binary STL facet: its normal, three vertices (mm) and an attribute word, after an 80-byte header and a count.
STL_RECORD = np.dtype([("normal", "<f4", 3), ("tri", "<f4", (3, 3)), ("attr", "<u2")])


def read_triangles(path, volume_mm3=None) -> np.ndarray:
    """The triangles (m, 3, 3) mm of the fixture's binary STL; ValueError (one line) when it is damaged:
    not that many facets as its header says, or not enclosing the recorded volume (mm^3)."""
    try:
        data = Path(path).read_bytes()
        count = int(np.frombuffer(data, "<u4", 1, 80)[0])
        if len(data) != 84 + count * STL_RECORD.itemsize:
            raise ValueError
    except (OSError, ValueError):
        raise ValueError(f"{path} is damaged (not readable as STL): rebuild the fixture") from None
    triangles = np.frombuffer(data, STL_RECORD, count, 84)["tri"].astype(np.float64)
    volume = np.einsum("ij,ij->", triangles[:, 0], cross(triangles[:, 1], triangles[:, 2])) / 6.0
    if not count or (volume_mm3 is not None and not abs(volume - volume_mm3) <= MESH_VOLUME_TOLERANCE * volume_mm3):
        raise ValueError(f"{path} is damaged (not a closed mesh of the fixture's volume): rebuild the fixture")
    return triangles


def load_mesh(path, volume_mm3=None):
    """The fixture's STL as a trimesh mesh (three vertices a triangle, as in the file); ValueError as
    :func:`read_triangles`."""
    import trimesh

    triangles = read_triangles(path, volume_mm3)
    return trimesh.Trimesh(triangles.reshape(-1, 3), np.arange(3 * len(triangles)).reshape(-1, 3), process=False)


def plan_entries(document, plan="default"):
    """Touch-plan entries of a named plan of a features.json document, and the radius (mm) of the ball tip
    whose centres its points are (0: a point probe)."""
    plans = document.get("plans") or {}
    if plan not in plans:
        raise ValueError(f"unknown touch plan {plan!r}; choose from {', '.join(sorted(plans))}")
    return plans[plan]["touch_plan"], float(plans[plan].get("ball_radius_mm", 0.0))


def feature_faces(mesh, feature):
    """Indices of the mesh triangles lying on a surface feature (plane, sphere, cylinder)."""
    triangles = mesh.triangles  # (m, 3, 3)
    distance = np.abs(feature.signed_distance(triangles.reshape(-1, 3))).reshape(-1, 3)
    on = np.all(distance < VERTEX_ON_SURFACE_MM, axis=1)
    centroids = triangles.mean(axis=1)
    agree = np.einsum("ij,ij->i", mesh.face_normals, feature.normal_at(centroids)) > NORMAL_AGREEMENT
    inside = feature.contains(centroids, VERTEX_ON_SURFACE_MM)
    return np.flatnonzero(on & agree & inside)


def sample_on_feature(mesh, faces, feature, count, rng, attempts=20):
    """Points (count, 3) uniform by area on a feature's triangles, inside its finite patch."""
    kept = np.zeros((0, 3))
    for _ in range(attempts):
        points = sample_on_faces(mesh, faces, 4 * count, rng)
        kept = np.vstack([kept, points[feature.contains(points, 0.0)]])
        if len(kept) >= count:
            return kept[:count]
    raise ValueError(f"cannot sample touches inside the patch of feature {feature.id}")


def sample_on_faces(mesh, faces, count, rng):
    """Points (count, 3) drawn uniformly by area on the given triangles."""
    return drawn_on_faces(mesh, faces, count, rng)[0]


def drawn_on_faces(mesh, faces, count, rng):
    """Points (count, 3) drawn uniformly by area on the given triangles, and the triangle (an index into
    ``faces``) of each."""
    triangles = mesh.triangles[faces]
    area = mesh.area_faces[faces]
    pick = rng.choice(len(faces), size=count, p=area / area.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0
    u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
    a, b, c = triangles[pick, 0], triangles[pick, 1], triangles[pick, 2]
    return a + u[:, None] * (b - a) + v[:, None] * (c - a), pick


def closest_on_faces(mesh, faces, points):
    """The closest points on the given triangles to ``points`` (n, 3)."""
    from trimesh.triangles import closest_point

    triangles = mesh.triangles[faces]
    out = np.empty((len(points), 3))
    for k, p in enumerate(np.asarray(points, float)):
        candidates = closest_point(triangles, np.tile(p, (len(triangles), 1)))
        out[k] = candidates[np.argmin(np.linalg.norm(candidates - p, axis=1))]
    return out


def face_owners(mesh, faces):
    """The face (an index into ``faces``, features.json's faces as features) each mesh triangle lies on;
    ValueError when one lies on none."""
    owner = np.full(len(mesh.faces), -1)
    for k, face in enumerate(faces):
        on = feature_faces(mesh, face)
        owner[on[owner[on] < 0]] = k
    if np.any(owner < 0):
        raise ValueError(f"{np.count_nonzero(owner < 0)} STL triangles lie on no face of features.json: rebuild the fixture")
    return owner


class TouchSampler:
    """Draws noisy touches of a touch plan on the STL of a fixture; ``anywhere``: its point touches anywhere on
    the part a probe reaches, each on the face (features.json's ``faces``) it lies on."""

    def __init__(self, document, mesh, plan="default", random_positions=False, tolerance=None, anywhere=False):
        self.features = {entry["id"]: feature_from_json(entry) for entry in document["features"]}
        self.tolerance = tolerance  # the FixtureTolerance printed parts are drawn from
        # The mesh is the drawing's: an as-built folder keeps the drawing's features to find it by.
        drawing = (document.get("calibration") or {}).get("drawing")
        self.drawing = self.features if drawing is None else {e["id"]: feature_from_json(e) for e in drawing}
        self.entries, self.ball_radius_mm = plan_entries(document, plan)
        self.mesh = mesh
        self.random_positions = random_positions
        self.faces = {}
        for entry in self.entries:
            feature = self.drawing[entry["feature"]]
            if "sensor" not in entry and element(feature.kind).surface:
                faces = feature_faces(mesh, feature)
                if not len(faces):
                    raise ValueError(f"no STL triangles found on feature {feature.id}")
                self.faces[feature.id] = faces
        self.anywhere = None
        if anywhere:
            faces = list(faces_from_json(document).values())
            self.features.update({face.id: face for face in faces})
            self.drawing = {**self.drawing, **{face.id: face for face in faces}}
            self.anywhere = (faces, face_owners(mesh, faces))
        # Nominal touches snapped onto the mesh, once: the default plan's positions.
        self.snapped = []
        for entry in self.entries:
            points = np.asarray(entry["points"], float).reshape(-1, 3)
            if entry["feature"] in self.faces and "sensor" not in entry:
                # Where the probe touches: a ball tip's centre is its radius off the surface.
                points = points - self.ball_radius_mm * self.drawing[entry["feature"]].normal_at(points)
                points = closest_on_faces(mesh, self.faces[entry["feature"]], points)
            self.snapped.append(points)

    def fixture_entries(self, rng):
        """Plan entries with their points on the mesh (nominal or random, where the probe touches), fixture
        frame; on an as-built folder, moved from the drawing's features onto the as-built ones."""
        if self.anywhere is not None:
            return self._anywhere_entries(rng)
        out = []
        for entry, snapped in zip(self.entries, self.snapped):
            points = snapped
            feature = self.drawing[entry["feature"]]
            if self.random_positions and "sensor" not in entry:
                if feature.id in self.faces:
                    points = sample_on_feature(self.mesh, self.faces[feature.id], feature, len(points), rng)
                elif feature.kind == "line" and feature.extent.interval is not None:
                    s = rng.uniform(*feature.extent.interval, size=len(points))
                    points = feature.point + s[:, None] * feature.direction
            entry = {**entry, "points": np.asarray(points).tolist()}
            if self.features[entry["feature"]] is not feature:
                modes_of_drawing = modes(feature)
                entry = entry_on(entry, modes_of_drawing, coordinates(modes_of_drawing, self.features[entry["feature"]]))
            out.append(entry)
        return out

    def _anywhere_entries(self, rng):
        """The plan's sensors, and as many point touches as it has drawn by area on the whole mesh where a
        probe along the face's normal reaches, by the face they lie on."""
        faces, owner = self.anywhere
        count = sum(len(np.reshape(e["points"], (-1, 3))) for e in self.entries if "sensor" not in e)
        points, on = np.zeros((0, 3)), np.zeros(0, int)
        for _ in range(20):
            more, pick = drawn_on_faces(self.mesh, np.arange(len(owner)), 4 * count, rng)
            face = owner[pick]
            normals = np.zeros_like(more)
            for k in np.unique(face):
                normals[face == k] = faces[k].normal_at(more[face == k])
            keep = reachable(self.mesh.triangles, more, normals, self.ball_radius_mm)
            points, on = np.vstack([points, more[keep]]), np.concatenate([on, face[keep]])
            if len(points) >= count:
                break
        else:
            raise ValueError("a probe reaches too little of the part to sample touches anywhere on it")
        points, on = points[:count], on[:count]
        return [e for e in self.entries if "sensor" in e] + [
            {"feature": faces[k].id, "points": points[on == k].tolist()} for k in np.unique(on)]

    def _centres(self, entry, part):
        """A ball tip's entry with its centres: its radius out from the touched points, along the normal of
        the feature touched (of the printed ``part``'s, when it is printed)."""
        if "sensor" in entry:
            return entry
        fid = entry["feature"]
        feature = self.features[fid] if part is None else part[fid]
        points = np.asarray(entry["points"], float)
        return {**entry, "points": (points + self.ball_radius_mm * feature.normal_at(points)).tolist()}

    def draw(self, rng, noise_mm, fixture2meas=None, lever_mm=SENSOR_LEVER_MM, printed=None):
        """(touches by feature, contacts, true fixture2meas), sensors placed with noise ``noise_mm``.

        The engine's sensor noise model (:func:`perturb_touches`): translation
        ``noise_mm``, rotation ``noise_mm / lever_mm`` about each contact point.
        ``printed``: a printed part (:meth:`FixtureTolerance.random_deviations`,
        dict id -> mode coordinates) the touches are made on; the true pose is
        then that of its datum frame.
        """
        if fixture2meas is None:
            fixture2meas = fixture2meas_from_rt(
                random_rotation(rng), rng.uniform(-POSE_TRANSLATION_RANGE_MM, POSE_TRANSLATION_RANGE_MM, 3)
            )
        entries = self.fixture_entries(rng)
        truth, part = fixture2meas, None
        if printed is not None:
            entries, part, frame = self.tolerance.printed_plan(entries, printed)
            truth = fixture2meas @ frame
        if self.ball_radius_mm > 0:
            entries = [self._centres(entry, part) for entry in entries]
        touches, contacts = plan_touches(entries, fixture2meas)
        touches, contacts = perturb_touches(touches, contacts, rng, noise_mm, lever_mm)
        return touches, contacts, truth
