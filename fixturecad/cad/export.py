"""The one way files leave the CAD kernel: ``export(shape, path)``, the format from the file name.

``.step`` / ``.stp``: AP214, millimetres, one solid. ``.stl``: the checked
tessellation of :mod:`.mesh` at an absolute chord tolerance (mm).
"""

from pathlib import Path

from fixturecad.cad.mesh import mesh_from_shape, write_stl

FORMATS = (".step", ".stp", ".stl")


def export(shape, path, chord_tolerance_mm=None, name="fixture") -> Path:
    """Write ``shape`` to ``path`` in the format its suffix names; the STL needs its chord tolerance."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".step", ".stp"):
        shape.exportStep(str(path))
    elif suffix == ".stl":
        if chord_tolerance_mm is None:
            raise ValueError("an STL needs its chord tolerance in mm")
        vertices, faces = mesh_from_shape(shape, chord_tolerance_mm)
        write_stl(path, vertices, faces, name)
    else:
        raise ValueError(f"cannot export {path.name}: formats are {', '.join(FORMATS)}")
    return path
