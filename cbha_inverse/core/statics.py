"""
Quasi-static equilibrium of a frame chain: Newton with line search and automatic load stepping.

Solves ``f(q) + f_ext = 0`` (paper eq. 9 without actuation; actuation enters through
``load_function``) for the poses of frames 1..n:

- residual ``r(q) = internal(q) + lam (f_dead + f_follower(q))``, ``lam`` the load factor;
- Newton increments ``dq = T^-1 r`` (world axes, as for :func:`cbha_inverse.core.chain.retract`)
  with the exact, non-symmetric tangent ``T = -d internal / dq`` (material + geometric part, see
  :mod:`cbha_inverse.core.links`; banded LU). Dead loads (tip and frame wrenches, gravity) are
  constant in world axes and have no tangent; follower loads from ``load_function`` are not
  differentiated (the line search keeps the iteration robust, convergence is then linear);
- the increment is applied in the chain's deformation coordinates: each link's offset and
  rotation vector move by the linearised change ``B dq``, and the poses follow from the base by
  forward kinematics with multiplicative rotations ``R_{i+1} = R_i exp(phi_i) Q0_i``. To first
  order this is ``retract``; at large rotations it lets a bending increment carry the rest of
  the chain rigidly instead of stretching the links along their tangents, which is what makes
  full Newton steps work for slender (axially stiff) chains: the PL^2/EI = 10 elastica converges
  from rest in one load step of 7 iterations instead of creeping with tiny steps;
- backtracking line search on the Euclidean norm of the scaled residual (Armijo, factor 1/2);
- load stepping: the full load is tried first; a load step that fails (no convergence within
  ``max_iterations`` or a failed line search) is halved; successful steps double the increment.

Convergence test (``residual_norm`` reports the left-hand side)::

    max |r_scaled| <= tolerance * load_scale + floor

``r_scaled`` is the residual with moments divided by the chain length L_c (so both are in N);
``load_scale`` is the largest scaled component of the applied loads and of the internal wrenches
at the current state; ``floor`` is the round-off level of the internal forces,
``64 eps max_links(|K_tt| x_ref + |K_tr|, (|K_rt| x_ref + |K_rr|) / L_c)`` with ``x_ref = L_c +
|base position|`` (max-abs entries of the stiffness blocks), below which no residual is
meaningful.
"""

from dataclasses import dataclass

from cbha_inverse.core.assembly import assemble_tangent, chain_terms, internal_wrenches
from cbha_inverse.core.chain import ChainState, rest_state
from cbha_inverse.core.se3 import so3_exp
import numpy as np
from scipy.linalg import solve_banded

_ARMIJO = 1e-4
_MAX_HALVINGS = 6
_MIN_LOAD_INCREMENT = 1.0 / 2 ** 20
_BLOCK_ROWS, _BLOCK_COLS = (idx.ravel() for idx in np.indices((6, 6)))


class StaticConvergenceError(RuntimeError):
    """A static solve did not converge (raised only by strict solves); ``.result`` holds it."""

    def __init__(self, result):
        super().__init__(result.message)
        self.result = result


@dataclass(frozen=True, eq=False)
class StaticResult:
    """
    Result of :func:`solve_static`.

    Attributes
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins, frame 0 = base.
    quaternions : (n + 1, 4) ndarray
        Frame orientations (x, y, z, w).
    rotations : (n + 1, 3, 3) ndarray
        Frame rotation matrices.
    state : ChainState
        The same poses as a state (e.g. to warm-start the next solve).
    converged : bool
        True only if the full load was reached and the residual test passed.
    iterations : int
        Total Newton iterations over all load steps.
    residual_norm : float  [N]
        Max-norm of the scaled residual (moments / chain length) of the returned state under
        the full load.
    load_steps : int
        Load steps attempted (successful and failed).
    load_factor : float
        Fraction of the load in equilibrium at the returned state (1.0 when converged).
    message : str
        What happened, in words.

    """

    positions: np.ndarray
    quaternions: np.ndarray
    rotations: np.ndarray
    state: ChainState
    converged: bool
    iterations: int
    residual_norm: float
    load_steps: int
    load_factor: float
    message: str


def external_wrenches(model, tip_wrench=None, frame_wrenches=None, gravity=None):
    """
    Dead external wrenches on frames 1..n (world axes, at the frame origins).

    Parameters
    ----------
    model : ChainModel
        The chain (masses are lumped at frames 1..n).
    tip_wrench : (6,) array_like, optional  [N, N*m]
        Added at the last frame.
    frame_wrenches : (n, 6) array_like, optional  [N, N*m]
        Wrench on each of frames 1..n.
    gravity : (3,) array_like, optional  [m/s^2]
        Acceleration of gravity; force ``m_i g`` on frame i.

    Returns
    -------
    (n, 6) ndarray

    """
    n = model.n_links
    ext = np.zeros((n, 6))
    if frame_wrenches is not None:
        fw = np.asarray(frame_wrenches, dtype=float)
        if fw.shape != (n, 6):
            raise ValueError(f'frame_wrenches must have shape ({n}, 6), got {fw.shape}')
        ext += fw
    if tip_wrench is not None:
        tw = np.asarray(tip_wrench, dtype=float)
        if tw.shape != (6,):
            raise ValueError(f'tip_wrench must have shape (6,), got {tw.shape}')
        ext[-1] += tw
    if gravity is not None:
        g = np.asarray(gravity, dtype=float)
        if g.shape != (3,):
            raise ValueError(f'gravity must have shape (3,), got {g.shape}')
        ext[:, :3] += model.masses[:, None] * g
    return ext


def _residual_floor(model, length):
    """Round-off level of the scaled internal wrenches (see the module docstring)."""
    k = np.abs(model.stiffnesses)
    k_tt = k[:, :3, :3].max()
    k_tr = max(k[:, :3, 3:].max(), k[:, 3:, :3].max())
    k_rr = k[:, 3:, 3:].max()
    x_ref = length + float(np.linalg.norm(model.base_position))
    return 64.0 * np.finfo(float).eps * max(k_tt * x_ref + k_tr, (k_tr * x_ref + k_rr) / length)


def _scaled(wrenches, length):
    """Return wrenches with moments divided by the characteristic length."""
    out = wrenches.copy()
    out[:, 3:] /= length
    return out


def _newton_direction(tangent, residual):
    """
    Solve ``T dq = r`` with the exact (non-symmetric) block-tridiagonal tangent.

    LAPACK banded LU (``dgbsv``, 11 sub- and super-diagonals); O(n), and level-2 BLAS only, so it
    stays fast on small problems where threaded level-3 BLAS would dominate.
    """
    n = tangent.diagonal.shape[0]
    ab = np.zeros((23, 6 * n))
    # general band storage ab[11 + i - j, j] = A[i, j], filled from the three block diagonals
    for blocks, shift in ((tangent.exact_diagonal, 0), (tangent.upper, 1),
                          (np.swapaxes(tangent.upper, 1, 2), -1)):
        k = np.arange(blocks.shape[0])[:, None]
        i = 6 * (k + max(-shift, 0)) + _BLOCK_ROWS
        j = 6 * (k + max(shift, 0)) + _BLOCK_COLS
        ab[11 + i - j, j] = blocks.reshape(-1, 36)
    return solve_banded((11, 11), ab, residual.ravel(), check_finite=False).reshape(n, 6)


class _Problem:
    """Residual evaluation of one static problem (model, loads, scaling)."""

    def __init__(self, model, external, load_function, tolerance):
        self.model = model
        self.external = external
        self.load_function = load_function
        self.tolerance = tolerance
        self.length = model.length if model.length > 0.0 else 1.0
        self.floor = _residual_floor(model, self.length)

    def loads(self, state, lam):
        """Return the applied wrenches at load factor ``lam``."""
        loads = self.external
        if self.load_function is not None:
            extra = np.asarray(self.load_function(state), dtype=float)
            if extra.shape != self.external.shape:
                raise ValueError(f'load_function must return shape {self.external.shape}')
            loads = loads + extra
        return lam * loads

    def evaluate(self, state, lam, internal=None):
        """Return (residual, scaled max-norm, scaled 2-norm, converged flag)."""
        if internal is None:
            internal = internal_wrenches(self.model, state)
        loads = self.loads(state, lam)
        res = internal + loads
        scaled = _scaled(res, self.length)
        scale = max(np.abs(_scaled(loads, self.length)).max(),
                    np.abs(_scaled(internal, self.length)).max())
        r_max = float(np.abs(scaled).max())
        ok = r_max <= self.tolerance * scale + self.floor
        return res, r_max, float(np.linalg.norm(scaled)), ok


def _relative_update(model, state, step, terms):
    """
    Map world increments of frames 1..n to link-deformation increments and a pose generator.

    Newton's increment is applied in the chain's deformation coordinates (offset and rotation
    vector of each link in its frame-a axes): ``u += R_a^T (dx_b - dx_a - dtheta_a x p)``,
    ``phi += Jl^-1(phi) R_a^T (dtheta_b - dtheta_a)`` (the linearisation of the link deformation,
    DESIGN §3), then the poses follow by forward kinematics from the fixed base. To first order
    this is the same Newton step as :func:`retract`, but a bending increment carries the rest of
    the chain along rigidly instead of stretching every link along its tangent, which keeps full
    steps acceptable at large rotations.
    """
    pos, rot = state.positions, state.rotations
    inc = np.concatenate([np.zeros((1, 6)), step], axis=0)
    rot_at = np.swapaxes(rot[:-1], 1, 2)
    dx = inc[1:, :3] - inc[:-1, :3] - np.cross(inc[:-1, 3:], pos[1:] - pos[:-1])
    du = (rot_at @ dx[..., None])[..., 0]
    dphi = (terms.jinv @ rot_at @ (inc[1:, 3:] - inc[:-1, 3:])[..., None])[..., 0]

    def poses(alpha):
        rel = so3_exp(terms.phi + alpha * dphi) @ model.rest_rotations
        rots = np.empty_like(rot)
        rots[0] = rot[0]
        for i in range(rel.shape[0]):
            rots[i + 1] = rots[i] @ rel[i]
        arms = (rots[:-1] @ (terms.offset + alpha * du)[..., None])[..., 0]
        new_pos = np.empty_like(pos)
        new_pos[0] = pos[0]
        new_pos[1:] = pos[0] + np.cumsum(arms, axis=0)
        return ChainState(new_pos, rots)

    return poses


def _line_search(problem, state, terms, lam, step, r_two):
    """
    Backtrack along the Newton step (in deformation coordinates) on the residual norm.

    Armijo test on the Euclidean norm of the scaled residual, ``|r(a)| <= (1 - 1e-4 a) |r(0)|``,
    halving ``a`` at most ``_MAX_HALVINGS`` times; returns the accepted state and its link terms,
    or None (the load step is then cut, which is cheaper than creeping along a poor direction).
    """
    model = problem.model
    poses = _relative_update(model, state, step, terms)
    alpha = 1.0
    for _ in range(_MAX_HALVINGS):
        trial = poses(alpha)
        trial_terms = chain_terms(model, trial)
        internal = internal_wrenches(model, trial, trial_terms)
        _, _, t_two, ok = problem.evaluate(trial, lam, internal)
        if ok or t_two <= (1.0 - _ARMIJO * alpha) * r_two:
            return trial, trial_terms
        alpha *= 0.5
    return None


def _newton(problem, state, lam, max_iterations):
    """Newton iterations at a fixed load factor; returns (ok, state, iterations, r_max, why)."""
    model = problem.model
    iterations = 0
    terms = chain_terms(model, state)
    while True:
        internal = internal_wrenches(model, state, terms)
        res, r_max, r_two, ok = problem.evaluate(state, lam, internal)
        if ok:
            return True, state, iterations, r_max, 'converged'
        if not np.isfinite(r_max):
            return False, state, iterations, r_max, 'non-finite residual'
        if iterations >= max_iterations:
            return False, state, iterations, r_max, 'iteration budget exhausted'
        try:
            step = _newton_direction(assemble_tangent(model, state, terms), res)
        except np.linalg.LinAlgError:
            return False, state, iterations, r_max, 'singular tangent'
        iterations += 1
        accepted = _line_search(problem, state, terms, lam, step, r_two)
        if accepted is None:
            return False, state, iterations, r_max, 'line search failed'
        state, terms = accepted


def solve_static(model, tip_wrench=None, frame_wrenches=None, gravity=None, *,
                 load_function=None, initial_state=None, tolerance=1e-10, max_iterations=50,
                 max_load_steps=64, strict=False):
    """
    Solve for the static equilibrium of a chain under dead and follower loads (paper eq. 9).

    Parameters
    ----------
    model : ChainModel
        The chain; frame 0 is fixed.
    tip_wrench : (6,) array_like, optional  [N, N*m]
        Dead wrench at the last frame, world axes.
    frame_wrenches : (n, 6) array_like, optional  [N, N*m]
        Dead wrenches at frames 1..n, world axes.
    gravity : (3,) array_like, optional  [m/s^2]
        Acting on the masses lumped at frames 1..n (force only).
    load_function : callable, optional
        ``load_function(state) -> (n, 6)`` extra configuration-dependent wrenches (world axes,
        at frames 1..n), e.g. cables or pressure; scaled by the load factor like the dead loads.
    initial_state : ChainState, optional
        Warm start (e.g. the previous solution): Newton on the full load from it; if that
        fails, load stepping from the rest shape (the default start).
    tolerance : float
        Relative residual tolerance (see the module docstring).
    max_iterations : int
        Newton iterations allowed per load step.
    max_load_steps : int
        Load steps allowed (attempts, successful or not).
    strict : bool
        Raise :class:`StaticConvergenceError` instead of returning an unconverged result.

    Returns
    -------
    StaticResult
        ``converged`` is False (with a message) if the full load was not reached; the state is
        then the last equilibrium found (at ``load_factor`` < 1) or the last iterate.

    """
    external = external_wrenches(model, tip_wrench, frame_wrenches, gravity)
    problem = _Problem(model, external, load_function, float(tolerance))
    lam = 0.0
    increment = 1.0
    steps = 0
    total = 0
    message = ''
    state = rest_state(model)
    if initial_state is not None:
        if initial_state.positions.shape != (model.n_frames, 3):
            raise ValueError('initial_state does not match the model')
        # warm start: the full load from the given state; if that fails, step up from rest
        steps = 1
        ok, new_state, total, _, why = _newton(problem, initial_state, 1.0, max_iterations)
        if ok:
            state, lam = new_state, 1.0
        else:
            message = f'warm start failed: {why}'
    while lam < 1.0:
        if steps >= max_load_steps:
            message = (f'not converged: load step budget ({max_load_steps}) exhausted at load '
                       f'factor {lam:.6g} ({message})')
            break
        if increment < _MIN_LOAD_INCREMENT:
            message = (f'not converged: load increment below {_MIN_LOAD_INCREMENT:.3g} at load '
                       f'factor {lam:.6g} ({message})')
            break
        target = min(1.0, lam + increment)
        steps += 1
        ok, new_state, its, _, why = _newton(problem, state, target, max_iterations)
        total += its
        if ok:
            state, lam = new_state, target
            increment = min(2.0 * increment, 1.0)
        else:
            increment *= 0.5
            message = f'last failure at load factor {target:.6g}: {why}'
    converged = lam >= 1.0
    _, r_max, _, _ = problem.evaluate(state, 1.0)
    if converged:
        message = f'converged in {total} Newton iterations, {steps} load step(s)'
    result = StaticResult(state.positions, state.quaternions, state.rotations, state,
                          bool(converged), int(total), float(r_max), int(steps), float(lam),
                          message)
    if strict and not converged:
        raise StaticConvergenceError(result)
    return result
