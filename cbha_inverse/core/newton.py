"""
The one Newton engine for the quasi-static equilibrium of a frame chain (paper eq. 9, DESIGN §3).

Behind :func:`cbha_inverse.core.statics.solve_static`, the scenes' forward model
(:func:`cbha_inverse.core.equilibrium.solve_equilibrium`) and the simulated plant
(:class:`cbha_inverse.core.plant.StaticPlant`). It solves, for the poses of frames 1..n,

    r(q) = f(q) + lam (f_dead + f_load(q)) = 0

with ``f`` the internal wrenches (:func:`cbha_inverse.core.assembly.internal_wrenches`),
``f_dead`` constant world wrenches (tip, frame wrenches, gravity), ``f_load(q)`` configuration-
dependent (follower) wrenches such as cables and pressure (``J_a(q)ᵀ λ``) and ``lam`` the load
factor:

- Newton increments ``dq = T⁻¹ r`` (world axes, as for :func:`cbha_inverse.core.chain.retract`)
  with ``T = K + lam L``: ``K = -d f / dq`` the exact, non-symmetric structural tangent (material
  + geometric part, :mod:`cbha_inverse.core.links`) and ``L = -d f_load / dq`` the load
  stiffness, given by an optional ``load_tangent(state) -> (6n, 6n)`` (frames 1..n, world-axis
  increments, at the full load; :func:`cbha_inverse.core.equilibrium.actuator_loads` builds it
  from a scene's actuators). Without it the follower loads are not differentiated: Newton then
  converges linearly at best, and stalls when a tendon-compressed chain looks unstable to the
  structural tangent alone;
- linear solves by LU: dense up to ``_DENSE_MAX_LINKS`` links (faster there), LAPACK banded LU
  for longer chains (11 sub- and super-diagonals without ``L``; with ``L`` the bandwidth of the
  nonzeros, e.g. cables routed over neighbouring vertebrae), O(n). If the tangent is singular,
  the step is not finite or the line search rejects it, the iteration falls back to the
  material tangent (:func:`material_tangent`, SPD whatever the stresses, BTD Cholesky):
  a modified-Newton step, robust where ``T`` is indefinite or singular (a chain near a limit
  point, high pressure);
- the increment is applied in the chain's deformation coordinates (:func:`_relative_update`):
  full Newton steps stay acceptable at large rotations of slender chains (the PL^2/EI = 10
  elastica converges from rest in one load step of 7 iterations);
- backtracking line search on the Euclidean norm of the scaled residual (Armijo, factor 1/2),
  optionally starting from a step shortened so that no link turns by more than
  ``max_rotation_step``;
- load stepping (:func:`solve_chain`): a warm start (``initial_state``) is tried at the full
  load first; otherwise or if it fails, the full load from the rest shape; a load step that fails
  (no convergence within ``max_iterations`` or a failed line search) is halved, successful steps
  double the increment.

Convergence test (``residual_norm`` reports the left-hand side), by default relative. Forces
and moments are compared in one unit: ``r_scaled`` is the residual with moments divided by the
chain length L_c (so both parts are in N), and the force and moment parts of the applied loads
and of the internal wrenches give one ``load_scale`` (the largest scaled component of either),
so a pure moment load judges the force residual against it and vice versa. A state converges:

1. if every component is finite and ``max |r_scaled| <= tolerance * load_scale``; or
2. (round-off limited) if every frame's residual is within ``tolerance * load_scale + floor_i``
   and the Newton correction from that state moves no frame by more than
   ``_ROUNDOFF_STEP * x_ref`` (1e-8) nor turns one by more than ``_ROUNDOFF_STEP`` rad: the
   correction is applied (unless it is below ``1000 eps``, i.e. noise) and the corrected state
   is returned. ``floor_i`` is the round-off level of the internal wrench at frame i,
   ``64 eps max(|K_tt| x_ref + |K_tr|, (|K_rt| x_ref + |K_rr|) / L_c)`` over the (at most two)
   links meeting at frame i, with ``x_ref = L_c + |base position|`` (max-abs entries of their
   stiffness blocks). A near-rigid link (compliance / 1e9) has forces
   that no double-precision state resolves below its floor, so its frames can only converge
   this way; the floor of one stiff link never lets the residual of other frames pass, and the
   rest state under a small load never passes (its correction is the deflection). The result
   then carries a warning when the residual exceeds ``_ROUNDOFF_WARNING`` (1e-4) of the
   applied load.

A non-finite residual never converges. With ``absolute_tolerance`` the test is instead
``|r|_2 <= absolute_tolerance`` (unscaled Euclidean norm in N and N*m, the plant's contract).

Warnings (:attr:`NewtonResult.warnings`, checked at the returned state): round-off limited
convergence (above), a tangent that is not positive definite at the equilibrium (an unstable
equilibrium, e.g. the straight shape under a compression above the buckling load:
:func:`_stability_warnings`) and links strained beyond the small-strain range of their
compliance: an axial deformation above ``STRAIN_LIMIT`` (10 %) of the rest length, or a
rotation above ``ROTATION_LIMIT`` (0.5 rad) within one link. The links are linear elastic in
their corotated frame; beyond those limits refine the chain (more, shorter links).
"""

from dataclasses import dataclass

from cbha_inverse.core import btd
from cbha_inverse.core.assembly import (assemble_tangent, blocks_to_dense, chain_terms,
                                        internal_wrenches, material_tangent)
from cbha_inverse.core.chain import ChainState, checked_array, rest_state
from cbha_inverse.core.se3 import so3_exp
import numpy as np
from scipy.linalg import solve_banded

_ARMIJO = 1e-4
_MAX_HALVINGS = 6
_MIN_LOAD_INCREMENT = 1.0 / 2 ** 20
# round-off limited convergence: a Newton correction below sqrt(eps) of the chain's size is
# applied and ends the iteration; one below 1000 eps is noise and is not even applied
_ROUNDOFF_STEP = 1e-8
_ROUNDOFF_NOISE = 1e3 * np.finfo(float).eps
# a round-off limited residual above this fraction of the applied load gives a warning
_ROUNDOFF_WARNING = 1e-4
#: largest axial link deformation, as a fraction of the rest length, before a warning
STRAIN_LIMIT = 0.1
#: largest rotation within one link [rad] before a warning
ROTATION_LIMIT = 0.5
# dense LU of (6n)^2 beats the banded one (which builds its band storage in Python) up to ~20
# links (single-threaded BLAS: 96 vs 132 us at 16 links, 183 vs 154 us at 24)
_DENSE_MAX_LINKS = 20
_BLOCK_ROWS, _BLOCK_COLS = (idx.ravel() for idx in np.indices((6, 6)))


@dataclass(frozen=True, eq=False)
class NewtonResult:
    """
    Result of :func:`solve_chain`.

    Attributes
    ----------
    state : ChainState
        Equilibrium; if not converged, the last equilibrium at ``load_factor`` < 1, or (when no
        load step succeeded after a warm start) the warm start's last iterate.
    converged : bool
        True only if the full load was reached and the convergence test passed.
    iterations : int
        Total Newton iterations over all load steps.
    residual_norm : float  [N]
        Convergence measure (see the module docstring) of ``state`` under the full load.
    residual : (n, 6) ndarray  [N, N*m]
        The residual ``r`` of ``state`` under the full load.
    load_steps : int
        Load steps attempted (successful and failed; a warm start counts as one).
    load_factor : float
        Fraction of the load in equilibrium at ``state`` (1.0 when converged).
    message : str
        What happened, in words.
    warnings : tuple of str
        What the user should know about the returned state (module docstring): round-off
        limited residual, unstable equilibrium, strain beyond the links' range.

    """

    state: ChainState
    converged: bool
    iterations: int
    residual_norm: float
    residual: np.ndarray
    load_steps: int
    load_factor: float
    message: str
    warnings: tuple = ()


def _residual_floor(model, length):
    """
    Round-off level of the scaled internal wrench at each of frames 1..n (module docstring).

    Returns
    -------
    (n,) ndarray  [N]

    """
    k = np.abs(model.stiffnesses)
    k_tt = k[:, :3, :3].max(axis=(1, 2))
    k_tr = np.maximum(k[:, :3, 3:].max(axis=(1, 2)), k[:, 3:, :3].max(axis=(1, 2)))
    k_rr = k[:, 3:, 3:].max(axis=(1, 2))
    x_ref = length + float(np.linalg.norm(model.base_position))
    per_link = 64.0 * np.finfo(float).eps * np.maximum(k_tt * x_ref + k_tr,
                                                       (k_tr * x_ref + k_rr) / length)
    # frame j (1..n) is the end of link j - 1 and the start of link j
    per_frame = per_link.copy()
    per_frame[:-1] = np.maximum(per_frame[:-1], per_link[1:])
    return per_frame


def _scaled(wrenches, length):
    """Return wrenches with moments divided by the characteristic length."""
    out = wrenches.copy()
    out[:, 3:] /= length
    return out


def _banded_solve(diagonal, upper, residual):
    """
    Solve the block-tridiagonal system ``T dq = r`` (lower blocks = ``upper`` transposed).

    LAPACK banded LU (``dgbsv``, 11 sub- and super-diagonals); O(n) and level-2 BLAS only.
    """
    n = diagonal.shape[0]
    ab = np.zeros((23, 6 * n))
    # general band storage ab[11 + i - j, j] = A[i, j], filled from the three block diagonals
    for blocks, shift in ((diagonal, 0), (upper, 1), (np.swapaxes(upper, 1, 2), -1)):
        k = np.arange(blocks.shape[0])[:, None]
        i = 6 * (k + max(-shift, 0)) + _BLOCK_ROWS
        j = 6 * (k + max(shift, 0)) + _BLOCK_COLS
        ab[11 + i - j, j] = blocks.reshape(-1, 36)
    return solve_banded((11, 11), ab, residual.ravel(), check_finite=False)


def _dense_banded_solve(matrix, residual):
    """Solve ``T dq = r`` by banded LU with the bandwidth of ``T``'s nonzeros (long chains)."""
    rows, cols = np.nonzero(matrix)
    lower, upper = int(max(0, (rows - cols).max())), int(max(0, (cols - rows).max()))
    if 4 * (lower + upper) > matrix.shape[0]:
        return np.linalg.solve(matrix, residual.ravel())
    ab = np.zeros((lower + upper + 1, matrix.shape[0]))
    ab[upper + rows - cols, cols] = matrix[rows, cols]
    return solve_banded((lower, upper), ab, residual.ravel(), check_finite=False)


class _Problem:
    """One static problem: model, loads, convergence test and the tangent solves."""

    def __init__(self, model, external, load_function, load_tangent, tolerance,
                 absolute_tolerance, max_rotation_step):
        self.model = model
        self.external = external
        self.load_function = load_function
        self.load_tangent = load_tangent
        self.tolerance = float(tolerance)
        self.absolute = None if absolute_tolerance is None else float(absolute_tolerance)
        self.max_rotation_step = max_rotation_step
        self.length = model.length if model.length > 0.0 else 1.0
        self.floor = _residual_floor(model, self.length)
        self.x_ref = self.length + float(np.linalg.norm(model.base_position))

    def loads(self, state, lam):
        """Return the applied wrenches (n, 6) at load factor ``lam``."""
        loads = self.external
        if self.load_function is not None:
            extra = np.asarray(self.load_function(state), dtype=float)
            if extra.shape != self.external.shape:
                raise ValueError(f'load_function must return shape {self.external.shape}')
            loads = loads + extra
        return lam * loads

    def evaluate(self, state, lam, internal=None):
        """
        Return (residual, convergence measure, scaled 2-norm, converged, within round-off).

        ``converged`` is test 1 of the module docstring; ``within round-off`` is the residual
        part of test 2 (the caller checks the Newton correction).
        """
        if internal is None:
            internal = internal_wrenches(self.model, state)
        loads = self.loads(state, lam)
        res = internal + loads
        scaled = _scaled(res, self.length)
        if not np.all(np.isfinite(scaled)):
            return res, float('inf'), float('inf'), False, False
        if self.absolute is not None:
            measure = float(np.linalg.norm(res))
            return res, measure, float(np.linalg.norm(scaled)), measure <= self.absolute, False
        # the line search's merit: the part of the residual above each frame's round-off floor
        r_two = float(np.linalg.norm(np.maximum(np.abs(scaled) - self.floor[:, None], 0.0)))
        scale = self.load_scale(loads, internal)
        per_frame = np.abs(scaled).max(axis=1)
        measure = float(per_frame.max())
        bound = self.tolerance * scale
        return (res, measure, r_two, measure <= bound,
                bool(np.all(per_frame <= bound + self.floor)))

    def load_scale(self, loads, internal):
        """Return the largest scaled component of the applied and internal wrenches [N]."""
        return max(np.abs(_scaled(loads, self.length)).max(),
                   np.abs(_scaled(internal, self.length)).max())

    def roundoff_step(self, step, relative):
        """Return whether a Newton correction (n, 6) is below ``relative`` (module docstring)."""
        return bool(np.abs(step[:, :3]).max() <= relative * self.x_ref
                    and np.abs(step[:, 3:]).max() <= relative)

    def exact_step(self, state, terms, lam, res):
        """Newton step with the exact tangent ``K + lam L`` (LU)."""
        tangent = assemble_tangent(self.model, state, terms)
        load = None if self.load_tangent is None or lam == 0.0 else self.load_tangent(state)
        if load is None and self.model.n_links > _DENSE_MAX_LINKS:
            step = _banded_solve(tangent.exact_diagonal, tangent.upper, res)
        else:
            matrix = blocks_to_dense(tangent.exact_diagonal, tangent.upper)
            if load is not None:
                matrix += lam * np.asarray(load, dtype=float)
            if self.model.n_links > _DENSE_MAX_LINKS:
                step = _dense_banded_solve(matrix, res)
            else:
                step = np.linalg.solve(matrix, res.ravel())
        if not np.all(np.isfinite(step)):
            raise np.linalg.LinAlgError('singular tangent (non-finite Newton step)')
        return step.reshape(-1, 6)

    def material_step(self, state, terms, lam, res):
        """Modified-Newton step with the material tangent (SPD, BTD Cholesky): the fallback."""
        diagonal, upper = material_tangent(self.model, state, terms)
        step = btd.factorize(diagonal, upper).solve(res.ravel())
        if not np.all(np.isfinite(step)):
            raise np.linalg.LinAlgError('non-finite material step')
        return step.reshape(-1, 6)

    def first_alpha(self, link_rotation):
        """Return the first line-search step: no link turns by more than the limit."""
        limit = self.max_rotation_step
        if limit is None or link_rotation <= limit:
            return 1.0
        return limit / link_rotation


def _relative_update(model, state, step, terms):
    """
    Map world increments of frames 1..n to link-deformation increments and a pose generator.

    Returns ``poses(alpha) -> ChainState`` and the largest link rotation increment [rad].

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

    rel_count = step.shape[0]

    def poses(alpha):
        rots = np.empty_like(rot)
        rots[0] = rot[0]
        rots[1:] = so3_exp(terms.phi + alpha * dphi) @ model.rest_rotations
        rots[1] = rot[0] @ rots[1]
        # R_{i+1} = R_i rel_i for all i: ordered prefix products in log2(n) batched steps
        shift = 1
        while shift < rel_count:
            rots[shift + 1:] = rots[1:-shift] @ rots[shift + 1:]
            shift *= 2
        arms = (rots[:-1] @ (terms.offset + alpha * du)[..., None])[..., 0]
        new_pos = np.empty_like(pos)
        new_pos[0] = pos[0]
        new_pos[1:] = pos[0] + np.cumsum(arms, axis=0)
        return ChainState(new_pos, rots)

    return poses, float(np.sqrt(np.max(np.einsum('ij,ij->i', dphi, dphi))))


def _point(problem, state, lam, terms=None):
    """
    Evaluate a state.

    Returns ``(state, link terms, residual, measure, scaled 2-norm, converged, within
    round-off)`` (see :meth:`_Problem.evaluate`).
    """
    if terms is None:
        terms = chain_terms(problem.model, state)
    internal = internal_wrenches(problem.model, state, terms)
    return (state, terms) + problem.evaluate(state, lam, internal)


def _line_search(problem, point, lam, step):
    """
    Backtrack along the Newton step (in deformation coordinates) on the residual norm.

    Armijo test on the Euclidean norm of the scaled residual above the round-off floor of each
    frame (module docstring; the plain scaled norm with an absolute tolerance),
    ``|r(a)| <= (1 - 1e-4 a) |r(0)|``,
    halving ``a`` at most ``_MAX_HALVINGS`` times; returns the accepted point (see
    :func:`_point`), or None (the caller then tries the fallback direction or cuts the load step,
    which is cheaper than creeping along a poor direction).
    """
    state, terms, _, _, r_two, _, _ = point
    poses, link_rotation = _relative_update(problem.model, state, step, terms)
    alpha = problem.first_alpha(link_rotation)
    for _ in range(_MAX_HALVINGS):
        trial = _point(problem, poses(alpha), lam)
        if trial[5] or trial[4] <= (1.0 - _ARMIJO * alpha) * r_two:
            return trial
        alpha *= 0.5
    return None


def _newton(problem, state, lam, max_iterations):
    """Newton iterations at a fixed load factor; returns (ok, last point, iterations, why)."""
    point = _point(problem, state, lam)
    iterations = 0
    while True:
        state, terms, res, measure, _, ok, roundoff = point
        if ok:
            return True, point, iterations, 'converged'
        if not np.isfinite(measure):
            return False, point, iterations, 'non-finite residual'
        exhausted = iterations >= max_iterations
        if exhausted and not roundoff:
            return False, point, iterations, 'iteration budget exhausted'
        accepted, why = None, ''
        for direction in (problem.exact_step, problem.material_step):
            try:
                step = direction(state, terms, lam, res)
            except np.linalg.LinAlgError as exc:
                why = str(exc) or 'singular tangent'
                continue
            if roundoff and problem.roundoff_step(step, _ROUNDOFF_NOISE):
                # the correction is noise itself (e.g. the rest shape under no load)
                return True, point, iterations, 'converged (round-off limited)'
            if roundoff and problem.roundoff_step(step, _ROUNDOFF_STEP):
                corrected = _point(problem, _relative_update(problem.model, state, step,
                                                             terms)[0](1.0), lam)
                if corrected[5] or corrected[6]:
                    return True, corrected, iterations + 1, 'converged (round-off limited)'
            if exhausted:
                return False, point, iterations, 'iteration budget exhausted'
            accepted = _line_search(problem, point, lam, step)
            if accepted is not None:
                break
            why = 'line search failed'
        iterations += 1
        if accepted is None:
            return False, point, iterations, why
        point = accepted


def solve_chain(model, external=None, *, load_function=None, load_tangent=None,
                initial_state=None, tolerance=1e-10, absolute_tolerance=None, max_iterations=50,
                max_load_steps=64, max_rotation_step=None, check_warnings=True):
    """
    Solve ``f(q) + f_dead + f_load(q) = 0`` for the frames of a chain (paper eq. 9).

    Parameters
    ----------
    model : ChainModel
        The chain; frame 0 is fixed.
    external : (n, 6) array_like, optional  [N, N*m]
        Dead wrenches on frames 1..n (world axes, at the frame origins).
    load_function : callable, optional
        ``load_function(state) -> (n, 6)`` follower wrenches (world axes, frames 1..n) at the
        full load, e.g. ``J_a(q)ᵀ λ``.
    load_tangent : callable, optional
        ``load_tangent(state) -> (6n, 6n)`` ndarray (or None): the load stiffness
        ``-d load_function / dq`` (world-axis increments of frames 1..n, as ``retract``) at the
        full load; the engine scales it by the load factor. The exact (non-symmetric) derivative
        gives quadratic convergence; its symmetric part still converges.
    initial_state : ChainState, optional
        Warm start: Newton on the full load from it first; if that fails, load stepping from
        the rest shape (the default start).
    tolerance : float
        Relative tolerance of the default convergence test (module docstring).
    absolute_tolerance : float, optional  [N, N*m]
        Use ``|r|_2 <= absolute_tolerance`` instead.
    max_iterations : int
        Newton iterations allowed per load step (and for the warm start).
    max_load_steps : int
        Load steps allowed (attempts, successful or not; the warm start counts as one).
    max_rotation_step : float, optional  [rad]
        Largest link rotation of a line search's first trial step.
    check_warnings : bool
        Check the converged state for the warnings of the module docstring (one more tangent
        and factorization; a plant updated at every tick turns it off).

    Returns
    -------
    NewtonResult
        ``converged`` False with a message when the full load was not reached.

    """
    n = model.n_links
    external = (np.zeros((n, 6)) if external is None
                else checked_array(external, (n, 6), 'external wrenches'))
    problem = _Problem(model, external, load_function, load_tangent, tolerance,
                       absolute_tolerance, max_rotation_step)
    lam, increment, steps, total, message = 0.0, 1.0, 0, 0, ''
    state, warm, final = None, None, None
    if initial_state is not None:
        checked_array(initial_state.positions, (model.n_frames, 3), 'initial_state.positions')
        checked_array(initial_state.rotations, (model.n_frames, 3, 3), 'initial_state.rotations')
        steps = 1
        ok, point, total, why = _newton(problem, initial_state, 1.0, max_iterations)
        if ok:
            state, lam, final = point[0], 1.0, point
        else:
            message, warm = f'warm start failed: {why}', point[0]
    if state is None:
        state = rest_state(model)
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
        ok, point, its, why = _newton(problem, state, target, max_iterations)
        total += its
        if ok:
            state, lam, final = point[0], target, point
            increment = min(2.0 * increment, 1.0)
        else:
            increment *= 0.5
            message = f'last failure at load factor {target:.6g}: {why}'
    converged = lam >= 1.0
    if converged:
        message = f'converged in {total} Newton iterations, {steps} load step(s)'
    else:
        if lam == 0.0 and warm is not None:
            state = warm  # no equilibrium reached: the warm iterate is the better place to resume
        final = _point(problem, state, 1.0)
    warnings = _result_warnings(problem, final) if converged and check_warnings else ()
    return NewtonResult(state, bool(converged), int(total), float(final[3]), final[2],
                        int(steps), float(lam), message, warnings)


def _result_warnings(problem, point):
    """
    Return the warnings (tuple of str) about a converged point (module docstring).

    Parameters
    ----------
    problem : _Problem
        The problem solved.
    point : tuple
        From :func:`_point` at the full load.

    Returns
    -------
    tuple of str

    """
    state, terms, _, measure = point[:4]
    warnings = []
    if problem.absolute is None:
        loads = problem.loads(state, 1.0)
        applied = np.abs(_scaled(loads, problem.length)).max()
        if applied > 0.0 and measure > problem.tolerance * problem.load_scale(
                loads, point[2] - loads) and measure > _ROUNDOFF_WARNING * applied:
            worst = int(np.argmax(np.abs(_scaled(point[2], problem.length)).max(axis=1))) + 1
            warnings.append(
                f'residual {measure:.3g} N is limited by round-off at frame {worst} '
                f'({measure / max(applied, np.finfo(float).tiny):.2g} of the applied load): '
                'its links are too stiff relative to the load to resolve their forces in double '
                'precision (stiffness ratio too large; merge the stiff link into its neighbour)')
    warnings.extend(strain_warnings(problem.model, terms))
    warnings.extend(_stability_warnings(problem, state, terms))
    return tuple(warnings)


def strain_warnings(model, terms):
    """
    Warn about links deformed beyond the small-strain range of their compliance.

    Parameters
    ----------
    model : ChainModel
        The chain.
    terms : LinkTerms
        Link terms at the state (:func:`cbha_inverse.core.assembly.chain_terms`).

    Returns
    -------
    list of str
        Empty when every link's axial deformation (along its rest offset) is below
        ``STRAIN_LIMIT`` of its rest length and its rotation below ``ROTATION_LIMIT``.

    """
    rest = np.linalg.norm(model.rest_offsets, axis=1)
    safe = np.where(rest > 0.0, rest, 1.0)
    # axial: the transverse part of the offset change is mostly the chord turning with bending,
    # which the rotation limit covers
    strain = np.abs(np.einsum('ij,ij->i', terms.offset, model.rest_offsets) / safe - rest) / safe
    strain[rest == 0.0] = 0.0
    rotation = np.linalg.norm(terms.phi, axis=1)
    out = []
    worst = int(np.argmax(strain))
    if strain[worst] > STRAIN_LIMIT:
        out.append(f'link {worst} is strained axially by {strain[worst]:.3g} of its rest '
                   f'length (small-strain limit {STRAIN_LIMIT:g}): its linear compliance is not '
                   'accurate there')
    worst = int(np.argmax(rotation))
    if rotation[worst] > ROTATION_LIMIT:
        out.append(f'link {worst} turns by {rotation[worst]:.3g} rad within one link (limit '
                   f'{ROTATION_LIMIT:g} rad): use more, shorter links')
    return out


def _stability_warnings(problem, state, terms):
    """
    Warn when the tangent at an equilibrium is not positive definite (possibly unstable).

    The symmetric part of the exact tangent ``K + L`` (structure and load stiffness) is
    factorised by BTD Cholesky (structure alone) or dense Cholesky (with a load stiffness); a
    failure means a direction of decreasing stiffness. Under dead forces the equilibrium is then
    unstable (e.g. the straight shape above the buckling load); under moments or follower loads,
    which are not conservative in 3D, it is a warning sign rather than a proof.

    Returns
    -------
    list of str

    """
    tangent = assemble_tangent(problem.model, state, terms)
    load = None if problem.load_tangent is None else problem.load_tangent(state)
    try:
        if load is None:
            btd.factorize(tangent.diagonal, tangent.upper)
        else:
            matrix = tangent.to_dense() + np.asarray(load, dtype=float)
            np.linalg.cholesky(0.5 * (matrix + matrix.T))
    except (np.linalg.LinAlgError, ValueError):
        return ['the tangent stiffness is not positive definite at this equilibrium: it may be '
                'unstable (a compression above the buckling load, lateral buckling under a large '
                'end moment, a snap-through) and the structure need not take the returned shape']
    return []
