"""Cylinder whose end is cut by an inclined plane (the paper's Example Two, Figs. 9-10).

Fixture frame as in the paper: origin o where the cylinder axis meets the
plane, Z = s along the axis (pointing out through the inclined face),
Y = n x s, X = Y x Z, so the plane's outward normal is
n = (-cos a, 0, sin a) for an inclination a between plane and axis.

The cylinder face runs from the bottom face z = -(R cot a + length) up to the
inclined face; the inclined face is an ellipse. The ``minimal`` plan
(class {S-C}{S-C}{S-C}{S-T2}{S-T2}{S-T2}): three P/F-PL/M on ``plane``, three
P/F-C/M on ``cylinder``, plus a fourth cylinder touch that removes the finite
set of solutions (Section V-B); the default plan touches the plane six times
and the cylinder eight, so that the touches check each other. At a = 90 deg
the plane cannot fix the rotation about the axis, and near 0 deg the face
runs off to infinity: the angle is limited to 10..80 deg. The base hangs from
the flat bottom face.
"""

import math

import numpy as np

from fixturecad.registration.datums import DatumScheme
from fixturecad.registration.features import Cylinder, Extent, Plane
from fixturecad.templates.base import Anchor, Param, Plan, Template, halfspace, touch


class InclinedPlaneCylinder(Template):
    name = "inclined-plane-cylinder"
    title = "cylinder with its end cut by a plane inclined to the axis"
    origin = "paper Example Two, Figs. 9-10"
    PARAMS = (
        Param("radius", "mm", 20.0, 2.0, 200.0, "radius of the cylinder", "r"),
        Param("angle", "deg", 45.0, 10.0, 80.0, "inclination between plane and axis", "a",
              "near 90 the plane cannot fix the rotation about the axis; near 0 the face runs off to infinity"),
        Param("length", "mm", 40.0, 2.0, 1000.0, "cylinder length below the lowest point of the inclined face", "l"),
    )
    contact_class = "{S-C}{S-C}{S-C}{S-T2}{S-T2}{S-T2}"
    FRAME = "paper Fig. 10: origin where the axis meets the plane, Z = s along the axis, Y = n x s, X = Y x Z"
    DATUMS = DatumScheme("axis-plane", ("cylinder", "plane"))
    DATUM_TEXT = ("the paper's Example Two: primary the cylinder (its axis is Z: X, Y and the tilts), "
                  "secondary the plane (the origin where the axis meets it, Z; Y = n x Z fixes the turn about Z)")
    VIEW_DIRECTIONS = ((-1.0, -1.3, 1.0), (1.2, 1.0, -0.3))

    @property
    def normal(self) -> np.ndarray:
        a = math.radians(self.angle)
        return np.array([-math.cos(a), 0.0, math.sin(a)])

    @property
    def rise(self) -> float:
        """Half the axial extent of the inclined face: R cot a."""
        return self.radius / math.tan(math.radians(self.angle))

    @property
    def bottom(self) -> float:
        return -(self.rise + self.length)

    def body(self):
        import cadquery as cq

        r, top = self.radius, self.rise + 1.0
        cylinder = cq.Solid.makeCylinder(r, top - self.bottom, cq.Vector(0, 0, self.bottom))
        size = 4 * (r + top - self.bottom)
        n = cq.Vector(*self.normal)
        # a big box on the outer side of the plane, removed
        cutter = cq.Workplane(cq.Plane(origin=(0, 0, 0), xDir=(0, 1, 0), normal=n)).rect(size, size).extrude(size).val()
        return cylinder.cut(cutter).clean().Solids()[0]

    def body_volume(self) -> float:
        # the plane passes through the axis: the wedge above z = 0 equals the one below
        return math.pi * self.radius**2 * (self.rise + self.length)

    def anchor(self) -> Anchor:
        r = self.radius
        return Anchor(np.array([0.0, 0.0, self.bottom]), np.array([0.0, 0.0, -1.0]), 0.5 * r, r, 2.5 * r, 0.3 * r)

    def features(self) -> list:
        r = self.radius
        return [
            Plane("plane", [0, 0, 0], self.normal, Extent(cylinders=[[0, 0, 0, 0, 0, 1, r]])),
            Cylinder("cylinder", [0, 0, 0], [0, 0, 1], r,
                     Extent(halfspaces=[halfspace(self.normal, 0.0)], interval=(self.bottom, self.rise))),
        ]

    def _on_plane(self, xy) -> np.ndarray:
        xy = np.atleast_2d(xy)
        z = xy[:, 0] / math.tan(math.radians(self.angle))  # n . p = 0
        return np.column_stack([xy, z])

    def _on_cylinder(self, azimuth_deg, depth_fraction) -> np.ndarray:
        phi = np.radians(azimuth_deg)
        z = -self.rise - np.asarray(depth_fraction) * self.length
        return np.column_stack([self.radius * np.cos(phi), self.radius * np.sin(phi), z])

    def touch_plans(self) -> dict:
        r = self.radius
        angles = np.radians([90.0, 210.0, 330.0, 45.0, 135.0, 270.0])
        plane_points = self._on_plane(0.6 * r * np.column_stack([np.cos(angles), np.sin(angles)]))
        cylinder_points = self._on_cylinder([20.0, 140.0, 260.0, 200.0, 80.0, 320.0, 0.0, 120.0],
                                            [0.3, 0.6, 0.4, 0.8, 0.9, 0.1, 0.6, 0.95])

        def plan(plane_count, cylinder_count):
            return [touch("P/F-PL/M", "plane", plane_points[:plane_count]),
                    touch("P/F-C/M", "cylinder", cylinder_points[:cylinder_count])]

        return {
            # The plane alone holds the origin along the axis and the turn about it: touches at six distinct
            # heights across the axis, so that any five still check each other (docs/plans.md).
            "default": Plan(self.contact_class, plan(6, 8),
                            "6 plane + 8 cylinder touches: a single touch off or mislabelled is found and named"),
            "minimal": Plan(self.contact_class, plan(3, 4),
                            "3 plane + 3 cylinder touches, and a 4th cylinder touch for a unique solution"),
        }
