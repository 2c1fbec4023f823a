"""
The shape estimator: the equilibrium that reproduces the string-potentiometer lengths.

The pots are effectors in length space (``docs/proprioception.md``): at the current estimate of
the frames ``q``, the effective actuation ``λ`` and, optionally, an unknown payload ``μ`` (a mass
at the last frame, its weight along gravity), one linearisation of the equilibrium (paper eq. 9,
the control tick's :class:`~cbha_inverse.core.system.EquilibriumSystem`) gives ``K``, ``r`` and
``J_aᵀ``; with the pots' ``J_s`` (:class:`~cbha_inverse.core.sensors.StringPots`) the lengths
after the Newton step ``dq = K⁻¹ (r + J_aᵀ Δλ + J_μᵀ Δμ)`` are ``ℓ0 + J_s K⁻¹ r + W_sx Δx``
with ``W_sx = J_s K⁻¹ [J_aᵀ, J_μᵀ]`` (``W_sa = J_s K⁻¹ J_aᵀ``, the pots' ``W_ea``). One update
is a Kalman step on ``x = (λ, μ)``, a random walk (the compiled
:func:`cbha_inverse.core._kernels.estimation.length_update`): the previous estimate (its
covariance grown by the walk) and the measured pressures (``λ`` measured with ``pressure_std``,
which also covers the model's error in effective area) are the prior, the pot lengths
(``noise_std`` each) the measurements; the regularised least-squares solution is exact (7 x 7
for the CBHA with a payload). The state then takes the Newton step of the same factorisation
(the control tick's ``apply_linear_step``), so repeated updates converge to the equilibrium of
the estimate.

Bad input (wrong length, non-finite or out-of-range readings or pressures) is rejected with a
reason and changes nothing; a pot whose innovation is ``outlier_sigma`` standard deviations off,
or that is stuck (:class:`cbha_inverse.estimate.checks.StuckDetector`), is dropped from the fit
and the estimate is ``degraded``; ``rank`` says how many directions the remaining pots determine.
"""

from dataclasses import dataclass
import math
import time
from typing import NamedTuple

from cbha_inverse.core._kernels.estimation import length_update
from cbha_inverse.core._kernels.projection import project_effectors
from cbha_inverse.core._kernels.retraction import apply_linear_step
from cbha_inverse.core.chain import ChainState, external_wrenches, rest_state
from cbha_inverse.core.system import EquilibriumSystem
from cbha_inverse.estimate.checks import check_vector, StuckDetector
import numpy as np

# scale of the unknowns inside the least squares: 1 bar of actuation, 0.1 kg of payload
_PRESSURE_SCALE = 1.0e5
_MASS_SCALE = 0.1


@dataclass(frozen=True)
class EstimatorOptions:
    """
    Options of :class:`ShapeEstimator` (SI units).

    Attributes
    ----------
    pressure_std : float  [Pa]
        Standard deviation of the effective actuation about the measured pressure (sensor noise
        and the model's error in effective area together).
    actuation_walk_std : float  [Pa]
        Random walk of the effective actuation per update (its prior when no pressure is
        measured).
    initial_actuation_std : float  [Pa]
        Prior standard deviation of the first estimate, and the random walk of an update after
        one that was not settled.
    settle_sigma : float
        An update is settled when every pot used is within this many standard deviations of
        its prediction; only then is the outlier test applied and the walk the small one.
    payload_std : float or None  [kg]
        Prior standard deviation of an unknown mass at the last frame (a payload, its weight
        along the scene's gravity); None: no such unknown.
    payload_walk_std : float  [kg]
        Random walk of the payload per update.
    outlier_sigma : float
        A pot whose innovation exceeds this many standard deviations is dropped for the update.
    stuck_window : int
        Updates over which a stuck pot is looked for (0: never).
    stuck_tolerance : float  [m]
        A pot that moved less than this over the window is stuck ...
    motion_threshold : float  [m]
        ... while the median of the others moved more than this.
    length_range : (float, float)
        Accepted lengths, as factors of each pot's rest length.
    max_pressure : float  [Pa]
        Measured pressures above this (or below ``-max_pressure``) are rejected.
    gain_learning : float
        Step of the learnt ratio of effective to measured actuation (0: not learnt).
    gain_pressure : float  [Pa]
        Pressures below this weigh less in that ratio.
    iterations : int
        Newton steps per update (1 in a loop; more to settle from far away).
    max_rotation_step : float  [rad]
        Largest frame rotation of one step (the control tick's limit).

    """

    pressure_std: float = 1.0e4
    actuation_walk_std: float = 20000.0
    initial_actuation_std: float = 5.0e4
    settle_sigma: float = 4.0
    payload_std: float = None
    payload_walk_std: float = 1.0e-4
    outlier_sigma: float = 8.0
    stuck_window: int = 25
    stuck_tolerance: float = 2.0e-5
    motion_threshold: float = 2.0e-3
    length_range: tuple = (0.5, 1.5)
    max_pressure: float = 1.0e6
    gain_learning: float = 0.05
    gain_pressure: float = 2.0e4
    iterations: int = 1
    max_rotation_step: float = 0.2


class ShapeEstimate(NamedTuple):
    """
    One update of :class:`ShapeEstimator`.

    Attributes
    ----------
    status : str
        ``'ok'``, ``'degraded'`` (a pot dropped) or ``'rejected'`` (the input; nothing changed).
    reason : str
        Why it was rejected or degraded (empty when ``'ok'``).
    effector_positions : (k, 3) ndarray  [m]
        The scene's effectors (the tip last) at the estimated equilibrium.
    tip_covariance : (3, 3) ndarray  [m^2]
        Of the last effector, from the posterior of ``x`` (linear).
    lengths : (c,) ndarray  [m]
        Measured pot lengths.
    residuals : (c,) ndarray  [m]
        Measured minus estimated length of every pot (the dropped ones too).
    active : (c,) ndarray of bool
        The pots used.
    rank : int
        Directions of ``x`` the active pots determine (the numerical rank of their whitened
        ``W_sx``).
    actuation : (m,) ndarray  [Pa, N]
        Estimated effective actuation.
    payload : float  [kg]
        Estimated payload at the last frame (0 without that unknown).
    seconds : float
        Time of the update.

    """

    status: str
    reason: str
    effector_positions: np.ndarray
    tip_covariance: np.ndarray
    lengths: np.ndarray
    residuals: np.ndarray
    active: np.ndarray
    rank: int
    actuation: np.ndarray
    payload: float
    seconds: float

    @property
    def degraded(self):
        """Return whether a pot was dropped from the fit."""
        return self.status == 'degraded'

    @property
    def tip(self):
        """Return the last effector's position (3,) [m]."""
        return self.effector_positions[-1]

    @property
    def confidence(self):
        """Return the tip's standard deviation ``sqrt(trace(tip_covariance))`` [m]."""
        return math.sqrt(max(float(np.trace(self.tip_covariance)), 0.0))


class ShapeEstimator:
    """
    The estimator of the module docstring (pure numerics, no ROS).

    Parameters
    ----------
    model : cbha_inverse.core.chain.ChainModel
        The chain.
    actuators : cbha_inverse.core.actuation.actuators.ActuatorSet
        Its actuators (``m``).
    effectors : cbha_inverse.core.actuation.effectors.PointEffectors
        Its effectors (the tip last).
    sensors : cbha_inverse.core.sensors.StringPots
        The pots.
    gravity : (3,) array_like or None  [m/s^2]
        Gravity on the lumped masses.
    options : EstimatorOptions, optional
        The options.

    """

    def __init__(self, model, actuators, effectors, sensors, gravity=None, options=None):
        """Precompute the evaluator and start at rest."""
        self.options = options or EstimatorOptions()
        self.model, self.actuators, self.effectors, self.sensors = (model, actuators, effectors,
                                                                    sensors)
        self._system = EquilibriumSystem(model, actuators,
                                         external_wrenches(model, gravity=gravity).reshape(-1))
        self._m = actuators.n_actuators
        self._n_mass = 0 if self.options.payload_std is None else 1
        if self._n_mass and gravity is None:
            raise ValueError("a payload unknown needs the scene's gravity")
        self._gravity = np.zeros(3) if gravity is None else np.asarray(gravity, dtype=float)
        size = self._system.size
        # columns [r, J_aᵀ, J_fᵀ]: the force acts at the last frame's origin
        self._columns = np.zeros((size, 1 + self._m + self._n_mass))
        if self._n_mass:
            self._columns[size - 6:size - 3, 1 + self._m] = self._gravity
        self._scale = np.concatenate([np.full(self._m, _PRESSURE_SCALE),
                                      np.full(self._n_mass, _MASS_SCALE)])
        walk = [self.options.actuation_walk_std] * self._m + [
            self.options.payload_walk_std] * self._n_mass
        self._walk = (np.asarray(walk) / self._scale) ** 2
        self._settle_walk = self._walk.copy()
        self._settle_walk[:self._m] = (self.options.initial_actuation_std / _PRESSURE_SCALE) ** 2
        self._pressure_weight = (_PRESSURE_SCALE / self.options.pressure_std) ** 2
        self._no_pressure = np.zeros(0)
        self._effector_frames = np.ascontiguousarray(effectors.frames, dtype=np.int64)
        self._effector_offsets = np.ascontiguousarray(effectors.offsets, dtype=float)
        rest = rest_state(model)
        self._rest_lengths = sensors.lengths(rest.positions, rest.rotations).copy()
        self._stuck = StuckDetector(sensors.n_sensors, self.options.stuck_window,
                                    self.options.stuck_tolerance, self.options.motion_threshold)
        self.reset()

    @classmethod
    def from_scene(cls, scene, options=None):
        """
        Build the estimator of a scene with a ``sensors`` block.

        Parameters
        ----------
        scene : cbha_inverse.scene.scene.Scene
            The scene (its ``sensors`` are the pots).
        options : EstimatorOptions, optional
            The estimator's options.

        Returns
        -------
        ShapeEstimator

        Raises
        ------
        ValueError
            If the scene has no sensors.

        """
        if scene.sensors is None:
            raise ValueError(f'scene {scene.name!r} declares no sensors (a `sensors` block)')
        return cls(scene.model, scene.actuators, scene.effectors, scene.sensors,
                   gravity=scene.gravity, options=options)

    def reset(self, state=None, actuation=None):
        """
        Return to rest (or a given state and actuation) with the initial prior.

        Parameters
        ----------
        state : cbha_inverse.core.chain.ChainState, optional
            Start frames (default: the rest shape).
        actuation : (m,) array_like, optional  [Pa, N]
            Start effective actuation (default: zero).

        """
        state = rest_state(self.model) if state is None else state
        self._positions = np.array(state.positions, dtype=float)
        self._rotations = np.array(state.rotations, dtype=float)
        x = np.zeros(self._m + self._n_mass)
        if actuation is not None:
            x[:self._m] = np.asarray(actuation, dtype=float)
        self._x = x
        std = [self.options.initial_actuation_std] * self._m + [
            self.options.payload_std or 0.0] * self._n_mass
        self._covariance = np.diag((np.asarray(std) / self._scale) ** 2)
        self._stuck.reset()
        self._ranks = {}
        self._settled = False
        self.gain_error = np.zeros(self._m)
        self._increment = np.zeros(self._m + self._n_mass)
        self._last_pressures = None
        self._last = None

    def warm_up(self):
        """Update on the rest shape's readings (compiles or loads the kernels), then reset."""
        rest = rest_state(self.model)
        readings = self.sensors.readings(self.sensors.lengths(rest.positions, rest.rotations))
        self.update(readings)
        self.update(readings, np.zeros(self._m))
        self.reset()

    @property
    def state(self):
        """Return a copy of the estimated frames as a ``ChainState``."""
        return ChainState(self._positions.copy(), self._rotations.copy())

    @property
    def last(self):
        """Return the last accepted :class:`ShapeEstimate` (None before the first)."""
        return self._last

    def update(self, readings, pressures=None):
        """
        Run one estimation update.

        Parameters
        ----------
        readings : (c,) array_like  [reading]
            Raw pot readings in the sensors' order.
        pressures : (m,) array_like or None  [Pa]
            Measured pressures in actuator order (None: none measured).

        Returns
        -------
        ShapeEstimate

        """
        started = time.perf_counter()
        c = self.sensors.n_sensors
        readings, reason = check_vector(readings, c, 'readings')
        if reason is None and pressures is not None:
            pressures, reason = check_vector(pressures, self._m, 'pressures',
                                             self.options.max_pressure)
        if reason is None:
            lengths = self.sensors.lengths_of(readings)
            low, high = self.options.length_range
            outside = (lengths < low * self._rest_lengths) | (lengths > high * self._rest_lengths)
            if outside.any():
                names = ', '.join(n for n, o in zip(self.sensors.names, outside) if o)
                reason = f'out_of_range: length of {names} outside the accepted range'
        if reason is not None:
            return self._rejected(reason, started)
        stuck = self._stuck.update(lengths)
        if pressures is not None:
            # the prediction: the effective actuation moves as the measured pressures do
            if self._last_pressures is not None:
                self._increment[:self._m] = ((pressures - self._last_pressures)
                                             * (1.0 + self.gain_error))
            self._last_pressures = pressures
        for _ in range(max(1, self.options.iterations)):
            estimate = self._step(lengths, pressures, stuck)
            if estimate is None:
                return self._rejected('not_positive_definite: no factor of the tangent', started)
            if not (np.all(np.isfinite(estimate.effector_positions))
                    and np.all(np.isfinite(self._x))):
                # never a NaN estimate: start over from rest, the next readings settle it
                self.reset()
                return self._rejected('diverged: non-finite estimate, restarted at rest',
                                      started)
        self._last = estimate._replace(seconds=time.perf_counter() - started)
        return self._last

    def _rejected(self, reason, started):
        """Return a rejected update that keeps the previous estimate."""
        last = self._last
        c = self.sensors.n_sensors
        positions = self.effectors.positions(self._positions, self._rotations)
        return ShapeEstimate(
            'rejected', reason, positions,
            np.full((3, 3), np.nan) if last is None else last.tip_covariance,
            np.full(c, np.nan), np.full(c, np.nan), np.zeros(c, dtype=bool),
            0 if last is None else last.rank, self._x[:self._m].copy(), self._payload(),
            time.perf_counter() - started)

    def _payload(self):
        """Return the estimated payload [kg]."""
        return float(self._x[self._m]) if self._n_mass else 0.0

    def _learn_gain(self, actuation, pressures):
        """
        Follow the ratio of effective to measured actuation while every pot is in the fit.

        A normalised least-mean-squares step on ``λ ≈ (1 + b) p`` (``gain_learning`` per
        update, pressures below ``gain_pressure`` weigh less); the prior of the pressures is
        ``(1 + b) p``, so a dropped pot leaves the gains learned before it.
        """
        rate, floor = self.options.gain_learning, self.options.gain_pressure
        error = actuation - pressures * (1.0 + self.gain_error)
        self.gain_error = np.clip(self.gain_error + rate * error * pressures
                                  / (pressures ** 2 + floor ** 2), -0.5, 0.5)

    def _rank(self, active, w_sz):
        """Return the numerical rank of the active pots' whitened ``W_sz`` (cached per set)."""
        key = active.tobytes()
        if key not in self._ranks:
            whitened = w_sz[active] / self.sensors.noise_std[active, None]
            self._ranks[key] = (int(np.linalg.matrix_rank(
                whitened, tol=1e-9 * max(1.0, np.abs(whitened).max()))) if active.any() else 0)
        return self._ranks[key]

    def _step(self, lengths, pressures, stuck):
        """One linearisation, Kalman update and Newton step; None if nothing factors."""
        m, x_previous = self._m, self._x
        positions, rotations = self._positions, self._rotations
        tangent, rhs = self._system.linearise(positions, rotations, x_previous[:m])
        columns = self._columns
        columns[:, :1 + m] = rhs
        if self._n_mass:
            columns[-6:-3, 0] += x_previous[m] * self._gravity
        factor = self._system.factor(tangent)
        if factor is None:
            factor = next(self._system.fallback_factors(positions, rotations, x_previous[:m],
                                                        evaluated=True), None)
            if factor is None:
                return None
        solved = factor.solve(columns)
        ell0, jacobian = self.sensors.lengths_and_jacobian(positions, rotations)
        measured = (self._no_pressure if pressures is None
                    else pressures * (1.0 + self.gain_error) / _PRESSURE_SCALE)
        z, covariance, predicted, ratio, active, w_sz = length_update(
            jacobian @ solved, ell0, lengths, self.sensors.noise_std, self._scale,
            x_previous / self._scale, (x_previous + self._increment) / self._scale,
            self._covariance, self._walk if self._settled else self._settle_walk, measured,
            self._pressure_weight, self.options.outlier_sigma, self._settled, stuck)
        x = z * self._scale
        self._increment = np.zeros_like(x)
        w_ex, _, _, _ = project_effectors(solved, columns, positions, rotations,
                                          self._effector_frames, self._effector_offsets,
                                          x_previous)
        w_tip = w_ex[-3:] * self._scale
        apply_linear_step(positions, rotations, solved[:, 0], solved[:, 1:], x - x_previous,
                          self.options.max_rotation_step)
        # settled: every used pot within settle_sigma of its prediction (else the next update
        # lets the actuation move by initial_actuation_std, as from far away)
        self._settled = bool(np.all(ratio[active] < self.options.settle_sigma))
        self._x, self._covariance = x, covariance
        if pressures is not None and active.all() and self._settled:
            self._learn_gain(x[:m], pressures)
        rank = self._rank(active, w_sz)
        status, reason = 'ok', ''
        if not active.all():
            names = self.sensors.names
            reason = '; '.join(
                [f'{n} stuck' for n, s in zip(names, stuck) if s]
                + [f'{n} {r:.0f} sigma off' for n, s, a, r in zip(names, stuck, active, ratio)
                   if not (s or a)] + [f'rank {rank} of {x.size}'])
            status = 'degraded'
        return ShapeEstimate(status, reason, self.effectors.positions(positions, rotations),
                             w_tip @ covariance @ w_tip.T, lengths, lengths - predicted, active,
                             rank, x[:m].copy(), self._payload(), 0.0)
