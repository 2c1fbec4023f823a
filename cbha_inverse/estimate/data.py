"""
The buffers of the shape estimator's update, and the argument tuple of its compiled entry.

:class:`EstimatorData` holds every array that
:func:`cbha_inverse.core._kernels.estimation.estimate_tick` reads and writes: the estimator's
own control-tick data (frames, actuation, the linearisation;
:class:`cbha_inverse.core.inverse.tick_data.TickData`), the pots' routing and rows, the
unknowns and their covariance. An update passes :attr:`EstimatorData.arguments`, built once; named
attributes are views of the same memory.
"""

import functools

from cbha_inverse.core._kernels import estimation as rows
from cbha_inverse.core._kernels.cables import routing_work_size
from cbha_inverse.core._kernels.links import link_work_size
from cbha_inverse.core._kernels.tick import compiled_entry
from cbha_inverse.core.inverse.results import InverseOptions
from cbha_inverse.core.inverse.tick_data import TickData
from cbha_inverse.core.sections import link_sections
import numpy as np


class EstimatorData:
    """
    Preallocated buffers of one estimator's updates.

    Parameters
    ----------
    system : cbha_inverse.core.system.EquilibriumSystem
        The estimator's evaluator (with the fused linearisation).
    effectors : cbha_inverse.core.actuation.effectors.PointEffectors
        The effectors (``k``, the tip last).
    sensors : cbha_inverse.core.sensors.StringPots
        The pots (``c``).
    scale : (u,) ndarray
        Unit of every unknown ``(g, δ, μ)`` (``x = scale z``, ``u = 2 m + w``).
    load : (w, 6n) ndarray  [N/kg]
        External wrench of one kg of each weight unknown (0-2: the arm's own weight's
        distribution, the payload at the last frame), then one row per section stiffness
        unknown (any values: the update writes them).
    max_rotation_step : float  [rad]
        Largest frame rotation of one step.
    sections : tuple, optional
        The section stiffness unknowns: ``section_links`` (dict ``name -> (first link index,
        count)`` in chain order, :attr:`cbha_inverse.scene.scene.Scene.section_links`),
        ``nominal`` (n, 6, 6) (the model's link stiffness) and ``stiffness`` (n, 6, 6), the
        writable array of which ``system.stiffness`` is a read-only view; default: none.

    Raises
    ------
    ValueError
        If the scene's actuators need the general evaluation (no fused linearisation).

    """

    def __init__(self, system, effectors, sensors, scale, load, max_rotation_step,
                 sections=None):
        """Allocate every buffer and build the argument tuple."""
        n, m, k, c = system.n, system.m, effectors.n_effectors, sensors.n_sensors
        u = scale.size
        zeros = np.zeros(m)
        self.tick = TickData(system, effectors, np.ones(m), zeros, np.ones(m), None,
                             InverseOptions(max_rotation_step=max_rotation_step), 1)
        if not self.tick.fused:
            raise ValueError('the shape estimator needs the fused linearisation (one cable '
                             'group at most, no skinned-mesh cavities)')
        self.external = self.tick.external
        self.base_external = self.external.copy()
        self.positions, self.rotations = self.tick.positions, self.tick.rotations
        self.actuation = self.tick.actuation
        self.pots = np.zeros((rows.POT_ROWS, c))
        self.measured, self.noise = self.pots[rows.MEASURED], self.pots[rows.NOISE]
        self.noise[:] = sensors.noise_std
        self.state = np.zeros((rows.STATE_ROWS, u))
        self.z, self.walk = self.state[rows.Z], self.state[rows.WALK]
        self.state[rows.SCALE] = scale
        self.covariance = np.zeros((u, u))
        self.pressure_rows = np.zeros((rows.PRESSURE_ROWS, m))
        self.pressures = self.pressure_rows[rows.PRESSURE]
        self.scalars = np.zeros(rows.SCALARS)
        self.load = np.ascontiguousarray(load, dtype=float).reshape(-1, 6 * n)
        w = self.load.shape[0]
        if u != 2 * m + w:
            raise ValueError(f'{u} unknowns for {m} actuators and {w} weights')
        # the weights of the linearisation [kg]
        self.masses = np.zeros(w)
        # the compiled update solves the weights' columns with its own factor (the fallback
        # chain clears this while it hands over columns solved with another factor)
        self.scalars[rows.SOLVE_MASS] = 1.0
        self.scalars[rows.MAX_ROTATION] = max_rotation_step
        self.jacobian = np.zeros((c, 6 * n))
        self.moved = np.zeros((c, m + 1 + w))
        self.h = np.zeros((c, u))
        self.mass_columns = np.zeros((6 * n, 1 + w))
        self.mass_rhs = np.zeros((6 * n, 1 + w))
        self.mass_effectors = (np.zeros((3 * k, w)), np.zeros((w, w)), np.zeros(3 * k),
                               np.zeros((3 * k, 1 + w)), np.zeros((k, 3)), np.zeros(w),
                               np.zeros((6 * n, 3 * k)))
        self.stuck = np.zeros(c, dtype=np.bool_)
        self.active = np.zeros(c, dtype=np.bool_)
        self.effector_w = np.zeros((3, u))
        self.sections = self._section_arguments(system, sections)
        self.effector_positions = np.zeros((k, 3))
        self.tip_covariance = np.zeros((3, 3))
        routing = sensors.routing
        work = np.zeros(routing_work_size(routing[0].size, routing[2].size, c))
        self.arguments = (self.tick.buffers, system.tick_cholesky, routing + (work,), self.pots,
                          self.jacobian, self.moved, self.h, self.state, self.covariance,
                          self.pressure_rows, self.scalars, self.masses, self.load,
                          self.base_external, self.mass_columns, self.mass_rhs,
                          self.mass_effectors, self.stuck, self.active, np.zeros(6 * n),
                          self.effector_w, self.effector_positions, self.tip_covariance,
                          np.zeros(max(u + 2, 6 * n)), self.sections)

    @staticmethod
    def _section_arguments(system, sections):
        """
        Return the ``sections`` argument of ``estimate_tick`` (``section_loads``).

        Parameters
        ----------
        system : cbha_inverse.core.system.EquilibriumSystem
            The evaluator (``system.stiffness`` must view ``sections[2]``).
        sections : tuple or None
            ``(section_links, nominal, stiffness)`` of the constructor.

        Returns
        -------
        tuple

        """
        n = system.n
        if sections is None:
            section_links, nominal, stiffness = {}, np.zeros((n, 6, 6)), np.zeros((n, 6, 6))
        else:
            section_links, nominal, stiffness = sections
            if not np.shares_memory(system.stiffness, stiffness):
                raise ValueError("the system's stiffness must view the scaled stiffness")
        link_section = link_sections(section_links, n)
        # first link and count of each section; the model's stiffness of its links alone
        ranges = np.array(list(section_links.values()), dtype=np.int64).reshape(-1, 2)
        per_section = np.zeros((len(ranges), n, 6, 6))
        for index, (first, count) in enumerate(ranges):
            per_section[index, first:first + count] = nominal[first:first + count]
        # read-only as the tick's own stiffness (one compiled type of the link pass)
        nominal = np.array(nominal, dtype=float)
        for array in (nominal, per_section):
            array.setflags(write=False)
        return (link_section, nominal, stiffness, per_section, ranges, np.zeros(0),
                np.zeros((n, 0, 6)), np.zeros((n, 0, 6, 6)), np.zeros((n, 0), dtype=np.int64),
                np.zeros((6 * n, 1)), np.zeros((n, 12, 12)), np.zeros(link_work_size(0)))

    @functools.cached_property
    def update_entry(self):
        """
        Return the compiled ``estimate_tick`` for :attr:`arguments` (no per-call dispatch).

        See :func:`cbha_inverse.core._kernels.tick.compiled_entry`; call it with
        :attr:`arguments`.
        """
        return compiled_entry(rows.estimate_tick, *self.arguments)

    @property
    def from_linearisation_arguments(self):
        """Return the arguments of ``estimate_from_linearisation`` (after a fallback)."""
        skip = (1, 13, 24)   # cholesky, base_external, sections
        return tuple(a for i, a in enumerate(self.arguments) if i not in skip)
