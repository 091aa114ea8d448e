"""V-block: a block with a V-groove and a flat end face, touched on the groove walls and the end.

Shop-floor datum for shafts and for robot tool registration. The block
occupies x in [0, s], y in [-s/2, s/2], z in [-s, 0]; the groove runs along
X with its bottom line at z = -depth and walls at half the included
``angle`` from the vertical. Fixture frame: origin where the top face meets
the end face above the groove bottom. Sensing: ``groove_a`` (wall at y > 0),
``groove_b`` (wall at y < 0) and ``end`` (x = 0, its rectangle below the
groove). The ``minimal`` plan: six P/F-PL/M touches, 3 on ``groove_a``, 2 on
``groove_b``, 1 on ``end`` (class {S-T2}x6, none checked by the others); the
default plan touches each wall five times and the end four. The base hangs
from the bottom face.
"""

import math

import numpy as np

from fixturecad.errors import InputError
from fixturecad.registration.datums import DatumScheme
from fixturecad.registration.features import Extent, Plane
from fixturecad.templates.base import Anchor, Param, Plan, Template, halfspace, touch


class VBlock(Template):
    name = "v-block"
    title = "block with a V-groove and an end face"
    origin = "shop-floor V-block datum"
    PARAMS = (
        Param("size", "mm", 60.0, 10.0, 1000.0, "edge length of the block", "s"),
        Param("angle", "deg", 90.0, 60.0, 150.0, "included angle of the V", "a"),
        Param("depth", "mm", 20.0, 2.0, 500.0, "depth of the groove", "d"),
    )
    contact_class = "{S-T2}{S-T2}{S-T2}{S-T2}{S-T2}{S-T2}"
    FRAME = "origin on the end face at the top, above the groove bottom line; X along the groove, Z up; block in x [0, size], z [-size, 0]"
    DATUMS = DatumScheme("planes", ("groove_a", "groove_b", "end"))
    DATUM_TEXT = ("primary groove_a (its offset and tilts), secondary groove_b (with groove_a: the groove's bottom "
                  "line and the turn about it), tertiary end (X: where the origin lies along the groove)")
    VIEW_DIRECTIONS = ((-1.2, -0.9, 1.2), (-1.2, 0.9, 1.2))

    @property
    def half_width(self) -> float:
        """Half the groove width at the top face."""
        return self.depth * math.tan(math.radians(self.angle / 2))

    def check(self) -> None:
        if self.half_width > self.size / 2 - 1.0:
            raise InputError(f"the groove ({2 * self.half_width:.4g} mm wide) must be at least 2 mm narrower than --size {self.size:g}")
        if self.depth > self.size - 2.0:
            raise InputError(f"--depth must be at most --size - 2 = {self.size - 2:g} mm")

    def _wall_normal(self, side: int) -> np.ndarray:
        h = math.radians(self.angle / 2)
        return np.array([0.0, -side * math.cos(h), math.sin(h)])

    def body(self):
        import cadquery as cq

        s, w, d = self.size, self.half_width, self.depth
        block = cq.Solid.makeBox(s, s, s, pnt=cq.Vector(0, -s / 2, -s))
        groove = cq.Workplane("YZ").polyline([(-w, 0), (0, -d), (w, 0)]).close().extrude(s).val()
        return block.cut(groove).clean().Solids()[0]

    def body_volume(self) -> float:
        return self.size**3 - self.half_width * self.depth * self.size

    def anchor(self) -> Anchor:
        s = self.size
        return Anchor(np.array([s / 2, 0.0, -s]), np.array([0.0, 0.0, -1.0]), 0.2 * s, 0.4 * s, 0.8 * s, 0.15 * s)

    def features(self) -> list:
        s, w, d = self.size, self.half_width, self.depth
        along = [halfspace([1, 0, 0], s), halfspace([-1, 0, 0], 0.0)]
        bottom = [0.0, 0.0, -d]
        return [
            Plane("groove_a", bottom, self._wall_normal(+1), Extent(halfspaces=along + [halfspace([0, -1, 0], 0.0), halfspace([0, 1, 0], w)])),
            Plane("groove_b", bottom, self._wall_normal(-1), Extent(halfspaces=along + [halfspace([0, 1, 0], 0.0), halfspace([0, -1, 0], w)])),
            Plane("end", [0, 0, 0], [-1, 0, 0], Extent(halfspaces=[
                halfspace([0, 1, 0], s / 2), halfspace([0, -1, 0], s / 2), halfspace([0, 0, 1], -d), halfspace([0, 0, -1], s)])),
        ]

    def _on_wall(self, side: int, x, fraction) -> np.ndarray:
        """Points on a wall at ``x`` and ``fraction`` of the way from the bottom line to the top."""
        fraction = np.asarray(fraction, dtype=float)
        y = side * fraction * self.half_width
        z = -self.depth * (1 - fraction)
        return np.column_stack([np.asarray(x, dtype=float), y, z])

    def touch_plans(self) -> dict:
        s, d = self.size, self.depth
        # 3-2-1, then more: every touch checked by the others, also with any one left out, and a fifth on each
        # wall near its top, so that an error too small to be found moves no plan point 0.05 mm.
        wall_a = self._on_wall(+1, s * np.array([0.2, 0.8, 0.5, 0.5, 0.75]), [0.3, 0.3, 0.7, 0.2, 0.9])
        wall_b = self._on_wall(-1, s * np.array([0.2, 0.8, 0.5, 0.5, 0.25]), [0.5, 0.5, 0.2, 0.8, 0.9])
        end = np.array([[0.0, 0.0, -(d + s) / 2], [0.0, -0.35 * s, -0.9 * s], [0.0, 0.35 * s, -0.9 * s],
                        [0.0, 0.0, -0.45 * s]])

        def plan(a_count, b_count, end_count):
            return [touch("P/F-PL/M", "groove_a", wall_a[:a_count]), touch("P/F-PL/M", "groove_b", wall_b[:b_count]),
                    touch("P/F-PL/M", "end", end[:end_count])]

        return {
            "default": Plan(self.contact_class, plan(5, 5, 4), "5-5-4 point-to-plane touches on the groove walls and "
                            "end: a single touch off or mislabelled is found and named"),
            "minimal": Plan(self.contact_class, plan(3, 2, 1),
                            "3-2-1 point-to-plane touches on the groove walls and end: none is checked"),
        }
