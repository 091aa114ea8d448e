"""Cube (the paper's Fig. 1): point-to-plane touches on three faces, 3-2-1 and more.

The cube occupies [0, s]^3. Fixture frame: origin at the corner where the
three sensing faces' planes meet, axes along the cube edges. Sensing:
``top`` (z = s, outward +Z), ``front`` (y = 0, outward -Y) and ``left``
(x = 0, outward -X). The ``minimal`` plan is the paper's 3-2-1 (six touches,
none checked by the others); the default plan touches each face four times.
The base hangs from the bottom face.
"""

import numpy as np

from fixturecad.registration.datums import DatumScheme
from fixturecad.registration.features import Extent, Plane
from fixturecad.templates.base import Anchor, Param, Plan, Template, box_halfspaces, touch


class Cube(Template):
    name = "cube"
    title = "cube touched on three mutually perpendicular faces"
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
        # 3-2-1, then a fourth touch on each face: every touch checked by the others, also with any one left out
        # (docs/plans.md).
        top = [[0.2, 0.2, 1], [0.8, 0.2, 1], [0.5, 0.8, 1], [0.2, 0.8, 1]]
        front = [[0.2, 0, 0.5], [0.8, 0, 0.5], [0.5, 0, 0.2], [0.5, 0, 0.8]]
        left = [[0, 0.5, 0.5], [0, 0.2, 0.2], [0, 0.8, 0.2], [0, 0.5, 0.8]]

        def plan(top_count, front_count, left_count):
            return [touch("P/F-PL/M", "top", s * np.array(top[:top_count])),
                    touch("P/F-PL/M", "front", s * np.array(front[:front_count])),
                    touch("P/F-PL/M", "left", s * np.array(left[:left_count]))]

        return {
            "default": Plan(self.contact_class, plan(4, 4, 4),
                            "4-4-4 point-to-plane touches: a single touch off or mislabelled is found and named"),
            "minimal": Plan(self.contact_class, plan(3, 2, 1), "3-2-1 point-to-plane touches: none is checked"),
        }
