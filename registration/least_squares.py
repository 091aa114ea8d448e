"""Levenberg-Marquardt over the pose: the (weighted) sum of the problem's squared rows.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

from .pose import apply_twist, rotation_from_vector

MAX_ITERATIONS = 60
STEP_TOLERANCE = 1e-4  # LM stops, the step not taken, once one would move the touches less than this many sigma
STALLED_AFTER = 4  # LM iterations before a refinement may be abandoned as stalled ...
STALLED_COST_FACTOR = 1e4  # ... while its cost exceeds this many times sigma^2 per row ...
STALLED_DECREASE = 0.5  # ... and one iteration removes less than half of it
FLAT_DECREASE = 1e-6  # LM stops once an iteration lowers the cost by less than this many sigma^2


def levenberg_marquardt(problem, rotation, translation, weights=None, max_iterations=MAX_ITERATIONS,
                        may_give_up=True):
    """Minimise the (weighted) sum of squared rows from a pose; return R, t, residuals, Jacobian.

    ``may_give_up``: stop when the cost stalls far above any acceptable residual.
    """
    r, J = problem.evaluate(rotation, translation)
    w = np.ones(len(r)) if weights is None else weights
    cost = float(np.sum(w * r * r))
    hopeless = STALLED_COST_FACTOR * problem.sigma**2 * max(len(r), 1)
    length = problem.scale()
    lam = 1e-4
    for iteration in range(max_iterations):
        Jw = J * w[:, None]
        A = J.T @ Jw
        g = Jw.T @ r
        diag = np.diag(A).copy()
        diag[diag < 1e-12 * max(diag.max(), 1e-300)] = max(diag.max(), 1.0) * 1e-12
        improved = False
        for _ in range(12):
            step = -np.linalg.solve(A + lam * np.diag(diag), g)
            if step_moves(step, length) < STEP_TOLERANCE * problem.sigma:
                return rotation, translation, r, J  # a step this small changes nothing the test sees: not taken
            R2, t2 = apply_twist(rotation, translation, step)
            r2, J2 = problem.evaluate(R2, t2)
            cost2 = float(np.sum(w * r2 * r2))
            if cost2 <= cost:
                improved = True
                break
            lam *= 8.0
        if not improved:
            break
        # A decrease this small is nothing to the residual test: in a flat valley LM would creep on for long.
        tiny = cost - cost2 <= 1e-16 * max(cost, 1e-30) + FLAT_DECREASE * problem.sigma**2
        stalled = may_give_up and iteration >= STALLED_AFTER and cost2 > hopeless and cost2 > STALLED_DECREASE * cost
        rotation, translation, r, J, cost = R2, t2, r2, J2, cost2
        lam = max(lam / 10.0, 1e-9)
        if tiny or stalled:
            break
    return rotation, translation, r, J


def step_moves(step, length):
    """How far a twist step (..., 6) moves the touches at most, mm: its turn over the part's ``length``, its shift."""
    return np.linalg.norm(step[..., :3], axis=-1) * length + np.linalg.norm(step[..., 3:], axis=-1)


def levenberg_marquardt_batch(problem, rotations, translations, without=None, max_iterations=MAX_ITERATIONS):
    """Many starts (K, 3, 3), (K, 3) refined at once, each by :func:`levenberg_marquardt`'s steps and stops;
    returns their poses (Rs, ts) and costs (K,), the sums of their squared rows. ``without`` (K,): a touch each
    start's problem leaves out (:meth:`.problem.Problem.evaluate_batch`). The steps are fixture-frame twists, as
    ``evaluate_batch`` gives the Jacobian: ``x -> R (exp(omega) x + v) + t``."""
    Rs, ts = np.array(rotations, dtype=np.float64), np.array(translations, dtype=np.float64)
    without = None if without is None else np.asarray(without)

    def evaluate(k, R, t):
        return problem.evaluate_batch(R, t, None if without is None else without[k])

    r, J = evaluate(slice(None), Rs, ts)
    cost = np.sum(r * r, axis=1)
    # Each start's rows: a left-out touch's are zero, Jacobian and all (a row's never is: it moves with the pose).
    hopeless = STALLED_COST_FACTOR * problem.sigma**2 * np.maximum(np.sum(np.any(J != 0, axis=2), axis=1), 1)
    length = problem.scale()
    lam = np.full(len(Rs), 1e-4)
    active = np.arange(len(Rs))
    for iteration in range(max_iterations):
        if not len(active):
            break
        A = J[active].transpose(0, 2, 1) @ J[active]
        g = np.einsum("kmi,km->ki", J[active], r[active])
        diag = np.diagonal(A, axis1=1, axis2=2).copy()
        top = diag.max(axis=1, keepdims=True)
        diag = np.where(diag < 1e-12 * np.maximum(top, 1e-300), np.maximum(top, 1.0) * 1e-12, diag)
        # Each start tries until a step lowers its cost (lambda grown 8 times a try), at most 12 tries.
        trying = np.ones(len(active), bool)
        stop = np.zeros(len(active), bool)
        for _ in range(12):
            k = np.flatnonzero(trying)
            idx = active[k]
            step = -np.linalg.solve(A[k] + lam[idx, None, None] * (diag[k, :, None] * np.eye(6)), g[k, :, None])[..., 0]
            small = step_moves(step, length) < STEP_TOLERANCE * problem.sigma
            stop[k[small]], trying[k[small]] = True, False
            k, idx, step = k[~small], idx[~small], step[~small]
            if not len(k):
                break
            R2 = Rs[idx] @ rotation_from_vector(step[:, :3])
            t2 = ts[idx] + np.einsum("kij,kj->ki", Rs[idx], step[:, 3:])
            r2, J2 = evaluate(idx, R2, t2)
            cost2 = np.sum(r2 * r2, axis=1)
            ok = cost2 <= cost[idx]
            moved, before, after = idx[ok], cost[idx[ok]], cost2[ok]
            tiny = before - after <= 1e-16 * np.maximum(before, 1e-30) + FLAT_DECREASE * problem.sigma**2
            stalled = (iteration >= STALLED_AFTER) & (after > hopeless[moved]) & (after > STALLED_DECREASE * before)
            Rs[moved], ts[moved], r[moved], J[moved], cost[moved] = R2[ok], t2[ok], r2[ok], J2[ok], after
            lam[moved] = np.maximum(lam[moved] / 10.0, 1e-9)
            lam[idx[~ok]] *= 8.0
            stop[k[ok]] = tiny | stalled
            trying[k[ok]] = False
            if not trying.any():
                break
        active = active[~(trying | stop)]  # (still trying after 12: no step lowers its cost)
    return Rs, ts, cost
