"""A designed fixture as a template: what ``fixturecad build`` writes, for any catalogue combination.

:func:`design` turns a :class:`~fixturecad.design.combination.Combination`
into a :class:`Design` whose layout (:mod:`fixturecad.design.layout`) locates
the part with its touch plan at the real geometry; ``fixturecad.build.build``
then writes it like any template.
"""

from types import SimpleNamespace

import numpy as np

from fixturecad.errors import InputError
from fixturecad.registration.datums import DatumScheme
from fixturecad.registration.motions import free_motions
from fixturecad.design import DEFAULT_BALL_MM, DEFAULT_SIZE_MM, DESIGN_SEED
from fixturecad.design.combination import Combination
from fixturecad.design.layout import (LAYOUT_TRIALS, MIN_SIZE_MM, Layout, best_layout, layout_plan, plan_problem,
                                      rim_points)
from fixturecad.templates.base import Param, Plan, Template, touch



class Design(Template):
    name = "design"
    title = "a base block with one feature per fixture element, laid out for the combination"
    origin = "fixturecad design"
    PARAMS = (
        Param("size", "mm", DEFAULT_SIZE_MM, MIN_SIZE_MM, 2000.0, "side of the base block", "s",
              f"below {MIN_SIZE_MM:g} mm the features leave no room for a sensor"),
        Param("sensor-ball", "mm", DEFAULT_BALL_MM, 0.1, 50.0, "radius of ball and cylinder sensors", "b"),
    )
    FRAME = ("origin at the centre of the base block's top face, Z up out of it, X and Y along its edges; "
             "each feature stands on a stalk rising from that face")
    DATUMS = DatumScheme("planes", ("datum_top", "datum_front", "datum_left"))  # named after the planes on them
    DATUM_TEXT = ("primary the block's top face (Z, and the tilts about X and Y), secondary its front face (Y, and "
                  "the turn about Z), tertiary its left face (X): the origin is that corner moved to the top face's centre")
    VIEW_DIRECTIONS = ((0.6, -1.0, 1.2), (-0.8, 0.7, 1.0))

    def __init__(self, combination: Combination, layout: Layout, seed: int, **values):
        self.combination, self.layout, self.seed = combination, layout, seed
        faces = layout.face_ids()
        self.DATUMS = DatumScheme("planes", (faces["top"], faces["front"], faces["left"]))
        super().__init__(**values)
        self.contact_class = combination.contact_class

    def slug(self) -> str:
        counts = {}
        for member in self.combination.members:
            counts[member] = counts.get(member, 0) + 1
        name = "_".join(m + (f"x{n}" if n > 1 else "") for m, n in counts.items())
        return f"design-{name}-s{self.size:g}"

    def body(self):
        from fixturecad.cad.solid import design_body

        return design_body(self.layout)

    def body_volume(self) -> float:
        return self.layout.volume()

    def features(self) -> list:
        return self.layout.features()

    def touch_plans(self) -> dict:
        s, t = self.size, self.layout.thickness
        faces = self.layout.face_ids()
        # Three rim touches on top; three on the front and on the left face at two heights, so that the sides'
        # touches see the top's tilt and each touch is checked by the others (the CSV template's plan).
        low, high = -0.75 * t, -0.25 * t
        probe = [
            touch("P/F-PL/M", faces["top"], rim_points(s)),
            touch("P/F-PL/M", faces["front"], [[-0.4 * s, -s / 2, low], [0.0, -s / 2, high], [0.4 * s, -s / 2, low]]),
            touch("P/F-PL/M", faces["left"], [[-s / 2, -0.4 * s, high], [-s / 2, 0.0, low], [-s / 2, 0.4 * s, high]]),
        ]
        tokens = " ".join(self.combination.tokens())
        return {
            "default": Plan(self.contact_class, self.layout.touches + self.layout.checks,
                            f"{tokens}, each contact touched twice: the second touches pick one of the poses "
                            "the first allow"),
            "minimal": Plan(self.contact_class, self.layout.touches, f"{tokens}: one touch per contact"),
            "point-probe": Plan("{S-T2}{S-T2}{S-T2}{S-T2}{S-T2}{S-T2}", probe,
                                "a point probe alone: 3-3-3 on the block, each touch checked"),
        }

    def extras(self) -> dict:
        return {"design": {
            "combination": self.combination.tokens(),
            "contact_class": self.contact_class,
            "mobility": self.layout.mobility,
            "margin": self.layout.margin,
            "seed": self.seed,
            "pieces": [piece.to_json() for piece in self.layout.pieces],
        }}


def remaining_freedom(combination: Combination, size: float, ball_mm: float, seed: int) -> str:
    """The free motions of the combination's plan on a layout that fits, named after its features."""
    rng = np.random.default_rng(seed)
    for _ in range(LAYOUT_TRIALS):
        layout = layout_plan(combination.contacts, combination.labels, size, ball_mm, rng)
        if layout is not None:
            problem = plan_problem(layout.features(), layout.touches)
            nominal = SimpleNamespace(jacobian=problem.sensor_rows(np.eye(3), np.zeros(3))[1],
                                      rotation=np.eye(3), translation=np.zeros(3))
            return "; ".join(free_motions(problem, nominal))
    return ""


def design(combination: Combination, size: float = DEFAULT_SIZE_MM, ball_mm: float = DEFAULT_BALL_MM,
           seed: int = DESIGN_SEED) -> Design:
    """The fixture that realises ``combination``; InputError (one line) when it cannot."""
    values = Design.validate({"size": size, "sensor-ball": ball_mm})
    layout, lowest = best_layout(combination.contacts, combination.labels, values["size"], values["sensor_ball"],
                                 seed)
    if layout is None:
        if lowest == 6:
            raise InputError(f"{len(set(combination.labels))} features do not fit on a {values['size']:g} mm block "
                             "with room for the sensors: give a larger --size")
        freedom = remaining_freedom(combination, values["size"], values["sensor_ball"], seed)
        raise InputError(f"{' '.join(combination.tokens())} does not locate the part: {lowest} "
                         f"{'freedoms remain' if lowest > 1 else 'freedom remains'} ({freedom})")
    return Design(combination, layout, seed, **{k.replace("_", "-"): v for k, v in values.items()})
