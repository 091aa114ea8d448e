"""Defaults of the noise models, in one place (no imports: the command line reads them at start)."""

DEFAULT_SIGMA_MM = 0.005  # sensor placement noise, each axis: a touch probe's repeatability
SENSOR_LEVER_MM = 20.0  # sensor size: plane, line and fixed-surface sensors tilt by sigma / lever rad
DEFAULT_ZONE_MM = 0.1  # manufacturing tolerance of a good FDM print: every sensing point within +-0.05 mm
MAX_COORDINATE_MM = 1e6  # 1 km: a touch coordinate beyond is a unit or typing error, not a measurement
