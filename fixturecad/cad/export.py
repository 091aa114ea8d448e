"""The one way files leave the CAD kernel: ``export(shape, paths)``, each format from its file name.

``.step`` / ``.stp``: AP214, millimetres, one solid; with ``features``, an
XCAF document whose sensing faces and edges carry their feature ids as names
and the preview's colours, so a CAD tool's tree shows ``flat_a``, ``sphere``,
``edge``. ``.stl``: the checked tessellation of :mod:`.mesh` at an absolute
chord tolerance (mm). ``.3mf``: the same tessellation, each triangle coloured
as its feature (3MF core specification: ``basematerials`` with
``displaycolor``), for slicers that print in colour.
"""

import zipfile
from dataclasses import dataclass
from pathlib import Path

from fixturecad.cad.mesh import labelled_mesh, write_stl
from fixturecad.preview import INERT_COLOUR, rgb

FORMATS = (".step", ".stp", ".stl", ".3mf")
# How far the STEP's solid, read back, may stray from the kernel's in volume (relative).
STEP_VOLUME_TOLERANCE = 1e-3


@dataclass(frozen=True)
class Named:
    """A sensing feature on the solid: its id, its faces or (for a line) edges by index, its colour (hex)."""

    id: str
    faces: tuple = ()
    edges: tuple = ()
    colour: str = INERT_COLOUR


def export(shape, paths, chord_tolerance_mm=None, name="fixture", features=()) -> list:
    """Write ``shape`` to each path (one or a list) in the format its suffix names; meshes need their
    chord tolerance (mm) and are tessellated once for all of them.

    ``features``: :class:`Named` sensing features, named and coloured in the STEP and the 3MF.
    """
    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)]
    for path in paths:
        if path.suffix.lower() not in FORMATS:
            raise ValueError(f"cannot export {path.name}: formats are {', '.join(FORMATS)}")
    meshes = [p for p in paths if p.suffix.lower() in (".stl", ".3mf")]
    if meshes and chord_tolerance_mm is None:
        raise ValueError(f"a {meshes[0].suffix} mesh needs its chord tolerance in mm")
    mesh = labelled_mesh(shape, chord_tolerance_mm) if meshes else None
    for path in paths:
        suffix = path.suffix.lower()
        if suffix in (".step", ".stp"):
            _write_step(shape, path, name, features)
        elif suffix == ".stl":
            write_stl(path, *mesh[:2], name)
        else:
            _write_3mf(path, *mesh, name, features)
    return paths


def _write_step(shape, path, name, features) -> None:
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.Interface import Interface_Static
    from OCP.Quantity import Quantity_Color, Quantity_TOC_sRGB
    from OCP.STEPCAFControl import STEPCAFControl_Writer
    from OCP.STEPControl import STEPControl_AsIs
    from OCP.TCollection import TCollection_ExtendedString
    from OCP.TDataStd import TDataStd_Name
    from OCP.TDocStd import TDocStd_Document
    from OCP.XCAFApp import XCAFApp_Application
    from OCP.XCAFDoc import XCAFDoc_ColorType, XCAFDoc_DocumentTool

    document = TDocStd_Document(TCollection_ExtendedString("XmlXCAF"))
    XCAFApp_Application.GetApplication_s().InitDocument(document)
    shapes = XCAFDoc_DocumentTool.ShapeTool_s(document.Main())
    colours = XCAFDoc_DocumentTool.ColorTool_s(document.Main())
    label = shapes.AddShape(shape.wrapped, False)
    TDataStd_Name.Set_s(label, TCollection_ExtendedString(name))
    all_faces, all_edges = shape.Faces(), shape.Edges()
    for feature in features:
        colour = Quantity_Color(*rgb(feature.colour), Quantity_TOC_sRGB)
        for sub, kind in [(all_faces[i], XCAFDoc_ColorType.XCAFDoc_ColorSurf) for i in feature.faces] + \
                         [(all_edges[i], XCAFDoc_ColorType.XCAFDoc_ColorCurv) for i in feature.edges]:
            sub_label = shapes.AddSubShape(label, sub.wrapped)
            TDataStd_Name.Set_s(sub_label, TCollection_ExtendedString(feature.id))
            colours.SetColor(sub_label, colour, kind)
    writer = STEPCAFControl_Writer()  # first: it registers the STEP parameters set below
    Interface_Static.SetCVal_s("write.step.schema", "AP214IS")
    Interface_Static.SetCVal_s("write.step.unit", "MM")
    Interface_Static.SetIVal_s("write.stepcaf.subshapes.name", 1)  # the faces' names, not only the part's
    writer.SetNameMode(True)
    writer.SetColorMode(True)
    if not writer.Transfer(document, STEPControl_AsIs) or writer.Write(str(path)) != IFSelect_RetDone:
        raise RuntimeError(f"the STEP writer failed on {path.name}")
    check_step(path, shape.Volume())


def read_step(path):
    """The shape of a STEP file as the plain reader (not the XCAF one that wrote it) rebuilds it."""
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.STEPControl import STEPControl_Reader

    reader = STEPControl_Reader()
    if reader.ReadFile(str(path)) != IFSelect_RetDone or not reader.TransferRoots():
        raise RuntimeError(f"{path.name} does not read back")
    return reader.OneShape()


def check_step(path, volume_mm3) -> None:
    """RuntimeError unless the STEP reads back as one valid solid of ``volume_mm3``: a reader rebuilds
    each face from its bounding wires, and a wire it misreads (a face across a sphere's seam) turns the
    face inside out in the file while the kernel's solid is right."""
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps
    from OCP.TopAbs import TopAbs_SOLID
    from OCP.TopExp import TopExp_Explorer

    shape = read_step(path)
    solids, explorer = 0, TopExp_Explorer(shape, TopAbs_SOLID)
    while explorer.More():
        solids, _ = solids + 1, explorer.Next()
    properties = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, properties)
    if solids != 1 or not BRepCheck_Analyzer(shape).IsValid():
        raise RuntimeError(f"{path.name} does not read back as one valid solid ({solids} solids)")
    if abs(properties.Mass() - volume_mm3) > STEP_VOLUME_TOLERANCE * volume_mm3:
        raise RuntimeError(f"{path.name} reads back as {properties.Mass():.1f} mm^3, the solid holds {volume_mm3:.1f}")


def _write_3mf(path, vertices, faces, owner, name, features) -> None:
    """A 3MF package: one mesh object, millimetres, a colour group with the inert colour first."""
    colour_of_face = {}
    for index, feature in enumerate(features, start=1):
        for face in feature.faces:
            colour_of_face[face] = index
    colours = [INERT_COLOUR] + [feature.colour for feature in features]
    group = [colour_of_face.get(int(face), 0) for face in owner]
    materials = "".join(f'<base name="{n}" displaycolor="{c.upper()}FF"/>'
                        for n, c in zip(["fixture"] + [f.id for f in features], colours))
    nodes = "".join(f'<vertex x="{x:.9g}" y="{y:.9g}" z="{z:.9g}"/>' for x, y, z in vertices)
    triangles = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}" pid="1" p1="{g}"/>'
                        for (a, b, c), g in zip(faces, group))
    model = ('<?xml version="1.0" encoding="UTF-8"?>\n'
             '<model unit="millimeter" xml:lang="en-US" '
             'xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02">'
             f'<metadata name="Title">{name}</metadata>'
             f'<resources><basematerials id="1">{materials}</basematerials>'
             f'<object id="2" type="model" pid="1" pindex="0" name="{name}"><mesh><vertices>{nodes}</vertices>'
             f'<triangles>{triangles}</triangles></mesh></object></resources>'
             '<build><item objectid="2"/></build></model>')
    types = ('<?xml version="1.0" encoding="UTF-8"?>\n'
             '<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">'
             '<Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>'
             '<Default Extension="model" ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>'
             '</Types>')
    rels = ('<?xml version="1.0" encoding="UTF-8"?>\n'
            '<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">'
            '<Relationship Target="/3D/3dmodel.model" Id="rel0" '
            'Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/></Relationships>')
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as package:
        package.writestr("[Content_Types].xml", types)
        package.writestr("_rels/.rels", rels)
        package.writestr("3D/3dmodel.model", model)
