"""What a build folder's STEP, STL and 3MF hold, read by readers other than the writers'."""

import numpy as np
import pytest

trimesh = pytest.importorskip("trimesh")

FILE_VOLUME_TOLERANCE = 1e-3  # relative: what every file must keep of the solid's volume
READ_BACK_CHORD_MM = 0.01


def step_solid(path):
    """(solids, valid, volume mm^3, tessellation as trimesh) of a STEP read by OCP's plain STEPControl_Reader."""
    from OCP.BRep import BRep_Tool
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.BRepGProp import BRepGProp
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.GProp import GProp_GProps
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.STEPControl import STEPControl_Reader
    from OCP.TopAbs import TopAbs_FACE, TopAbs_REVERSED, TopAbs_SOLID
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopLoc import TopLoc_Location
    from OCP.TopoDS import TopoDS

    reader = STEPControl_Reader()
    assert reader.ReadFile(str(path)) == IFSelect_RetDone and reader.TransferRoots()
    shape = reader.OneShape()
    solids, explorer = 0, TopExp_Explorer(shape, TopAbs_SOLID)
    while explorer.More():
        solids += 1
        explorer.Next()
    properties = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, properties)
    BRepMesh_IncrementalMesh(shape, READ_BACK_CHORD_MM, False, 0.5, True)
    vertices, triangles, explorer = [], [], TopExp_Explorer(shape, TopAbs_FACE)
    while explorer.More():
        face = TopoDS.Face_s(explorer.Current())
        location = TopLoc_Location()
        poly = BRep_Tool.Triangulation_s(face, location)
        nodes = np.array([poly.Node(i).Transformed(location.Transformation()).Coord()
                          for i in range(1, poly.NbNodes() + 1)])
        tris = np.array([poly.Triangle(i).Get() for i in range(1, poly.NbTriangles() + 1)]) - 1
        if face.Orientation() == TopAbs_REVERSED:
            tris = tris[:, ::-1]
        triangles.append(tris + sum(len(v) for v in vertices))
        vertices.append(nodes)
        explorer.Next()
    mesh = trimesh.Trimesh(np.vstack(vertices), np.vstack(triangles))  # merges the faces' shared nodes
    mesh.update_faces(mesh.nondegenerate_faces())  # a sphere's pole: facets with two nodes in one place
    return solids, BRepCheck_Analyzer(shape).IsValid(), properties.Mass(), mesh


def assert_the_files_hold(folder, volume_mm3):
    """fixture.step one valid closed solid, its tessellation watertight, and it, fixture.stl and
    fixture.3mf all within FILE_VOLUME_TOLERANCE of ``volume_mm3`` (an answer the kernel did not give)."""
    solids, valid, volume, mesh = step_solid(folder / "fixture.step")
    assert solids == 1 and valid
    assert volume == pytest.approx(volume_mm3, rel=FILE_VOLUME_TOLERANCE)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(volume_mm3, rel=FILE_VOLUME_TOLERANCE)
    for name in ("fixture.stl", "fixture.3mf"):
        printed = trimesh.load(folder / name, force="mesh")
        assert printed.is_watertight and printed.is_winding_consistent, name
        assert printed.volume == pytest.approx(volume_mm3, rel=FILE_VOLUME_TOLERANCE), name
