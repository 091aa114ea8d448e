"""Tessellation of a CadQuery solid into a checked triangle mesh.

The chord tolerance is absolute, in mm (cadquery's own ``tessellate`` uses
a relative one): every triangle lies within ``tolerance`` of the surface.
"""

import numpy as np
from OCP.BRep import BRep_Tool
from OCP.BRepMesh import BRepMesh_IncrementalMesh
from OCP.BRepTools import BRepTools
from OCP.TopAbs import TopAbs_REVERSED
from OCP.TopLoc import TopLoc_Location

from fixturecad.registration.sampling import STL_RECORD

# Largest angle between neighbouring facet normals, rad. The chord tolerance
# is normally the finer limit; this one only matters on very small radii.
ANGULAR_TOLERANCE_RAD = 0.5
MERGE_DIGITS = 9  # decimals of mm kept when merging the faces' shared boundary nodes


class MeshError(RuntimeError):
    """The tessellation is not a clean closed surface."""


def triangulate(shape, tolerance: float, angular_tolerance: float = ANGULAR_TOLERANCE_RAD):
    """Vertices (n, 3) mm and triangles (m, 3), outward winding, per BREP face.

    Returns a list of ``(face, vertices, triangles)``, one entry per face.
    """
    BRepTools.Clean_s(shape.wrapped)
    BRepMesh_IncrementalMesh(shape.wrapped, tolerance, False, angular_tolerance, True)
    out = []
    for face in shape.Faces():
        location = TopLoc_Location()
        poly = BRep_Tool.Triangulation_s(face.wrapped, location)
        if poly is None:
            continue
        transform = location.Transformation()
        nodes = np.array(
            [poly.Node(i).Transformed(transform).Coord() for i in range(1, poly.NbNodes() + 1)], dtype=np.float64
        )
        triangles = np.array([poly.Triangle(i).Get() for i in range(1, poly.NbTriangles() + 1)], dtype=np.int64) - 1
        if face.wrapped.Orientation() == TopAbs_REVERSED:
            triangles = triangles[:, [0, 2, 1]]
        out.append((face, nodes, triangles))
    return out


def merged_mesh(parts):
    """One indexed mesh from per-face parts: shared boundary nodes merged, degenerate facets dropped.

    Returns vertices (n, 3), faces (m, 3) and the index of the part (the BREP face) of every face (m,).
    """
    offsets = np.cumsum([0] + [len(nodes) for _, nodes, _ in parts])
    vertices = np.vstack([nodes for _, nodes, _ in parts])
    faces = np.vstack([tri + offset for (_, _, tri), offset in zip(parts, offsets)])
    owner = np.concatenate([np.full(len(tri), k) for k, (_, _, tri) in enumerate(parts)])
    # faces share their boundary edges' nodes exactly; merge far below any chord tolerance
    _, first, inverse = np.unique(np.round(vertices, MERGE_DIGITS), axis=0, return_index=True, return_inverse=True)
    vertices, faces = vertices[first], inverse.reshape(-1)[faces]
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    keep[keep] = _areas(vertices, faces[keep]) > 0
    return vertices, faces[keep], owner[keep]


def _areas(vertices, faces):
    tris = vertices[faces]
    return 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)


def mesh_from_shape(shape, tolerance: float):
    """Vertices and faces of a watertight, consistently outward-wound mesh of ``shape``; MeshError if not."""
    vertices, faces, _ = labelled_mesh(shape, tolerance)
    return vertices, faces


def labelled_mesh(shape, tolerance: float):
    """:func:`mesh_from_shape` with the index of the BREP face (in ``shape.Faces()``) of every triangle."""
    parts = triangulate(shape, tolerance)
    if len(parts) != len(shape.Faces()):
        raise MeshError("a face of the solid has no triangulation")
    vertices, faces, owner = merged_mesh(parts)
    check_mesh(vertices, faces)
    return vertices, faces, owner


def check_mesh(vertices, faces) -> None:
    """Raise MeshError unless every directed edge is met once in each direction (closed, consistent
    winding), the enclosed volume is positive (outward) and no facet is degenerate."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    n = len(vertices)
    forward = directed[:, 0] * n + directed[:, 1]
    backward = directed[:, 1] * n + directed[:, 0]
    unique_forward, counts = np.unique(forward, return_counts=True)
    if np.any(counts != 1):
        raise MeshError("the STL mesh has an edge used twice in the same direction (inconsistent winding or non-manifold)")
    if not np.all(np.isin(backward, unique_forward)):
        raise MeshError("the STL mesh is not watertight: some edge has no opposite neighbour")
    if mesh_volume(vertices, faces) <= 0:
        raise MeshError("the STL mesh is inside out")
    if np.any(_areas(vertices, faces) <= 0):
        raise MeshError("the STL mesh has degenerate facets")


def mesh_volume(vertices, faces) -> float:
    tris = vertices[faces]
    return float(np.einsum("ij,ij->i", tris[:, 0], np.cross(tris[:, 1], tris[:, 2])).sum() / 6.0)


def write_stl(path, vertices, faces, name: str = "fixture") -> None:
    """Binary STL, mm, facet normals from the winding."""
    tris = vertices[faces].astype(np.float32)
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
    record = np.zeros(len(faces), dtype=STL_RECORD)
    record["normal"], record["tri"] = normals, tris
    header = f"{name} fixturecad binary STL, units mm".encode()[:80].ljust(80, b" ")
    with open(path, "wb") as handle:
        handle.write(header)
        handle.write(np.uint32(len(faces)).tobytes())
        handle.write(record.tobytes())

