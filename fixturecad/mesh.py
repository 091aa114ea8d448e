"""Tessellation of a CadQuery solid into a checked triangle mesh (CAD layer).

The chord tolerance is absolute, in mm (cadquery's own ``tessellate`` uses
a relative one): every triangle lies within ``tolerance`` of the surface.
"""

import numpy as np

# Largest angle between neighbouring facet normals, rad. The chord tolerance
# is normally the finer limit; this one only matters on very small radii.
ANGULAR_TOLERANCE_RAD = 0.5


class MeshError(RuntimeError):
    """The tessellation is not a clean closed surface."""


def triangulate(shape, tolerance: float, angular_tolerance: float = ANGULAR_TOLERANCE_RAD):
    """Vertices (n, 3) mm and triangles (m, 3), outward winding, per BREP face.

    Returns a list of ``(face, vertices, triangles)``, one entry per face.
    """
    from OCP.BRep import BRep_Tool
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.BRepTools import BRepTools
    from OCP.TopAbs import TopAbs_REVERSED
    from OCP.TopLoc import TopLoc_Location

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


def mesh_from_shape(shape, tolerance: float):
    """A watertight, consistently wound trimesh of ``shape``; MeshError if that fails."""
    import trimesh

    parts = triangulate(shape, tolerance)
    offsets = np.cumsum([0] + [len(nodes) for _, nodes, _ in parts])
    vertices = np.vstack([nodes for _, nodes, _ in parts])
    faces = np.vstack([tri + offset for (_, _, tri), offset in zip(parts, offsets)])
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    # faces share their boundary edges' nodes exactly; merge on a tolerance far below the chord
    mesh.merge_vertices(digits_vertex=9)
    mesh.update_faces(mesh.nondegenerate_faces(height=1e-12))
    mesh.remove_unreferenced_vertices()
    check_mesh(mesh)
    return mesh


def check_mesh(mesh) -> None:
    """Raise MeshError unless the mesh is watertight, consistently wound, outward and non-degenerate."""
    if not mesh.is_watertight:
        raise MeshError("the STL mesh is not watertight")
    if not mesh.is_winding_consistent:
        raise MeshError("the STL mesh winding is not consistent")
    if mesh.volume <= 0:
        raise MeshError("the STL mesh is inside out")
    if np.any(mesh.area_faces <= 0):
        raise MeshError("the STL mesh has degenerate facets")
