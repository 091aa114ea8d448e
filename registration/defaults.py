"""The sensor noise model's defaults, in one place (no imports: the command line reads them at start)."""

DEFAULT_SIGMA_MM = 0.005  # sensor placement noise, each axis: a touch probe's repeatability
SENSOR_LEVER_MM = 20.0  # sensor size: plane, line and fixed-surface sensors tilt by sigma / lever rad
