"""
Compiled update of the shape estimator on string-potentiometer lengths, one entry per update.

The unknowns ``z`` (scaled: ``x = scale z``) are the effective actuation's gain and offset about
the measured pressures, ``λ = (1 + g) ∘ p + δ``, and optionally load unknowns ``μ``: up to two
weights (an error of the arm's own weight spread as its lumped masses, a payload mass at the
last frame: the wrench of one kg of each is a row of ``load``) and a stiffness error ``σ_j`` per
chain section (its links' stiffness is ``(1 + σ_j)`` times the model's, in the linearisation
itself; the row of ``load`` is ``∂r/∂σ_j``, the elastic force of the section's links at the
current frames, their model stiffness alone: :func:`estimator_loads`); they follow a random walk.
At the current frames one linearisation of the equilibrium (the control tick's
:func:`cbha_inverse.core._kernels.tick.linearise_tick`, completed by the backward sweep of its
block factor) gives ``K⁻¹ [r, J_aᵀ]``; with the pots' lengths ``ℓ0`` and gradient ``J_s``
(:func:`cbha_inverse.core._kernels.cables.routing_lengths_into`) the lengths after the Newton
step are linear in ``z``: ``ℓ = base + H z``, ``H = W_sa [diag(p), I] | W_sμ``,
``W_sa = J_s K⁻¹ J_aᵀ`` (the pots' ``W_ea``, paper eq. 11), ``W_sμ = J_s K⁻¹ ∂r/∂μ`` (by the
implicit function theorem, the lengths' derivative along the equilibrium).
:func:`kalman_lengths` is the Kalman update on them. An update is three compiled calls over one
:class:`EstimatorRecord` (fields :data:`ESTIMATOR_FIELDS`, built by
:class:`cbha_inverse.estimate.data.EstimatorData`): :func:`estimator_loads`, the linearisation,
then :func:`estimate_from_linearisation` (the Kalman update, the Newton step of the same
factorisation, :func:`cbha_inverse.core._kernels.retraction.apply_linear_step_into`, and the
effector positions).
"""

import math

from cbha_inverse.core._kernels.block_band import block_solve
from cbha_inverse.core._kernels.cables import routing_lengths_into
from cbha_inverse.core._kernels.evaluation import evaluate
from cbha_inverse.core._kernels.projection import (effector_columns_into, effector_points_into,
                                                   project_effectors_into)
from cbha_inverse.core._kernels.records import define_record, Field, Record, RecordType
from cbha_inverse.core._kernels.retraction import apply_linear_step_into
from cbha_inverse.core._kernels.tick import backward_solves
import numba
from numba.experimental import structref
import numpy as np

F8, I8 = np.float64, np.int64

ESTIMATOR_FIELDS = (
    Field('tick', 'record', 0, "the estimator's tick buffers (tick.TickRecord)"),
    # the pots: c of them, routed through P points along S spans
    Field('pot_frames', I8, 1, '(P,) frame of every routing point', read_only=True),
    Field('pot_offsets', F8, 2, '(P, 3) routing points in their frame [m]', read_only=True),
    Field('pot_span_start', I8, 1, '(S,) first point of every span', read_only=True),
    Field('pot_span_end', I8, 1, '(S,) second point of every span', read_only=True),
    Field('pot_span_owner', I8, 1, '(S,) pot of every span', read_only=True),
    Field('pot_point_owner', I8, 1, '(P,) pot of every point', read_only=True),
    Field('measured', F8, 1, '(c,) measured lengths [m]'),
    Field('noise', F8, 1, '(c,) their noise std [m]'),
    Field('stuck', np.bool_, 1, '(c,) pots left out'),
    Field('active', np.bool_, 1, '(c,) the pots the update used'),
    Field('length0', F8, 1, '(c,) lengths at the linearisation [m]'),
    Field('base', F8, 1, '(c,) lengths after the step at z = 0: l = base + H z [m]'),
    Field('predicted', F8, 1, '(c,) base + H z at the posterior [m]'),
    Field('ratio', F8, 1, '(c,) innovation over its std'),
    Field('jacobian', F8, 2, '(c, 6n) J_s = d l / dq'),
    Field('moved', F8, 2, '(c, m + 1 + w) J_s K⁻¹ [r, J_aᵀ, J_μᵀ]'),
    Field('h', F8, 2, '(c, u) d l / d z [m]'),
    # the unknowns z (u = 2 m + w) and the pressures
    Field('z', F8, 1, '(u,) the unknowns (scaled)'),
    Field('walk', F8, 1, '(u,) their random walk variance per update'),
    Field('unknown_scale', F8, 1, '(u,) x = scale z'),
    Field('covariance', F8, 2, '(u, u) covariance of z'),
    Field('kalman_gain', F8, 1, '(u,) workspace of the update'),
    Field('pressures', F8, 1, '(m,) measured pressures (0 when none) [Pa]'),
    Field('last_pressures', F8, 1, '(m,) those of the previous update [Pa]'),
    Field('change_walk', float, 0, 'relative walk of the offset per measured pressure change'),
    Field('gate_sigma', float, 0, 'outlier gate [sigma]'),
    Field('gate', np.bool_, 1, '(1,) whether the gate is on'),
    Field('solve_mass', np.bool_, 1, '(1,) solve the load columns by the block factor'),
    # the load unknowns μ (w of them: weights [kg], then the sections' σ [-])
    Field('masses', F8, 1, '(w,) the load unknowns of the linearisation'),
    Field('load', F8, 2, '(w, 6n) J_μᵀ: wrench of one kg, then ∂r/∂σ_j [N/kg, N]'),
    Field('base_external', F8, 1, '(6n,) external wrenches without the weight unknowns'),
    Field('mass_columns', F8, 2, '(6n, 1 + w) K⁻¹ [r, J_μᵀ]'),
    Field('load_solved', F8, 2, "(6n, w) K⁻¹ J_μᵀ (the block solve's columns)"),
    Field('mass_rhs', F8, 2, '(6n, 1 + w) [r, J_μᵀ]'),
    Field('mass_w', F8, 2, "(3k, w) the load unknowns' W on the effectors"),
    Field('mass_w_aa', F8, 2, '(w, w) their W_aa (unused)'),
    Field('mass_offset', F8, 1, "(3k,) their projection's offset (unused)"),
    Field('mass_moved', F8, 2, '(3k, 1 + w) workspace of their projection'),
    Field('mass_levers', F8, 2, '(k, 3) workspace of their projection'),
    Field('mass_previous', F8, 1, '(w,) zeros'),
    Field('mass_effector_columns', F8, 2, '(6n, 3k) J_eᵀ'),
    # the sections' stiffness unknowns (s of them)
    Field('link_section', I8, 1, '(n,) section of every link (-1: none)'),
    Field('nominal', F8, 3, "(n, 6, 6) the model's link stiffness", read_only=True),
    Field('scaled_stiffness', F8, 3, '(n, 6, 6) receives (1 + σ) K (the tick reads it)'),
    Field('section_stiffness', F8, 4, "(s, n, 6, 6) section j's links' stiffness, else 0",
          read_only=True),
    Field('sections', 'record', 0, 'an evaluator of the bare chain (∂r/∂σ_j)'),
    # the outcome
    Field('free_step', F8, 2, '(6n, 1) K⁻¹ r + K⁻¹ J_μᵀ Δμ'),
    Field('effector_w', F8, 2, "(3, u) the last effector's d p / d z [m]"),
    Field('effector_positions', F8, 2, '(k, 3) effector positions after the step [m]'),
    Field('tip_covariance', F8, 2, "(3, 3) the last effector's covariance [m^2]"),
    # scratch of the pots' routing
    Field('pot_levers', F8, 2, '(P, 3)'),
    Field('pot_points', F8, 2, '(P, 3)'),
    Field('pot_forces', F8, 2, '(P, 3)'),
    Field('pot_units', F8, 2, '(S, 3)'),
    Field('pot_span_lengths', F8, 1, '(S,)'),
    Field('pot_unit_gains', F8, 1, '(c,) ones', read_only=True),
)
"""The fields of :class:`EstimatorRecord`."""


@structref.register
class EstimatorRecordType(RecordType):
    """The numba type of :class:`EstimatorRecord`."""


class EstimatorRecord(Record):
    """The buffers of one shape estimator's updates (:data:`ESTIMATOR_FIELDS`)."""

    __slots__ = ()


define_record(EstimatorRecord, EstimatorRecordType, ESTIMATOR_FIELDS)


@numba.njit(cache=True)
def new_estimator_record(*values):
    """Build an :class:`EstimatorRecord` (fields in declaration order)."""
    return EstimatorRecord(*values)


@numba.njit(cache=True)
def kalman_lengths(h, measured, noise, base, z, walk, covariance, stuck, gate_sigma, active,
                   gain, ratio, predicted):
    """
    Run the Kalman update of the unknowns on the pot lengths, in place.

    The prior is ``z`` with ``covariance + diag(walk)``; a pot's innovation against it, over its
    standard deviation, is ``ratio``; the pots not ``stuck`` and within the gate ``gate_sigma``
    standard deviations of it (0: no gate; no gate either when half of the pots or more are off)
    are ``active`` and update the mean and the covariance one after the other (exact for
    independent noise).

    Parameters
    ----------
    h : (c, u) ndarray
        ``dℓ/dz`` [m].
    measured, noise, base : (c,) ndarray  [m]
        Measured lengths, their noise std, and ``base`` (``ℓ = base + H z``).
    z : (u,) ndarray
        Prior mean in, posterior out.
    walk : (u,) ndarray
        Variance added per update.
    covariance : (u, u) ndarray
        Covariance of ``z`` (in and out).
    stuck : (c,) bool ndarray
        Pots left out whatever their innovation.
    gate_sigma : float
        The gate (0: off).
    active : (c,) bool ndarray
        Receives the pots used.
    gain : (u,) ndarray
        Workspace.
    ratio, predicted : (c,) ndarray
        Receive the innovation ratios and ``base + H z`` at the posterior.

    """
    c, u = h.shape
    for j in range(u):
        covariance[j, j] += walk[j]
    for i in range(c):
        innovation = measured[i] - base[i]
        spread = noise[i] * noise[i]
        for j in range(u):
            innovation -= h[i, j] * z[j]
            acc = 0.0
            for k in range(u):
                acc += covariance[j, k] * h[i, k]
            spread += h[i, j] * acc
        ratio[i] = abs(innovation) / math.sqrt(spread)
    # the gate drops a minority of pots: when more are off, the linear model is (a jump of the
    # arm), not the pots
    off = 0
    for i in range(c):
        off += not stuck[i] and gate_sigma > 0.0 and ratio[i] > gate_sigma
    for i in range(c):
        active[i] = not stuck[i] and not (2 * off < c and gate_sigma > 0.0
                                          and ratio[i] > gate_sigma)
    for i in range(c):
        if not active[i]:
            continue
        innovation = measured[i] - base[i]
        spread = noise[i] * noise[i]
        for j in range(u):
            innovation -= h[i, j] * z[j]
            acc = 0.0
            for k in range(u):
                acc += covariance[j, k] * h[i, k]
            gain[j] = acc
            spread += h[i, j] * acc
        for j in range(u):
            z[j] += gain[j] * innovation / spread
        for j in range(u):
            for k in range(u):
                covariance[j, k] -= gain[j] * gain[k] / spread
    for j in range(u):
        for k in range(j):
            mean = 0.5 * (covariance[j, k] + covariance[k, j])
            covariance[j, k] = mean
            covariance[k, j] = mean
    for i in range(c):
        acc = base[i]
        for j in range(u):
            acc += h[i, j] * z[j]
        predicted[i] = acc


@numba.njit(cache=True)
def estimator_loads(estimator):
    """
    Set the loads of the load unknowns at the current frames, in place (before a linearisation).

    The tick's external wrenches become ``base_external`` plus the weights' rows of ``load``
    times their current masses. The last ``s`` entries of ``masses`` are the sections' ``σ`` at
    the linearisation (none: nothing more to do): the tick's link stiffness
    (``scaled_stiffness``, which the tick's evaluator reads) becomes the model's times ``1 + σ``
    of each link's section, so the linearisation is that of the scaled chain (as a scene's
    ``calibration.section_stiffness`` builds it); row ``w - s + j`` of ``load`` becomes the
    elastic force of section ``j``'s links at the current frames, their model stiffness alone:
    the bare chain's residual (paper eq. 4-7) with the stiffness of ``section_stiffness[j]``,
    zero outside the section.
    """
    tick, masses, load = estimator.tick, estimator.masses, estimator.load
    section_stiffness = estimator.section_stiffness
    n_sections = section_stiffness.shape[0]
    first = masses.size - n_sections
    external, base_external = tick.system.external, estimator.base_external
    for row in range(external.size):
        external[row] = base_external[row]
    for a in range(first):
        for row in range(external.size):
            external[row] += masses[a] * load[a, row]
    if n_sections == 0:
        return
    nominal, scaled, link_section = (estimator.nominal, estimator.scaled_stiffness,
                                     estimator.link_section)
    for link in range(link_section.size):
        section = link_section[link]
        factor = 1.0 if section < 0 else 1.0 + masses[first + section]
        for i in range(6):
            for j in range(6):
                scaled[link, i, j] = factor * nominal[link, i, j]
    sections = estimator.sections
    for section in range(n_sections):
        sections.stiffness = section_stiffness[section]
        evaluate(sections, tick.positions, tick.rotations, estimator.mass_previous[:0],
                 bool(False), bool(False))
        rhs = sections.rhs
        for row in range(rhs.shape[0]):
            load[first + section, row] = rhs[row, 0]


@numba.njit(cache=True)
def estimate_from_linearisation(estimator):
    """
    Finish an update after its linearisation: Kalman update, Newton step, effector positions.

    The tick's buffers hold a solved linearisation at the loads of :func:`estimator_loads`
    (:func:`cbha_inverse.core._kernels.tick.linearise_tick`, or a factor of the fallback chain
    projected into them, with the load columns ``K⁻¹ J_μᵀ`` already in ``mass_columns`` when
    ``solve_mass`` is off). The tick's half-solves ``L⁻¹ [r, J_aᵀ]`` are completed to
    ``K⁻¹ [r, J_aᵀ]`` first.
    """
    tick = estimator.tick
    backward_solves(tick)
    routing_lengths_into(tick.positions, tick.rotations, estimator.pot_frames,
                         estimator.pot_offsets, estimator.pot_span_start,
                         estimator.pot_span_end, estimator.pot_span_owner,
                         estimator.pot_point_owner, estimator.length0, estimator.jacobian,
                         estimator.pot_levers, estimator.pot_points, estimator.pot_forces,
                         estimator.pot_units, estimator.pot_span_lengths,
                         estimator.pot_unit_gains)
    if estimator.masses.size:
        load_columns(estimator)
    linear_lengths(estimator)
    grow_offset_walk(estimator)
    kalman_lengths(estimator.h, estimator.measured, estimator.noise, estimator.base,
                   estimator.z, estimator.walk, estimator.covariance, estimator.stuck,
                   estimator.gate_sigma if estimator.gate[0] else 0.0, estimator.active,
                   estimator.kalman_gain, estimator.ratio, estimator.predicted)
    step_to_the_estimate(estimator)
    effector_points_into(tick.positions, tick.rotations, tick.effector_frames,
                         tick.effector_offsets, estimator.effector_positions)
    tip_covariance(estimator)


@numba.njit(cache=True, inline='always')
def load_columns(estimator):
    """
    Compute the load unknowns' columns ``K⁻¹ J_μᵀ`` and their ``W`` on the effectors (eq. 11).

    ``mass_columns = K⁻¹ [r, J_μᵀ]`` (the load columns by the tick's block factor when
    ``solve_mass`` is on, else as the caller left them) and ``mass_w = J_e K⁻¹ J_μᵀ``.
    """
    tick = estimator.tick
    solved, rhs, load = tick.solved, tick.system.rhs, estimator.load
    mass_columns, mass_rhs = estimator.mass_columns, estimator.mass_rhs
    size, n_mass = solved.shape[0], load.shape[0]
    for row in range(size):
        mass_columns[row, 0] = solved[row, 0]
        mass_rhs[row, 0] = rhs[row, 0]
        for a in range(n_mass):
            mass_rhs[row, 1 + a] = load[a, row]
    if estimator.solve_mass[0]:
        load_solved = estimator.load_solved
        for row in range(size):
            for a in range(n_mass):
                load_solved[row, a] = load[a, row]
        block_solve(tick.system.blocks[:size // 6], load_solved)
        for row in range(size):
            for a in range(n_mass):
                mass_columns[row, 1 + a] = load_solved[row, a]
    effector_columns_into(tick.rotations, tick.effector_frames, tick.effector_offsets,
                          estimator.mass_levers, estimator.mass_effector_columns)
    project_effectors_into(mass_columns, mass_rhs, estimator.mass_effector_columns,
                           bool(False), tick.column_starts, tick.positions, tick.rotations,
                           tick.effector_frames, tick.effector_offsets,
                           tick.orientation_effectors[:0], estimator.mass_previous,
                           estimator.mass_w, estimator.mass_w_aa, estimator.mass_offset,
                           estimator.mass_moved)


@numba.njit(cache=True, inline='always')
def linear_lengths(estimator):
    """
    Linearise the pots' lengths after the Newton step in the unknowns: ``ℓ = base + H z``.

    ``moved = J_s K⁻¹ [r, J_aᵀ, J_μᵀ]``; then ``ℓ = ℓ0 + J_s K⁻¹ r + W_sa (λ(z) - λ_lin) +
    W_sμ (μ - μ_lin)`` with ``λ(z) = (1 + g) ∘ p + δ`` gives ``base`` (``z = 0``) and ``H``.
    """
    tick = estimator.tick
    solved, mass_columns, jacobian, moved = (tick.solved, estimator.mass_columns,
                                             estimator.jacobian, estimator.moved)
    lam, p, scale = tick.actuation, estimator.pressures, estimator.unknown_scale
    masses = estimator.masses
    h, base, length0 = estimator.h, estimator.base, estimator.length0
    size, m, n_mass = solved.shape[0], solved.shape[1] - 1, masses.size
    for i in range(h.shape[0]):
        for j in range(m + 1 + n_mass):
            acc = 0.0
            if j <= m:
                for row in range(size):
                    acc += jacobian[i, row] * solved[row, j]
            else:
                for row in range(size):
                    acc += jacobian[i, row] * mass_columns[row, j - m]
            moved[i, j] = acc
        acc = length0[i] + moved[i, 0]
        for j in range(m):
            acc += moved[i, 1 + j] * (p[j] - lam[j])
            h[i, j] = moved[i, 1 + j] * p[j] * scale[j]
            h[i, m + j] = moved[i, 1 + j] * scale[m + j]
        for a in range(n_mass):
            acc -= moved[i, m + 1 + a] * masses[a]
            h[i, 2 * m + a] = moved[i, m + 1 + a] * scale[2 * m + a]
        base[i] = acc


@numba.njit(cache=True, inline='always')
def grow_offset_walk(estimator):
    """Grow the offsets' random walk with the measured change of the pressures."""
    walk, last, p = estimator.walk, estimator.last_pressures, estimator.pressures
    scale, m = estimator.unknown_scale, p.size
    for j in range(m):
        change = estimator.change_walk * (p[j] - last[j]) / scale[m + j]
        walk[m + j] += change * change
        last[j] = p[j]


@numba.njit(cache=True, inline='always')
def step_to_the_estimate(estimator):
    """
    Take the Newton step of the same factorisation to the estimated actuation and loads.

    ``λ = (1 + g) ∘ p + δ`` and ``μ`` at the posterior; ``dq = K⁻¹ r + K⁻¹ J_μᵀ Δμ +
    K⁻¹ J_aᵀ Δλ`` (:func:`~cbha_inverse.core._kernels.retraction.apply_linear_step_into`).
    """
    tick = estimator.tick
    solved, mass_columns, masses = tick.solved, estimator.mass_columns, estimator.masses
    lam, change, p = tick.actuation, tick.change, estimator.pressures
    z, scale = estimator.z, estimator.unknown_scale
    m, n_mass, free_step = p.size, masses.size, estimator.free_step
    for j in range(m):
        new = (1.0 + z[j] * scale[j]) * p[j] + z[m + j] * scale[m + j]
        change[j] = new - lam[j]
        lam[j] = new
    for row in range(solved.shape[0]):
        acc = solved[row, 0]
        for a in range(n_mass):
            acc += mass_columns[row, 1 + a] * (z[2 * m + a] * scale[2 * m + a] - masses[a])
        free_step[row, 0] = acc
    apply_linear_step_into(tick.positions, tick.rotations, free_step[:, 0], solved[:, 1:],
                           change, tick.max_rotation, tick.increments,
                           tick.system.blocks[:solved.shape[0] // 6], bool(False))
    for a in range(n_mass):
        masses[a] = z[2 * m + a] * scale[2 * m + a]


@numba.njit(cache=True, inline='always')
def tip_covariance(estimator):
    """Propagate to the last effector's covariance ``W_pz Σ W_pzᵀ``, ``W_pz = d p / d z`` [m²]."""
    tick = estimator.tick
    p, scale, covariance = estimator.pressures, estimator.unknown_scale, estimator.covariance
    effector_w, mass_w = estimator.effector_w, estimator.mass_w
    m, n_mass, u = p.size, estimator.masses.size, covariance.shape[0]
    last_row = 3 * tick.effector_frames.size - 3
    for i in range(3):
        for j in range(m):
            effector_w[i, j] = tick.w_ea[last_row + i, j] * p[j] * scale[j]
            effector_w[i, m + j] = tick.w_ea[last_row + i, j] * scale[m + j]
        for a in range(n_mass):
            effector_w[i, 2 * m + a] = mass_w[last_row + i, a] * scale[2 * m + a]
    for i in range(3):
        for k in range(3):
            acc = 0.0
            for j in range(u):
                for q in range(u):
                    acc += effector_w[i, j] * covariance[j, q] * effector_w[k, q]
            estimator.tip_covariance[i, k] = acc


@numba.njit(cache=True)
def stuck_pots(history, counters, lengths, stuck, tolerance, motion):
    """
    Add one reading to a window and update which pots are stuck, in place.

    Over the window, a pot is stuck when its range (max - min) is below ``tolerance`` while the
    median range of the other pots exceeds ``motion`` (more than half of them move more), and
    fewer than half of the pots are; a stuck pot stays stuck until its own range exceeds
    ``tolerance`` again.

    Parameters
    ----------
    history : (window, c) ndarray  [m]
        The last readings (a ring).
    counters : (2,) int ndarray
        Next slot of the ring and number of readings in it.
    lengths : (c,) ndarray  [m]
        The new reading.
    stuck : (c,) bool ndarray
        Stuck pots (in and out).
    tolerance, motion : float  [m]
        As above.

    """
    window, c = history.shape
    for i in range(c):
        history[counters[0], i] = lengths[i]
    counters[0] = (counters[0] + 1) % window
    counters[1] = min(counters[1] + 1, window)
    if counters[1] < window:
        return
    moving = 0
    for i in range(c):
        low, high = history[0, i], history[0, i]
        for k in range(1, window):
            low, high = min(low, history[k, i]), max(high, history[k, i])
        lengths_range = high - low
        moving += lengths_range > motion
        stuck[i] = stuck[i] and lengths_range < tolerance
    count = 0
    for i in range(c):
        low, high = history[0, i], history[0, i]
        for k in range(1, window):
            low, high = min(low, history[k, i]), max(high, history[k, i])
        if high - low < tolerance:
            others = moving - (high - low > motion)
            stuck[i] = stuck[i] or 2 * others > c - 1
        count += stuck[i]
    if 2 * count >= c:
        # half of the pots or more still: the arm holds a direction, no pot is broken
        stuck[:] = False
