"""
The buffers of the shape estimator's update, held in one compiled record.

:class:`EstimatorData` allocates every array that the compiled update
(:mod:`cbha_inverse.core._kernels.estimation`) reads and writes: the estimator's
own control-tick data (frames, actuation, the linearisation;
:class:`cbha_inverse.core.inverse.tick_data.TickData`), the pots' routing and lengths, the
unknowns and their covariance, the sections' stiffness unknowns. They are the fields of one
:class:`cbha_inverse.core._kernels.estimation.EstimatorRecord`, built once; the attributes of
this object are the same arrays.
"""

from cbha_inverse.core._kernels import estimation as kernels
from cbha_inverse.core._kernels.records import compiled_entry, make_record, RecordOwner
from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.inverse.results import InverseOptions
from cbha_inverse.core.inverse.tick_data import TickData
from cbha_inverse.core.sections import link_sections
from cbha_inverse.core.system import EquilibriumSystem
import numpy as np


class EstimatorData(RecordOwner):
    """
    Preallocated buffers of one estimator's updates.

    Parameters
    ----------
    system : cbha_inverse.core.system.EquilibriumSystem
        The estimator's evaluator.
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
    change_walk : float
        Relative walk of the actuation's offset per measured pressure change.
    gate_sigma : float
        Outlier gate of the pots [sigma] (while the gate is on).
    sections : tuple, optional
        The section stiffness unknowns: ``section_links`` (dict ``name -> (first link index,
        count)`` in chain order, :attr:`cbha_inverse.scene.scene.Scene.section_links`),
        ``model`` (the chain) and ``stiffness`` (n, 6, 6), the writable array of which
        ``system.stiffness`` is a read-only view; default: none.

    Attributes
    ----------
    record : cbha_inverse.core._kernels.estimation.EstimatorRecord
        The compiled record.
    tick : cbha_inverse.core.inverse.tick_data.TickData
        The estimator's own tick data (its record is the record's ``tick``).

    """

    def __init__(self, system, effectors, sensors, scale, load, max_rotation_step, change_walk,
                 gate_sigma, sections=None):
        """Allocate every buffer and build the record."""
        n, m, k, c = system.n, system.m, effectors.n_effectors, sensors.n_sensors
        u = scale.size
        self.tick = TickData(system, effectors, np.ones(m), np.zeros(m), np.ones(m), None,
                             InverseOptions(max_rotation_step=max_rotation_step), 1)
        load = np.ascontiguousarray(load, dtype=float).reshape(-1, 6 * n)
        w = load.shape[0]
        if u != 2 * m + w:
            raise ValueError(f'{u} unknowns for {m} actuators and {w} weights')
        frames, offsets, start, end, span_owner, point_owner = sensors.routing
        arrays = {
            'pot_frames': frames, 'pot_offsets': offsets, 'pot_span_start': start,
            'pot_span_end': end, 'pot_span_owner': span_owner, 'pot_point_owner': point_owner,
            'measured': np.zeros(c), 'noise': np.array(sensors.noise_std, dtype=float),
            'stuck': np.zeros(c, dtype=np.bool_), 'active': np.zeros(c, dtype=np.bool_),
            'length0': np.zeros(c), 'base': np.zeros(c), 'predicted': np.zeros(c),
            'ratio': np.zeros(c), 'jacobian': np.zeros((c, 6 * n)),
            'moved': np.zeros((c, m + 1 + w)), 'h': np.zeros((c, u)),
            'z': np.zeros(u), 'walk': np.zeros(u),
            'unknown_scale': np.array(scale, dtype=float), 'covariance': np.zeros((u, u)),
            'kalman_gain': np.zeros(u), 'pressures': np.zeros(m),
            'last_pressures': np.zeros(m), 'gate': np.zeros(1, dtype=np.bool_),
            'solve_mass': np.ones(1, dtype=np.bool_), 'masses': np.zeros(w), 'load': load,
            'base_external': system.external.copy(), 'mass_columns': np.zeros((6 * n, 1 + w)),
            'load_solved': np.zeros((6 * n, w)),
            'mass_rhs': np.zeros((6 * n, 1 + w)), 'mass_w': np.zeros((3 * k, w)),
            'mass_w_aa': np.zeros((w, w)), 'mass_offset': np.zeros(3 * k),
            'mass_moved': np.zeros((3 * k, 1 + w)), 'mass_levers': np.zeros((k, 3)),
            'mass_previous': np.zeros(w), 'mass_effector_columns': np.zeros((6 * n, 3 * k)),
            'free_step': np.zeros((6 * n, 1)), 'effector_w': np.zeros((3, u)),
            'effector_positions': np.zeros((k, 3)), 'tip_covariance': np.zeros((3, 3)),
            'pot_levers': np.zeros((frames.size, 3)), 'pot_points': np.zeros((frames.size, 3)),
            'pot_forces': np.zeros((frames.size, 3)), 'pot_units': np.zeros((start.size, 3)),
            'pot_span_lengths': np.zeros(start.size), 'pot_unit_gains': np.ones(c)}
        arrays.update(self._section_arrays(system, sections))
        self._sections_system = arrays.pop('sections')
        self._hold(make_record(
            kernels.EstimatorRecord, kernels.new_estimator_record, tick=self.tick.record,
            sections=self._sections_system.record, change_walk=float(change_walk),
            gate_sigma=float(gate_sigma), **arrays), arrays)
        self.positions, self.rotations = self.tick.positions, self.tick.rotations
        self.actuation = self.tick.actuation
        self.external = system.external
        self._entries = {}

    @staticmethod
    def _section_arrays(system, sections):
        """
        Return the record's section fields (none: no section stiffness unknown).

        Parameters
        ----------
        system : cbha_inverse.core.system.EquilibriumSystem
            The evaluator (``system.stiffness`` must view ``sections[2]``).
        sections : tuple or None
            ``(section_links, stiffness)`` of the constructor.

        Returns
        -------
        dict

        """
        n = system.n
        if sections is None:
            section_links, stiffness = {}, np.zeros((n, 6, 6))
        else:
            section_links, stiffness = sections
            if not np.shares_memory(system.stiffness, stiffness):
                raise ValueError("the system's stiffness must view the scaled stiffness")
        nominal = np.array(system.model.stiffnesses, dtype=float)
        ranges = np.array(list(section_links.values()), dtype=np.int64).reshape(-1, 2)
        # the model's stiffness of each section's links alone, zero elsewhere
        per_section = np.zeros((len(ranges), n, 6, 6))
        for index, (first, count) in enumerate(ranges):
            per_section[index, first:first + count] = nominal[first:first + count]
        bare = EquilibriumSystem(system.model, ActuatorSet((), n + 1), np.zeros(6 * n))
        return {'link_section': link_sections(section_links, n), 'nominal': nominal,
                'scaled_stiffness': stiffness, 'section_stiffness': per_section,
                'sections': bare}

    def entry(self, name):
        """
        Return the compiled ``estimator_loads`` or ``estimate_from_linearisation`` of the record.

        Without numba's per-call type dispatch
        (:func:`cbha_inverse.core._kernels.records.compiled_entry`); call it with
        :attr:`record`.
        """
        entry = self._entries.get(name)
        if entry is None:
            entry = compiled_entry(getattr(kernels, name), self.record)
            self._entries[name] = entry
        return entry
