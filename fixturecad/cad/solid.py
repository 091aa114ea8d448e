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
