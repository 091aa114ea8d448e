"""Cube (the paper's Fig. 1): six point-to-plane touches, 3-2-1.

The cube occupies [0, s]^3. Fixture frame: origin at the corner where the
three sensing faces' planes meet, axes along the cube edges. Sensing:
``top`` (z = s, outward +Z, 3 touches), ``front`` (y = 0, outward -Y, 2) and
``left`` (x = 0, outward -X, 1). The base hangs from the bottom face.
"""

import numpy as np

from fixturecad.registration.datums import DatumScheme
from fixturecad.registration.features import Extent, Plane
from fixturecad.templates.base import Anchor, Param, Plan, Template, box_halfspaces, touch


class Cube(Template):
    name = "cube"
    title = "cube touched 3-2-1 on three mutually perpendicular faces"
    origin = "paper Fig. 1"
    PARAMS = (Param("size", "mm", 50.0, 5.0, 1000.0, "edge length of the cube", "s"),)
    contact_class = "{S-T2}{S-T2}{S-T2}{S-T2}{S-T2}{S-T2}"
    FRAME = "origin at the corner where the left (x = 0), front (y = 0) and bottom faces meet; axes along the edges; cube in [0, size]^3"
    DATUMS = DatumScheme("planes", ("top", "front", "left"))
    DATUM_TEXT = ("primary top (Z, and the tilts about X and Y), secondary front (Y, and the turn about Z), "
                  "tertiary left (X); the origin is the corner of left, front and the face size below top")
    VIEW_DIRECTIONS = ((1.0, -1.6, 1.1), (-1.6, 0.7, 0.9))

    def body(self):
        import cadquery as cq

        return cq.Solid.makeBox(self.size, self.size, self.size)

    def body_volume(self) -> float:
        return self.size**3

    def anchor(self) -> Anchor:
        s = self.size
        return Anchor(np.array([s / 2, s / 2, 0.0]), np.array([0.0, 0.0, -1.0]), 0.2 * s, 0.5 * s, 0.8 * s, 0.15 * s)

    def features(self) -> list:
        s = self.size
        lower, upper = np.zeros(3), np.full(3, s)
        return [
            Plane("top", [0, 0, s], [0, 0, 1], Extent(halfspaces=box_halfspaces(lower, upper, 2))),
            Plane("front", [0, 0, 0], [0, -1, 0], Extent(halfspaces=box_halfspaces(lower, upper, 1))),
            Plane("left", [0, 0, 0], [-1, 0, 0], Extent(halfspaces=box_halfspaces(lower, upper, 0))),
        ]

    def touch_plans(self) -> dict:
        s = self.size
        plan = [
            touch("P/F-PL/M", "top", s * np.array([[0.2, 0.2, 1], [0.8, 0.2, 1], [0.5, 0.8, 1]])),
            touch("P/F-PL/M", "front", s * np.array([[0.2, 0, 0.5], [0.8, 0, 0.5]])),
            touch("P/F-PL/M", "left", s * np.array([[0, 0.5, 0.5]])),
        ]
        return {"default": Plan(self.contact_class, plan, "3-2-1 point-to-plane touches")}
