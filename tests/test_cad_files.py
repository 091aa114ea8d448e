"""The STEP names and colours its sensing faces and edges; the 3MF carries the same colours.

Both are read back with readers independent of the writers: OCP's
STEPCAFControl_Reader into an XCAF document, trimesh's 3MF loader for the
mesh and the 3MF XML itself for the colour of every triangle.
"""

import json
import zipfile
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from fixturecad.preview import feature_colours, rgb
from fixturecad.registration.features import features_from_json
from fixturecad.templates import TEMPLATES

NAMES = sorted(TEMPLATES)
CORE = "{http://schemas.microsoft.com/3dmanufacturing/core/2015/02}"


def step_named_subshapes(path):
    """[(name, TopoDS shape, (r, g, b) sRGB or None)] of the sub-shapes named in a STEP's XCAF document."""
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.Interface import Interface_Static
    from OCP.Quantity import Quantity_Color, Quantity_TOC_sRGB
    from OCP.STEPCAFControl import STEPCAFControl_Reader
    from OCP.TCollection import TCollection_ExtendedString
    from OCP.TDataStd import TDataStd_Name
    from OCP.TDF import TDF_LabelSequence
    from OCP.TDocStd import TDocStd_Document
    from OCP.XCAFApp import XCAFApp_Application
    from OCP.XCAFDoc import XCAFDoc_ColorType, XCAFDoc_DocumentTool

    document = TDocStd_Document(TCollection_ExtendedString("XmlXCAF"))
    XCAFApp_Application.GetApplication_s().InitDocument(document)
    reader = STEPCAFControl_Reader()
    Interface_Static.SetIVal_s("read.stepcaf.subshapes.name", 1)
    reader.SetNameMode(True)
    reader.SetColorMode(True)
    assert reader.ReadFile(str(path)) == IFSelect_RetDone and reader.Transfer(document)
    shapes = XCAFDoc_DocumentTool.ShapeTool_s(document.Main())
    top = TDF_LabelSequence()
    shapes.GetFreeShapes(top)
    assert top.Length() == 1
    subs = TDF_LabelSequence()
    shapes.GetSubShapes_s(top.Value(1), subs)
    out = []
    for k in range(1, subs.Length() + 1):
        label = subs.Value(k)
        name = TDataStd_Name()
        assert label.FindAttribute(TDataStd_Name.GetID_s(), name)
        colour = Quantity_Color()
        found = any(XCAFDoc_DocumentTool.ColorTool_s(document.Main()).GetColor_s(label, kind, colour)
                    for kind in (XCAFDoc_ColorType.XCAFDoc_ColorSurf, XCAFDoc_ColorType.XCAFDoc_ColorCurv))
        out.append((name.Get().ToExtString(), shapes.GetShape_s(label),
                    colour.Values(Quantity_TOC_sRGB) if found else None))
    return out


@pytest.mark.parametrize("name", NAMES)
def test_the_step_names_and_colours_every_sensing_face_and_edge(built, name):
    import cadquery as cq
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE
    from OCP.TopoDS import TopoDS

    folder = built(name)
    document = json.loads((folder / "features.json").read_text())
    features = features_from_json(document)
    colours = feature_colours(list(features))
    named = step_named_subshapes(folder / "fixture.step")
    wanted = {fid for fid, f in features.items() if f.kind != "point"}
    assert {n for n, _, _ in named} == wanted
    for fid, shape, colour in named:
        feature = features[fid]
        assert np.allclose(colour, rgb(colours[fid]), atol=1.5 / 255), fid
        if feature.kind == "line":
            assert shape.ShapeType() == TopAbs_EDGE
            edge = cq.Edge(TopoDS.Edge_s(shape))
            ends = np.array([edge.startPoint().toTuple(), edge.endPoint().toTuple()])
            assert np.abs(feature.signed_distance(ends)).max() < 1e-6, fid
            continue
        assert shape.ShapeType() == TopAbs_FACE
        face = cq.Face(TopoDS.Face_s(shape))
        assert face.geomType() == {"plane": "PLANE", "sphere": "SPHERE", "cylinder": "CYLINDER"}[feature.kind]
        on = np.array(face.positionAt(0.5, 0.5).toTuple())  # a point of the face itself
        assert abs(feature.signed_distance(on[None])[0]) < 1e-6, fid
        normal = np.array(face.normalAt(cq.Vector(*on)).toTuple())
        assert np.dot(normal, feature.normal_at(on[None])[0]) > 1 - 1e-9, fid


def read_3mf_colours(path):
    """(vertices, triangles, colour name of every triangle) from the 3MF's XML."""
    with zipfile.ZipFile(path) as package:
        root = ET.fromstring(package.read("3D/3dmodel.model"))
    bases = root.findall(f".//{CORE}basematerials/{CORE}base")
    names = [(b.get("name"), b.get("displaycolor")) for b in bases]
    vertices = np.array([[float(v.get(a)) for a in "xyz"] for v in root.iter(f"{CORE}vertex")])
    triangles = root.findall(f".//{CORE}triangle")
    faces = np.array([[int(t.get(a)) for a in ("v1", "v2", "v3")] for t in triangles])
    group = [int(t.get("p1")) for t in triangles]
    return vertices, faces, [names[g] for g in group]


@pytest.mark.parametrize("name", NAMES)
def test_the_3mf_is_the_stl_with_every_feature_coloured_on_its_surface(built, name):
    import trimesh

    folder = built(name)
    document = json.loads((folder / "features.json").read_text())
    assert document["files"]["3mf"] == "fixture.3mf"
    features = features_from_json(document)
    colours = feature_colours(list(features))
    mesh = trimesh.load(folder / "fixture.3mf", force="mesh")
    stl = trimesh.load(folder / "fixture.stl")
    assert mesh.is_watertight and abs(mesh.volume - stl.volume) < 1e-6 * stl.volume
    vertices, faces, labels = read_3mf_colours(folder / "fixture.3mf")
    chord = document["files"]["stl_tolerance_mm"]
    centroids = vertices[faces].mean(axis=1)
    coloured = {}
    for (fid, colour), centroid in zip(labels, centroids):
        if fid in features:
            assert colour == colours[fid].upper() + "FF"
            assert abs(features[fid].signed_distance(centroid[None])[0]) <= chord + 1e-6, fid
            coloured[fid] = coloured.get(fid, 0) + 1
    assert set(coloured) == {fid for fid, f in features.items() if f.kind in ("plane", "sphere", "cylinder")}
