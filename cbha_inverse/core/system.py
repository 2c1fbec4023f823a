"""
The evaluator of the chain's equilibrium: residual, actuator columns and tangents (paper eq. 9).

:class:`EquilibriumSystem` is the one evaluator of ``r(q) = f(q) + f_ext + J_a(q)ᵀ λ`` behind
the controller's tick (:class:`cbha_inverse.core.inverse.solver.InverseSolver`), the static
solver (:func:`cbha_inverse.core.statics.solve_static`), the scenes' forward model, the
simulated plant and the shape estimator. It gathers the model's constant terms (the links'
stiffness and rest shape, the condensed cavities, every cable, the skinned-mesh cavities, the
external wrenches) and the buffers of an evaluation into one compiled record
(:class:`cbha_inverse.core._kernels.evaluation.EquilibriumRecord`, :attr:`record`), which the
compiled evaluation (:func:`cbha_inverse.core._kernels.evaluation.evaluate`) and the tick's
entries read; every method here is a call of those kernels.

Every block of the tangent is added by a constant index into one of two storages of 6 x 6 frame
blocks: the block band of the symmetric part (weights ½ on the mirrored entries, the control
tick's block Cholesky, :meth:`EquilibriumSystem.linearise`), or the blocks of the exact,
non-symmetric tangent (Newton's block LU, :meth:`EquilibriumSystem.exact_system`); cables that
skip frames widen both. Every factorisation returns a
:class:`~cbha_inverse.core.linalg.factors.TangentFactor` (``solve(rhs)``, ``method``);
:meth:`EquilibriumSystem.fallback_factors` is the one fallback chain (exact LU, then material
Cholesky) of the control tick and of Newton's method.
"""

from cbha_inverse.core._kernels import evaluation
from cbha_inverse.core._kernels.records import make_record
from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.actuation.cables import CableGroup, CableTerms
from cbha_inverse.core.actuation.cavities import CavityGroup
from cbha_inverse.core.actuation.condensed_cavities import LinearCavityGroup
from cbha_inverse.core.chain import rest_state
from cbha_inverse.core.linalg.factors import BlockCholesky, BlockLU, DenseLU
import numpy as np


class EquilibriumSystem:
    """
    Preallocated compiled evaluator of the equilibrium of a chain and its actuators.

    Parameters
    ----------
    model : cbha_inverse.core.chain.ChainModel
        The chain.
    actuators : cbha_inverse.core.actuation.actuators.ActuatorSet
        The actuators (``m``): cable groups, condensed cavities
        (:class:`~cbha_inverse.core.actuation.condensed_cavities.LinearCavityGroup`) and
        skinned-mesh cavities (:class:`~cbha_inverse.core.actuation.cavities.CavityGroup`).
    external : (6n,) ndarray  [N, N*m]
        Constant external wrenches on frames 1..n (gravity); the evaluations read this array
        (not a copy when it is a C-ordered float array: a solver changes it in place for a
        payload).
    stiffness : (n, 6, 6) ndarray, optional
        The links' stiffness the evaluations read (default: the model's); a solver or the shape
        estimator passes a view of its own array, which it scales by its section factors.

    Attributes
    ----------
    model : cbha_inverse.core.chain.ChainModel
        The chain.
    n, m, size : int
        Links, actuators and unknowns ``6 n``.
    block_width : int
        Blocks of the tangent below (and above) its diagonal (``B``, 1 for a chain whose
        actuators act within a link).
    record : cbha_inverse.core._kernels.evaluation.EquilibriumRecord
        The compiled record of the terms and buffers.

    Raises
    ------
    ValueError
        If ``stiffness`` has the wrong shape, a condensed cavity part does not lie on one link
        with its rest geometry, or an actuator group is of no known kind.

    """

    def __init__(self, model, actuators, external, stiffness=None):
        """Gather the constant terms, build the assembly index and the buffers."""
        n, m = model.n_links, actuators.n_actuators
        self.model = model
        self.n, self.m, self.size = n, m, 6 * n
        self.stiffness = np.ascontiguousarray(model.stiffnesses if stiffness is None
                                              else stiffness, dtype=float)
        if self.stiffness.shape != (n, 6, 6):
            raise ValueError(f'stiffness must have shape ({n}, 6, 6), got '
                             f'{self.stiffness.shape}')
        self.external = np.ascontiguousarray(external, dtype=float).reshape(-1)
        position = {name: k for k, name in enumerate(actuators.names)}
        cables, meshes = [], []
        self._cavity_wrench, self._cavity_stiffness = np.zeros((n, 0, 6)), np.zeros((n, 0, 6, 6))
        for group in actuators.groups:
            columns = [position[name] for name in group.names]
            if isinstance(group, CableGroup):
                cables.append((group, columns))
            elif isinstance(group, LinearCavityGroup):
                self._add_condensed_cavities(group, columns, model)
            elif isinstance(group, CavityGroup):
                meshes.append((group, columns))
            else:
                raise ValueError(f'actuators {group.names}: no evaluation of '
                                 f'{type(group).__name__} groups')
        self.has_cavities = self._cavity_wrench.shape[1] > 0
        # the cavities as built, kept by the first scale_cavities (which overwrites them)
        self._built_cavities = None
        cable_terms = CableTerms(cables, model.n_frames)
        index_fields = self._assembly(cable_terms)
        self.record = make_record(
            evaluation.EquilibriumRecord, evaluation.new_equilibrium_record,
            **self._link_fields(model), **_cable_fields(cable_terms),
            **_mesh_fields(meshes, model.n_frames), **index_fields,
            **self._buffers(cable_terms, meshes, model.n_frames))

    def _add_condensed_cavities(self, group, columns, model):
        """Add a group of condensed cavities to the links' ``G0`` and ``H``."""
        n = model.n_links
        if not _matches_links(group, model):
            raise ValueError(f'condensed cavities {group.names}: every part must lie on one link '
                             'and carry its rest offset and rotation')
        if self._cavity_wrench.shape[1] == 0:
            self._cavity_wrench = np.zeros((n, self.m, 6))
            self._cavity_stiffness = np.zeros((n, self.m, 6, 6))
        for e in range(group.lower.size):
            column = columns[group.owner[e]]
            self._cavity_wrench[group.lower[e], column] += group.g0[e]
            self._cavity_stiffness[group.lower[e], column] += group.hessian[e]

    def _link_fields(self, model):
        """Return the record's link and condensed-cavity fields."""
        return {'stiffness': self.stiffness,
                'rest_offsets': np.ascontiguousarray(model.rest_offsets, dtype=float),
                'rest_rotations_t': np.ascontiguousarray(
                    np.swapaxes(np.asarray(model.rest_rotations, dtype=float), 1, 2)),
                'cavity_wrench': self._cavity_wrench,
                'cavity_stiffness': self._cavity_stiffness,
                'cavity_columns': nonzero_cavity_columns(self._cavity_wrench,
                                                         self._cavity_stiffness),
                'external': self.external}

    def _assembly(self, cables):
        """
        Return the record's assembly fields: where every block value goes in either band.

        The values are the links' 12 x 12 blocks (frames ``l``, ``l + 1``), the cables' span
        blocks (one 12 x 12 per frame pair) and point moment blocks (3 x 3 per frame), in this
        order. The block band stores entry ``(r, c)``, ``r >= c``, in block
        ``[c // 6, r // 6 - c // 6]`` at ``[r % 6, c % 6]``
        (:mod:`cbha_inverse.core._kernels.block_band`), the exact tangent's blocks in block
        ``[c // 6, B + r // 6 - c // 6]`` (:mod:`cbha_inverse.core._kernels.block_lu`). Entries
        of the base frame go to a trash row of blocks at the end of either, value ``i`` to its
        slot ``i mod 36`` (consecutive values add into different slots).
        """
        n = self.n
        rows, cols = [], []
        link_dof = 6 * np.arange(n)[:, None] + np.arange(12)[None, :] - 6
        rows.append(np.broadcast_to(link_dof[:, :, None], (n, 12, 12)).reshape(-1))
        cols.append(np.broadcast_to(link_dof[:, None, :], (n, 12, 12)).reshape(-1))
        for a, b in cables.pairs:
            dof = np.concatenate([6 * (a - 1) + np.arange(6), 6 * (b - 1) + np.arange(6)])
            rows.append(np.repeat(dof, 12))
            cols.append(np.tile(dof, 12))
        for frame in cables.moment_frames:
            dof = 6 * (frame - 1) + 3 + np.arange(3)
            rows.append(np.repeat(dof, 3))
            cols.append(np.tile(dof, 3))
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        valid = (rows >= 0) & (cols >= 0)
        low, high = np.minimum(rows, cols), np.maximum(rows, cols)
        self.block_width = max(int((high // 6 - low // 6)[valid].max()) if valid.any() else 0, 1)
        lower_blocks, exact_blocks = self.block_width + 1, 2 * self.block_width + 1
        lower_slot = (((low // 6) * lower_blocks + high // 6 - low // 6) * 6 + high % 6) * 6 + (
            low % 6)
        exact_slot = (((cols // 6) * exact_blocks + self.block_width + rows // 6 - cols // 6) * 6
                      + rows % 6) * 6 + cols % 6
        trash = np.arange(rows.size) % 36
        self._pair_start = 144 * n
        self._moment_start = self._pair_start + 144 * len(cables.pairs)
        return {'index': np.where(valid, lower_slot, n * lower_blocks * 36 + trash),
                'weights': np.where(rows == cols, 1.0, 0.5),
                'exact_index': np.where(valid, exact_slot, n * exact_blocks * 36 + trash),
                'pair_start': self._pair_start, 'moment_start': self._moment_start,
                'moment_count': len(cables.moment_frames)}

    def _buffers(self, cables, meshes, n_frames):
        """Return the record's buffers and scratch arrays."""
        n, m, size, width = self.n, self.m, self.size, self.block_width
        points, spans = cables.frames.size, cables.start.size
        vertices = sum(group.frame_a.size for group, _ in meshes)
        n_mesh = sum(group.n_actuators for group, _ in meshes)
        return {
            'rhs': np.zeros((size, m + 1)),
            'values': np.zeros(self._moment_start + 9 * len(cables.moment_frames)),
            'blocks': np.zeros((n + 1, width + 1, 6, 6)),
            'exact_blocks': np.zeros((n + 1, 2 * width + 1, 6, 6)),
            'lu_pivots': np.zeros((n, 6), dtype=np.int64),
            'link_difference': np.zeros(3), 'link_relative': np.zeros((3, 3)),
            'link_delta': np.zeros(6), 'link_stress': np.zeros(6),
            'link_jl_inverse': np.zeros((3, 3)), 'link_weighted': np.zeros((6, 6)),
            'link_tangent': np.zeros((6, 6)), 'link_local': np.zeros((6, m + 1)),
            'link_world': np.zeros((6, m + 1)), 'link_block': np.zeros((12, 12)),
            'cable_levers': np.zeros((points, 3)), 'cable_points': np.zeros((points, 3)),
            'cable_forces': np.zeros((points, 3)), 'span_units': np.zeros((spans, 3)),
            'span_lengths': np.zeros(spans),
            'pair_sums': np.zeros((len(cables.pairs), 6, 3, 3)),
            'span_projection': np.zeros((3, 3)), 'start_hat': np.zeros((3, 3)),
            'end_hat': np.zeros((3, 3)), 'start_product': np.zeros((3, 3)),
            'end_product': np.zeros((3, 3)),
            'mesh_points': np.zeros((vertices, 3)), 'mesh_levers_a': np.zeros((vertices, 3)),
            'mesh_levers_b': np.zeros((vertices, 3)), 'mesh_forces': np.zeros((vertices, 3)),
            'mesh_wrenches': np.zeros((n_mesh, n_frames, 6))}

    @property
    def rhs(self):
        """Return the (6n, m + 1) buffer ``[r, J_aᵀ]`` that every evaluation writes."""
        return self.record.rhs

    def evaluate(self, positions, rotations, actuation, material=False):
        """
        Evaluate the residual, ``J_aᵀ`` and every tangent block at a state.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        actuation : (m,) ndarray  [N, Pa]
            ``λ`` (enters the residual and the load stiffness).
        material : bool
            Keep only the material tangent (:meth:`material_system`).

        Returns
        -------
        rhs : (6n, m + 1) ndarray
            Column 0: the residual ``f(q) + f_ext + J_aᵀ λ``; columns 1..m: ``J_aᵀ``. A buffer
            of this object (overwritten by the next evaluation).

        """
        evaluation.evaluate(self.record, _floats(positions), _floats(rotations),
                            _floats(actuation), not material, False)
        return self.record.rhs

    def linearise(self, positions, rotations, actuation):
        """
        Return the symmetric tangent (block band) and the right-hand sides of a tick.

        The control tick's evaluation: the exact tangent's symmetric part added into the band.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        actuation : (m,) ndarray
            ``λ_prev`` (enters the residual and the load stiffness).

        Returns
        -------
        tangent : (n, B + 1, 6, 6) ndarray
            ``K`` (symmetric part of structure + load stiffness) in block band storage,
            ``tangent[c, d] = K_(c + d, c)`` (:mod:`cbha_inverse.core._kernels.block_band`), for
            :meth:`factor`; :meth:`dense` converts it. A buffer of this object.
        rhs : (6n, m + 1) ndarray
            As :meth:`evaluate`.

        """
        evaluation.evaluate(self.record, _floats(positions), _floats(rotations),
                            _floats(actuation), True, True)
        return self.record.blocks[:self.n], self.record.rhs

    def material_system(self, positions, rotations, actuation):
        """
        Return the material tangent (block band, SPD) and the right-hand sides.

        The links' ``Dᵀ Bᵀ K B D`` alone (paper eq. 8): no geometric part, no load stiffness,
        so it stays positive definite far from equilibrium (the fallback of a step whose
        exact tangent is singular or indefinite). Arguments and results as :meth:`linearise`.

        """
        rhs = self.evaluate(positions, rotations, actuation, material=True)
        evaluation.assemble_symmetric(self.record)
        return self.record.blocks[:self.n], rhs

    def exact_system(self, positions, rotations, actuation):
        """
        Return the exact tangent (its frame blocks) and the right-hand sides.

        ``K = -d r / dq`` including the geometric part and the actuators' exact load stiffness
        (not symmetric): Newton's tangent (quadratic convergence). Arguments as
        :meth:`evaluate`.

        Returns
        -------
        tangent : (n, 2B + 1, 6, 6) ndarray
            ``tangent[c, B + d] = K_(c + d, c)`` (:mod:`cbha_inverse.core._kernels.block_lu`);
            :meth:`dense_exact` converts it. A buffer of this object.
        rhs : (6n, m + 1) ndarray
            As :meth:`evaluate`.

        """
        rhs = self.evaluate(positions, rotations, actuation)
        return self.exact_tangent(), rhs

    def exact_tangent(self):
        """
        Return the exact tangent of the last (exact) :meth:`evaluate`.

        Returns
        -------
        (n, 2B + 1, 6, 6) ndarray
            Its frame blocks (:meth:`exact_system`), a buffer of this object.

        """
        evaluation.assemble_exact(self.record)
        return self.record.exact_blocks[:self.n]

    def factor(self, tangent=None):
        """
        Factor the symmetric block band (of :meth:`linearise` or :meth:`material_system`).

        Parameters
        ----------
        tangent : (n, B + 1, 6, 6) ndarray, optional
            The block band those methods returned (this object's buffer, the default; it is
            factored in place).

        Returns
        -------
        BlockCholesky or None
            The compiled block Cholesky factor; ``None`` if the tangent is not positive
            definite.

        """
        self._check_buffer(tangent, self.record.blocks)
        if evaluation.factor_symmetric(self.record) != 0:
            return None
        return BlockCholesky(self.record.blocks[:self.n])

    def factor_exact(self):
        """
        Factor the exact tangent of the last (exact) :meth:`evaluate`, by block LU.

        Its blocks are assembled (as :meth:`exact_tangent`) and factored in place.

        Returns
        -------
        BlockLU or None
            ``None`` if the tangent is singular or not finite.

        """
        if evaluation.factor_exact(self.record) != 0:
            return None
        return BlockLU(self.record.exact_blocks[:self.n], self.record.lu_pivots)

    def _check_buffer(self, tangent, buffer):
        """Refuse a tangent that is not this object's buffer (the factors work in place on it)."""
        if tangent is not None and not np.shares_memory(tangent, buffer):
            raise ValueError('factor the tangent this system returned (its own buffer)')

    def dense_exact(self, tangent):
        """
        Return the blocks of :meth:`exact_system` as a dense matrix.

        Parameters
        ----------
        tangent : (n, 2B + 1, 6, 6) ndarray
            From :meth:`exact_system`.

        Returns
        -------
        (6n, 6n) ndarray

        """
        tangent, width = np.asarray(tangent), self.block_width
        out = np.zeros((self.size, self.size))
        for c in range(self.n):
            for d in range(max(-width, -c), min(width, self.n - 1 - c) + 1):
                out[6 * (c + d):6 * (c + d + 1), 6 * c:6 * (c + 1)] = tangent[c, width + d]
        return out

    def fallback_factors(self, positions, rotations, actuation, evaluated=False, load=None,
                         exact=True):
        """
        Yield the factors of the fallback chain, for a state whose first choice fails.

        The control tick's first choice is the Cholesky factor of the symmetric tangent
        (:meth:`linearise`), Newton's the exact tangent; when it fails (a tangent that is not
        positive definite at high pressures, a singular one near a limit point, a step that the
        line search rejects), the chain is, in this order:

        1. the exact tangent, structure + geometric part + exact load stiffness (not symmetric,
           :meth:`exact_system`), by block LU (:meth:`factor_exact`); with a user load stiffness
           ``load`` added, by dense LU;
        2. the material tangent alone (paper eq. 8, :meth:`material_system`), positive definite
           whatever the stresses, far from equilibrium too, by block Cholesky (:meth:`factor`).

        The residual is the same for every tangent (only the convergence rate changes). A
        tangent that does not factor is skipped. The evaluation of step 2 overwrites this
        object's buffers (those of the last evaluation).

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        actuation : (m,) ndarray  [N, Pa]
            ``λ`` (enters the load stiffness).
        evaluated : bool
            The last evaluation was an exact :meth:`evaluate` at this state and actuation: step
            1 reuses its blocks (the band of :meth:`linearise` or of the compiled tick has
            none).
        load : (6n, 6n) ndarray or None  [N/m, N, N*m/rad]
            Load stiffness ``-d f_load / dq`` of user follower loads, added to the exact tangent.
        exact : bool
            Begin with step 1 (else the caller has tried the exact tangent itself).

        Yields
        ------
        cbha_inverse.core.linalg.factors.TangentFactor
            Each factor that succeeds (``BlockLU`` or ``DenseLU``, then ``BlockCholesky``).

        """
        if exact:
            if not evaluated:
                self.evaluate(positions, rotations, actuation)
            if load is None:
                factor = self.factor_exact()
            else:
                factor = DenseLU(self.dense_exact(self.exact_tangent()) + load)
            if factor is not None:
                yield factor
        self.material_system(positions, rotations, actuation)
        factor = self.factor()
        if factor is not None:
            yield factor

    def scale_cavities(self, gains):
        """
        Scale each condensed cavity's wrench and load stiffness by a gain, in place.

        The evaluations (and the compiled tick, which holds the same arrays) then see cavity
        ``j`` with ``gains[j]`` times the effective area it was built with, as a scene's
        ``calibration.actuator_gain`` builds it.

        Parameters
        ----------
        gains : (m,) ndarray  [-]
            Gain of each actuator relative to the built one (1: unchanged).

        Raises
        ------
        ValueError
            If the actuators are not condensed cavities alone, or ``gains`` does not have shape
            (m,).

        """
        record = self.record
        if not self.has_cavities or record.cable_frames.size or record.mesh_columns.size:
            raise ValueError('actuator gains need condensed cavities alone')
        gains = np.asarray(gains, dtype=float)
        if gains.shape != (self.m,):
            raise ValueError(f'gains must have shape ({self.m},), got {gains.shape}')
        if self._built_cavities is None:
            self._built_cavities = (self._cavity_wrench.copy(), self._cavity_stiffness.copy())
        wrench, stiffness = self._built_cavities
        np.multiply(wrench, gains[None, :, None], out=self._cavity_wrench)
        np.multiply(stiffness, gains[None, :, None, None], out=self._cavity_stiffness)

    def tridiagonal_blocks(self, tangent):
        """
        Return the block band of :meth:`linearise` as the blocks of a block-tridiagonal matrix.

        Parameters
        ----------
        tangent : (n, 2, 6, 6) ndarray
            From :meth:`linearise` of a chain whose actuators act within a link.

        Returns
        -------
        diagonal : (n, 6, 6) ndarray
            Diagonal blocks (symmetric).
        upper : (n - 1, 6, 6) ndarray
            ``upper[i]`` = block (i, i + 1).

        """
        if self.block_width != 1:
            raise ValueError(f'the tangent is not block tridiagonal ({self.block_width} blocks '
                             'below the diagonal)')
        tangent = np.asarray(tangent)
        lower = np.tril(tangent[:, 0])
        diagonal = lower + np.swapaxes(np.tril(lower, -1), 1, 2)
        upper = np.swapaxes(tangent[:-1, 1], 1, 2)
        return diagonal, np.ascontiguousarray(upper)

    def dense(self, tangent):
        """
        Return the block band of :meth:`linearise` as a full lower-triangular matrix.

        Parameters
        ----------
        tangent : (n, B + 1, 6, 6) ndarray
            From :meth:`linearise` (or its factor).

        Returns
        -------
        (6n, 6n) ndarray
            ``K`` on and below the diagonal, zero above.

        """
        tangent = np.asarray(tangent)
        out = np.zeros((self.size, self.size))
        for c in range(self.n):
            for d in range(min(tangent.shape[1], self.n - c)):
                out[6 * (c + d):6 * (c + d + 1), 6 * c:6 * (c + 1)] = tangent[c, d]
        return np.tril(out)


def chain_stiffness(model, state=None):
    """
    Return the symmetric tangent stiffness of a bare chain over frames 1..n (dense).

    Parameters
    ----------
    model : cbha_inverse.core.chain.ChainModel
        The chain.
    state : cbha_inverse.core.chain.ChainState, optional
        Frame poses (default: the rest shape, where the tangent is the assembled ``K`` of the
        links, paper eq. 8).

    Returns
    -------
    (6n, 6n) ndarray  [N/m, N, N*m/rad]

    """
    state = rest_state(model) if state is None else state
    system = EquilibriumSystem(model, ActuatorSet((), model.n_frames), np.zeros(6 * model.n_links))
    tangent, _ = system.linearise(state.positions, state.rotations, np.zeros(0))
    lower = system.dense(tangent)
    return lower + np.tril(lower, -1).T


def _floats(array):
    """Return an array as the compiled kernels take it (C-ordered floats, no copy if it is)."""
    return np.ascontiguousarray(array, dtype=float)


def _cable_fields(cables):
    """Return the record's cable fields of every cable of the scene."""
    return {'cable_gains': cables.gains, 'cable_columns': cables.columns,
            'cable_frames': cables.frames, 'cable_offsets': cables.offsets,
            'point_owner': cables.point_owner, 'point_slot': cables.point_slot,
            'span_start': cables.start, 'span_end': cables.end, 'span_owner': cables.span_owner,
            'span_pair': cables.span_pair}


def _mesh_fields(meshes, n_frames):
    """Return the record's skinned-mesh fields, every group's cavities numbered in a row."""
    fields = {name: [] for name in ('mesh_frame_a', 'mesh_local_a', 'mesh_local_b',
                                    'mesh_weight_b', 'mesh_triangles', 'mesh_owner',
                                    'mesh_gains', 'mesh_columns')}
    vertices, cavities = 0, 0
    for group, columns in meshes:
        for name, value in (('mesh_frame_a', group.frame_a), ('mesh_local_a', group.local_a),
                            ('mesh_local_b', group.local_b), ('mesh_weight_b', group.weight_b),
                            ('mesh_triangles', group.triangles + vertices),
                            ('mesh_owner', group.vertex_owner + cavities),
                            ('mesh_gains', group.gains), ('mesh_columns', columns)):
            fields[name].append(np.asarray(value))
        vertices += group.frame_a.size
        cavities += group.n_actuators
    empty = {'mesh_frame_a': (0,), 'mesh_local_a': (0, 3), 'mesh_local_b': (0, 3),
             'mesh_weight_b': (0,), 'mesh_triangles': (0, 3), 'mesh_owner': (0,),
             'mesh_gains': (0,), 'mesh_columns': (0,)}
    out = {}
    for name, parts in fields.items():
        dtype = float if name in ('mesh_local_a', 'mesh_local_b', 'mesh_weight_b',
                                  'mesh_gains') else np.int64
        out[name] = np.ascontiguousarray(np.concatenate(parts) if parts
                                         else np.zeros(empty[name]), dtype=dtype)
    return out


def nonzero_cavity_columns(cavity_wrench, cavity_stiffness):
    """
    Return the cavity columns of every link whose ``G0`` or ``H`` is nonzero, padded with -1.

    Parameters
    ----------
    cavity_wrench : (n, c, 6) ndarray  [N/Pa, N*m/Pa]
        ``G0`` per link and cavity column.
    cavity_stiffness : (n, c, 6, 6) ndarray
        ``H`` per link and cavity column.

    Returns
    -------
    (n, c) int64 ndarray
        Per link, its nonzero cavity columns in increasing order, then -1 (the link pass
        computes only those: the others add exact zeros).

    """
    n, c = cavity_wrench.shape[:2]
    nonzero = (np.any(cavity_wrench != 0.0, axis=2)
               | np.any(cavity_stiffness.reshape((n, c, 36)) != 0.0, axis=2))
    columns = np.full((n, c), -1, dtype=np.int64)
    for link in range(n):
        active = np.flatnonzero(nonzero[link])
        columns[link, :active.size] = active
    return columns


def _matches_links(group, model):
    """Whether every condensed cavity part has the rest geometry of its link."""
    lower = group.lower
    if lower.size == 0 or lower.min() < 0 or lower.max() >= model.n_links:
        return False
    return bool(np.allclose(group.rest_offset, np.asarray(model.rest_offsets)[lower],
                            rtol=0.0, atol=1e-12)
                and np.allclose(group.rest_rotation, np.asarray(model.rest_rotations)[lower],
                                rtol=0.0, atol=1e-12))
