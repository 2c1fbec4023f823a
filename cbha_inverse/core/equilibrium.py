"""
Static equilibrium under actuator loads, with their load stiffness (paper eq. 9, DESIGN §3).

Cable forces follow the structure; a Newton iteration that ignores their stiffness (the
structural tangent alone) sees a tendon-compressed backbone as unstable and fails to converge
beyond small tensions. :func:`solve_equilibrium` uses the full tangent (structure from
:class:`cbha_inverse.core.kernel.ChainKernel` plus
:meth:`cbha_inverse.core.actuation.ActuatorSet.load_tangent`), a backtracking line search on the
residual norm and, only if the full load fails, load continuation. The Newton step solves with
the exact (non-symmetric) load stiffness by LU; the inverse solver's tick uses its symmetric part
with a Cholesky factorization. This is the forward model of
the scenes, and the same linearisation the inverse solver uses per tick, so the two agree.
"""

from dataclasses import dataclass

from cbha_inverse.core.chain import ChainState
from cbha_inverse.core.kernel import DenseCholesky, fast_retract
import numpy as np


@dataclass(frozen=True)
class EquilibriumResult:
    """
    Result of :func:`solve_equilibrium`.

    Attributes
    ----------
    state : cbha_inverse.core.chain.ChainState
        Final frames.
    converged : bool
        Whether the residual met the tolerance at the full load.
    iterations : int
        Total Newton iterations.
    residual_norm : float  [N, N*m]
        Final residual norm.
    load_steps : int
        Load increments used (1 without continuation).
    message : str
        What happened.

    """

    state: ChainState
    converged: bool
    iterations: int
    residual_norm: float
    load_steps: int
    message: str


def _residual(kernel, actuators, external, actuation, positions, rotations, factor):
    """Return the residual (6n,) at a state and load factor."""
    internal = kernel.internal(positions, rotations)
    wrenches, _ = actuators.evaluate(positions, rotations, False)
    m = wrenches.shape[0]
    return internal.reshape(-1) + factor * (
        external + actuation @ wrenches[:, 1:, :].reshape(m, -1))


def _newton(kernel, actuators, external, actuation, positions, rotations, factor, tolerance,
            max_iterations):
    """Newton with line search at one load factor; return (positions, rotations, ok, its, r)."""
    r = _residual(kernel, actuators, external, actuation, positions, rotations, factor)
    norm = np.linalg.norm(r)
    for it in range(1, max_iterations + 1):
        if norm <= tolerance:
            return positions, rotations, True, it - 1, norm
        _, tangent = kernel.linearise(positions, rotations)
        load = actuators.load_tangent(positions, rotations, factor * actuation, symmetric=False)
        if load is not None:
            tangent = tangent + load
        try:
            step = np.linalg.solve(tangent, r)
            if not np.all(np.isfinite(step)):
                raise np.linalg.LinAlgError('non-finite Newton step')
        except np.linalg.LinAlgError:
            _, tangent = kernel.linearise(positions, rotations, geometric=False)
            if load is not None:
                tangent = tangent + 0.5 * (load + load.T)
            try:
                step = DenseCholesky(tangent).solve(r)
            except np.linalg.LinAlgError:
                return positions, rotations, False, it, norm
        step = step.reshape(-1, 6)
        alpha = 1.0
        for _ in range(12):
            trial = fast_retract(positions, rotations, alpha * step)
            r_new = _residual(kernel, actuators, external, actuation, *trial, factor)
            norm_new = np.linalg.norm(r_new)
            if np.isfinite(norm_new) and norm_new < (1.0 - 1e-4 * alpha) * norm:
                break
            alpha *= 0.5
        else:
            return positions, rotations, False, it, norm
        positions, rotations = trial
        r, norm = r_new, norm_new
    return positions, rotations, norm <= tolerance, max_iterations, norm


def solve_equilibrium(kernel, actuators, actuation, external, initial_state, *,
                      tolerance=1e-10, max_iterations=50, max_load_steps=64):
    """
    Solve ``f(q) + f_ext + J_a(q)ᵀ λ = 0`` for the frames (paper eq. 9).

    Parameters
    ----------
    kernel : cbha_inverse.core.kernel.ChainKernel
        The chain's mechanics.
    actuators : cbha_inverse.core.actuation.ActuatorSet
        The actuators.
    actuation : (m,) ndarray  [N or Pa]
        Applied actuation.
    external : (6n,) ndarray  [N, N*m]
        Constant external wrenches (gravity) on frames 1..n.
    initial_state : ChainState
        Start (the rest shape or a warm start).
    tolerance : float
        Residual tolerance relative to the applied loads (``‖f_ext‖ + Σ |λ_j| ‖J_aᵀ_j‖``, plus
        an absolute floor of ``tolerance``).
    max_iterations : int
        Newton iterations per load step.
    max_load_steps : int
        Largest number of load increments of the continuation.

    Returns
    -------
    EquilibriumResult
        Never silently unconverged: check ``converged``.

    """
    positions = np.array(initial_state.positions, dtype=float)
    rotations = np.array(initial_state.rotations, dtype=float)
    wrenches, _ = actuators.evaluate(positions, rotations, False)
    columns = wrenches[:, 1:, :].reshape(wrenches.shape[0], -1)
    # scale of the applied loads: a pressure column holds large wrenches that cancel between
    # neighbouring frames, so its own norm (not that of the sum) sets the round-off floor
    scale = np.linalg.norm(external) + np.abs(actuation) @ np.linalg.norm(columns, axis=1)
    tol = tolerance * (1.0 + scale)
    pos, rot, ok, its, norm = _newton(kernel, actuators, external, actuation, positions,
                                      rotations, 1.0, tol, max_iterations)
    if ok:
        return EquilibriumResult(ChainState(pos, rot), True, its, float(norm), 1, 'converged')
    total, steps, factor, increment = its, 0, 0.0, 0.25
    while factor < 1.0 and steps < max_load_steps:
        target = min(1.0, factor + increment)
        pos, rot, ok, its, norm = _newton(kernel, actuators, external, actuation, positions,
                                          rotations, target, tol, max_iterations)
        total += its
        steps += 1
        if ok:
            positions, rotations, factor = pos, rot, target
            increment *= 1.5
        else:
            increment *= 0.5
    converged = factor >= 1.0
    message = 'converged with load continuation' if converged else (
        f'not converged: load factor {factor:.4g} after {steps} load steps '
        f'(residual {norm:.3g})')
    return EquilibriumResult(ChainState(positions, rotations), converged, total, float(norm),
                             steps, message)
