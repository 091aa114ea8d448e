"""Every face of the solid as a feature: where an unlabelled touch made anywhere on the part may lie.

features.json's ``faces`` (``--anywhere``): each BREP face as a plane, sphere or cylinder whose patch is the
convex hull of the face's tessellation, grown by twice its chord tolerance. A point of the face lies within the
chord tolerance of a triangle, and so of the hull; twice that covers the mesher's rounding of it. The hull of
a face that is not convex (a face with a notch, a face whose edge is a hollow arc) holds more than the face: a
patch a touch may lie on is never smaller than the face, which is what the search's guarantee needs.
"""

import numpy as np
from scipy.spatial import ConvexHull

from fixturecad.cad.brep import read_faces
from fixturecad.cad.mesh import triangulate
from fixturecad.registration.elements import perpendicular_basis
from fixturecad.registration.features import Cylinder, Extent, Plane, Sphere

FACE_CHORD_MM = 0.2  # the faces' tessellation: far finer than any face, coarse enough for few facets in a hull
GROWTH = 2.0  # the hulls grown by this many chord tolerances
KINDS = {"PLANE": "plane", "SPHERE": "sphere", "CYLINDER": "cylinder"}


def face_features(shape):
    """Every face of ``shape`` as a feature with id ``face_<n>`` (n its index in ``shape.Faces()``), or None
    with the reason when a face is none of a plane, a convex sphere or a convex cylinder (a cone, a torus, a
    hole: no feature takes it)."""
    infos, parts = read_faces(shape), triangulate(shape, FACE_CHORD_MM)
    if len(parts) != len(infos):
        raise RuntimeError("the CAD kernel left a face without triangles")
    out = []
    for info, (_, nodes, _) in zip(infos, parts):
        kind = KINDS.get(info.geom_type)
        if kind is None:
            return None, f"face {info.index} is a {info.geom_type.lower()}"
        feature = _feature(kind, f"face_{info.index}", info, nodes)
        if kind != "plane" and feature.normal_at(info.center[None])[0] @ info.normal < 0:
            return None, f"face {info.index} is a hollow {kind}"
        out.append(feature)
    return out, ""


def _feature(kind, fid, info, nodes):
    p, grow = info.params, GROWTH * FACE_CHORD_MM
    if kind == "plane":
        # In the face's plane: the hull of its nodes in two dimensions, lifted to half-spaces across the plane.
        e1, e2 = perpendicular_basis(info.normal)
        hull = ConvexHull(np.column_stack([(nodes - p["point"]) @ e1, (nodes - p["point"]) @ e2]))
        normals = hull.equations[:, :1] * e1 + hull.equations[:, 1:2] * e2
        offsets = -hull.equations[:, 2] + normals @ p["point"]
        return Plane(fid, p["point"], info.normal, _extent(normals, offsets + grow))
    hull = ConvexHull(nodes)
    extent = _extent(hull.equations[:, :3], -hull.equations[:, 3] + grow)
    if kind == "sphere":
        return Sphere(fid, p["center"], p["radius"], extent)
    return Cylinder(fid, p["point"], p["axis"], p["radius"], extent)


def _extent(normals, offsets):
    """Half-spaces ``n . x <= h`` (qhull's facets are unit already); facets repeated by qhull merged."""
    rows = np.unique(np.round(np.column_stack([normals, offsets]), 12), axis=0)
    return Extent(halfspaces=rows)


def faces_record(shape):
    """features.json's ``faces``: every face as a feature's entry, or ``{"unsupported": reason}``."""
    faces, reason = face_features(shape)
    return {"unsupported": reason} if faces is None else [face.to_json() for face in faces]
