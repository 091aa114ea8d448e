"""A template's fixture as one solid: its body, with the mounting base fused on when asked."""

import cadquery as cq
import numpy as np


def base_solid(anchor) -> cq.Solid:
    """The mounting base of an :class:`~fixturecad.templates.base.Anchor`: stem and plate."""
    d = cq.Vector(*anchor.direction)
    start = cq.Vector(*anchor.start)
    stem = cq.Solid.makeCylinder(anchor.stem_radius, anchor.length, start, d)
    x_dir = np.cross(anchor.direction, np.eye(3)[int(np.argmin(np.abs(anchor.direction)))])
    plane = cq.Plane(origin=start + d * anchor.length, xDir=cq.Vector(*x_dir), normal=d)
    plate = cq.Workplane(plane).rect(anchor.plate_size, anchor.plate_size).extrude(anchor.plate_thickness).val()
    return stem.fuse(plate).clean()


def fixture_solid(template) -> cq.Shape:
    """The fixture of a template instance as one CadQuery solid, its base fused on when asked."""
    body = template.body()
    if not template.base:
        return body
    fused = body.fuse(base_solid(template.anchor())).clean()
    solids = fused.Solids()
    return solids[0] if len(solids) == 1 else fused


def _piece_solid(piece) -> cq.Shape:
    """One designed feature on its stalk (see :mod:`fixturecad.design.layout`)."""
    w = cq.Vector(*piece.w)
    below = piece.below()
    start = cq.Vector(*(piece.foot - below * piece.w))
    shape = cq.Solid.makeCylinder(piece.radius, below + piece.length, start, w)
    top = cq.Vector(*piece.top)
    if piece.element == "S":
        # poles on the stalk's axis: the stalk meets the ball in a parallel, not across the seam
        shape = shape.fuse(cq.Solid.makeSphere(piece.head_radius, top, w, angleDegrees1=-90, angleDegrees2=90))
    elif piece.element == "P":
        shape = shape.fuse(cq.Solid.makeCone(piece.radius, 0.0, piece.feature().point @ piece.w - piece.top @ piece.w,
                                             top, w))
    elif piece.element == "L":
        for normal in piece.roof_normals():
            plane = cq.Plane(origin=top, xDir=cq.Vector(*piece.ridge), normal=cq.Vector(*normal))
            reach = 4 * piece.radius
            shape = shape.cut(cq.Workplane(plane).rect(reach, reach).extrude(reach).val())
    return shape


def design_body(layout) -> cq.Shape:
    """A designed fixture: the base block with every feature's piece fused on, one solid."""
    s, t = layout.size, layout.thickness
    block = cq.Solid.makeBox(s, s, t, cq.Vector(-s / 2, -s / 2, -t))
    if not layout.pieces:  # every feature a face of the block
        return block
    fused = block.fuse(*[_piece_solid(piece) for piece in layout.pieces]).clean()
    solids = fused.Solids()
    return solids[0] if len(solids) == 1 else fused
