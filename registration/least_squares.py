"""Levenberg-Marquardt over the pose: the (weighted) sum of the problem's squared rows.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

from .pose import apply_twist, rotation_angle

MAX_ITERATIONS = 60
STEP_TOLERANCE = 1e-4  # LM stops once a step moves the touches less than this many sigma
STALLED_AFTER = 4  # LM iterations before a refinement may be abandoned as stalled ...
STALLED_COST_FACTOR = 1e4  # ... while its cost exceeds this many times sigma^2 per row ...
STALLED_DECREASE = 0.5  # ... and one iteration removes less than half of it
FLAT_DECREASE = 1e-6  # LM stops once an iteration lowers the cost by less than this many sigma^2
NEAR_KNOWN_RAD = 1e-3  # a refinement this close to a found solution is converging onto it
NEAR_KNOWN_MM = 0.05


def levenberg_marquardt(problem, rotation, translation, weights=None, max_iterations=MAX_ITERATIONS, known=(),
                        may_give_up=True):
    """Minimise the (weighted) sum of squared rows from a pose; return R, t, residuals, Jacobian.

    ``known`` poses (R, t): stop early once the iterate comes close to one of
    them (it is falling into a basin already explored). ``may_give_up``:
    stop when the cost stalls far above any acceptable residual.
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
            R2, t2 = apply_twist(rotation, translation, step)
            r2, J2 = problem.evaluate(R2, t2)
            cost2 = float(np.sum(w * r2 * r2))
            if cost2 <= cost:
                improved = True
                break
            lam *= 8.0
        if not improved:
            break
        small = np.linalg.norm(step[:3]) * length + np.linalg.norm(step[3:]) < STEP_TOLERANCE * problem.sigma
        # A decrease this small is nothing to the residual test: in a flat valley LM would creep on for long.
        tiny = cost - cost2 <= 1e-16 * max(cost, 1e-30) + FLAT_DECREASE * problem.sigma**2
        stalled = may_give_up and iteration >= STALLED_AFTER and cost2 > hopeless and cost2 > STALLED_DECREASE * cost
        rotation, translation, r, J, cost = R2, t2, r2, J2, cost2
        lam = max(lam / 10.0, 1e-9)
        if small or tiny or stalled:
            break
        for R_known, t_known in known:
            if rotation_angle(rotation @ R_known.T) < NEAR_KNOWN_RAD and np.linalg.norm(translation - t_known) < NEAR_KNOWN_MM:
                return R_known, t_known, r, J
    return rotation, translation, r, J
