"""Quarter sphere (the paper's Example One, Fig. 8).

A solid ball of radius R cut by the planes z = 0 and y = 0, keeping y >= 0
and z >= 0. Fixture frame: origin at the ball centre, X along the edge where
the two flat faces meet. Sensing features: ``flat_a`` (z = 0, outward -Z),
``flat_b`` (y = 0, outward -Y), ``sphere`` and ``edge`` (the X axis).

The paper's contacts, class {G3}{S-S}{S-T2}{C-R-C}: PL/F-PL/F on ``flat_a``,
P/F-S/M on ``sphere``, P/F-PL/M on ``flat_b`` and L/M-L/M on ``edge``. The
sphere contact leaves two solutions along the edge; the ``minimal`` plan adds
a second sphere touch to pick one, and the default plan seven point touches
more (three on ``flat_a``, two on ``flat_b``, two on the sphere) so that the
touches check each other. The ``point-probe`` plan needs only a point
probe: 3 + 2 touches on the flats and 2 on the sphere.

The mounting base leaves the spherical face near the +X end of the edge, along
a direction 35 deg from X towards the curved face, so that both flats, the
edge and most of the sphere stay free; the sphere's sensing patch stops
BASE_CLEARANCE_MM short of the stem.
"""

import math

import numpy as np

from fixturecad.errors import InputError
from fixturecad.registration.datums import DatumScheme
from fixturecad.registration.features import Extent, Line, Plane, Sphere
from fixturecad.templates.base import BASE_CLEARANCE_MM, Anchor, Param, Plan, Template, halfspace, touch, unit

_TILT = math.radians(35.0)
STEM_DIRECTION = np.array([math.cos(_TILT), math.sin(_TILT) / math.sqrt(2), math.sin(_TILT) / math.sqrt(2)])
STEM_RADIUS_FRACTION = 0.15


class QuarterSphere(Template):
    name = "quarter-sphere"
    title = "solid quarter sphere: two flats, the spherical face and their edge"
    origin = "paper Example One, Fig. 8"
    PARAMS = (Param("radius", "mm", 40.0, 5.0, 500.0, "radius of the sphere", "r"),)
    contact_class = "{G3}{S-S}{S-T2}{C-R-C}"
    FRAME = "origin at the ball centre; X along the edge where the flats meet; flat_a in z = 0, flat_b in y = 0; material at y >= 0, z >= 0"
    DATUMS = DatumScheme("planes-point", ("flat_a", "flat_b", "sphere"))
    DATUM_TEXT = ("primary flat_a (Z, and the tilts about X and Y), secondary flat_b (Y, and the turn about Z), "
                  "tertiary the sphere's centre (X): the origin is that centre dropped onto the edge where the flats meet")
    VIEW_DIRECTIONS = ((0.45, -1.0, -0.8), (0.45, 1.0, 0.9))

    def body(self):
        import cadquery as cq

        r = self.radius
        ball = cq.Solid.makeSphere(r, angleDegrees1=-90, angleDegrees2=90)
        keep = cq.Solid.makeBox(4 * r, 2 * r, 2 * r, pnt=cq.Vector(-2 * r, 0, 0))
        return ball.intersect(keep).clean().Solids()[0]

    def body_volume(self) -> float:
        return math.pi * self.radius**3 / 3.0

    def _stem_radius(self) -> float:
        return STEM_RADIUS_FRACTION * self.radius

    def anchor(self) -> Anchor:
        r, rs = self.radius, self._stem_radius()
        # start where the whole stem section keeps the clearance from both flats
        dy = STEM_DIRECTION[1]
        h0 = math.sqrt(r**2 - rs**2)
        start = max((BASE_CLEARANCE_MM + rs * math.sqrt(1 - dy**2)) / dy, 0.5 * h0)
        cap = r - h0
        inside = math.pi * rs**2 * (h0 - start) + math.pi * cap**2 * (3 * r - cap) / 3.0
        return Anchor(start * STEM_DIRECTION, STEM_DIRECTION, rs, 1.5 * r - start, 1.2 * r, 0.15 * r, inside)

    def check(self) -> None:
        if self.base and self.anchor().start @ STEM_DIRECTION >= math.sqrt(self.radius**2 - self._stem_radius() ** 2):
            raise InputError(f"--base needs a larger --radius than {self.radius:g} mm to keep its stem off the flats")

    def features(self) -> list:
        r = self.radius
        y_pos, z_pos = halfspace([0, -1, 0], 0.0), halfspace([0, 0, -1], 0.0)
        ball = [0.0, 0.0, 0.0, r]
        sphere_rows = [y_pos, z_pos]
        if self.base:
            keep_out = self._stem_radius() + BASE_CLEARANCE_MM
            sphere_rows.append(halfspace(STEM_DIRECTION, math.sqrt(r**2 - keep_out**2)))
        return [
            Plane("flat_a", [0, 0, 0], [0, 0, -1], Extent(halfspaces=[y_pos], balls=[ball])),
            Plane("flat_b", [0, 0, 0], [0, -1, 0], Extent(halfspaces=[z_pos], balls=[ball])),
            Sphere("sphere", [0, 0, 0], r, Extent(halfspaces=sphere_rows)),
            Line("edge", [0, 0, 0], [1, 0, 0], Extent(interval=(-r, r))),
        ]

    def touch_plans(self) -> dict:
        r = self.radius
        sphere_1 = r * unit([0.5, 0.6, 0.3])
        sphere_2 = r * unit([-0.5, 0.3, 0.6])
        flat_a = r * np.array([[-0.5, 0.3, 0], [0.5, 0.3, 0], [0, 0.7, 0]])
        flat_b = r * np.array([[-0.5, 0, 0.4], [0.5, 0, 0.4]])
        paper = [
            touch("PL/F-PL/F", "flat_a", [0, 0.4 * r, 0],
                  {"kind": "plane", "point": [0, 0.4 * r, 0], "normal": [0, 0, 1]}),
            touch("P/F-S/M", "sphere", sphere_1),
            touch("P/F-PL/M", "flat_b", flat_b[1]),
            touch("L/M-L/M", "edge", [-0.3 * r, 0, 0],
                  {"kind": "line", "point": [-0.3 * r, 0, 0], "direction": unit([0, 1, -1])}),
        ]
        point_probe = [
            touch("P/F-PL/M", "flat_a", flat_a),
            touch("P/F-PL/M", "flat_b", flat_b),
            touch("P/F-S/M", "sphere", [sphere_1, sphere_2]),
        ]
        minimal = paper + [touch("P/F-S/M", "sphere", sphere_2)]
        # Point touches on both flats and the sphere: every touch checked by the others, also with any one left
        # out (docs/plans.md).
        checks = [touch("P/F-PL/M", "flat_a", flat_a), touch("P/F-PL/M", "flat_b", [flat_b[0], [0, 0, 0.7 * r]]),
                  touch("P/F-S/M", "sphere", r * np.array([unit([0.1, 0.5, 0.8]), unit([-0.6, 0.7, 0.3])]))]
        return {
            "default": Plan(self.contact_class, minimal + checks,
                            "the paper's four contacts, a second sphere touch and seven point touches: a single "
                            "touch off or mislabelled is found and named"),
            "minimal": Plan(self.contact_class, minimal,
                            "the paper's four contacts plus a second sphere touch that removes the two-fold solution"),
            # The sphere touch is met again with the part moved along the edge by twice its x.
            "paper": Plan(self.contact_class, paper, f"Example One exactly: two exact solutions, the second "
                          f"{2 * sphere_1[0]:.1f} mm along the edge, where the sensors would touch beyond the "
                          "part's flat and edge: register finds both and rules the second out"),
            "point-probe": Plan("{S-S}{S-T2}{S-T2}{S-T2}{S-T2}{S-T2}", point_probe,
                                "point probe only: 3 + 2 flat touches, 2 sphere touches for a unique pose"),
        }
