"""
The control tick's paths beside its one compiled call (:mod:`cbha_inverse.core.inverse.solver`).

:meth:`InverseSolver.step <cbha_inverse.core.inverse.solver.InverseSolver.step>` runs a tick of
the active set on the fused linearisation as one compiled call
(:func:`cbha_inverse.core._kernels.tick.control_tick`). :class:`TickPaths` holds every other
path, as the solver ran them before: a held tick (a non-finite target or QP solution, no
factorization), a target beyond reach (clamped), the fallback chain after a failed band
Cholesky, the target check, the linearisation and the QP each as a call of its own (proxsuite,
Gauss-Seidel, the general evaluation, ``newton_steps`` > 1), proxsuite after an active set that
did not converge, and the result of such a tick.
"""

import time

from cbha_inverse.core._kernels import tick as fused
from cbha_inverse.core._kernels.projection import tick_outcome
from cbha_inverse.core._kernels.qp import SOLVED
from cbha_inverse.core.inverse.qp import binding_bounds, projected_gauss_seidel, qp_problem
from cbha_inverse.core.inverse.results import TickResult
import numpy as np

FAST_MOVE = 0.02
"""An actuator moving more than this fraction of its range ends a kept linearisation."""


class TickPaths:
    """The tick's paths beside its one compiled call (a mixin of the solver's class)."""

    def _held(self, status, started, qp_status='not_run', warnings=()):
        """Return a tick result that keeps the actuation and the state."""
        m = self.actuation.size
        elapsed = time.perf_counter() - started
        timings = {'assembly': 0.0, 'factor': 0.0, 'projection': 0.0, 'qp': 0.0, 'update': 0.0,
                   'total': elapsed}
        return TickResult(self.actuation.copy(), self.effector_positions(), status, qp_status, 0,
                          np.zeros(m, dtype=bool), float('nan'), float('nan'), timings,
                          tuple(warnings))

    def _reachable(self, targets):
        """
        Return the targets moved onto the reach sphere when beyond it, and the warnings.

        Parameters
        ----------
        targets : (k, 3) ndarray  [m]
            Finite effector targets.

        Returns
        -------
        targets : (k, 3) ndarray  [m]
        warnings : tuple of str

        """
        away = targets - self._base
        largest = np.abs(away).max(axis=1)
        far = largest > self._reach
        # direction without overflow: divide by the largest component before the norm
        unit = away[far] / largest[far, None]
        unit /= np.linalg.norm(unit, axis=1)[:, None]
        clamped = targets.copy()
        clamped[far] = self._base + self._reach[far, None] * unit
        names = ', '.join(name for name, f in zip(self.effector_names, far) if f)
        return clamped, (f'target of {names} is beyond any reach of the chain: clamped to '
                         f'{self._reach[far].max():.3g} m from the base',)

    def _after_tick(self, code, targets, fresh, residual_norm, t_start):
        """
        Finish a tick whose compiled call (``control_tick``) did not end with a solved QP.

        The same paths as the two compiled calls: a non-finite target holds, a target beyond
        reach is clamped, a failed band Cholesky takes the fallback chain, a non-finite QP
        solution holds, and proxsuite takes over from an active set that did not converge.
        """
        if code == fused.TARGET_NOT_FINITE:
            return self._held('rejected', t_start, warnings=('non-finite target rejected',))
        if code == fused.BEYOND_REACH:
            return self._step(targets, 2, t_start)
        prepared, self._prepared = self._prepared, False
        if fresh:
            self._pending = False
            if code == fused.NOT_FACTORED:
                # the evaluation is written: the fallback chain, then the QP as in _step
                self._linearised = self._fall_back()
                if not self._linearised:
                    return self._held('not_positive_definite', t_start)
                self._age = 1
                return self._solve(targets, (), fresh, prepared, t_start, time.perf_counter())
            self._linearised, self._residual_norm, self._age = True, residual_norm, 1
        else:
            self._age = 1 if prepared else self._age + 1
        if code == fused.REJECTED:
            return self._rejected(t_start, 'solved', ())
        # the active set did not converge: proxsuite (status checked) takes over; it has not
        # seen this Hessian
        self._active_set.reset()
        return self._general_qp(targets, 'proxsuite', False, (), t_start,
                                time.perf_counter() if fresh else t_start)

    def _step(self, targets, checked, t_start):
        """
        Run a tick after the target check, the linearisation and the QP each a call of its own.

        Parameters
        ----------
        targets : (k, 3) ndarray  [m]
            Finite effector targets (C-ordered floats).
        checked : int
            The target check's result: 0 within reach, 2 some target beyond it (clamped here).
        t_start : float  [s]
            ``time.perf_counter()`` at the start of the tick.

        Returns
        -------
        TickResult

        """
        targets, warnings = self._reachable(targets) if checked == 2 else (targets, ())
        prepared, self._prepared = self._prepared, False
        fresh = not self._linearised or self._age >= self.options.relinearize_every
        if fresh:
            self._materialise()
            self._linearised = self._linearise()
            if not self._linearised:
                return self._held('not_positive_definite', t_start)
            self._age = 1
            t_linearised = time.perf_counter()
        else:
            self._age = 1 if prepared else self._age + 1
            t_linearised = t_start
        return self._solve(targets, warnings, fresh, prepared, t_start, t_linearised)

    def _solve(self, targets, warnings, fresh, prepared, t_start, t_linearised):
        """Solve the QP of the tick data's linearisation and apply it (steps 3-4), as `_step`."""
        apply_step = self.options.relinearize_every == 1
        data = self._data
        if self.options.qp_solver == 'active_set':
            code, iterations, largest_gap, largest_move, binding = data.solve_entry(
                targets, data.buffers, apply_step)
            if code == fused.REJECTED:
                return self._rejected(t_start, 'solved', warnings)
            if code == SOLVED:
                return self._finish(targets, 'saturated' if binding else 'solved',
                                    'solved', iterations, data.mask.copy(), largest_gap,
                                    largest_move, True, warnings, t_start, t_linearised)
            # the active set did not converge: proxsuite (status checked) takes over; it has
            # not seen this Hessian
            self._active_set.reset()
            qp_solver, same_hessian = 'proxsuite', False
        else:
            qp_solver, same_hessian = self.options.qp_solver, not (fresh or prepared)
        return self._general_qp(targets, qp_solver, same_hessian, warnings, t_start,
                                t_linearised)

    def _general_qp(self, targets, qp_solver, same_hessian, warnings, t_start, t_linearised):
        """Solve the tick's QP in Python (proxsuite, Gauss-Seidel) and apply it (steps 3-4)."""
        apply_step = self.options.relinearize_every == 1
        data = self._data
        delta_free = data.offset - targets.reshape(-1)
        problem = qp_problem(data.matrices, delta_free, self.actuation, self.lower_bounds,
                             self.upper_bounds, rate_limit=self._rate)
        solution, status = self._solve_qp(problem, qp_solver, same_hessian)
        actuation, gap, largest_gap, largest_move, finite = tick_outcome(
            data.w_ea, delta_free, problem.scale, solution.x, problem.previous, self.lower_bounds,
            self.upper_bounds)
        if not finite:
            return self._rejected(t_start, solution.status, warnings)
        saturated = binding_bounds(problem, solution.x)
        if status == 'solved' and saturated.any():
            status = 'saturated'
        self.actuation[:] = actuation
        data.gap[:] = gap
        if apply_step:
            data.step_entry(data.buffers)
        return self._finish(targets, status, solution.status, solution.iterations, saturated,
                            largest_gap, largest_move, False, warnings, t_start, t_linearised)

    def _rejected(self, t_start, qp_status, warnings):
        """Hold after a non-finite QP solution and forget the warm starts."""
        # never a NaN actuation, never a poisoned warm start: hold, the next tick recovers
        self._qp.reset()
        self._active_set.reset()
        return self._held('rejected', t_start, qp_status,
                          warnings + ('QP returned a non-finite actuation: held',))

    def _finish(self, targets, status, qp_status, iterations, saturated, largest_gap,
                largest_move, positions_written, warnings, t_start, t_linearised):
        """
        Close a solved tick: age of the linearisation, Newton steps, effector positions, result.

        ``positions_written``: the compiled tick wrote the effector positions into the tick
        data (of the new state, or between linearisations the linear model's prediction).
        """
        data = self._data
        if self._age < self.options.relinearize_every and largest_move > FAST_MOVE:
            # the actuation moves fast: the next tick relinearises
            self._age = self.options.relinearize_every
        t_qp = time.perf_counter()
        if self.options.relinearize_every == 1:
            self._pending = False
            newton = self.options.newton_steps > 1
            for _ in range(self.options.newton_steps - 1):
                if not self._newton_step():
                    break
            if positions_written and not newton:
                effector_positions = data.effector_positions.copy()
            else:
                effector_positions = self.effectors.positions(self._positions, self._rotations)
        else:
            # between linearisations the tick is the linear model of paper eq. 11
            self._pending = True
            effector_positions = (data.effector_positions.copy() if positions_written
                                  else targets + data.gap.reshape(-1, 3))
        t_end = time.perf_counter()
        timings = {'assembly': t_linearised - t_start, 'factor': 0.0, 'projection': 0.0,
                   'qp': t_qp - t_linearised, 'update': t_end - t_qp, 'total': t_end - t_start}
        return TickResult.of_tick(self.actuation.copy(), effector_positions, status, qp_status,
                                  iterations, saturated, largest_gap, self._residual_norm,
                                  timings, warnings)

    def _solve_qp(self, problem, qp_solver, same_hessian):
        """
        Solve the tick's QP (step 3 of the module docstring) with the chosen solver and fallbacks.

        The active set falls back to proxsuite when it does not converge, proxsuite (status
        checked) to projected Gauss-Seidel. Returns ``(solution, status)``, the status
        ``'solved'`` or ``'qp_fallback'``.
        """
        status = 'solved'
        if qp_solver == 'active_set':
            solution = self._active_set.solve(problem)
            if solution.ok:
                return solution, status
            # proxsuite (status checked) takes over; it has not seen this Hessian
            qp_solver, same_hessian = 'proxsuite', False
        if qp_solver == 'proxsuite':
            solution = self._qp.solve(problem, same_hessian=same_hessian)
            if not solution.ok:
                status = 'qp_fallback'
                solution = projected_gauss_seidel(problem)
                solution = type(solution)(solution.x, self._qp_status_text(solution), 0, True)
            return solution, status
        return projected_gauss_seidel(problem), status

    @staticmethod
    def _qp_status_text(solution):
        """Label the Gauss-Seidel fallback's status."""
        return f'gauss_seidel_{solution.status}'
