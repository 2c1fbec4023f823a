"""
The shape estimator: the equilibrium that reproduces the string-potentiometer lengths.

The pots are effectors in length space (``docs/proprioception.md``): at the current estimate of the
frames ``q`` and the effective actuation ``λ`` (and, optionally, unknown weights ``μ``: an error of
the arm's own weight, a payload mass at the last frame, or both), one linearisation of the
equilibrium (paper eq. 9, the control tick's
:func:`~cbha_inverse.core._kernels.tick.linearise_tick`) gives ``K⁻¹ [r, J_aᵀ]``; with the pots'
``J_s`` (:class:`~cbha_inverse.core.sensors.StringPots`) the
lengths after the Newton step are linear in the actuation through ``W_sa = J_s K⁻¹ J_aᵀ`` (the
pots' ``W_ea``, eq. 11). The unknowns are not the actuation itself but its error about the measured
pressures, ``λ = (1 + g) ∘ p + δ`` (a gain and an offset per actuator: the model's error in
effective area and stiffness), and ``μ`` (optionally also a stiffness error ``σ_j`` per chain
section, which scales that section's links in the linearisation itself, as a scene's
``calibration.section_stiffness`` does); they change slowly, so they follow a small random walk
and each update is a Kalman step that averages the pot noise over many updates (the compiled
:mod:`cbha_inverse.core._kernels.estimation`, over the buffers of
:class:`cbha_inverse.estimate.data.EstimatorData`). The offset's walk grows with the measured
pressure change (the model's error shows when the arm moves); without measured pressures ``λ = δ``
with a large walk. The state then takes the Newton step of the same factorisation, so repeated
updates converge to the equilibrium of the estimate; after a step of the measured pressures
(``predict_pressure_change``) the state first takes Newton steps to the equilibrium of the prior at
the new pressures (the prediction), so that the pots correct the unknowns against the right shape,
not against one linearisation's error.

Bad input (wrong length, non-finite or out-of-range readings or pressures) is rejected with a
reason and changes nothing; a pot whose innovation is ``outlier_sigma`` standard deviations off,
or that is stuck (:class:`cbha_inverse.estimate.checks.StuckDetector`), is dropped from the fit
and the estimate is ``degraded``; ``rank`` says how many directions the remaining pots determine.
"""

import math
import time

from cbha_inverse.core._kernels.tick import SOLVED
from cbha_inverse.core.chain import ChainState, external_wrenches, rest_state
from cbha_inverse.core.loads import dead_wrenches
from cbha_inverse.core.sections import SECTION_FACTOR_BOUNDS
from cbha_inverse.core.system import EquilibriumSystem
from cbha_inverse.estimate.checks import check_vector, StuckDetector
from cbha_inverse.estimate.data import EstimatorData
from cbha_inverse.estimate.results import EstimatorOptions, ShapeEstimate
import numpy as np

# scale of the unknowns inside the filter: a gain of 1, 10 kPa of offset, 0.1 kg of payload,
# a tenth of a section's stiffness
_GAIN_SCALE = 1.0
_OFFSET_SCALE = 1.0e4
_MASS_SCALE = 0.1
_SECTION_SCALE = 0.1
# the section stiffness factors 1 + σ_j are kept within these
_SECTION_BOUNDS = SECTION_FACTOR_BOUNDS


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
    sections : dict, optional
        The chain's sections, ``name -> (first link index, count)`` in chain order
        (:attr:`cbha_inverse.scene.scene.Scene.section_links`); needed by
        ``section_stiffness_std``.
    loads : cbha_inverse.core.loads.Loads, optional
        Known external loads (a scene's :attr:`~cbha_inverse.scene.scene.Scene.loads`): dead
        wrenches and masses (:func:`cbha_inverse.core.loads.dead_wrenches`); follower wrenches
        are refused.

    Attributes
    ----------
    section_names : tuple of str
        The sections with a stiffness unknown (empty without).

    """

    def __init__(self, model, actuators, effectors, sensors, gravity=None, options=None,
                 sections=None, loads=None):
        """Precompute the evaluator and the buffers, and start at rest."""
        self.options = options or EstimatorOptions()
        opts = self.options
        self.model, self.actuators, self.effectors, self.sensors = (model, actuators, effectors,
                                                                    sensors)
        external = external_wrenches(model, gravity=gravity).reshape(-1)
        if loads:
            if loads.has_followers:
                raise ValueError('the shape estimator takes dead loads and masses, not follower '
                                 '(local) wrenches')
            external += dead_wrenches(loads, model.n_links, gravity).reshape(-1)
        self.section_names, section_arguments = (), None
        if opts.section_stiffness_std is None:
            self._system = EquilibriumSystem(model, actuators, external)
        else:
            if not sections:
                raise ValueError('a section stiffness unknown needs the chain sections (a '
                                 'segments scene)')
            self.section_names = tuple(sections)
            # the links' stiffness the linearisation reads: the model's scaled by 1 + σ_j of
            # each link's section before every update (a read-only view for the kernels)
            stiffness = np.array(model.stiffnesses, dtype=float)
            view = stiffness.view()
            view.setflags(write=False)
            self._system = EquilibriumSystem(model, actuators, external, stiffness=view)
            section_arguments = (sections, stiffness)
        m = self._m = actuators.n_actuators
        # the load unknowns, in this order: the arm's own weight error, a payload at the last
        # frame (the wrench of one kg of each), the sections' stiffness errors (rows the update
        # writes); their prior and walk std
        loads, self._mass_stds, self._mass_index = [], [], {}
        for name, std, walk in (('weight', opts.weight_std, opts.weight_walk_std),
                                ('payload', opts.payload_std, opts.payload_walk_std)):
            if std is None:
                continue
            if gravity is None:
                raise ValueError("a payload or weight unknown needs the scene's gravity")
            load = np.zeros(self._system.size)
            if name == 'weight':
                load[:] = (external_wrenches(model, gravity=gravity).reshape(-1)
                           / model.masses.sum())
            else:
                load[-6:-3] = gravity
            self._mass_index[name] = len(loads)
            loads.append(load)
            self._mass_stds.append((std, walk))
        n_weights = len(loads)
        for _ in self.section_names:
            loads.append(np.zeros(self._system.size))
            self._mass_stds.append((opts.section_stiffness_std,
                                    opts.section_stiffness_walk_std))
        self._n_mass = len(loads)
        load = np.array(loads).reshape(self._n_mass, self._system.size)
        self._scale = np.concatenate([np.full(m, _GAIN_SCALE), np.full(m, _OFFSET_SCALE),
                                      np.full(n_weights, _MASS_SCALE),
                                      np.full(len(self.section_names), _SECTION_SCALE)])
        self._data = EstimatorData(self._system, effectors, sensors, self._scale, load,
                                   opts.max_rotation_step, opts.pressure_change_walk,
                                   opts.outlier_sigma, section_arguments)

        def walk(offset):
            stds = [opts.gain_walk_std] * m + [offset] * m + [w for _, w in self._mass_stds]
            return (np.asarray(stds) / self._scale) ** 2
        # the walk per update: (pressures measured, settled) -> variances of z
        self._walks = {(True, True): walk(opts.offset_walk_std),
                       (False, True): walk(opts.actuation_walk_std),
                       (True, False): walk(opts.initial_actuation_std),
                       (False, False): walk(opts.initial_actuation_std)}
        rest = rest_state(model)
        self._length_bounds = np.outer(opts.length_range,
                                       sensors.lengths(rest.positions, rest.rotations))
        self._stuck = StuckDetector(sensors.n_sensors, opts.stuck_window,
                                    opts.stuck_tolerance, opts.motion_threshold)
        # the unknowns before each of the last stuck_window updates, the next slot and count
        window, u = max(opts.stuck_window, 1), self._scale.size
        self._snapshots = (np.zeros((window, u)), np.zeros((window, u, u)), [0, 0])
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
                   gravity=scene.gravity, options=options, sections=scene.section_links,
                   loads=scene.loads)

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
        data, m = self._data, self._m
        data.positions[:] = state.positions
        data.rotations[:] = state.rotations
        data.actuation[:] = 0.0 if actuation is None else np.asarray(actuation, dtype=float)
        data.z[:] = 0.0
        data.z[m:2 * m] = data.actuation / _OFFSET_SCALE
        stds = ([self.options.gain_std] * m + [self.options.pressure_std] * m
                + [std for std, _ in self._mass_stds])
        data.covariance[:] = np.diag((np.asarray(stds) / self._scale) ** 2)
        data.masses[:] = 0.0
        self._stuck.reset()
        self._ranks = {}
        self._settled = False
        self._first = True
        self._measured = None
        self._used = np.ones(self.sensors.n_sensors, dtype=bool)
        self._snapshots[2][:] = [0, 0]
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
        return ChainState(self._data.positions.copy(), self._data.rotations.copy())

    @property
    def gain_error(self):
        """Return the estimated gain error ``g`` of the actuation, (m,) [-]."""
        return self._data.z[:self._m] * _GAIN_SCALE

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
            outside = (lengths < self._length_bounds[0]) | (lengths > self._length_bounds[1])
            if outside.any():
                names = ', '.join(n for n, o in zip(self.sensors.names, outside) if o)
                reason = f'out_of_range: length of {names} outside the accepted range'
        if reason is not None:
            return self._rejected(reason, started)
        data = self._data
        data.stuck[:] = self._stuck.update(lengths)
        data.measured[:] = lengths
        measured = pressures is not None
        data.pressures[:] = pressures if measured else 0.0
        if self._measured is not None and measured != self._measured:
            self._restart_actuation(measured)
        self._measured = measured
        if self._first:
            data.last_pressures[:] = data.pressures
            self._first = False
            if not self._converge():
                return self._rejected('not_positive_definite: no factor of the tangent', started)
        elif measured and np.abs(data.pressures - data.last_pressures
                                 ).max() > self.options.predict_pressure_change:
            # the prediction of the state at the new pressures, before the pots correct it
            if not self._converge():
                return self._rejected('not_positive_definite: no factor of the tangent', started)
        data.gate[0] = self._settled
        walk = self._walks[measured, self._settled]
        self._snapshot()
        iterations = max(1, self.options.iterations)
        if not self._settled:
            iterations = max(iterations, self.options.settle_iterations)
        if iterations > 1:
            prior = (data.z.copy(), data.covariance.copy(),
                     data.last_pressures.copy())
        for iteration in range(iterations):
            if iteration:
                # iterated update: the same prior, relinearised at the last posterior
                data.z[:], data.covariance[:] = prior[0], prior[1]
                data.last_pressures[:] = prior[2]
            data.walk[:] = walk
            if not self._step():
                return self._rejected('not_positive_definite: no factor of the tangent', started)
            if not math.isfinite(data.effector_positions.sum() + data.z.sum()):
                # never a NaN estimate: start over from rest, the next readings settle it
                self.reset()
                return self._rejected('diverged: non-finite estimate, restarted at rest',
                                      started)
        dropped = self._used & ~data.active
        if dropped.any() and self._snapshots[2][1] == len(self._snapshots[0]):
            outliers = dropped & ~data.stuck
            ratios = data.ratio.copy()
            # a pot just dropped may have pulled the unknowns before: start again from them as
            # they were before the stuck window, without it (left out as if stuck, reported as
            # what it was)
            self._restore_oldest()
            data.stuck |= dropped
            data.walk[:] = walk
            if not self._step():
                return self._rejected('not_positive_definite: no factor of the tangent', started)
            data.stuck &= ~outliers
            data.ratio[outliers] = ratios[outliers]
        self._used = data.active.copy()
        self._last = self._estimate(lengths, time.perf_counter() - started)
        return self._last

    def _restart_actuation(self, measured):
        """
        Start the actuation's unknowns again when pressures start or stop being measured.

        ``λ = (1 + g) ∘ p + δ`` changes meaning: with pressures, gain and offset restart from
        their prior about them; without, the offset is the current actuation. The payload is
        kept; the next update is iterated as from far away.
        """
        data, m = self._data, self._m
        data.z[:m] = 0.0
        data.z[m:2 * m] = 0.0 if measured else data.actuation / _OFFSET_SCALE
        stds = [self.options.gain_std] * m + [self.options.pressure_std if measured else
                                              self.options.initial_actuation_std] * m
        data.covariance[:2 * m, :] = 0.0
        data.covariance[:, :2 * m] = 0.0
        data.covariance[range(2 * m), range(2 * m)] = (np.asarray(stds)
                                                       / self._scale[:2 * m]) ** 2
        data.last_pressures[:] = data.pressures
        self._settled = False

    def _converge(self):
        """
        Take Newton steps at the prior's actuation and payload (no pot used) until converged.

        The first update starts from the rest shape, and an update after a pressure step from
        the equilibrium of the previous pressures, far from that of the measured ones; the pots'
        linear model is then taken near it. Returns False if no factor.
        """
        data = self._data
        stuck = data.stuck.copy()
        data.stuck[:] = True
        # the pressure change is the next update's (the offset's walk), not these steps'
        last_pressures = data.last_pressures.copy()
        for step in range(self.options.initial_newton_steps):
            data.walk[:] = 0.0
            if not self._step():
                return False
            # the residual is that before the step, at the previous actuation: the first step's
            # says nothing about the equilibrium of the new one
            if step and (np.abs(data.moved[:, 0]) < data.noise).all():
                break
        data.stuck[:] = stuck
        data.last_pressures[:] = last_pressures
        return True

    def _snapshot(self):
        """Keep the unknowns and their covariance before this update (a ring of the window)."""
        z, covariance, counters = self._snapshots
        slot = counters[0]
        z[slot], covariance[slot] = self._data.z, self._data.covariance
        counters[0] = (slot + 1) % len(z)
        counters[1] = min(counters[1] + 1, len(z))

    def _restore_oldest(self):
        """Return the unknowns to the oldest snapshot of a full ring (which starts again)."""
        z, covariance, counters = self._snapshots
        self._data.z[:], self._data.covariance[:] = z[counters[0]], covariance[counters[0]]
        counters[:] = [0, 0]

    def _rejected(self, reason, started):
        """Return a rejected update that keeps the previous estimate."""
        last = self._last
        c = self.sensors.n_sensors
        data = self._data
        positions = self.effectors.positions(data.positions, data.rotations)
        return ShapeEstimate(
            'rejected', reason, positions,
            np.full((3, 3), np.nan) if last is None else last.tip_covariance,
            np.full(c, np.nan), np.full(c, np.nan), np.zeros(c, dtype=bool),
            0 if last is None else last.rank, data.actuation.copy(), self._payload(),
            self._weight_error(), time.perf_counter() - started, self._section_stiffness())

    def _mass(self, name):
        """Return the estimated weight unknown ``name`` [kg] (0 without it)."""
        index = self._mass_index.get(name)
        return 0.0 if index is None else float(self._data.masses[index])

    def _payload(self):
        """Return the estimated payload [kg] (0 without that unknown)."""
        return self._mass('payload')

    def _weight_error(self):
        """Return the estimated error of the arm's own weight [kg] (0 without that unknown)."""
        return self._mass('weight')

    def _section_stiffness(self):
        """Return the estimated stiffness factor ``1 + σ_j`` of every section, (s,) [-]."""
        return 1.0 + self._data.masses[self._n_mass - len(self.section_names):]

    def _rank(self, active):
        """Return the numerical rank of the active pots' whitened ``W_sx`` (cached per set)."""
        key = active.tobytes()
        if key not in self._ranks:
            m = self._m
            w_sx = self._data.moved[:, 1:1 + m + self._n_mass]
            whitened = (w_sx * self._scale[m:])[active] / self.sensors.noise_std[active, None]
            self._ranks[key] = (int(np.linalg.matrix_rank(
                whitened, tol=1e-9 * max(1.0, np.abs(whitened).max()))) if active.any() else 0)
        return self._ranks[key]

    def _step(self):
        """
        Run one update: the loads, the linearisation, the Kalman update and Newton step.

        Three compiled calls: the loads of the load unknowns
        (:func:`~cbha_inverse.core._kernels.estimation.estimator_loads`), the control tick's
        linearisation alone, then the rest
        (:func:`~cbha_inverse.core._kernels.estimation.estimate_from_linearisation`); the
        fallback chain when the band is not positive definite.
        """
        data, tick = self._data, self._data.tick
        data.entry('estimator_loads')(data.record)
        linearised = tick.entry('control_tick')(tick.effector_positions, tick.record, False,
                                                True, False, False)
        if linearised[0] == SOLVED:
            data.entry('estimate_from_linearisation')(data.record)
            self._bound_sections()
            return True
        system = self._system
        factor = next(system.fallback_factors(data.positions, data.rotations, data.actuation),
                      None)
        if factor is None:
            return False
        data.tick.project_factor(factor)
        if self._n_mass:
            data.mass_columns[:, 1:] = factor.solve(np.ascontiguousarray(data.load.T))
        data.solve_mass[0] = False
        data.entry('estimate_from_linearisation')(data.record)
        data.solve_mass[0] = True
        self._bound_sections()
        return True

    def _bound_sections(self):
        """
        Keep every section's stiffness factor within ``_SECTION_BOUNDS`` (state and step).

        An update far from the equilibrium (iterated from one prior) can drive a factor toward
        zero, a chain without stiffness; the next update relinearises at the bounded factor.
        """
        data, low, high = self._data, _SECTION_BOUNDS[0] - 1.0, _SECTION_BOUNDS[1] - 1.0
        for index in range(len(data.masses) - len(self.section_names), len(data.masses)):
            sigma = data.masses[index]
            if not low <= sigma <= high:
                data.masses[index] = min(max(sigma, low), high)
                data.z[2 * self._m + index] = data.masses[index] / _SECTION_SCALE

    def _estimate(self, lengths, seconds):
        """Return the :class:`ShapeEstimate` of the update just run."""
        data, m = self._data, self._m
        active = data.active.copy()
        ratio = data.ratio
        # settled: most pots within settle_sigma of their prediction (else the next update lets
        # the actuation's offset move by initial_actuation_std, as from far away, and gates no
        # pot); one pot off is the outlier gate's
        # and the Newton iteration converged (the residual moves no pot by as much)
        sigma = self.options.settle_sigma
        used = sorted(r for r, s in zip(ratio.tolist(), data.stuck.tolist()) if not s)
        self._settled = (bool(used) and used[len(used) // 2] < sigma
                         and bool((np.abs(data.moved[:, 0]) < sigma * data.noise).all()))
        rank = self._rank(active)
        status, reason = 'ok', ''
        if not active.all():
            names, stuck = self.sensors.names, data.stuck
            reason = '; '.join(
                [f'{n} stuck' for n, s in zip(names, stuck) if s]
                + [f'{n} {r:.0f} sigma off' for n, s, a, r in zip(names, stuck, active, ratio)
                   if not (s or a)] + [f'rank {rank} of {m + self._n_mass}'])
            status = 'degraded'
        return ShapeEstimate(status, reason, data.effector_positions.copy(),
                             data.tip_covariance.copy(), lengths,
                             lengths - data.predicted, active, rank,
                             data.actuation.copy(), self._payload(), self._weight_error(),
                             seconds, self._section_stiffness())
