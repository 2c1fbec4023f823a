"""
Compiled (numba) Cholesky factorisation and multi-RHS solve of symmetric band matrices.

Storage is LAPACK's lower band layout in C order, ``band[c, r - c] = K[r, c]`` for
``0 <= r - c <= kd`` (an (N, kd + 1) array: the Fortran (kd + 1, N) array of ``dpbtrf``). The
factorisation is right-looking, as LAPACK's unblocked ``dpbtf2``: every innermost loop is an axpy
over contiguous memory. For the small systems of a control tick (N ≤ ~100, kd ≤ ~20) it costs a few
microseconds, less than the call overhead of the LAPACK wrappers. Writing into the storage (the
assembly's scatter, a block-tridiagonal matrix's band) is
:mod:`cbha_inverse.core._kernels.band_assembly`.
"""

import math

import numba


@numba.njit(cache=True)
def band_cholesky(band):
    """
    Factor a symmetric positive definite band matrix in place, ``K = L Lᵀ`` (as LAPACK dpbtf2).

    Right-looking: each column of ``L`` is scaled, then the trailing block takes its rank-one
    update; the innermost loop is an axpy over contiguous memory (no loop-carried dependency).
    Half-bandwidth 11 (a block-tridiagonal frame chain) runs :func:`_cholesky_width12`, the same
    arithmetic with constant trip counts (~1.7x faster, identical result; also half-bandwidth 17,
    :data:`CABLE_BAND_WIDTH`, ~2x faster), or, when the band
    has the profile of 6 x 6 blocks (:func:`frame_profile`), :func:`_cholesky_frames`, which
    also skips the zeros outside it (~25 % faster again, identical result for finite values).

    Parameters
    ----------
    band : (N, kd + 1) ndarray
        Lower band storage, ``band[c, r - c] = K[r, c]`` for ``0 <= r - c <= kd`` (C order: the
        Fortran ``(kd + 1, N)`` layout of LAPACK; entries past the matrix end are ignored);
        overwritten by ``L`` in the same layout.

    Returns
    -------
    int
        0 on success, else ``j + 1`` for the first column whose pivot is not positive (or not
        finite); ``band`` is then partly overwritten.

    """
    return band_cholesky_profiled(band)[0]


@numba.njit(cache=True)
def band_cholesky_profiled(band):
    """
    Run :func:`band_cholesky` and tell whether its factor has the 6 x 6 block profile.

    The profile is checked once, on the band (:func:`frame_profile`): the factor of such a band
    keeps it (:func:`_cholesky_frames` writes no slot outside it), so the sweeps of that factor
    can skip their own check (:func:`band_forward_profiled`).

    Parameters
    ----------
    band : (N, kd + 1) ndarray
        As :func:`band_cholesky` (overwritten by ``L``).

    Returns
    -------
    info : int
        As :func:`band_cholesky`.
    profiled : bool
        Whether the band had the profile (then so has the factor, when ``info`` is 0).

    """
    if band.shape[1] == FRAME_BAND_WIDTH:
        if frame_profile(band):
            # no right-hand side: the sweep's loops vanish
            return _cholesky_frames(band, band[:0], 0, 0, 0), True
        return _cholesky_width12(band), False
    if band.shape[1] == CABLE_BAND_WIDTH:
        return _cholesky_constant_width(band, CABLE_BAND_WIDTH), False
    return _cholesky_columns(band, 0), False


@numba.njit(cache=True)
def band_cholesky_forward(band, rhs):
    """
    Run :func:`band_cholesky_profiled` and the forward sweep ``rhs <- L⁻¹ rhs`` in one pass.

    On the 6 x 6 block profile (:func:`frame_profile`) row ``j`` of the sweep runs right after
    column ``j`` of the factor (:func:`_cholesky_frames`), while the column is in L1, and the
    trailing columns that are zero down to some row (:func:`_zero_columns`: ``J_aᵀ`` of the
    actuators of a later section; so is ``L⁻¹ J_aᵀ`` there) are swept from that row's block
    on: ``x - w 0 = x`` for the finite factor. Each other entry of ``rhs`` takes the updates of
    :func:`band_forward_profiled` in the same order: the same result. Other bands are factored,
    then swept.

    Parameters
    ----------
    band : (N, kd + 1) ndarray
        As :func:`band_cholesky` (overwritten by ``L``).
    rhs : (N, c) ndarray
        Right-hand sides (C order), overwritten by ``L⁻¹ rhs`` when ``info`` is 0 (else partly).

    Returns
    -------
    info : int
        As :func:`band_cholesky`.
    profiled : bool
        As :func:`band_cholesky_profiled`.

    """
    counts = FORWARD_COLUMN_COUNTS
    if band.shape[1] == FRAME_BAND_WIDTH and frame_profile(band):
        n_rhs = rhs.shape[1]
        # literal column counts: one compiled specialisation each (a count known at run time
        # only makes the loops slower than the zeros they skip)
        if n_rhs == counts[0]:
            leading, zero_rows = _zero_columns(rhs)
            if leading == counts[0] - counts[2]:
                # the CBHA's: its second section's three actuators
                return _cholesky_frames(band, rhs, counts[0], counts[0] - counts[2],
                                        zero_rows), True
            return _cholesky_frames(band, rhs, counts[0], counts[0], 0), True
        if n_rhs == counts[1]:
            return _cholesky_frames(band, rhs, counts[1], counts[1], 0), True
        return _cholesky_frames(band, rhs, n_rhs, n_rhs, 0), True
    info, profiled = band_cholesky_profiled(band)
    if info == 0:
        band_forward_profiled(band, rhs, 0, profiled)
    return info, profiled


@numba.njit(cache=True)
def _zero_columns(rhs):
    """
    Return ``(p, s)``: columns ``p ... c - 1`` of ``rhs`` are zero in rows ``0 ... s - 1``.

    The split that leaves the most entries, ``(c - p) s``, out of the sweep
    (:func:`band_cholesky_forward`); ``(c, 0)`` when none is zero. The scan of a column stops at
    the first nonzero row, or at the rows that the columns after it leave.
    """
    size, n_rhs = rhs.shape
    leading, zero_rows, best = n_rhs, 0, 0
    rows = size
    for p in range(n_rhs - 1, -1, -1):
        q = 0
        while q < rows and rhs[q, p] == 0.0:
            q += 1
        rows = q
        if (n_rhs - p) * rows > best:
            leading, zero_rows, best = p, rows, (n_rhs - p) * rows
    return leading, zero_rows


@numba.njit(cache=True, inline='always')
def _factor_column(band, j, below):
    """
    Factor column ``j`` of :func:`band_cholesky`, update the trailing block; False on a bad pivot.

    ``below`` is the number of rows under the diagonal that the column reaches. Inlined into its
    callers, so a constant ``below`` gives loops of constant trip count.
    """
    column = band[j]
    pivot = column[0]
    if not (pivot > 0.0 and math.isfinite(pivot)):
        return False
    diagonal = math.sqrt(pivot)
    column[0] = diagonal
    inverse = 1.0 / diagonal
    for a in range(1, below + 1):
        column[a] *= inverse
    for b in range(1, below + 1):
        weight = column[b]
        target = band[j + b]
        for a in range(b, below + 1):
            target[a - b] -= column[a] * weight
    return True


@numba.njit(cache=True)
def _cholesky_columns(band, first):
    """Factor columns ``first`` ... N - 1 of :func:`band_cholesky` (envelope-length loops)."""
    size, width = band.shape
    kd = width - 1
    for j in range(first, size):
        if not _factor_column(band, j, min(kd, size - 1 - j)):
            return j + 1
    return 0


@numba.njit(cache=True)
def band_solve(factor, rhs):
    """
    Solve ``L Lᵀ X = rhs`` in place with a factor of :func:`band_cholesky`.

    :func:`band_forward` then :func:`band_backward`.

    Parameters
    ----------
    factor : (N, kd + 1) ndarray
        ``L`` in lower band storage.
    rhs : (N, c) ndarray
        Right-hand sides (C order), overwritten by ``X``.

    """
    band_forward(factor, rhs, 0)
    band_backward(factor, rhs)


@numba.njit(cache=True)
def band_forward(factor, rhs, first):
    """
    Solve ``L Y = rhs`` in place with a factor of :func:`band_cholesky` (the forward sweep).

    With ``K = L Lᵀ`` the control tick needs only these half-solves for its projection
    (``(L⁻¹ a)ᵀ (L⁻¹ b) = aᵀ K⁻¹ b``, `docs/design.md`); :func:`band_backward` completes a
    solve. Half-bandwidth 11 with :data:`FORWARD_COLUMN_COUNTS` right-hand sides runs the rows
    at least 12 from the end with constant trip counts (LLVM unrolls the loops over the
    columns); a factor with the profile of 6 x 6 blocks (:func:`frame_profile`) also skips the
    zeros outside it.

    Parameters
    ----------
    factor : (N, kd + 1) ndarray
        ``L`` in lower band storage.
    rhs : (N, c) ndarray
        Right-hand sides (C order), overwritten by ``Y``.
    first : int
        Rows ``0 ... first - 1`` of ``rhs`` are zero (so are those of ``Y``): the sweep starts
        at ``first`` (rounded down to a block of 6 on the block profile).

    """
    band_forward_profiled(factor, rhs, first,
                          factor.shape[1] == FRAME_BAND_WIDTH and frame_profile(factor))


@numba.njit(cache=True)
def band_forward_profiled(factor, rhs, first, profiled):
    """
    Run :func:`band_forward` with the factor's profile check given.

    Parameters
    ----------
    factor, rhs, first
        As :func:`band_forward`.
    profiled : bool
        Whether ``factor`` has the 6 x 6 block profile (:func:`frame_profile`), as
        :func:`band_cholesky_profiled` returned it for this factor; True for a factor without
        it would skip entries.

    """
    n_rhs = rhs.shape[1]
    counts = FORWARD_COLUMN_COUNTS
    if factor.shape[1] == FRAME_BAND_WIDTH:
        if profiled:
            # literal column counts: one compiled specialisation each
            if n_rhs == counts[0]:
                _forward_frames(factor, rhs, counts[0], first)
            elif n_rhs == counts[1]:
                _forward_frames(factor, rhs, counts[1], first)
            elif n_rhs == counts[2]:
                _forward_frames(factor, rhs, counts[2], first)
            else:
                _forward_frames(factor, rhs, n_rhs, first)
            return
        if n_rhs == counts[0]:
            _forward_columns(factor, rhs, counts[0], FRAME_BAND_WIDTH, first)
            return
        if n_rhs == counts[1]:
            _forward_columns(factor, rhs, counts[1], FRAME_BAND_WIDTH, first)
            return
    elif factor.shape[1] == CABLE_BAND_WIDTH and n_rhs == counts[1]:
        _forward_columns(factor, rhs, counts[1], CABLE_BAND_WIDTH, first)
        return
    _forward_columns(factor, rhs, n_rhs, 0, first)


@numba.njit(cache=True)
def band_backward(factor, rhs):
    """
    Solve ``Lᵀ X = rhs`` in place with a factor of :func:`band_cholesky` (the backward sweep).

    Completes :func:`band_forward`: ``X = K⁻¹ b`` from ``rhs = L⁻¹ b``. The loops of
    :func:`band_forward`, with the column counts :data:`BACKWARD_COLUMN_COUNTS`.

    Parameters
    ----------
    factor : (N, kd + 1) ndarray
        ``L`` in lower band storage.
    rhs : (N, c) ndarray
        ``L⁻¹ b`` (C order), overwritten by ``X``.

    """
    band_backward_profiled(factor, rhs,
                           factor.shape[1] == FRAME_BAND_WIDTH and frame_profile(factor))


@numba.njit(cache=True)
def band_backward_profiled(factor, rhs, profiled):
    """
    Run :func:`band_backward` with the factor's profile check given.

    Parameters
    ----------
    factor, rhs
        As :func:`band_backward`.
    profiled : bool
        Whether ``factor`` has the 6 x 6 block profile (:func:`frame_profile`), as
        :func:`band_cholesky_profiled` returned it for this factor; True for a factor without
        it would skip entries.

    """
    n_rhs = rhs.shape[1]
    counts = BACKWARD_COLUMN_COUNTS
    if factor.shape[1] == FRAME_BAND_WIDTH:
        if profiled:
            if n_rhs == counts[0]:
                _backward_frames(factor, rhs, counts[0])
            elif n_rhs == counts[1]:
                _backward_frames(factor, rhs, counts[1])
            elif n_rhs == counts[2]:
                _backward_frames(factor, rhs, counts[2])
            else:
                _backward_frames(factor, rhs, n_rhs)
            return
        if n_rhs == counts[0]:
            _backward_columns(factor, rhs, counts[0], FRAME_BAND_WIDTH)
            return
        if n_rhs == counts[1]:
            _backward_columns(factor, rhs, counts[1], FRAME_BAND_WIDTH)
            return
    elif factor.shape[1] == CABLE_BAND_WIDTH and n_rhs == counts[1]:
        _backward_columns(factor, rhs, counts[1], CABLE_BAND_WIDTH)
        return
    _backward_columns(factor, rhs, n_rhs, 0)


#: right-hand side counts that :func:`band_forward` compiles with a constant trip count at
#: half-bandwidth 11: ``m + 1`` for the CBHA's 6 cavities and 8 actuators (at 17 columns the
#: specialisation measured slower), then on the block profile the three columns of one
#: effector's ``J_eᵀ``; 9 at half-bandwidth 17 (``tendon_6f_8c``: 4.3 -> 3.0 µs for both
#: sweeps; 17 columns, ``tendon_10f_16c``, slower there too)
FORWARD_COLUMN_COUNTS = (7, 9, 3)
#: the same for :func:`band_backward`, with the one column of the tick's Newton step
BACKWARD_COLUMN_COUNTS = (7, 9, 1)


@numba.njit(cache=True, inline='always')
def _forward_columns(factor, rhs, n_rhs, constant_width, first):
    """
    Run the forward sweep of :func:`band_forward` over ``n_rhs`` columns from row ``first``.

    Inlined, so a literal ``n_rhs`` and a literal band width ``constant_width`` (0: none; else
    the factor's) give loops of constant trip count for all but the last
    ``constant_width - 1`` rows.
    """
    size, width = factor.shape
    kd = width - 1
    full = max(size - constant_width + 1, 0) if constant_width > 0 else 0
    for j in range(min(first, full), full):
        _forward_row(factor, rhs, j, constant_width - 1, n_rhs)
    for j in range(max(first, full), size):
        _forward_row(factor, rhs, j, min(kd, size - 1 - j), n_rhs)


@numba.njit(cache=True, inline='always')
def _backward_columns(factor, rhs, n_rhs, constant_width):
    """Run the backward sweep of :func:`band_backward` (the loops of :func:`_forward_columns`)."""
    size, width = factor.shape
    kd = width - 1
    full = max(size - constant_width + 1, 0) if constant_width > 0 else 0
    for j in range(size - 1, full - 1, -1):
        _backward_row(factor, rhs, j, min(kd, size - 1 - j), n_rhs)
    for j in range(full - 1, -1, -1):
        _backward_row(factor, rhs, j, constant_width - 1, n_rhs)


@numba.njit(cache=True, inline='always')
def _forward_row(factor, rhs, j, below, n_rhs):
    """Row ``j`` of the forward sweep (``below`` rows below the diagonal)."""
    inverse = 1.0 / factor[j, 0]
    for col in range(n_rhs):
        rhs[j, col] *= inverse
    for a in range(1, below + 1):
        weight = factor[j, a]
        for col in range(n_rhs):
            rhs[j + a, col] -= weight * rhs[j, col]


@numba.njit(cache=True, inline='always')
def _backward_row(factor, rhs, j, below, n_rhs):
    """
    Row ``j`` of the backward sweep (``below`` rows under the pivot).

    The farthest row first: the nearest, ``j + 1``, solved just before, enters last (one
    column's sweep waits on one multiply-add per row, not ``below``). One literal column sums in
    a register (the same operations in the same order).
    """
    if n_rhs == 1:
        acc = rhs[j, 0]
        for a in range(below, 0, -1):
            acc -= factor[j, a] * rhs[j + a, 0]
        rhs[j, 0] = acc * (1.0 / factor[j, 0])
        return
    for a in range(below, 0, -1):
        weight = factor[j, a]
        for col in range(n_rhs):
            rhs[j, col] -= weight * rhs[j + a, col]
    inverse = 1.0 / factor[j, 0]
    for col in range(n_rhs):
        rhs[j, col] *= inverse


#: band width 2b of the frame chain's block-tridiagonal matrices (b = 6), a compile-time constant
#: of :func:`_cholesky_width12`
FRAME_BAND_WIDTH = 12
#: band width with cables whose routing points sit on frames two links apart (pair blocks two
#: frames apart: ``kd = 17``, the tendon scenes), compiled with constant trip counts too
CABLE_BAND_WIDTH = 18


@numba.njit(cache=True)
def _cholesky_width12(band):
    """
    :func:`band_cholesky` for ``kd + 1 = 12``, with constant trip counts away from the end.

    The loops of a column that is at least 12 rows from the end run over the whole width (zeros
    included): with a constant trip count LLVM unrolls and vectorises them, which measured ~1.5x
    faster than the envelope-length loops at n = 6 ... 1000 blocks; the last 11 columns use
    :func:`_cholesky_columns`.
    """
    return _cholesky_constant_width(band, FRAME_BAND_WIDTH)


@numba.njit(cache=True, inline='always')
def _cholesky_constant_width(band, width):
    """
    :func:`band_cholesky` for a literal band ``width``, constant trip counts away from the end.

    The columns at least ``width`` rows from the end run their loops over the whole width; the
    last ``width - 1`` columns use :func:`_cholesky_columns`.
    """
    size = band.shape[0]
    full = max(size - width + 1, 0)
    for j in range(full):
        if not _factor_column(band, j, width - 1):
            return j + 1
    # the last columns: the envelope ends at the matrix end
    return _cholesky_columns(band, full)


@numba.njit(cache=True)
def frame_profile(band):
    """
    Return whether a band of half-bandwidth 11 has the profile of a chain of 6 x 6 blocks.

    Row ``c = 6 k + i`` of a block-tridiagonal matrix (blocks of 6) has no entry past row
    ``6 (k + 2) - 1``: its band slots ``12 - i ... 11`` are zero, and the Cholesky factor keeps
    them zero (it keeps every row's envelope). Checks them all (a NaN is not zero).

    Parameters
    ----------
    band : (N, kd + 1) ndarray
        Lower band storage of :func:`band_cholesky`, or its factor.

    Returns
    -------
    bool
        ``kd + 1 = 12``, N a multiple of 6 (at least 12) and every slot outside the profile 0.

    """
    size, width = band.shape
    if width != FRAME_BAND_WIDTH or size % FRAME_BLOCK != 0 or size < FRAME_BAND_WIDTH:
        return False
    # block by block, component i = 1 ... 5 (row 6k has none): literal trip counts (~25 % faster
    # than a loop over the rows, whose inner trip count varies with c % 6); one branch per block
    # on its 15 comparisons or-ed together (0.099 µs at N = 96, against 0.126 with one branch per
    # slot)
    for k in range(0, size, FRAME_BLOCK):
        nonzero = False
        for i in range(1, FRAME_BLOCK):
            row = band[k + i]
            for d in range(FRAME_BAND_WIDTH - i, FRAME_BAND_WIDTH):
                nonzero |= row[d] != 0.0
        if nonzero:
            return False
    return True


#: block size of the frame chain's block-tridiagonal matrices (:func:`frame_profile`)
FRAME_BLOCK = 6


@numba.njit(cache=True, inline='always')
def _factor_frame_block(band, j, last, rhs, n_rhs):
    """
    Factor the six columns ``j ... j + 5`` of a block of :func:`_cholesky_frames`.

    Column ``j + i`` reaches ``11 - i`` rows below the diagonal (``5 - i`` in the ``last``
    block), a literal for each (constant trip counts); row ``j + i`` of the forward sweep of
    ``n_rhs`` columns of ``rhs`` follows it. Returns 0, or the failing column + 1.
    """
    extra = 0 if last else FRAME_BLOCK
    if not _factor_column(band, j, extra + 5):
        return j + 1
    _forward_row(band, rhs, j, extra + 5, n_rhs)
    if not _factor_column(band, j + 1, extra + 4):
        return j + 2
    _forward_row(band, rhs, j + 1, extra + 4, n_rhs)
    if not _factor_column(band, j + 2, extra + 3):
        return j + 3
    _forward_row(band, rhs, j + 2, extra + 3, n_rhs)
    if not _factor_column(band, j + 3, extra + 2):
        return j + 4
    _forward_row(band, rhs, j + 3, extra + 2, n_rhs)
    if not _factor_column(band, j + 4, extra + 1):
        return j + 5
    _forward_row(band, rhs, j + 4, extra + 1, n_rhs)
    if not _factor_column(band, j + 5, extra):
        return j + 6
    _forward_row(band, rhs, j + 5, extra, n_rhs)
    return 0


@numba.njit(cache=True, inline='always')
def _cholesky_frames(band, rhs, n_rhs, leading, zero_rows):
    """
    :func:`band_cholesky` of a band with the 6 x 6 block profile (:func:`frame_profile`).

    The arithmetic of :func:`_cholesky_width12` without the updates by the zeros outside the
    profile (``x - 0 y = x`` for a finite ``y``: the same factor); with the forward sweep of
    ``n_rhs`` (a literal, or 0) columns of ``rhs`` (:func:`band_cholesky_forward`), of its
    ``leading`` columns only in the blocks above row ``zero_rows`` (:func:`_zero_columns`).
    Inlined, so literal counts give loops of constant trip count.
    """
    size = band.shape[0]
    zero_end = min(zero_rows - zero_rows % FRAME_BLOCK, size - FRAME_BLOCK)
    for j in range(0, zero_end, FRAME_BLOCK):
        info = _factor_frame_block(band, j, False, rhs, leading)
        if info != 0:
            return info
    for j in range(zero_end, size - FRAME_BLOCK, FRAME_BLOCK):
        info = _factor_frame_block(band, j, False, rhs, n_rhs)
        if info != 0:
            return info
    return _factor_frame_block(band, size - FRAME_BLOCK, True, rhs, n_rhs)


@numba.njit(cache=True, inline='always')
def _forward_frames(factor, rhs, n_rhs, first):
    """
    Run the forward sweep of :func:`band_forward` on a factor with the 6 x 6 block profile.

    Row ``j + i`` of a block reaches ``11 - i`` rows (``5 - i`` in the last block), literals
    (:func:`_cholesky_frames`): the arithmetic of :func:`_forward_columns` without the zeros,
    from the block of row ``first``.
    """
    last = factor.shape[0] - FRAME_BLOCK
    for j in range(first - first % FRAME_BLOCK, last, FRAME_BLOCK):
        _forward_frame_block(factor, rhs, j, FRAME_BLOCK, n_rhs)
    _forward_frame_block(factor, rhs, last, 0, n_rhs)


@numba.njit(cache=True, inline='always')
def _backward_frames(factor, rhs, n_rhs):
    """Run the backward sweep of :func:`band_backward` on the 6 x 6 block profile."""
    last = factor.shape[0] - FRAME_BLOCK
    _backward_frame_block(factor, rhs, last, 0, n_rhs)
    for j in range(last - FRAME_BLOCK, -1, -FRAME_BLOCK):
        _backward_frame_block(factor, rhs, j, FRAME_BLOCK, n_rhs)


@numba.njit(cache=True, inline='always')
def _forward_frame_block(factor, rhs, j, extra, n_rhs):
    """Forward rows ``j ... j + 5`` of :func:`_forward_frames` (``extra + 5 - i`` rows below)."""
    _forward_row(factor, rhs, j, extra + 5, n_rhs)
    _forward_row(factor, rhs, j + 1, extra + 4, n_rhs)
    _forward_row(factor, rhs, j + 2, extra + 3, n_rhs)
    _forward_row(factor, rhs, j + 3, extra + 2, n_rhs)
    _forward_row(factor, rhs, j + 4, extra + 1, n_rhs)
    _forward_row(factor, rhs, j + 5, extra, n_rhs)


@numba.njit(cache=True, inline='always')
def _backward_frame_block(factor, rhs, j, extra, n_rhs):
    """Backward rows ``j + 5 ... j`` of :func:`_backward_frames` (``extra + 5 - i`` rows below)."""
    _backward_row(factor, rhs, j + 5, extra, n_rhs)
    _backward_row(factor, rhs, j + 4, extra + 1, n_rhs)
    _backward_row(factor, rhs, j + 3, extra + 2, n_rhs)
    _backward_row(factor, rhs, j + 2, extra + 3, n_rhs)
    _backward_row(factor, rhs, j + 1, extra + 4, n_rhs)
    _backward_row(factor, rhs, j, extra + 5, n_rhs)
