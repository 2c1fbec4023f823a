"""
Compiled update of the shape estimator on string-potentiometer lengths, one entry per update.

The unknowns ``z`` (scaled: ``x = scale z``) are the effective actuation's gain and offset about
the measured pressures, ``λ = (1 + g) ∘ p + δ``, and optionally load unknowns ``μ``: up to two
weights (an error of the arm's own weight spread as its lumped masses, a payload mass at the
last frame: the wrench of one kg of each is a row of ``load``) and a stiffness error ``σ_j`` per
chain section (its links' stiffness is ``(1 + σ_j)`` times the model's, in the linearisation
itself; the row of ``load`` is ``∂r/∂σ_j``, the elastic force of the section's links at the
current frames, evaluated by :func:`cbha_inverse.core._kernels.links.link_pass_into` with their
model stiffness alone); they follow a random walk. At the current frames one linearisation of
the equilibrium (the control tick's :func:`cbha_inverse.core._kernels.tick.linearise_tick`,
completed by the backward sweep of its band factor) gives ``K⁻¹ [r, J_aᵀ]``; with the pots'
lengths ``ℓ0`` and gradient ``J_s``
(:func:`cbha_inverse.core._kernels.cables.routing_lengths_into`) the lengths after the Newton
step are linear in ``z``: ``ℓ = base + H z``, ``H = W_sa [diag(p), I] | W_sμ``,
``W_sa = J_s K⁻¹ J_aᵀ`` (the pots' ``W_ea``, paper eq. 11), ``W_sμ = J_s K⁻¹ ∂r/∂μ`` (by the
implicit function theorem, the lengths' derivative along the equilibrium).
:func:`kalman_lengths` is the Kalman update on them, :func:`estimate_tick` the whole update:
linearisation, Kalman update, the Newton step of the same factorisation
(:func:`cbha_inverse.core._kernels.retraction.apply_linear_step_into`) and the effector
positions, over the preallocated buffers of
:class:`cbha_inverse.estimate.data.EstimatorData` (rows below).
"""

import math

from cbha_inverse.core._kernels import tick
from cbha_inverse.core._kernels.band import band_backward, band_solve
from cbha_inverse.core._kernels.band_assembly import band_rows
from cbha_inverse.core._kernels.cables import routing_lengths_into
from cbha_inverse.core._kernels.links import link_pass_into
from cbha_inverse.core._kernels.projection import (effector_columns_into, effector_points_into,
                                                   project_effectors_into)
from cbha_inverse.core._kernels.retraction import apply_linear_step_into
import numba

# rows of the per-pot vectors (POT_ROWS, c)
MEASURED, NOISE, LENGTH0, BASE, PREDICTED, RATIO = 0, 1, 2, 3, 4, 5
POT_ROWS = 6
# rows of the unknowns' vectors (STATE_ROWS, u)
Z, WALK, SCALE, GAIN_OF = 0, 1, 2, 3
STATE_ROWS = 4
# rows of the actuator vectors (PRESSURE_ROWS, m): measured pressures, those of the last update
PRESSURE, LAST_PRESSURE = 0, 1
PRESSURE_ROWS = 2
# entries of the scalars (SCALARS,): relative walk of the offset per measured pressure change,
# outlier gate [sigma], gate on (1) / off (0), mass columns solved by the band factor (1) or
# given (0), largest frame rotation of a step [rad]
CHANGE_WALK, GATE_SIGMA, GATE, SOLVE_MASS, MAX_ROTATION = 0, 1, 2, 3, 4
SCALARS = 5


@numba.njit(cache=True)
def kalman_lengths(h, pots, state, covariance, stuck, active, work):
    """
    Run the Kalman update of the unknowns on the pot lengths, in place.

    The prior is ``state[Z]`` with ``covariance + diag(state[WALK])``; a pot's innovation
    against it, over its standard deviation, is ``pots[RATIO]``; the pots not ``stuck`` and
    within the gate ``work[u + 1]`` standard deviations of it (0: no gate; no gate either when
    half of the pots or more are off) are ``active`` and update the mean
    and the covariance one after the other (exact for independent noise).

    Parameters
    ----------
    h : (c, u) ndarray
        ``dℓ/dz`` [m].
    pots : (POT_ROWS, c) ndarray
        Reads ``MEASURED``, ``NOISE`` [m] and ``BASE`` (``ℓ = base + H z``), writes ``RATIO``
        and ``PREDICTED`` (``base + H z`` at the posterior).
    state : (STATE_ROWS, u) ndarray
        ``Z`` (prior mean in, posterior out) and ``WALK`` (variance per update).
    covariance : (u, u) ndarray
        Covariance of ``z`` (in and out).
    stuck : (c,) bool ndarray
        Pots left out whatever their innovation.
    active : (c,) bool ndarray
        Receives the pots used.
    work : (u + 2,) ndarray
        Workspace; ``work[u + 1]`` is the gate [sigma] (0: off).

    """
    c, u = h.shape
    z = state[Z]
    for j in range(u):
        covariance[j, j] += state[WALK, j]
    gain = work[:u]
    sigma = work[u + 1]
    for i in range(c):
        innovation = pots[MEASURED, i] - pots[BASE, i]
        spread = pots[NOISE, i] * pots[NOISE, i]
        for j in range(u):
            innovation -= h[i, j] * z[j]
            acc = 0.0
            for k in range(u):
                acc += covariance[j, k] * h[i, k]
            spread += h[i, j] * acc
        pots[RATIO, i] = abs(innovation) / math.sqrt(spread)
    # the gate drops a minority of pots: when more are off, the linear model is (a jump of the
    # arm), not the pots
    off = 0
    for i in range(c):
        off += not stuck[i] and sigma > 0.0 and pots[RATIO, i] > sigma
    for i in range(c):
        active[i] = not stuck[i] and not (2 * off < c and sigma > 0.0
                                          and pots[RATIO, i] > sigma)
    for i in range(c):
        if not active[i]:
            continue
        innovation = pots[MEASURED, i] - pots[BASE, i]
        spread = pots[NOISE, i] * pots[NOISE, i]
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
        acc = pots[BASE, i]
        for j in range(u):
            acc += h[i, j] * z[j]
        pots[PREDICTED, i] = acc


@numba.njit(cache=True)
def section_loads(buffers, sections, masses, load):
    """
    Scale the sections' link stiffness by ``1 + σ_j`` and write ``∂r/∂σ_j``, in place.

    The last ``s`` entries of ``masses`` are the sections' ``σ`` at the linearisation (``s``
    the first dimension of ``sections[3]``; none: nothing to do). The tick's link stiffness
    (``buffers.stiffness``, a read-only view of ``sections[2]``) becomes the model's times
    ``1 + σ`` of each link's section, so the linearisation is that of the scaled chain (as a
    scene's ``calibration.section_stiffness`` builds it); row ``w - s + j`` of ``load`` becomes
    the elastic force of section ``j``'s links at the current frames, their model stiffness
    alone (the link pass at zero actuation, no cavity: ``-Dᵀ Bᵀ K δ``, paper eq. 4-7), over
    the section's links and the link before it (zero in ``section_stiffness``: its frame ``a``
    is the section's first frame, which the pass skips for a chain's first link).

    Parameters
    ----------
    buffers : cbha_inverse.core._kernels.tick_buffers.TickBuffers
        The estimator's tick buffers (frames, rest terms).
    sections : tuple
        ``link_section`` (n,) int (a link's section, -1: none), ``nominal`` (n, 6, 6) (the
        model's link stiffness), ``stiffness`` (n, 6, 6) (receives the scaled one),
        ``section_stiffness`` (s, n, 6, 6) (the model's stiffness of section ``j``'s links,
        zero elsewhere), ``ranges`` (s, 2) int (first link and count of each section), then
        the link pass's arguments without cavities and its workspaces: ``actuation`` (0,),
        ``cavity_wrench`` (n, 0, 6), ``cavity_stiffness`` (n, 0, 6, 6), ``cavity_columns``
        (n, 0), ``rhs`` (6n, 1), ``blocks`` (n, 12, 12), ``work``.
    masses : (w,) ndarray
        The load unknowns of the linearisation (weights [kg], then the sections' ``σ`` [-]).
    load : (w, 6n) ndarray
        Its last ``s`` rows receive ``∂r/∂σ_j`` [N, N*m].

    """
    (link_section, nominal, stiffness, section_stiffness, ranges, actuation, cavity_wrench,
     cavity_stiffness, cavity_columns, rhs, blocks, work) = sections
    n_sections = section_stiffness.shape[0]
    if n_sections == 0:
        return
    first = masses.size - n_sections
    for link in range(link_section.size):
        section = link_section[link]
        factor = 1.0 if section < 0 else 1.0 + masses[first + section]
        for i in range(6):
            for j in range(6):
                stiffness[link, i, j] = factor * nominal[link, i, j]
    rest_rotations_t = buffers.rest_rotations_t
    for section in range(n_sections):
        low = max(ranges[section, 0] - 1, 0)
        high = ranges[section, 0] + ranges[section, 1]
        rotations_t = (rest_rotations_t[low:high] if rest_rotations_t.shape[0] > 0
                       else rest_rotations_t)
        link_pass_into(buffers.positions[low:high + 1], buffers.rotations[low:high + 1],
                       section_stiffness[section, low:high], buffers.rest_offsets[low:high],
                       rotations_t, actuation, cavity_wrench[low:high],
                       cavity_stiffness[low:high], cavity_columns[low:high],
                       rhs[6 * low:6 * high], blocks[low:high], True, work)
        row = first + section
        load[row, :] = 0.0
        for k in range(6 * low, 6 * high):
            load[row, k] = rhs[k, 0]


@numba.njit(cache=True)
def estimate_tick(buffers, cholesky, routing, pots, jacobian, moved, h, state,
                  covariance, pressures, scalars, masses, load, base_external, mass_columns,
                  mass_rhs, mass_effectors, stuck, active, free_step, effector_w,
                  effector_positions, tip_covariance, work, sections):
    """
    Run one estimator update (linearise, Kalman update, Newton step), in place.

    Parameters
    ----------
    buffers : cbha_inverse.core._kernels.tick_buffers.TickBuffers
        :attr:`cbha_inverse.core.inverse.tick_data.TickData.buffers` of the estimator's own
        tick data (frames, ``vectors[ACTUATION]`` = the actuation of the linearisation, the
        model terms and buffers).
    cholesky : bool
        Factor the symmetric band (else return at once for the fallback chain).
    routing : tuple
        The pots' routing (frames, offsets, span start, end, owner, point owner) and its
        workspace (:func:`~cbha_inverse.core._kernels.cables.routing_work_size`).
    pots : (POT_ROWS, c) ndarray
        Per-pot rows (see :func:`kalman_lengths`; ``LENGTH0`` receives ``ℓ0``).
    jacobian : (c, 6n) ndarray
        Receives ``J_s``.
    moved : (c, m + 1 + w) ndarray
        Receives ``J_s K⁻¹ [r, J_aᵀ, J_μᵀ]`` [m, m/Pa, m/kg or m] (``w`` load unknowns: 0-2
        weights, then the sections' stiffness errors).
    h : (c, u) ndarray
        Receives ``dℓ/dz``.
    state : (STATE_ROWS, u) ndarray
        ``Z``, ``WALK``, ``SCALE`` and ``GAIN_OF`` (1 for the gains, 0 otherwise) of the
        unknowns ``(g, δ, μ)`` (``u = 2 m + w``).
    covariance : (u, u) ndarray
        Covariance of ``z``.
    pressures : (PRESSURE_ROWS, m) ndarray  [Pa]
        Measured pressures (zero when none) and those of the previous update.
    scalars : (SCALARS,) ndarray
        See the module's rows.
    masses : (w,) ndarray  [kg, -]
        The load unknowns of the linearisation (in and out: those after the step): the
        weights, then the sections' stiffness errors ``σ``.
    load : (w, 6n) ndarray  [N/kg, N]
        ``J_μᵀ``: the external wrench of one kg of each weight unknown (the arm's own weight's
        distribution, the payload at the last frame), then ``∂r/∂σ_j`` of each section (written
        here, :func:`section_loads`).
    base_external : (6n,) ndarray  [N, N*m]
        External wrenches without the weight unknowns.
    mass_columns, mass_rhs : (6n, 1 + w) ndarray
        Workspace: ``K⁻¹ [r, J_μᵀ]`` (the load columns solved here with ``SOLVE_MASS``, else
        given) and ``[r, J_μᵀ]``.
    mass_effectors : tuple
        Workspace of the load unknowns' projection on the effectors: ``w`` (3k, w), ``w_aa``
        (w, w), ``offset`` (3k,), ``moved`` (3k, 1 + w), ``levers`` (k, 3), ``previous``
        (w,), ``columns`` (6n, 3k) (``J_eᵀ``).
    stuck, active : (c,) bool ndarray
        Pots left out; receives the pots used.
    free_step : (6n,) ndarray
        Workspace: ``K⁻¹ r + K⁻¹ J_μᵀ Δμ``.
    effector_w : (3, u) ndarray
        Receives the last effector's ``d p / dz`` [m].
    effector_positions : (k, 3) ndarray  [m]
        Receives the effector positions after the step.
    tip_covariance : (3, 3) ndarray  [m^2]
        Receives the last effector's covariance ``W P Wᵀ`` (``W = effector_w``, linear).
    work : (max(u + 2, n * 6),) ndarray
        Workspace.
    sections : tuple
        The sections' stiffness unknowns (:func:`section_loads`; none: ``section_stiffness``
        of shape (0, n, 6, 6)).

    Returns
    -------
    int
        0 when the update ran, else the band Cholesky's code (nothing changed but the
        evaluation, for the fallback chain; then run :func:`estimate_from_linearisation`).

    """
    external = buffers.external
    size = external.size
    for row in range(size):
        external[row] = base_external[row]
    for a in range(masses.size - sections[3].shape[0]):
        for row in range(size):
            external[row] += masses[a] * load[a, row]
    section_loads(buffers, sections, masses, load)
    info, _ = tick.linearise_tick(buffers, cholesky)
    if info != 0:
        return info
    estimate_from_linearisation(buffers, routing, pots, jacobian, moved, h, state,
                                covariance, pressures, scalars, masses, load, mass_columns,
                                mass_rhs, mass_effectors, stuck, active, free_step,
                                effector_w, effector_positions, tip_covariance, work)
    return 0


@numba.njit(cache=True)
def estimate_from_linearisation(buffers, routing, pots, jacobian, moved, h, state,
                                covariance, pressures, scalars, masses, load, mass_columns,
                                mass_rhs, mass_effectors, stuck, active, free_step,
                                effector_w, effector_positions, tip_covariance, work):
    """
    :func:`estimate_tick` after its linearisation (the tick data hold a solved one).

    The tick's half-solves ``L⁻¹ [r, J_aᵀ]`` (``half_solved``) are completed to
    ``K⁻¹ [r, J_aᵀ]`` by the backward sweep of the band factor first.
    """
    positions, rotations, vectors = buffers.positions, buffers.rotations, buffers.vectors
    band, rhs, solved = buffers.band, buffers.rhs, buffers.solved
    size = solved.shape[0]
    factor = band_rows(band, size)
    if buffers.half_solved[0]:
        band_backward(factor, solved)
        buffers.half_solved[0] = False
    w_ea = buffers.effector_matrices[tick.W_EA]
    effector_frames, effector_offsets = buffers.effector_frames, buffers.effector_offsets
    m = solved.shape[1] - 1
    c, u = h.shape
    n_mass = masses.size
    routing_lengths_into(positions, rotations, routing[0], routing[1], routing[2], routing[3],
                         routing[4], routing[5], pots[LENGTH0], jacobian, routing[6])
    if n_mass:
        for row in range(size):
            mass_columns[row, 0] = solved[row, 0]
            mass_rhs[row, 0] = rhs[row, 0]
            for a in range(n_mass):
                mass_rhs[row, 1 + a] = load[a, row]
        if scalars[SOLVE_MASS] > 0.0:
            for row in range(size):
                for a in range(n_mass):
                    mass_columns[row, 1 + a] = mass_rhs[row, 1 + a]
            band_solve(factor, mass_columns[:, 1:])
        w_mass, w_aa, offset, levers_moved, levers, previous, columns = mass_effectors
        effector_columns_into(rotations, effector_frames, effector_offsets, levers, columns)
        project_effectors_into(mass_columns, mass_rhs, columns, False, positions, rotations,
                               effector_frames, effector_offsets, previous, w_mass, w_aa, offset,
                               levers_moved)
    for i in range(c):
        for j in range(m + 1 + n_mass):
            acc = 0.0
            if j <= m:
                for row in range(size):
                    acc += jacobian[i, row] * solved[row, j]
            else:
                for row in range(size):
                    acc += jacobian[i, row] * mass_columns[row, j - m]
            moved[i, j] = acc
    # ℓ = ℓ0 + J_s K⁻¹ r + W_sa (λ(z) - λ_lin) + W_sμ (μ - μ_lin), λ(z) = (1 + g) ∘ p + δ
    lam = vectors[tick.ACTUATION]
    p = pressures[PRESSURE]
    scale = state[SCALE]
    for i in range(c):
        acc = pots[LENGTH0, i] + moved[i, 0]
        for j in range(m):
            acc += moved[i, 1 + j] * (p[j] - lam[j])
            h[i, j] = moved[i, 1 + j] * p[j] * scale[j]
            h[i, m + j] = moved[i, 1 + j] * scale[m + j]
        for a in range(n_mass):
            acc -= moved[i, m + 1 + a] * masses[a]
            h[i, 2 * m + a] = moved[i, m + 1 + a] * scale[2 * m + a]
        pots[BASE, i] = acc
    # the offset's walk grows with the measured change of the pressures
    for j in range(m):
        change = scalars[CHANGE_WALK] * (p[j] - pressures[LAST_PRESSURE, j]) / scale[m + j]
        state[WALK, m + j] += change * change
        pressures[LAST_PRESSURE, j] = p[j]
    work[u + 1] = scalars[GATE_SIGMA] if scalars[GATE] > 0.0 else 0.0
    kalman_lengths(h, pots, state, covariance, stuck, active, work)
    # the Newton step of the same factorisation to the new actuation and weights
    change = vectors[tick.CHANGE]
    z = state[Z]
    for j in range(m):
        new = (1.0 + z[j] * scale[j]) * p[j] + z[m + j] * scale[m + j]
        change[j] = new - lam[j]
        lam[j] = new
    for row in range(size):
        acc = solved[row, 0]
        for a in range(n_mass):
            acc += mass_columns[row, 1 + a] * (z[2 * m + a] * scale[2 * m + a] - masses[a])
        free_step[row] = acc
    n = size // 6
    increments = work[:6 * n].reshape((n, 6))
    apply_linear_step_into(positions, rotations, free_step, solved[:, 1:], change,
                           scalars[MAX_ROTATION], increments, factor, False, False)
    for a in range(n_mass):
        masses[a] = z[2 * m + a] * scale[2 * m + a]
    effector_points_into(positions, rotations, effector_frames, effector_offsets,
                         effector_positions)
    last = w_ea.shape[0] - 3
    for i in range(3):
        for j in range(m):
            effector_w[i, j] = w_ea[last + i, j] * p[j] * scale[j]
            effector_w[i, m + j] = w_ea[last + i, j] * scale[m + j]
        for a in range(n_mass):
            effector_w[i, 2 * m + a] = mass_effectors[0][last + i, a] * scale[2 * m + a]
    for i in range(3):
        for k in range(3):
            acc = 0.0
            for j in range(u):
                for q in range(u):
                    acc += effector_w[i, j] * covariance[j, q] * effector_w[k, q]
            tip_covariance[i, k] = acc


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
    history[counters[0]] = lengths
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
