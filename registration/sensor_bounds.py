"""Sensor touches the search bounds by their own rows: those with no stand-in (:mod:`.stand_ins`).

A line sensor across an edge or round a boss (both sides mobile: the lines' distance is ``rho``), and a
plane sensor lying on a plane, a line or a cylinder (a locus: the normals agree, or the line lies in the
plane, at an offset) know no point on either side, so no point touch stands in for them. The search
(:mod:`.search`) bounds their cost over each cell directly. Write the cell's rotations as within ``delta``
of ``R0`` and its images ``y`` within ``h`` (the y box's half-diagonal) of its centre ``y_c``; a sensor's
point ``x`` maps to ``x' = R^T (x - c) + y`` on the fixture, which moves by at most ``delta |x - c| + h``
over the cell, and its directions ``R^T u`` by at most ``delta``.

A sensor touch's cost is ``r^T C^-1 r``, ``C = G G^T / L^2 + J_v J_v^T`` (:func:`.noise.row_whitening`:
``J_v`` the rows' translation Jacobian, ``G`` their change with a turn of the fixture about the sensor's
placement centre ``o``, ``L`` the lever). For a subset S of its rows it is at least ``r_S^T C_SS^-1 r_S >=
|r_S|^2 / lambda_max(C_SS)`` (leaving rows out of a Mahalanobis distance never raises it); the bound is the
largest over the subsets below, each row's least size over the cell over a bound of ``lambda_max``:

* rows that only turn (a plane's normal against the sensor's, ``n.t1, n.t2``; a line's direction in a
  plane, ``n.d``): their length is the sine (cosine) of an angle that the cell moves by at most ``delta``,
  and a turn changes them at most one for one (``G`` has rows ``n x t_k``, of largest singular value 1;
  ``|d x n| <= 1``), no shift does: ``lambda_max <= 1 / L^2``;
* a plane's offset row ``n.(q_B - q_A) - rho`` (the other side's point from the plane): in the fixture frame
  ``(R^T n).(q - y) - n.(q_A - c) - rho`` with the plane the sensor's, or ``n.(x' - q) - rho`` with it the
  fixture's; it moves by at most ``delta |q - y_c| + (1 + delta) h`` or ``delta |x - c| + h``; a shift
  moves it one for one and a turn about ``o`` by at most ``|q - o'|`` (``|x - o|``):
  ``lambda_max <= 1 + lever^2 / L^2``. At ``R0`` the row is linear in y, so a pose that passes keeps y in a slab
  (:meth:`SensorBounds.slabs`): the row within ``sqrt(slack T)``, its deviation and the turn's part of its move;
* the distance of two lines, ``|(p_A - p_B).m| - rho``, ``m`` the unit common normal: at the cell's centre
  the closest point ``x_a`` on the sensor's line, ``D_c`` the distance, ``p*`` the closest on the fixture's;
  the distance is ``|(x_a' - p*).m|`` (any points of the two lines will do), and ``x_a'_c - p* = D_c m_c``,
  so it moves by at most ``delta |x_a - c| + h + D_c |dm|^2 / 2``, ``dm`` the unit normal's change: ``m = d_A' x d_B``
  moves by at most delta, so while ``delta < s_c`` its direction turns by at most ``asin(delta / s_c)`` and
  ``|dm| <= 2 sin(asin(delta / s_c) / 2)`` (else 2)
  (``s_c = |d_A' x d_B|`` the sine of their angle, moved at most ``delta``); a shift moves it one for one and a turn about ``o`` by at most ``|x_b - o'|`` (``x_b`` the
  closest point on the fixture's line, by the envelope theorem), ``<= D_o (1 + 1/s^2) + e_o`` (``D_o`` the
  distance of ``o``'s foot on the sensor's line from the fixture's line, ``e_o`` that of ``o`` from its
  foot, ``s >= s_c - delta``): ``lambda_max <= 1 + lever^2 / L^2``. Where ``s_c <= delta`` the lines may
  turn parallel in the cell: no bound. At ``R0`` the signed distance ``u_c.(x_a' - p*_c)`` is linear in y, and
  the true one, ``u.(x_a' - p*_c)``, is it times ``u.u_c >= 1 - |du|^2 / 2``, give or take ``delta |x_a - c|``
  (x_a's turn) and ``|y - y_c| |du|`` (``x_a' - p*_c`` off ``u_c``, zero at the centre): a pose that passes,
  its distance within ``rho`` plus ``sqrt(slack T)`` and its deviation, keeps y in a slab
  (:meth:`SensorBounds.slabs`). With ``rho > 0`` the rows model the signed distance, the size where its sign
  holds: over the cell, or over the poses that pass, where ``D_c - swing`` lies above ``-rho + sqrt(slack T) +
  dev`` (a pose that passes with the other sign has it within that of ``-rho``); the search asks no more.

A sensor whose contact point x is given (``located``) on a cylinder or a line with an axial interval [t0, t1]
holds y in a slab whatever its rows: at a pose the verdict admits (:func:`.verdict.inadmissible`) x projects onto
the feature's patch, its axial parameter ``(x' - p).d`` within the interval widened by the verdict's tolerance and
widening, and the cell's turn moves it by at most ``delta |x - c|`` (:meth:`SensorBounds.located`). Three such
slabs with independent axes bound y by themselves: a plan of line sensors alone, their contact points given, is
searched completely (:class:`.search.Tree`).

On a printed part (:class:`Printed`) the test's rows are ``r - J_d z``, ``J_d`` the rows' change as the
fixture's feature moves by its modes (a twist ``(omega_f, v_f)``, moving a point p by ``D(p) = omega_f x p +
v_f``, and a radius), ``z`` of a pose that passes within ``z^T S^-1 z <= q``: the feature turns by at most
``tilt`` and moves its mode centre ``o_f`` by at most ``dev`` (:func:`.stand_ins.deviation_bound_mm`), so a
point p by at most ``dev + tilt |p - o_f|``. A turn row changes by ``(n x t).omega_f`` (at most ``tilt``), a
plane's offset row by ``n.D(q)`` at the fixture plane's or line's own point (the sensor's normal n), by
``-n.D(x)`` at the sensor's point x (the fixture's normal), and two lines' distance by ``-u.D(p*)`` at the
closest point on the fixture's line (the envelope theorem), less one per mm of the fixture's radius where the
offset holds it. Each subset bound takes each row's least size less that (its largest change), and the rows'
change at the cell's centre (``twist``, ``radius``) enters the search's first-order model with the modes as
unknowns, off by at most how far the cell turns the row's direction times the move and turns the place it is
taken at times ``tilt``: ``delta (dev + tilt |p - o_f|) + tilt |dp|``. The closest point p* on the fixture's
line is where it meets the plane through the sensor's line along their common normal m (the plane's normal
``n_P = (d_B - cos d_A) / s`` has ``n_P.d_B = s``), so its distance along the fixture's line from p*_c is
``n_P.(a - p*_c) / s``, a the image of the sensor's closest point x_a; ``a - p*_c = (a - a_c) + D_c m_c`` and
``n_P`` is normal to m: ``|dp*| <= (delta |x_a - c| + h + D_c |dm|) / (s_c - delta)``.

This module imports numpy only and nothing of fixturecad: it is inlined into the
generated standalone ``register.py``.
"""

import numpy as np

from .elements import cross, dot
from .stand_ins import touch_side

LINE_KINDS = ("L", "C")  # elements whose core is a line


def bounded(group):
    """Whether the search bounds this sensor group's touches (module doc): a plane sensor on a plane, a line or a
    cylinder, a plane feature under a line or a cylinder sensor, and a mobile line or cylinder on a mobile
    line or cylinder."""
    ctype = group.ctype
    if ctype.is_locus:
        return True
    return (ctype.sensor in LINE_KINDS and ctype.fixture in LINE_KINDS and not ctype.sensor_fixed
            and not ctype.fixture_fixed)


class Printed:
    """A sensor touch's fixture feature as printed (module doc): ``tilt`` (rad) the largest turn and ``dev`` (mm)
    the largest move of its mode centre ``centre`` (3,) mm that a pose that passes allows; or several features'
    (:meth:`stacked`)."""

    def __init__(self, tilt, dev, centre):
        self.tilt, self.dev, self.centre = np.asarray(tilt, float), np.asarray(dev, float), np.asarray(centre, float)

    @classmethod
    def stacked(cls, features):
        """Several features' at once: their tilts and deviation bounds (s,) and mode centres (s, 3)."""
        return cls(*(np.array([getattr(f, key) for f in features]).reshape(n) for key, n in
                     (("tilt", -1), ("dev", -1), ("centre", (-1, 3)))))

    def at(self, p, reach=0.0):
        """The largest move (K,) mm of the feature at points p (K, 3), or anywhere within ``reach`` (K,) of them
        (of each stacked feature at its own points, (K, s))."""
        off = p - self.centre
        far = np.sqrt(dot(off, off)) + reach
        return self.dev + np.where(self.tilt > 0.0, self.tilt * far, 0.0)


EXACT = Printed(0.0, 0.0, np.zeros(3))  # a feature that does not deviate


class SensorBounds:
    """Lower bounds of sensor touches' cost over cells (module doc). ``touches``: (group, k) pairs, each touch k
    of a group that :func:`bounded` accepts; ``centroid`` (3,) mm: the point whose image is y; ``weight``: the
    bounds' factor (the search's threshold is divided by its stand-ins' factor, the sensors' cost not);
    ``printed``: each touch's :class:`Printed` feature on a printed part."""

    def __init__(self, touches, lever_mm, centroid, weight=1.0, printed=None, admitted_mm=0.0):
        self.lever2 = float(lever_mm) ** 2
        self.centroid = np.asarray(centroid, float)
        self.weight = float(weight)
        self.touches = [(group.ctype, touch_side(group.sensor, group.count, k),
                         touch_side(group.fixture, group.count, k), float(group.rho[k]),
                         np.asarray(group.centre[k], float)) for group, k in touches]
        # Each cylinder or line with an axial interval [t0, t1] on which touches' contact points x are given
        # (``located``): at a pose the verdict admits, each x's axial parameter lies in it, widened by at most
        # ``admitted_mm`` (:meth:`located`). Each: the points x (n, 3), the axis's point and direction, t0 and t1.
        axial = {}
        for group, k in touches:
            feature = group.feature
            if group.located and feature.core()[0] == "line" and feature.extent.interval is not None:
                axial.setdefault(feature.id, (feature, []))[1].append(np.asarray(group.centre[k], float))
        self.axial = [(np.array(x), feature.point, feature.core()[2], feature.extent.interval[0] - admitted_mm,
                       feature.extent.interval[1] + admitted_mm) for feature, x in axial.values()]
        # The same, all points at once (:meth:`located`): each point's x - c (N, 3), its feature's index, where each
        # feature's points begin, each point's |x - c|, and each feature's axis (s, 3), p.d, t0 and t1 (s,).
        counts = [len(x) for x, *_ in self.axial]
        points = np.concatenate([x for x, *_ in self.axial] + [np.zeros((0, 3))]) - self.centroid
        self.located_points = (points, np.repeat(np.arange(len(counts)), counts),
                               np.cumsum([0] + counts[:-1]).astype(int), np.linalg.norm(points, axis=1))
        self.located_axes = tuple(np.array(column, float) for column in
                                  zip(*[(d, p @ d, t0, t1) for _, p, d, t0, t1 in self.axial])) if self.axial else ()
        self.printed = [EXACT] * len(touches) if printed is None else list(printed)
        # Where the sensors are placed (measurement frame): the points a region's extent follows besides the touches.
        self.markers = np.array([o for *_, o in self.touches]).reshape(-1, 3)
        # The loci one by one, then the pairs of lines all at once (:meth:`_crossing`): each line pair's sensor point
        # and direction, fixture point and direction, placement centre, rho, and whether the fixture's is a cylinder.
        self.loci = [k for k, (ctype, *_) in enumerate(self.touches) if ctype.is_locus]
        self.crossings = [k for k, (ctype, *_) in enumerate(self.touches) if not ctype.is_locus]
        pairs = [self.touches[k] for k in self.crossings]
        self.pair_lines = tuple(np.array([pair[side][key] for pair in pairs], float).reshape(-1, 3)
                                for side, key in ((1, "p"), (1, "d"), (2, "p"), (2, "d")))
        # Each placement centre's foot on its sensor's line (how far along it from its point), how far off it the
        # centre lies, and how far the foot lies from the centroid (the lever's parts that no cell moves,
        # :meth:`_crossing`).
        centre = np.array([o for *_, o in pairs], float).reshape(-1, 3)
        sp, sd = self.pair_lines[:2]
        self.pair_foot = dot(centre - sp, sd)
        self.pair_off = np.linalg.norm(centre - sp - self.pair_foot[:, None] * sd, axis=1)
        self.pair_foot_arm = np.linalg.norm(sp - self.centroid + self.pair_foot[:, None] * sd, axis=1)
        self.pair_rho = np.array([rho for *_, rho, _ in pairs], float)
        self.pair_fixture_c = np.array([ctype.fixture == "C" for ctype, *_ in pairs], bool)
        # Each row's touch: a plane on a plane has three rows, a plane and a line or a cylinder two, two lines one.
        counts = [3 if self.touches[k][0].sensor == self.touches[k][0].fixture else 2 for k in self.loci]
        self.row_touch = np.concatenate([np.repeat(np.array(self.loci, int), counts), self.crossings]).astype(int)

    def cells(self, R, delta, yc, h, root):
        """Over cells of rotations within ``delta`` (K,) rad of ``R`` (K, 3, 3) and images within ``h`` (K,) mm
        of ``yc`` (K, 3), fixture frame: the sum (K,) of the touches' cost bounds, and rows linear in the cell's
        turn omega (``R = R0 exp(omega)``) and image y whose squares sum to at most the touches' cost, off by at
        most ``remainder`` each, at every pose of the cell whose cost passes ``root^2`` (the search's threshold,
        before ``weight``): (bound, value (K, s), Jw (K, s, 3), m (K, s, 3), remainder (K, s), usable,
        twist (K, s, 6), radius (K, s)); a row is ``value + Jw.omega + m.y``, and on a printed part it changes
        by ``twist.(omega_f, v_f)`` as its touch's feature (``row_touch``) moves by that twist and by ``radius``
        per mm of its radius (module doc). A row whose model does not hold over a cell is zero there, and
        ``usable`` (K,) says whether all hold."""
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            parts = [self._locus(*self.touches[k], self.printed[k], R, delta, yc, h) for k in self.loci]
            if self.crossings:
                parts.append(self._lines(R, delta, yc, h, root / np.sqrt(self.weight)))
        bound = self.weight * sum(np.where(np.isfinite(b), b, 0.0) for b, *_ in parts)
        value, Jw, m, remainder, usable, twist, radius = (np.concatenate([part[k] for part in parts], axis=1)
                                                          for k in range(1, 8))
        fine = usable & np.isfinite(value) & np.isfinite(remainder) & np.all(np.isfinite(Jw) & np.isfinite(m), axis=2) \
            & np.all(np.isfinite(twist), axis=2)
        root = np.sqrt(self.weight)
        value, remainder = root * np.where(fine, value, 0.0), root * np.where(fine, remainder, 0.0)
        Jw, m = root * np.where(fine[..., None], Jw, 0.0), root * np.where(fine[..., None], m, 0.0)
        twist, radius = root * np.where(fine[..., None], twist, 0.0), root * np.where(fine, radius, 0.0)
        return bound, value, Jw, m, remainder, np.all(fine, axis=1), twist, radius

    def located(self, R, delta):
        """Slabs ``low <= d.y <= high`` (low, high (K, s)), one across each axis d of ``axial``, that hold the y of
        every pose of the cells (rotations within ``delta`` (K,) rad of R (K, 3, 3)) that the verdict admits:
        each located touch's axial parameter ``(x' - p).d``, ``x' = R^T (x - c) + y``, within its widened
        interval, and a turn within delta moves x' by at most ``delta |x - c|``."""
        points, of, first, arm = self.located_points
        d, pd, t0, t1 = self.located_axes
        along = np.einsum("ni,kin->kn", points, (R @ d.T)[:, :, of]) - pd[of]  # (K, N)
        turn = delta[:, None] * arm
        return (np.maximum.reduceat(t0[of] - along - turn, first, axis=1),
                np.minimum.reduceat(t1[of] - along + turn, first, axis=1))

    def _moved(self, x, R, yc):
        """Measurement-frame points (3,) or (K, 3) on the fixture at the cells' centres (K, 3)."""
        return np.einsum("ki,kij->kj", np.broadcast_to(x - self.centroid, (len(R), 3)), R) + yc

    def slabs(self, R, delta, yc, h, root):
        """Slabs ``low <= g.y <= high`` (g (K, s, 3), fixture frame; low, high (K, s)) that hold the y of every pose
        of the cells (as in :meth:`cells`) whose cost passes ``root^2`` (the search's threshold, before
        ``weight``): each plane sensor's (or plane feature's) offset row is ``value + g.(y - y_c)`` at ``R`` and a
        turn within delta moves it by at most its swing less h, while a pose that passes keeps it within ``sqrt(slack
        T)`` and its deviation; two lines' signed distance at ``R`` is ``g.y`` plus a constant, within its reach of
        ``rho`` (module doc). The loci's slabs first, then the pairs of lines'."""
        limit = root / np.sqrt(self.weight)
        g, middle, reach = [], [], []
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            for k in self.loci:
                ctype, s, f, rho, o = self.touches[k]
                _, _, offset, swing, _, lever, _, dev, _, _ = self._plane(ctype, s, f, rho, o, self.printed[k], R,
                                                                          delta, yc, h)
                g.append(offset[1][:, None])
                middle.append((np.einsum("ki,ki->k", offset[1], yc) - offset[0])[:, None])
                reach.append((limit * np.sqrt(1.0 + lever**2 / self.lever2) + dev + (swing - h))[:, None])
            if self.crossings:
                # Two lines' signed distance at R, u.(a + y - p*), is the true one's times u.u_R >= 1 - du^2/2, give
                # or take the turn's move and |y - y_c| du across u (module doc); the true one's size is within
                # the reach of rho.
                least_sine, u, _, a, du, arm, slack, dev, _ = self._crossing(R, delta, yc, h)
                dl, hl = delta[:, None], h[:, None]
                size = (self.pair_rho + limit * np.sqrt(slack) + dev + dl * arm + hl * du) / (1.0 - du**2 / 2.0)
                g.append(u)
                middle.append(-dot(u, a - self.pair_lines[2]))  # (u is across the fixture's line)
                reach.append(np.where(least_sine > 0.0, size, np.inf))
        if not g:
            return None
        middle, reach = np.concatenate(middle, axis=1), np.concatenate(reach, axis=1)
        finite = np.isfinite(reach)
        low, high = np.where(finite, middle - reach, -np.inf), np.where(finite, middle + reach, np.inf)
        return np.concatenate(g, axis=1), low, high

    def _plane(self, ctype, s, f, rho, o, printed, R, delta, yc, h):
        """A plane lying on a plane, a line or a cylinder (either side the plane), at the cells' centres: its turn
        rows and their omega-Jacobians, its offset row (value at y_c, m, Jw), how far the cells move that row
        (swing) and its first-order remainder, the lever, and the row's change with the feature's modes (twist,
        deviation bound and its remainder); with the radius flag of the offset."""
        c = self.centroid
        kappa = delta**2 / 2.0 + delta**3 / 6.0
        ones = np.ones(len(delta))
        radius = 0.0
        if ctype.sensor == "PL":
            n = s["n"] @ R  # the sensor's normal on the fixture, (K, 3)
            if ctype.fixture == "PL":  # the fixture's normal along the sensor's tangents
                tangents = [s["t1"] @ R, s["t2"] @ R]
                turn_rows = [t @ f["n"] for t in tangents]
                turn_jw = [cross(f["n"], t) for t in tangents]
                q = f["q"]
            else:  # the line's direction across the sensor's normal
                turn_rows, turn_jw, q = [n @ f["d"]], [cross(f["d"], n)], f["p"]
                radius = -1.0 if ctype.fixture == "C" else 0.0  # the offset holds the cylinder's radius
            constant = s["n"] @ (s["q"] - c) + rho
            offset = (np.einsum("ki,ki->k", n, q - yc) - constant, -n, cross(q - yc, n))  # at y_c; m; Jw
            reach = np.linalg.norm(q - yc, axis=1)
            swing = delta * (reach + h) + h
            offset_rest = delta * h + kappa * (reach + h)
            lever = np.linalg.norm(q - self._moved(o, R, yc), axis=1) + delta * np.linalg.norm(o - c) + h
            # The fixture's point q moves by D(q) along n, which the cell turns by delta.
            offset_twist = np.concatenate([np.broadcast_to(cross(q, n), n.shape), n], axis=1)
            offset_dev = printed.at(q) * ones
            offset_dev_rest = delta * offset_dev
        else:  # a line or a cylinder sensor on a plane feature
            d = s["d"] @ R
            turn_rows, turn_jw = [d @ f["n"]], [cross(f["n"], d)]
            a = self._moved(s["p"], R, np.zeros_like(yc))
            offset = ((a + yc - f["q"]) @ f["n"] - rho, np.broadcast_to(f["n"], a.shape), cross(f["n"], a))
            arm = np.linalg.norm(s["p"] - c)
            swing, offset_rest = delta * arm + h, kappa * arm * ones
            lever = np.linalg.norm(s["p"] - o) * ones
            # The plane moves by D(x) at the sensor's point x, which moves by at most the swing over the cell.
            x = a + yc
            offset_twist = np.concatenate([cross(f["n"], x), -np.broadcast_to(f["n"], x.shape)], axis=1)
            offset_dev = printed.at(x, swing)
            offset_dev_rest = printed.tilt * swing
        return turn_rows, turn_jw, offset, swing, offset_rest, lever, offset_twist, offset_dev, offset_dev_rest, radius

    def _locus(self, ctype, s, f, rho, o, printed, R, delta, yc, h):
        """A plane lying on a plane, a line or a cylinder (either side the plane)."""
        kappa = delta**2 / 2.0 + delta**3 / 6.0
        ones = np.ones(len(delta))
        turn_rows, turn_jw, offset, swing, offset_rest, lever, offset_twist, offset_dev, offset_dev_rest, radius = \
            self._plane(ctype, s, f, rho, o, printed, R, delta, yc, h)
        turn = np.sqrt(sum(r**2 for r in turn_rows))
        slack = 1.0 + lever**2 / self.lever2
        bound = np.maximum(self.lever2 * np.maximum(turn - delta - printed.tilt, 0.0) ** 2,
                           np.maximum(np.abs(offset[0]) - swing - offset_dev, 0.0) ** 2 / slack)
        # All rows at once: the turn rows times L and the offset, over sqrt(2 + lever^2 / L^2) (module doc).
        scale = 1.0 / np.sqrt(1.0 + slack)
        L = np.sqrt(self.lever2)
        value = np.stack([L * r for r in turn_rows] + [offset[0] - np.einsum("ki,ki->k", offset[1], yc)], axis=1)
        Jw = np.stack([L * j for j in turn_jw] + [offset[2]], axis=1)
        m = np.stack([np.zeros_like(offset[1])] * len(turn_rows) + [offset[1]], axis=1)
        remainder = np.stack([L * (kappa + delta * printed.tilt)] * len(turn_rows)
                             + [offset_rest + offset_dev_rest], axis=1)
        twist = np.stack([np.concatenate([L * j, np.zeros_like(j)], axis=1) for j in turn_jw] + [offset_twist], axis=1)
        radii = np.stack([0.0 * ones] * len(turn_rows) + [radius * ones], axis=1)
        usable = np.ones(value.shape, bool)
        return bound, value * scale[:, None], Jw * scale[:, None, None], m * scale[:, None, None], \
            remainder * scale[:, None], usable, twist * scale[:, None, None], radii * scale[:, None]

    def _crossing(self, R, delta, yc, h):
        """The pairs of lines at the cells' centres (module doc), (K, s) each: the sine of their angle less delta
        (``low``), the common normal ``u`` (K, s, 3) signed to make the distance positive there, the distance D_c,
        the sensor's closest point's image ``a`` (K, s, 3; y = 0), how far u turns (``du``) and a turn moves ``a``
        (``arm``, per rad), the whitening's ``slack`` and the printed features' deviation bound ``dev`` and remainder
        ``dev_rest``."""
        sp, sd, fp, fd = self.pair_lines
        dl, hl = delta[:, None], h[:, None]
        d = sd @ R  # (K, s, 3): R^T d per pair
        start = (sp - self.centroid) @ R  # the sensor's line's point's image, y = 0
        m = cross(d, fd[None])
        sine = np.sqrt(dot(m, m))
        # The closest point on the sensor's line at the cells' centres, along d from its point: t = f_w / (1 - cos^2),
        # w from that point to the fixture's line's.
        w = fp - yc[:, None] - start
        cosine = dot(d, fd)
        t = (dot(d, w) - cosine * dot(w, fd)) / sine**2
        a = start + t[..., None] * d
        signed = -dot(w, m) / sine
        distance = np.abs(signed)
        # How far the common normal turns over the cell: m moves by at most delta, its direction by asin(delta / s).
        du = np.where(dl < sine, 2.0 * np.sin(0.5 * np.arcsin(np.minimum(dl / sine, 1.0))), 2.0)
        arm = np.sqrt(dot(a, a))
        # The placement centre's foot on the sensor's line, and that foot's distance from the fixture's line.
        g = self.pair_foot[:, None] * d - w
        across = g - dot(g, fd)[..., None] * fd
        apart = np.sqrt(dot(across, across)) + dl * self.pair_foot_arm + hl
        low = sine - dl
        lever = np.where(low > 0.0, apart * (1.0 + 1.0 / low**2) + self.pair_off, np.inf)
        slack = 1.0 + lever**2 / self.lever2
        u = np.where(signed < 0.0, -1.0, 1.0)[..., None] * m / sine[..., None]
        dev, dev_rest = np.zeros_like(low), np.zeros_like(low)
        printed = Printed.stacked([self.printed[k] for k in self.crossings])
        if printed.tilt.any() or printed.dev.any():
            # The row moves by -u.D(p*); p* moves by at most ``shift`` over the cell (module doc).
            shift = np.where(low > 0.0, (dl * arm + hl + distance * du) / low, np.inf)
            dev = printed.at(self._foot(a, yc), shift)
            dev_rest = du * dev + np.where(printed.tilt > 0.0, printed.tilt * shift, 0.0)
        return low, u, distance, a, du, arm, slack, dev, dev_rest

    def _foot(self, a, yc):
        """The feet p* (K, s, 3) on the pairs' fixture lines of the sensors' closest points, ``a`` their images at
        y = 0, at the cells' centres yc (K, 3)."""
        fp, fd = self.pair_lines[2:]
        return fp + dot(a + yc[:, None] - fp, fd)[..., None] * fd

    def _lines(self, R, delta, yc, h, limit):
        """The pairs of lines (a line or a cylinder's axis at ``rho`` from another): their bounds' sum (K,) and
        their rows (K, s), as :meth:`cells` returns them; ``limit``, the root of each touch's largest cost at a
        pose that passes."""
        kappa = (delta**2 / 2.0 + delta**3 / 6.0)[:, None]
        dl, hl, rho = delta[:, None], h[:, None], self.pair_rho
        low, u, distance, a, du, arm, slack, dev, dev_rest = self._crossing(R, delta, yc, h)
        swing = dl * arm + hl + distance * du**2 / 2.0  # (x_a' - p*).u = D_c u_c.u + (x_a' - x_a'_c).u
        least = np.maximum(distance - swing - rho, rho - distance - swing) - dev
        # The distance (x_a' - p*).u along the common normal u: linear in (omega, y) but for u's turn and the
        # Rodrigues remainder.
        foot_f = self._foot(a, yc)
        value = dot(a - foot_f, u) - rho
        remainder = distance * du**2 / 2.0 + (dl * arm + kappa * arm + hl) * du + kappa * arm + dev_rest
        twist = np.concatenate([cross(u, foot_f), -u], axis=2)
        bound = np.where(low > 0.0, np.maximum(least, 0.0) ** 2 / slack, 0.0)
        bound = np.sum(np.where(np.isfinite(bound), bound, 0.0), axis=1)
        # With rho > 0 the unsigned distance is the signed one where it keeps its sign: over the cell, or over its
        # poses that pass, where the other sign would put it within its reach of -rho (module doc).
        reach = limit * np.sqrt(slack) + dev
        usable = (low > 0.0) & ((rho == 0.0) | (distance > swing) | (distance + rho > swing + reach))
        scale = 1.0 / np.sqrt(slack)
        radius = np.where(self.pair_fixture_c, -1.0, 0.0)  # the distance holds its radius
        return bound, value * scale, cross(u, a) * scale[..., None], u * scale[..., None], remainder * scale, usable, \
            twist * scale[..., None], radius * scale
