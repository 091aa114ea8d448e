"""Continuous subgroups of the Euclidean group (the paper's Table II) with concrete geometry.

A subgroup is stored with the point and direction that place it in space, so
that containment, intersection and the dimension of a product of subgroups
are computed, not looked up. Twists are (omega, v) with point velocity
omega x x + v; a rotation about the axis through p along w is (w, p x w).
"""

from dataclasses import dataclass

import numpy as np

from fixturecad.registration.elements import perpendicular_basis
from fixturecad.registration.mobility import matrix_rank, null_space
from fixturecad.registration.pose import fixture2meas_from_rt, motion_from_twist, skew

# Table II notation and degrees of freedom of each kind.
NOTATION = {"R": "R_u", "T1": "T_u", "T2": "T_P", "C": "C_u", "G3": "G_P", "S": "S_o"}
DOF = {"R": 1, "T1": 1, "T2": 2, "C": 2, "G3": 3, "S": 3}
# Order used to read a product in the paper's direction: S-T2 rather than T2-S, R-C rather than C-R.
NAME_RANK = {"S": 0, "G3": 1, "R": 2, "T1": 3, "T2": 3, "C": 4}


@dataclass(frozen=True, eq=False)
class Subgroup:
    """One subgroup: ``kind`` in R, T1, T2, C, G3, S.

    ``point``: on the axis (R, C), in the plane (G3) or the centre (S), mm.
    ``direction``: the axis (R, T1, C) or the plane normal (T2, G3), unit.
    """

    kind: str
    point: np.ndarray
    direction: np.ndarray

    def algebra(self) -> np.ndarray:
        """Twist basis, shape (dof, 6)."""
        p, w = self.point, self.direction
        rotation = lambda axis: np.concatenate([axis, np.cross(p, axis)])
        translation = lambda axis: np.concatenate([np.zeros(3), axis])
        if self.kind == "S":
            return np.array([rotation(axis) for axis in np.eye(3)])
        if self.kind == "R":
            return rotation(w)[None]
        if self.kind == "T1":
            return translation(w)[None]
        if self.kind == "C":
            return np.array([rotation(w), translation(w)])
        e1, e2 = perpendicular_basis(w)
        if self.kind == "T2":
            return np.array([translation(e1), translation(e2)])
        return np.array([rotation(w), translation(e1), translation(e2)])

    def contains(self, other: "Subgroup") -> bool:
        return matrix_rank(np.vstack([self.algebra(), other.algebra()])) == DOF[self.kind]

    def intersection_dim(self, other: "Subgroup") -> int:
        return DOF[self.kind] + DOF[other.kind] - matrix_rank(np.vstack([self.algebra(), other.algebra()]))

    def sample(self, rng: np.random.Generator, scale=1.0) -> np.ndarray:
        """A random element as a 4x4 homogeneous matrix."""
        twist = rng.normal(scale=scale, size=DOF[self.kind]) @ self.algebra()
        return fixture2meas_from_rt(*motion_from_twist(twist))


def adjoint(g) -> np.ndarray:
    """Adjoint of a 4x4 rigid motion acting on twists (omega, v)."""
    r, t = g[:3, :3], g[:3, 3]
    that = skew(t)
    out = np.zeros((6, 6))
    out[:3, :3] = r
    out[3:, 3:] = r
    out[3:, :3] = that @ r
    return out


def product_dimension(factors, rng: np.random.Generator) -> int:
    """Generic dimension of the set of products h1 h2 ... hk, hi in factor i."""
    frame = np.eye(4)
    tangents = []
    for factor in factors:
        tangents.append(factor.algebra() @ adjoint(frame).T)
        frame = frame @ factor.sample(rng)
    return matrix_rank(np.vstack(tangents)) if tangents else 0


def simplify(chain: list) -> list:
    """Rewrite a product of subgroups into the paper's compact form.

    Rules, applied until nothing changes:
    a factor inside a neighbour is dropped ({R_u}{S_o} = {S_o} when u passes
    through o); a spherical motion between two factors that each share one of
    its rotations keeps only the rotation about the common normal
    ({C_u}{S_o}{C_u''} = {C_u}{R_u'}{C_u''}); a cylindrical motion that shares
    its rotation with a neighbour keeps its translation, and the other way
    round; a planar motion sharing the rotation about its normal keeps its
    translations ({G_P}{S_o} = {T_P}{S_o}).
    """
    chain = list(chain)
    changed = True
    while changed:
        changed = False
        for i, factor in enumerate(chain):
            neighbours = [chain[j] for j in (i - 1, i + 1) if 0 <= j < len(chain)]
            if any(n.contains(factor) for n in neighbours):
                del chain[i]
                changed = True
                break
        if changed:
            continue
        for i in range(1, len(chain) - 1):
            left, middle, right = chain[i - 1], chain[i], chain[i + 1]
            if middle.kind == "S" and left.intersection_dim(middle) == 1 == right.intersection_dim(middle):
                axes = [_shared_rotation(n, middle) for n in (left, right)]
                if all(a is not None for a in axes) and np.linalg.norm(np.cross(*axes)) > 1e-6:
                    normal = np.cross(*axes)
                    chain[i] = Subgroup("R", middle.point, normal / np.linalg.norm(normal))
                    changed = True
                    break
        if changed:
            continue
        for kind in ("C", "G3"):
            for i, factor in enumerate(chain):
                if factor.kind != kind:
                    continue
                for j in (i - 1, i + 1):
                    if 0 <= j < len(chain) and factor.intersection_dim(chain[j]) == 1:
                        chain[i] = _reduce(factor, chain[j])
                        changed = True
                        break
                if changed:
                    break
            if changed:
                break
    return chain


def _shared_rotation(group: Subgroup, sphere: Subgroup):
    """Axis of the rotation about the sphere's centre that ``group`` contains, if any."""
    basis = group.algebra()
    # Rotations about the centre o are (w, o x w); look for one in the span of ``basis``.
    o = sphere.point
    rotations = np.array([np.concatenate([w, np.cross(o, w)]) for w in np.eye(3)])
    null = null_space(np.vstack([basis, rotations]).T)
    if len(null) != 1:
        return None
    w = null[0][len(basis):] @ np.eye(3)
    return w / np.linalg.norm(w)


def _reduce(factor: Subgroup, neighbour: Subgroup) -> Subgroup:
    """Remove from ``factor`` the one-dimensional subgroup it shares with ``neighbour``."""
    p, w = factor.point, factor.direction
    if factor.kind == "C":
        if neighbour.contains(Subgroup("R", p, w)):
            return Subgroup("T1", p, w)
        return Subgroup("R", p, w)
    return Subgroup("T2", p, w)


def class_name(chain: list) -> str:
    """The class of a product, read in the paper's direction: ``S-T2``, ``R-C``, ``C-R-C``."""
    kinds = [f.kind for f in chain]
    forward = tuple(NAME_RANK[k] for k in kinds)
    if tuple(reversed(forward)) < forward:
        kinds = kinds[::-1]
    return "-".join(kinds)


def labelled(chain: list) -> list[tuple[Subgroup, str, str]]:
    """The factors in the paper's reading order with their symbol and anchor letter.

    E.g. ``[(S, "S_o", "o"), (S, "S_{o'}", "o'")]``: each letter (o, u, P) is
    primed once more at every new factor that uses it, as in Table III.
    """
    if class_name(chain) != "-".join(f.kind for f in chain):
        chain = chain[::-1]
    counts = {}
    out = []
    for factor in chain:
        symbol = NOTATION[factor.kind]
        letter = symbol[-1]
        index = counts.get(letter, 0)
        counts[letter] = index + 1
        anchor = letter + "'" * index
        out.append((factor, f"{symbol[:-1]}{{{anchor}}}" if index else symbol, anchor))
    return out


def group_notation(chain: list) -> str:
    """Table III notation, e.g. ``{S_o}{T_P}`` or ``{C_u}{R_{u'}}{C_{u''}}``."""
    return "".join("{" + symbol + "}" for _, symbol, _ in labelled(chain))
