"""fixturecad: design, build and register touch-sensing reference fixtures."""

__version__ = "0.2.0"
