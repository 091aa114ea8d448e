"""Points on a feature's finite patch, and the patch's size.

The patch is where the feature exists on the solid (its :class:`Extent`).
Points are laid on a grid over the infinite feature, the grid window grown
until it holds the whole patch, then refined over the patch's bounding box.
The size of a patch (its centre, principal directions and half-extents) is
the lever over which a tilt of the printed face moves its points.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

from dataclasses import dataclass

import numpy as np

from .elements import perpendicular_basis

GRID = 48  # grid points per side of the window laid over a plane or a cylinder's unrolled surface
LARGEST_PATCH_MM = 1.0e4  # a patch still open at this size is unbounded


def _grid(low, high, count=GRID):
    u = np.linspace(low[0], high[0], count)
    v = np.linspace(low[1], high[1], count)
    return np.stack(np.meshgrid(u, v, indexing="ij"), axis=-1).reshape(-1, 2)


def _window_points(inside, to_space, low, high):
    """Grid points in the 2-D window [low, high] that lie on the patch, and their 2-D coordinates."""
    uv = _grid(low, high)
    points = to_space(uv)
    keep = inside(points)
    return points[keep], uv[keep]


def _cover(feature, inside, to_space, start):
    """Grow a 2-D window about ``start`` until the patch lies inside it, then fit the window to the patch."""
    half = 1.0
    while half <= LARGEST_PATCH_MM:
        low, high = start - half, start + half
        _, uv = _window_points(inside, to_space, low, high)
        cell = 2.0 * half / (GRID - 1)
        if len(uv) and np.all(uv.min(0) > low + cell) and np.all(uv.max(0) < high - cell):
            lo, hi = uv.min(0) - cell, uv.max(0) + cell
            points, _ = _window_points(inside, to_space, lo, hi)
            return points, float(np.max(hi - lo)) / (GRID - 1)
        half *= 2.0
    raise ValueError(f"the patch of feature {feature.id} is empty or unbounded")


def patch_points(feature):
    """Points (n, 3) mm, fixture frame, spread over the feature's finite patch.

    Raises ValueError when the patch is empty or unbounded.
    """
    return _patch(feature)[0]


def _patch(feature):
    """Points on the patch and the spacing (mm) of the grid they come from: a point core is the
    point itself or a sphere around it, a line core the line itself or a cylinder around it."""
    core, anchor, axis, radius = feature.core()
    if core == "point" and not radius:
        return anchor[None], 0.0
    inside = lambda p: feature.contains(p, 1e-9)  # noqa: E731
    if core == "plane":
        e1, e2 = perpendicular_basis(axis)
        return _cover(feature, inside, lambda uv: anchor + uv[:, :1] * e1 + uv[:, 1:] * e2, np.zeros(2))
    if core == "point":
        n = GRID * GRID
        k = np.arange(n) + 0.5
        z = 1.0 - 2.0 * k / n
        phi = np.pi * (1.0 + 5**0.5) * k
        s = np.sqrt(1.0 - z * z)
        points = anchor + radius * np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)
        points = points[inside(points)]
        if not len(points):
            raise ValueError(f"the patch of feature {feature.id} is empty")
        return points, 0.0
    if feature.extent.interval is not None:
        t = np.linspace(*feature.extent.interval, GRID)
    else:
        t = None
    if not radius:
        if t is None:
            return _cover(feature, inside, lambda uv: anchor + uv[:, :1] * axis, np.zeros(2))
        points = anchor + t[:, None] * axis
        return points[inside(points)], float(t[1] - t[0])
    e1, e2 = perpendicular_basis(axis)

    def on_cylinder(ta):
        angle = ta[:, 1]
        return anchor + ta[:, :1] * axis + radius * (
            np.cos(angle)[:, None] * e1 + np.sin(angle)[:, None] * e2)

    if t is None:
        # Unroll the surface: the angle spans a full turn, only the axial range grows.
        half = 1.0
        while half <= LARGEST_PATCH_MM:
            uv = _grid((-half, 0.0), (half, 2.0 * np.pi))
            keep = inside(on_cylinder(uv))
            cell = 2.0 * half / (GRID - 1)
            if keep.any() and uv[keep, 0].min() > -half + cell and uv[keep, 0].max() < half - cell:
                t = np.linspace(uv[keep, 0].min() - cell, uv[keep, 0].max() + cell, GRID)
                break
            half *= 2.0
        else:
            raise ValueError(f"the patch of feature {feature.id} is empty or unbounded")
    ta = np.stack(np.meshgrid(t, np.linspace(0.0, 2.0 * np.pi, GRID, endpoint=False), indexing="ij"), -1)
    points = on_cylinder(ta.reshape(-1, 2))
    points = points[inside(points)]
    if not len(points):
        raise ValueError(f"the patch of feature {feature.id} is empty")
    return points, float(t[1] - t[0])


_BOXES = {}  # id(feature) -> (feature, box): a registration asks for the same features' boxes again
BOXES_KEPT = 256


def patch_box(feature):
    """Axis-aligned box (lo (3,), hi (3,)) mm, fixture frame, that holds the feature's whole patch.

    The sampled patch grown by its grid spacing (and, on a cylinder, by the
    arc between its angle steps); a sphere's box holds the whole sphere; an
    unbounded patch's box is infinite.
    """
    kept = _BOXES.get(id(feature))
    if kept is None or kept[0] is not feature:
        if len(_BOXES) >= BOXES_KEPT:
            _BOXES.clear()
        kept = _BOXES[id(feature)] = (feature, _box(feature))
    return kept[1]


def _box(feature):
    core, anchor, _, radius = feature.core()
    if core == "point" and radius:
        return anchor - radius, anchor + radius
    try:
        points, spacing = _patch(feature)
    except ValueError:
        return np.full(3, -np.inf), np.full(3, np.inf)
    pad = spacing + 2.0 * np.pi * radius / GRID
    return points.min(axis=0) - pad, points.max(axis=0) + pad


def box_corners(low, high):
    """The eight corners (8, 3) of the box ``low``-``high`` (mm)."""
    return np.array([[(low, high)[k >> j & 1][j] for j in range(3)] for k in range(8)])


@dataclass(frozen=True)
class PatchSize:
    """Where a patch lies and how far it reaches, fixture frame.

    ``centre`` (3,) mm: the mean of the patch (on a cylinder or line: the
    middle of its axial range, on the axis); ``directions`` (2, 3): in-plane
    principal directions of a plane patch (the normal-perpendicular pair of a
    cylinder or line axis); ``half_extents_mm`` (2,): how far the patch
    reaches from the centre along each direction (a cylinder or line: its
    axial half-length twice).
    """

    centre: np.ndarray
    directions: np.ndarray
    half_extents_mm: np.ndarray


def patch_size(feature) -> PatchSize:
    """The centre, principal directions and half-extents of a plane, cylinder or line patch.

    The half-extents reach one grid spacing past the outermost grid point, so
    they never fall short of the patch.
    """
    points, spacing = _patch(feature)
    core, anchor, axis, _ = feature.core()
    if core == "plane":
        centre = points.mean(axis=0)
        e1, e2 = perpendicular_basis(axis)
        uv = np.stack([(points - centre) @ e1, (points - centre) @ e2], axis=1)
        _, _, vt = np.linalg.svd(uv - uv.mean(0), full_matrices=False)
        directions = vt @ np.stack([e1, e2])
        reach = np.abs((points - centre) @ directions.T).max(axis=0) + spacing
        return PatchSize(centre, directions, reach)
    t = (points - anchor) @ axis
    centre = anchor + 0.5 * (t.min() + t.max()) * axis
    half = 0.5 * (t.max() - t.min()) + spacing
    return PatchSize(centre, np.stack(perpendicular_basis(axis)), np.array([half, half]))
