"""Options and per-tick result of the inverse solver (:mod:`cbha_inverse.core.inverse.solver`)."""

from dataclasses import dataclass
import math
from typing import NamedTuple

from cbha_inverse.core.inverse.qp import QP_SOLVERS
import numpy as np

HELD_STATUSES = ('saturated', 'unreachable', 'not_converged', 'obstacle')
"""Tick statuses in which a bound, the reach, the state's convergence or an obstacle holds the
effector: a
closed loop's integral must not grow on them, or only across the gap the model predicts
(anti-windup, :class:`~cbha_inverse.core.inverse.correction.TargetCorrector`)."""


@dataclass(frozen=True)
class InverseOptions:
    """
    Options of the inverse solver.

    Attributes
    ----------
    energy_weight : float
        ``ε_E`` of the actuation-energy term (unit-free, see
        :mod:`cbha_inverse.core.inverse.qp`).
    proximal_weight : float
        ``ε_P`` of the tick-to-tick smoothing term (unit-free).
    rate_limit : tuple of float or None
        Largest change per tick of each actuator (N or Pa), ``None`` for none.
    qp_solver : str
        One of :data:`~cbha_inverse.core.inverse.qp.QP_SOLVERS`:
        ``'active_set'`` (default: principal pivoting on the active set,
        :class:`cbha_inverse.core.inverse.qp.ActiveSetQP`, compiled with numba), ``'proxsuite'``
        (dense, warm-started) or ``'gauss_seidel'`` (the paper's projected Gauss-Seidel). The
        active set is the default because it returns the exact KKT solution of the box QP and
        costs ~3 µs for ``m ≤ 16`` actuators, against ~30-60 µs for proxsuite's update and
        solve. proxsuite stays available and is the automatic fallback: it takes over (status
        checked) when the active set does not converge.
    newton_steps : int
        Newton steps per tick (1 = the update reuses the tick's factorization).
    max_rotation_step : float  [rad]
        Largest frame rotation increment per Newton step.
    eps_abs : float
        QP tolerance (normalised problem).
    equilibrium_tolerance : float  [m]
        Largest distance of an effector from the model's equilibrium at the current actuation
        for the state to count as an equilibrium. Each linearisation measures that distance to
        first order, ``|J_e K⁻¹ r|`` (the effector move of a Newton step at fixed actuation);
        above the tolerance the tick's status is ``'not_converged'`` and the solver narrows the
        actuation's trust region until the state converges again (:class:`InverseSolver
        <cbha_inverse.core.inverse.solver.InverseSolver>`). ``math.inf`` switches the check off
        (the paper's tick: no trust region, no restoration).
    max_step : float  [-]
        Largest change of each actuator in one tick, as a fraction of its range: the widest
        trust region of the actuation's step. 1 (default, the paper): a tick may move an
        actuator across its whole range when the target jumps. Below 1 no tick moves the arm
        by more than this step can, however far the target jumps (0.1 at 100 Hz: the whole
        range in a tenth of a second); the approach to a far target then takes more ticks.
    unreachable_distance : float  [m]
        Predicted effector gap above which a tick held by an actuator bound reports
        ``'unreachable'`` rather than ``'saturated'``: the QP's optimum within the actuators'
        range leaves the target this far away (``math.inf``: never).
    relinearize_every : int
        Ticks between linearisations. 1 (default) is the paper: tangent, factor,
        ``W`` and a Newton update at every tick. ``N > 1``: a linearisation is kept for up to
        ``N`` ticks and the ticks in between solve the QP of the same linear model (paper
        eq. 11, only ``δ_free`` changes with the target; proxsuite re-solves with the same
        Hessian) and report its predicted effector positions; the next linearisation applies
        the latest actuation to the linearisation state (one Newton step), so the fixed point
        is the same static equilibrium. A linearisation is dropped early when an actuator moves
        by more than 2 % of its range in one tick (large motions relinearise every tick).
    obstacle_margin : float  [m]
        Clearance the obstacle rows keep between the collision spheres and the obstacles
        (``docs/obstacles.md``): each active row asks the sphere's predicted clearance to stay
        at or above it.
    obstacle_activation : float  [m]
        A (sphere, obstacle) pair whose clearance at the linearisation is below
        ``obstacle_margin`` plus this adds a row to the tick's QP; farther pairs add none.
    obstacle_weight : float  [-]
        ``ρ`` of the rows' slack: a metre by which a row cannot hold costs ``ρ`` times a metre of
        tracking gap (:class:`cbha_inverse.core.inverse.qp.RowsQP`).

    """

    energy_weight: float = 1e-6
    proximal_weight: float = 1e-4
    rate_limit: tuple = None
    qp_solver: str = 'active_set'
    newton_steps: int = 1
    max_rotation_step: float = 0.5
    eps_abs: float = 1e-10
    relinearize_every: int = 1
    equilibrium_tolerance: float = 2e-4
    max_step: float = 1.0
    unreachable_distance: float = 1e-3
    obstacle_margin: float = 0.002
    obstacle_activation: float = 0.02
    obstacle_weight: float = 1e6

    def __post_init__(self):
        """Validate."""
        if self.qp_solver not in QP_SOLVERS:
            raise ValueError(f'qp_solver must be one of {", ".join(QP_SOLVERS)}, '
                             f'not {self.qp_solver!r}')
        if self.newton_steps < 1:
            raise ValueError('newton_steps must be >= 1')
        if self.relinearize_every < 1:
            raise ValueError('relinearize_every must be >= 1')
        if not (isinstance(self.max_step, (int, float)) and 0.0 < self.max_step <= 1.0):
            raise ValueError('max_step must lie in (0, 1] (a fraction of each actuator range), '
                             f'got {self.max_step!r}')
        for name in ('obstacle_margin', 'obstacle_activation'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0.0 <= value < math.inf):
                raise ValueError(f'{name} must be a finite distance >= 0 [m], got {value!r}')
        if not (isinstance(self.obstacle_weight, (int, float))
                and 0.0 < self.obstacle_weight < math.inf):
            raise ValueError(f'obstacle_weight must be finite and > 0, got '
                             f'{self.obstacle_weight!r}')
        for name in ('equilibrium_tolerance', 'unreachable_distance'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and value > 0.0):
                raise ValueError(f'{name} must be a positive distance [m] (inf: no check), '
                                 f'got {value!r}')


class TickResult(NamedTuple):
    """
    Result of one control tick (immutable).

    A named tuple: built every tick, several times cheaper than a frozen dataclass.

    Attributes
    ----------
    actuation : (m,) ndarray  [N or Pa]
        Commanded actuation, always finite and within the bounds.
    effector_positions : (k, 3) ndarray  [m]
        Effector positions of the updated model state (between linearisations, with
        ``relinearize_every > 1``: the linear model's prediction).
    status : str
        ``'solved'`` (QP solved, no bound limits the tracking), ``'saturated'`` (QP solved, some
        actuator is held by a bound the target pushes against: closest reachable point),
        ``'unreachable'`` (saturated, and the predicted gap exceeds
        :attr:`InverseOptions.unreachable_distance`: the target is outside what the actuators
        reach; ``predicted_error`` is the distance), ``'not_converged'`` (the state the tick
        linearised at is not an equilibrium of the model within
        :attr:`InverseOptions.equilibrium_tolerance`: ``equilibrium_gap`` is the distance; the
        actuation's step is narrowed until it converges),
        ``'obstacle'`` (some obstacle row cannot hold: the QP's slack lets a collision sphere
        come closer than ``obstacle_margin`` by more than
        :data:`~cbha_inverse.core.inverse.obstacle_rows.VIOLATION_TOLERANCE`;
        ``obstacle_violation`` is how much), ``'qp_fallback'`` (proxsuite failed, the
        Gauss-Seidel solution is used),
        ``'not_positive_definite'`` (tangent not SPD: actuation held, state unchanged) or
        ``'rejected'`` (non-finite target or non-finite QP solution: actuation held, state
        unchanged).
    qp_status : str
        The QP solver's own status.
    qp_iterations : int
        QP iterations.
    saturated : (m,) ndarray of bool
        Actuators held by a bound.
    predicted_error : float  [m]
        ``‖W_ea λ + δ_e^free‖`` of the linearised model (largest effector gap).
    residual_norm : float  [N, N*m]
        Norm of the equilibrium residual at the last linearisation (before its update).
    timings : dict
        Seconds spent in ``assembly`` (the whole linearisation, steps 1-2 of
        :class:`~cbha_inverse.core.inverse.solver.InverseSolver`; 0 on a tick on a prepared or
        kept linearisation), ``qp`` (the QP, its outcome and, with the active set, the Newton
        step and the effector positions), ``update`` (further Newton steps, a check of the new
        state, the result) and ``total``; ``factor`` and ``projection`` are 0 (they run inside
        the linearisation).
    warnings : tuple of str
        What the user should know about this tick (a clamped or rejected target, a held
        non-finite QP solution); a node logs them.
    equilibrium_gap : float  [m]
        Distance of the effectors from the model's equilibrium at the linearisation the tick
        solved on, ``max_k |(J_e K⁻¹ r)_k|`` (NaN for a held tick).
    predicted_orientation_error : float  [rad]
        The largest predicted orientation gap of the ``axis`` and ``pose`` effectors (the norm
        of each one's rotational rows of ``W_ea λ + δ_e^free``, ``docs/effectors.md``); NaN
        without them or for a held tick. ``predicted_error`` is the position gap; a saturated
        tick reads ``'unreachable'`` when either, the orientation gap times the effector's
        ``orientation_length``, exceeds :attr:`InverseOptions.unreachable_distance`.
    obstacle_rows : int
        Obstacle rows in the tick's QP (``docs/obstacles.md``).
    obstacle_violation : float  [m]
        With rows: the largest predicted clearance below ``obstacle_margin`` (0 when every row
        holds); NaN without rows. A saturated or solved tick whose rows bind while its predicted
        gap exceeds :attr:`InverseOptions.unreachable_distance` reads ``'unreachable'``.
    touch_forces : (k,) ndarray or None  [N]
        With contact targets (``docs/touch.md``): the contact force the tick's linear model
        predicts for each touching effector, ``max(0, d(λ)) / c``; NaN for the others. None
        without contact targets.
    touch_violation : float  [N]
        With contact targets: how far the predicted force lies outside its bounds at worst (0
        within them); a solved or saturated tick whose force bounds cannot hold reads
        ``'unreachable'``, a warning says why. NaN without.

    """

    actuation: np.ndarray
    effector_positions: np.ndarray
    status: str
    qp_status: str
    qp_iterations: int
    saturated: np.ndarray
    predicted_error: float
    residual_norm: float
    timings: dict
    warnings: tuple = ()
    equilibrium_gap: float = math.nan
    predicted_orientation_error: float = math.nan
    obstacle_rows: int = 0
    obstacle_violation: float = math.nan
    touch_forces: np.ndarray = None
    touch_violation: float = math.nan
