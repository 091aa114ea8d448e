"""Three spheres on posts above a round plate: the usual three-ball artefact.

Robot and CMM users locate such a plate by finding each ball centre from
touches on its upper half. Fixture frame: origin at the centre of the plate
top face, Z up; ball k (k = 1, 2, 3) has its centre at azimuth
90 + 120 (k - 1) deg, ``spacing`` from the Z axis, ``height`` above the
plate. Every touch is P/F-S/M, class {S-S} each; six give the minimal class
{S-S}x6 and the default plan uses four per ball (twelve) so that each centre
is found on its own and the pose is unique. The base hangs from the plate.
"""

import math

import numpy as np

from fixturecad.errors import InputError
from fixturecad.registration.datums import DatumScheme
from fixturecad.registration.features import Extent, Sphere
from fixturecad.templates.base import Anchor, Param, Plan, Template, halfspace, touch

POST_FRACTION = 0.4  # post radius / ball radius
TOUCH_ELEVATION_DEG = 25.0


class SpherePlate(Template):
    name = "sphere-plate"
    title = "three balls on posts above a plate"
    origin = "three-ball artefact for robot and CMM registration"
    PARAMS = (
        Param("radius", "mm", 10.0, 1.0, 100.0, "radius of each ball", "r"),
        Param("spacing", "mm", 50.0, 5.0, 1000.0, "distance of each ball centre from the plate axis", "s"),
        Param("height", "mm", 25.0, 2.0, 500.0, "height of the ball centres above the plate", "h"),
        Param("thickness", "mm", 8.0, 1.0, 100.0, "plate thickness", "t"),
    )
    contact_class = "{S-S}{S-S}{S-S}{S-S}{S-S}{S-S}"
    FRAME = "origin at the centre of the plate top face, Z up; ball k at azimuth 90 + 120 (k - 1) deg"
    DATUMS = DatumScheme("points", ("ball_1", "ball_2", "ball_3"))
    DATUM_TEXT = ("primary ball_1's centre (X, Y, Z), secondary ball_2's centre (the direction from ball_1: "
                  "two turns), tertiary ball_3's centre (the turn about that line)")
    VIEW_DIRECTIONS = ((1.0, -1.6, 1.1), (-1.0, 1.4, 1.2))

    def check(self) -> None:
        if self.spacing * math.sqrt(3) < 2 * self.radius + 2.0:
            raise InputError(
                f"--spacing {self.spacing:g} puts the balls within 2 mm of each other: use at least "
                f"{(2 * self.radius + 2.0) / math.sqrt(3):.4g} for --radius {self.radius:g}"
            )
        if self.height < self.radius + 2.0:
            raise InputError(f"--height must be at least --radius + 2 = {self.radius + 2:g} mm so the balls clear the plate")

    @property
    def plate_radius(self) -> float:
        return self.spacing + 1.5 * self.radius

    def centers(self) -> np.ndarray:
        a = np.radians(90.0 + 120.0 * np.arange(3))
        return np.column_stack([self.spacing * np.cos(a), self.spacing * np.sin(a), np.full(3, self.height)])

    @property
    def _cut_height(self) -> float:
        """Height of the circle where a post enters its ball."""
        rp = POST_FRACTION * self.radius
        return self.height - math.sqrt(self.radius**2 - rp**2)

    def body(self):
        import cadquery as cq

        solid = cq.Solid.makeCylinder(self.plate_radius, self.thickness, cq.Vector(0, 0, -self.thickness))
        for c in self.centers():
            post = cq.Solid.makeCylinder(POST_FRACTION * self.radius, c[2], cq.Vector(c[0], c[1], 0))
            solid = solid.fuse(post, cq.Solid.makeSphere(self.radius, cq.Vector(*c), angleDegrees1=-90, angleDegrees2=90))
        return solid.clean().Solids()[0]

    def body_volume(self) -> float:
        r, rp = self.radius, POST_FRACTION * self.radius
        cap = r - math.sqrt(r**2 - rp**2)  # the post's part inside the ball below the cut circle
        ball = 4.0 / 3.0 * math.pi * r**3 + math.pi * rp**2 * self._cut_height - math.pi * cap**2 * (3 * r - cap) / 3.0
        return math.pi * self.plate_radius**2 * self.thickness + 3 * ball

    def anchor(self) -> Anchor:
        s = self.spacing
        return Anchor(np.array([0.0, 0.0, -self.thickness]), np.array([0.0, 0.0, -1.0]), 0.3 * s, 0.5 * s, 1.5 * s,
                      max(self.thickness, 0.1 * s))

    def features(self) -> list:
        rows = [halfspace([0, 0, -1], -self._cut_height)]
        return [Sphere(f"ball_{k + 1}", c, self.radius, Extent(halfspaces=rows)) for k, c in enumerate(self.centers())]

    def touch_plans(self) -> dict:
        e = math.radians(TOUCH_ELEVATION_DEG)
        plan = []
        for k, c in enumerate(self.centers()):
            az = np.radians(30.0 + 120.0 * np.arange(3) + 40.0 * k)
            ring = np.column_stack([np.cos(e) * np.cos(az), np.cos(e) * np.sin(az), np.full(3, math.sin(e))])
            points = c + self.radius * np.vstack([[0, 0, 1], ring])
            plan.append(touch("P/F-S/M", f"ball_{k + 1}", points))
        return {
            "default": Plan(self.contact_class, plan, "4 touches per ball: each centre found alone, unique pose"),
        }
