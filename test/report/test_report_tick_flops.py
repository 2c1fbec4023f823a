"""
The tick's flop count (report/tick_flops) and the benchmark table that prints it.

The counts are checked against the kernels themselves: their Python source (``py_func`` of every
compiled function) runs on arrays of :class:`_Flop`, numbers that count their arithmetic, so the
count is the one of the operations the kernels execute, not of a formula. The convention of the
count: every ``+ - * /`` and every ``sqrt``, ``atan2``, ``sin``, ``cos`` is one flop, with two
exceptions: the literal zero that starts a local sum (``acc = 0.0; acc += a * b``: the six
products of a dot product cost 11 flops), and a sign change whose result is only stored
(``x = -y`` in memory is a copy; a sign change that feeds an operation, ``-(a - b) - c``,
counts). A value written to an array is data: a later add into it counts, zero or not. Each
instrumented run is checked against the compiled kernels or numpy too: it computes what they do.
"""

import math
from types import SimpleNamespace

from cbha_inverse.core._kernels import (assembly, block_band, cables, evaluation, links,
                                        mesh_cavities, so3)
from cbha_inverse.core._kernels.flop_rate import multiply_add_chains
from cbha_inverse.report import bench_inverse
from cbha_inverse.report.tick_flops import (measured_flop_rate, tick_flops, tick_shapes,
                                            TickShapes)
from cbha_inverse.scene import load_scene
import numba
import numpy as np
import pytest
from scipy.linalg import solve_triangular


class _Tally:
    """The flops counted since the last reset."""

    flops = 0


class _Flop:
    """A float that counts the arithmetic done with it (module docstring)."""

    __slots__ = ('value', 'pending')
    # numpy scalars defer to the reflected operators instead of wrapping the object
    __array_ufunc__ = None
    __hash__ = None

    def __init__(self, value, pending=False):
        self.value = float(value)
        # a sign change not yet counted (counted when the value feeds an operation)
        self.pending = pending

    def __float__(self):
        raise TypeError('a counted value left the count')

    def __neg__(self):
        return _Flop(-self.value, True)


def _operand(value):
    """Return the float of an operand, counting its pending sign change."""
    if isinstance(value, _Flop):
        if value.pending:
            _Tally.flops += 1
            value.pending = False
        return value.value
    return float(value)


def _arithmetic(operation, reflected, additive):
    def method(self, other):
        if not isinstance(other, (_Flop, int, float, np.floating, np.integer)):
            return NotImplemented
        literal_zero = additive and not isinstance(other, _Flop) and other == 0
        a, b = _operand(self), _operand(other)
        _Tally.flops += not literal_zero
        return _Flop(operation(b, a) if reflected else operation(a, b))
    return method


def _comparison(operation):
    def method(self, other):
        return operation(self.value, other.value if isinstance(other, _Flop) else float(other))
    return method


for _name, _operation, _additive in (('add', float.__add__, True), ('sub', float.__sub__, True),
                                     ('mul', float.__mul__, False),
                                     ('truediv', float.__truediv__, False),
                                     ('pow', float.__pow__, False)):
    setattr(_Flop, f'__{_name}__', _arithmetic(_operation, False, _additive))
    setattr(_Flop, f'__r{_name}__', _arithmetic(_operation, True, _additive))
for _name in ('lt', 'le', 'gt', 'ge', 'eq', 'ne'):
    setattr(_Flop, f'__{_name}__', _comparison(getattr(float, f'__{_name}__')))


def _stored(value):
    """Return a value as an array holds it: a number is data (no pending sign change)."""
    if isinstance(value, _Flop):
        return _Flop(value.value)
    if isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool):
        return _Flop(value)
    return value


class _Memory(np.ndarray):
    """An object array of :class:`_Flop` whose stores make data of what they store."""

    def __setitem__(self, key, value):
        if isinstance(value, np.ndarray):
            value = np.vectorize(_stored, otypes=[object])(value) if value.size else value
        else:
            value = _stored(value)
        super().__setitem__(key, value)


def _counted_function(function):
    def counted(*arguments):
        values = [_operand(argument) for argument in arguments]
        _Tally.flops += 1
        return _Flop(function(*values))
    return counted


_COUNTING_MATH = SimpleNamespace(
    sqrt=_counted_function(math.sqrt), atan2=_counted_function(math.atan2),
    sin=_counted_function(math.sin), cos=_counted_function(math.cos),
    isfinite=lambda x: math.isfinite(x.value if isinstance(x, _Flop) else x))


def _flops(array):
    """Return a float array as a :class:`_Memory` of counting numbers."""
    array = np.asarray(array, dtype=float)
    out = np.empty(array.shape, dtype=object)
    out.reshape(-1)[:] = [_Flop(value) for value in array.reshape(-1)]
    return out.view(_Memory)


def _floats(array):
    """Return the values of a :class:`_Memory` as a float array."""
    array = np.asarray(array)
    return np.array([x.value for x in array.reshape(-1)], dtype=float).reshape(array.shape)


def _instrument(patch, *modules):
    """Replace every compiled function of the modules by its Python source, ``math`` by ours."""
    for module in modules:
        for name, value in list(vars(module).items()):
            if isinstance(value, numba.core.dispatcher.Dispatcher):
                patch.setattr(module, name, value.py_func)
        if hasattr(module, 'math'):
            patch.setattr(module, 'math', _COUNTING_MATH)


def _tallied(patch, module, names, tally):
    """Count the flops of some (instrumented) functions of a module, callees included."""
    for name in names:
        function = getattr(module, name)

        def wrapped(*arguments, _function=function, _name=name):
            before = _Tally.flops
            result = _function(*arguments)
            tally[_name] = tally.get(_name, 0) + _Tally.flops - before
            return result
        patch.setattr(module, name, wrapped)


def _count(function, *arguments):
    """Return the flops of one call."""
    _Tally.flops = 0
    function(*arguments)
    return _Tally.flops


def _block_band(n, width, rng):
    """Return a symmetric positive definite matrix with ``width`` blocks below the diagonal."""
    size = 6 * n
    rows = np.arange(size) // 6
    inside = np.abs(rows[:, None] - rows[None, :]) <= width
    values = rng.uniform(-1.0, 1.0, (size, size)) * inside
    dense = values + values.T
    # diagonally dominant: positive definite
    dense += np.diag(np.abs(dense).sum(axis=1) + 1.0)
    return dense


def _to_blocks(dense, width):
    """Return a symmetric matrix in block band storage, ``blocks[c, d] = K_(c+d, c)``."""
    n = dense.shape[0] // 6
    blocks = np.zeros((n, width + 1, 6, 6))
    for c in range(n):
        for d in range(min(width, n - 1 - c) + 1):
            blocks[c, d] = dense[6 * (c + d):6 * (c + d + 1), 6 * c:6 * (c + 1)]
    return blocks


def _counted_factor_and_sweeps(patch, blocks, rhs, starts, effector_columns, effector_starts):
    """
    Run the tick's block Cholesky and sweeps, instrumented (``linearise_tick``, the step's sweep).

    Returns the flops of the factorisation, of the forward sweeps (``[r, J_aᵀ]`` fused with the
    factorisation, ``J_eᵀ`` after it), of one column's backward sweep, and the factor and the
    swept columns as floats.
    """
    with patch.context() as inner:
        _instrument(inner, block_band)
        factor_alone = _count(block_band.block_cholesky, _flops(blocks))
        factor = _flops(blocks)
        swept = _flops(rhs)
        fused = _count(block_band.block_cholesky_forward, factor, swept, np.asarray(starts))
        effectors = _flops(effector_columns)
        effector_sweep = _count(block_band.block_forward, factor, effectors,
                                np.asarray(effector_starts))
        backward = _count(block_band.block_backward, factor, _flops(rhs[:, :1]))
    return {'factor': factor_alone, 'solve': fused - factor_alone + effector_sweep,
            'backward': backward, 'L': _floats(factor), 'swept': _floats(swept),
            'effectors': _floats(effectors)}


def _check_against_numpy(dense, counted, rhs, effector_columns):
    """Check that the instrumented run is a Cholesky factorisation and its forward sweeps."""
    n = dense.shape[0] // 6
    lower = np.linalg.cholesky(dense)
    factor = counted['L']
    width = factor.shape[1] - 1
    for c in range(n):
        diagonal = np.tril(factor[c, 0], -1) + np.diag(1.0 / np.diag(factor[c, 0]))
        np.testing.assert_allclose(diagonal, lower[6 * c:6 * c + 6, 6 * c:6 * c + 6],
                                   rtol=1e-10, atol=1e-12)
        for d in range(1, min(width, n - 1 - c) + 1):
            np.testing.assert_allclose(
                factor[c, d], lower[6 * (c + d):6 * (c + d + 1), 6 * c:6 * c + 6],
                rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(counted['swept'], solve_triangular(lower, rhs, lower=True),
                               rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(counted['effectors'],
                               solve_triangular(lower, effector_columns, lower=True),
                               rtol=1e-10, atol=1e-12)


def _first_rows(columns):
    """Return the first nonzero row of each column (its rows if none)."""
    nonzero = columns != 0.0
    return [int(np.argmax(column)) if column.any() else columns.shape[0]
            for column in nonzero.T]


def _shapes(n, width, starts, frames):
    # links without cables: 144 block values per link
    return TickShapes(n=n, m=len(starts) - 1, k=len(frames), block_width=width, cavities=0,
                      points=0, spans=0, values=144 * n, jacobian_entries=0,
                      effector_frames=tuple(frames), starts=tuple(starts))


@pytest.mark.parametrize('n, width, starts, frames', [
    (16, 1, (2, 4, 4, 4, 42, 42, 42), (16,)),            # the CBHA's
    (6, 2, (2, 30, 30, 30, 30, 18, 18, 18, 18), (6,)),   # a tendon arm's
    (5, 4, (0, 7, 30), (3, 5)),                          # a full band, a zero column
    (7, 3, (0, 13, 41), (2,))])
def test_block_counts_equal_the_kernels_operation_by_operation(monkeypatch, n, width, starts,
                                                               frames):
    rng = np.random.default_rng(n + width)
    dense = _block_band(n, width, rng)
    blocks = _to_blocks(dense, width)
    # [r, J_aᵀ] zero above its start rows, J_eᵀ 3 columns in each effector frame's rows
    rhs = rng.standard_normal((6 * n, len(starts)))
    for col, start in enumerate(starts):
        rhs[:start, col] = 0.0
    effector_columns = np.zeros((6 * n, 3 * len(frames)))
    for e, frame in enumerate(frames):
        effector_columns[6 * (frame - 1):6 * frame, 3 * e:3 * e + 3] = rng.standard_normal((6, 3))
    assert _first_rows(rhs) == list(starts)
    counted = _counted_factor_and_sweeps(monkeypatch, blocks, rhs, starts, effector_columns,
                                         _first_rows(effector_columns))
    _check_against_numpy(dense, counted, rhs, effector_columns)
    flops = tick_flops(_shapes(n, width, starts, frames))
    assert flops['factor'] == counted['factor']
    assert flops['solve'] == counted['solve']
    assert flops['total'] == sum(v for key, v in flops.items() if key != 'total')
    # the Newton step's one-column backward sweep is in the update: against the block
    # diagonal's (no block below the diagonal), the update differs by the sweeps' difference
    diagonal = _counted_factor_and_sweeps(monkeypatch, _to_blocks(dense, 0), rhs, starts,
                                          effector_columns, _first_rows(effector_columns))
    assert counted['backward'] > diagonal['backward']
    assert (flops['update'] - tick_flops(_shapes(n, 0, starts, frames))['update']
            == counted['backward'] - diagonal['backward'])


def _counted_evaluation(patch, system, positions, rotations, actuation):
    """
    Run the tick's evaluation (``evaluate`` into the block band), instrumented.

    Returns the flops per phase (the link pass without its additions into the band, the cable
    pass, the rest: the band additions, the external wrenches and the scattered cable blocks),
    the flops of one frame-a share of a link's wrench column, and the evaluated band and
    right-hand sides as floats.
    """
    fields = {name: _flops(value) if isinstance(value, np.ndarray) and value.dtype == float
              else value for name, value in system.record._values.items()}
    record = SimpleNamespace(**fields)
    tally = {}
    with patch.context() as inner:
        _instrument(inner, evaluation, links, so3, assembly, block_band, cables, mesh_cavities)
        _tallied(inner, evaluation, ['link_pass', 'cable_pass'], tally)
        _tallied(inner, links, ['add_link_block', 'add_to_frame_a'], tally)
        calls = []
        add_to_frame_a = links.add_to_frame_a
        inner.setattr(links, 'add_to_frame_a',
                      lambda *arguments: calls.append(1) or add_to_frame_a(*arguments))
        total = _count(evaluation.evaluate, record, _flops(positions), _flops(rotations),
                       _flops(actuation), True, True)
    link_pass = tally['link_pass'] - tally['add_link_block']
    return {'links': link_pass, 'cables': tally.get('cable_pass', 0),
            'assembly': total - link_pass - tally.get('cable_pass', 0),
            'frame_a_share': tally['add_to_frame_a'] / len(calls),
            'blocks': _floats(record.blocks), 'rhs': _floats(record.rhs)}


def _effector_columns(solver, rotations):
    """Return ``J_eᵀ`` of the solver's effectors: ``[I; r^]`` in their frames' rows."""
    effectors = solver.effectors
    columns = np.zeros((6 * solver._system.n, 3 * effectors.n_effectors))
    for e, (frame, offset) in enumerate(zip(effectors.frames, effectors.offsets)):
        lever = rotations[frame] @ offset
        rows = slice(6 * (frame - 1), 6 * frame)
        hat = np.array([[0.0, -lever[2], lever[1]], [lever[2], 0.0, -lever[0]],
                        [-lever[1], lever[0], 0.0]])
        columns[rows, 3 * e:3 * e + 3] = np.vstack([np.eye(3), hat])
    return columns


def test_the_cbha_tick_counts_its_links_cavities_and_band(monkeypatch):
    scene = load_scene('cbha')
    solver = scene.make_inverse_solver()
    solver.step(scene.workspace_center)
    # the state the next tick linearises at (its frames and λ_prev)
    data = solver._data
    positions, rotations, actuation = (data.positions.copy(), data.rotations.copy(),
                                       data.actuation.copy())
    assert (actuation != 0.0).all()
    solver.step(scene.workspace_center)
    shapes = tick_shapes(solver)
    assert (shapes.n, shapes.m, shapes.k, shapes.block_width) == (16, 6, 1, 1)
    # every link lies in one section: 3 of its 6 cavity columns are nonzero
    assert (shapes.cavities, shapes.points, shapes.spans) == (16 * 3, 0, 0)
    assert shapes.values == 16 * 144 and shapes.effector_frames == (16,)
    flops = tick_flops(shapes)
    # the tick's evaluation, instrumented, and compiled
    system = solver._system
    counted = _counted_evaluation(monkeypatch, system, positions, rotations, actuation)
    tangent, rhs = system.linearise(positions, rotations, actuation)
    np.testing.assert_allclose(counted['blocks'][:16], tangent, rtol=1e-9,
                               atol=1e-9 * np.abs(tangent).max())
    np.testing.assert_allclose(counted['rhs'], rhs, rtol=1e-9, atol=1e-9 * np.abs(rhs).max())
    assert shapes.starts == tuple(_first_rows(rhs))
    assert shapes.jacobian_entries == int((rhs[:, 1:] != 0.0).sum())
    assert flops['cables'] == counted['cables'] == 0
    # the links' lower triangles straight into the band, the external wrenches, nothing
    # scattered
    assert flops['assembly'] == counted['assembly']
    # the report charges every link its wrench columns' frame-a shares; the first link's frame
    # a is the base, which the pass skips (its column 0 and its nonzero cavity columns)
    first_link_columns = 1 + int((system.record.cavity_columns[0] >= 0).sum())
    assert first_link_columns == 4
    assert flops['links'] == counted['links'] + first_link_columns * counted['frame_a_share']
    # the block Cholesky of the tangent and the tick's sweeps
    dense = system.dense(tangent)
    dense = dense + np.tril(dense, -1).T
    effector_columns = _effector_columns(solver, rotations)
    sweeps = _counted_factor_and_sweeps(monkeypatch, tangent, rhs, shapes.starts,
                                        effector_columns, _first_rows(effector_columns))
    _check_against_numpy(dense, sweeps, rhs, effector_columns)
    assert flops['factor'] == sweeps['factor']
    assert flops['solve'] == sweeps['solve']
    assert 50_000 < flops['total'] < 200_000


def _first_links(record, n_links, cavities):
    """
    Return the link pass's fields for the first links of a chain, as counting numbers.

    From an evaluator's record: the links' stiffness, rest geometry and the first ``cavities``
    of each link's nonzero condensed cavity columns, zeroed outputs, the scratch arrays.
    """
    values = record._values
    columns = np.full((n_links, cavities), -1, dtype=np.int64)
    for link in range(n_links):
        used = values['cavity_columns'][link][values['cavity_columns'][link] >= 0]
        columns[link, :used[:cavities].size] = used[:cavities]
    fields = {'cavity_columns': columns}
    for name in ('stiffness', 'rest_offsets', 'rest_rotations_t', 'cavity_wrench',
                 'cavity_stiffness'):
        fields[name] = _flops(values[name][:n_links])
    for name, value in values.items():
        if name.startswith('link_'):
            fields[name] = _flops(value)
    fields['rhs'] = _flops(np.zeros((6 * n_links, values['rhs'].shape[1])))
    fields['values'] = _flops(np.zeros(144 * n_links))
    fields['blocks'] = _flops(np.zeros((n_links + 1, 2, 6, 6)))
    return SimpleNamespace(**fields)


@pytest.mark.parametrize('cavities', [0, 1, 3])
def test_a_link_and_its_cavity_columns_cost_what_the_link_pass_does(monkeypatch, cavities):
    """One more link (after the first) with its cavity columns: the pass's own count."""
    scene = load_scene('cbha')
    solver = scene.make_inverse_solver()
    solver.step(scene.workspace_center)
    data = solver._data
    # every cavity pressurised: the load stiffness of every column is evaluated
    actuation = 1e4 * (1.0 + np.arange(data.actuation.size))
    counted = []
    for n_links in (3, 4):
        record = _first_links(solver._system.record, n_links, cavities)
        tally = {}
        with monkeypatch.context() as inner:
            _instrument(inner, links, so3, assembly)
            _tallied(inner, links, ['add_link_block'], tally)
            total = _count(links.link_pass, record, _flops(data.positions[:n_links + 1]),
                           _flops(data.rotations[:n_links + 1]), _flops(actuation), True, True)
        counted.append(total - tally['add_link_block'])
        if cavities == 3:
            # every nonzero cavity column: the wrenches are the compiled evaluation's on those
            # frames less the external wrenches (the rows of frames 1 ... n - 1: frame n's lack
            # the next link's share)
            expected = solver._system.evaluate(data.positions, data.rotations, actuation).copy()
            expected[:, 0] -= solver._system.external
            rows = 6 * (n_links - 1)
            np.testing.assert_allclose(_floats(record.rhs)[:rows], expected[:rows],
                                       rtol=1e-9, atol=1e-9 * np.abs(expected).max())
    shapes = [TickShapes(n=n_links, m=6, k=1, block_width=1, cavities=n_links * cavities,
                         points=0, spans=0, values=144 * n_links, jacobian_entries=0,
                         effector_frames=(n_links,), starts=(0,) * 7)
              for n_links in (3, 4)]
    assert (tick_flops(shapes[1])['links'] - tick_flops(shapes[0])['links']
            == counted[1] - counted[0])


def test_the_multiply_add_chains_follow_their_closed_form():
    """``a_k = cᵏ a_0 + d (1 - cᵏ) / (1 - c)`` for each of the eight chains, summed."""
    c, d, n_steps, seed = 0.999999, 1e-7, 1000, 0.25
    starts = seed + np.arange(8.0)
    expected = (c ** n_steps * starts + d * (1 - c ** n_steps) / (1 - c)).sum()
    assert multiply_add_chains(n_steps, seed) == pytest.approx(expected, rel=1e-12)
    assert multiply_add_chains(0, seed) == pytest.approx(starts.sum(), rel=1e-15)


def test_flop_rate_and_the_table_print_the_bound():
    rate = measured_flop_rate(repeats=3, n_steps=10_000)
    assert math.isfinite(rate) and rate > 1e8
    row = bench_inverse.bench_scene('tendon_6f_8c', n_ticks=20, warmup=5, qp_solver='active_set')
    table = bench_inverse.format_table([row], rate)
    line = next(text for text in table.splitlines() if text.startswith('tendon_6f_8c'))
    bound = row['flops'] / rate
    assert f"{row['flops'] / 1e3:6.1f}" in line
    assert f"{row['median']['total'] / bound:6.1f}x" in line
    assert np.isfinite(row['median']['total'])
