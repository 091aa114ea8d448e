"""Read the solid's own BREP faces and edges back and match them to the analytic features.

This is the check that keeps features.json from drifting away from the
geometry: every surface feature must be a face of the solid with the same
surface type and parameters (and the same outward side), every line feature a
straight edge on the same line.
"""

from dataclasses import dataclass

import numpy as np
from OCP.BRepAdaptor import BRepAdaptor_Surface
from OCP.BRepTools import BRepTools

# How far BREP parameters may stray from the analytic ones, mm (and for unit vectors, 1 - cos).
MATCH_TOLERANCE_MM = 1e-6
PARALLEL_TOLERANCE = 1e-9

SURFACE_TYPES = {"plane": "PLANE", "sphere": "SPHERE", "cylinder": "CYLINDER"}


@dataclass
class FaceInfo:
    """One BREP face: its surface type and parameters read from the Geom surface."""

    index: int
    face: object  # cadquery Face
    geom_type: str
    center: np.ndarray  # a point on the face, mm
    normal: np.ndarray  # outward unit normal at ``center``
    params: dict
    samples: np.ndarray  # a few points of the surface inside the face's parameter box (k, 3)


def read_faces(shape) -> list:
    """Every face of ``shape`` with its type and parameters (plane point/normal, sphere centre/radius, cylinder axis/radius)."""
    out = []
    for index, face in enumerate(shape.Faces()):
        geom_type = face.geomType()
        surface = BRepAdaptor_Surface(face.wrapped)
        if geom_type == "PLANE":
            center = np.array(face.Center().toTuple())
            normal = np.array(face.normalAt(face.Center()).toTuple())
            samples = center[None, :]
        else:
            # Center() is the centre of mass, off a curved face: use the face's uv box instead
            u0, u1, v0, v1 = BRepTools.UVBounds_s(face.wrapped)
            grid = [(u0 + (u1 - u0) * a, v0 + (v1 - v0) * b) for a in (0.5, 0.2, 0.8) for b in (0.5, 0.2, 0.8)]
            samples = np.array([p.toTuple() for p in face.positions(grid)])
            center = samples[0]
            normal = np.array(face.normalAt(*grid[0])[0].toTuple())
        params = {}
        if geom_type == "PLANE":
            params = {"point": np.array(surface.Plane().Location().Coord())}
        elif geom_type == "SPHERE":
            sphere = surface.Sphere()
            params = {"center": np.array(sphere.Location().Coord()), "radius": sphere.Radius()}
        elif geom_type == "CYLINDER":
            cylinder = surface.Cylinder()
            axis = cylinder.Axis()
            params = {
                "point": np.array(axis.Location().Coord()),
                "axis": np.array(axis.Direction().Coord()),
                "radius": cylinder.Radius(),
            }
        out.append(FaceInfo(index, face, geom_type, center, normal, params, samples))
    return out


def read_line_edges(shape) -> list:
    """Straight edges of ``shape`` as (index, edge, start (3,), end (3,))."""
    return [
        (index, edge, np.array(edge.startPoint().toTuple()), np.array(edge.endPoint().toTuple()))
        for index, edge in enumerate(shape.Edges())
        if edge.geomType() == "LINE"
    ]


def face_matches(feature, info: FaceInfo, tol: float = MATCH_TOLERANCE_MM) -> bool:
    """Whether the BREP face is a piece of the analytic surface feature, same outward side,
    with its middle point on the feature's sensing patch (a coplanar face elsewhere is not)."""
    if SURFACE_TYPES.get(feature.kind) != info.geom_type:
        return False
    p = info.params
    if feature.kind == "plane":
        same_plane = abs(feature.signed_distance(p["point"])[0]) < tol
        same_side = info.normal @ feature.normal > 1 - PARALLEL_TOLERANCE
        return bool(same_plane and same_side and feature.contains(info.center, tol)[0])
    if feature.kind == "sphere":
        same = np.linalg.norm(p["center"] - feature.center) < tol and abs(p["radius"] - feature.radius) < tol
    else:
        parallel = abs(p["axis"] @ feature.axis) > 1 - PARALLEL_TOLERANCE
        offset = p["point"] - feature.point
        on_axis = np.linalg.norm(offset - (offset @ feature.axis) * feature.axis) < tol
        same = parallel and on_axis and abs(p["radius"] - feature.radius) < tol
    # convex, material inside: the BREP outward normal agrees with the feature's
    if not same:
        return False
    outward = info.normal @ feature.normal_at(info.center)[0] > 1 - 1e-6
    return bool(outward and feature.contains(info.samples, tol).any())


def match_features(shape, features, tol: float = MATCH_TOLERANCE_MM) -> dict:
    """``{feature id: [face or edge indices]}`` for every feature; ValueError naming any without a match."""
    faces = read_faces(shape)
    lines = read_line_edges(shape)
    matches, missing = {}, []
    for feature in features:
        if feature.kind == "line":
            found = [index for index, _, a, b in lines if np.all(feature.signed_distance(np.array([a, b])) < tol)]
        elif feature.kind == "point":
            vertices = np.array([v.toTuple() for v in shape.Vertices()])
            found = [int(i) for i in np.flatnonzero(np.linalg.norm(vertices - feature.point, axis=1) < tol)]
        else:
            found = [info.index for info in faces if face_matches(feature, info, tol)]
        if not found:
            missing.append(feature.id)
        matches[feature.id] = found
    if missing:
        raise ValueError(f"features not found on the solid's BREP: {', '.join(missing)}")
    return matches
