"""``fixturecad design``: a fixture for any catalogue combination (combination, layout, fixture).

The defaults live here, light to import, for the command line and the design alike.
"""

DEFAULT_SIZE_MM = 100.0  # side of the base block
DEFAULT_BALL_MM = 3.0  # radius of ball and cylinder sensors
DESIGN_SEED = 9  # of the layout search
