"""The tick's flop count (report/tick_flops) and the benchmark table that prints it."""

import math

from cbha_inverse.report import bench_inverse
from cbha_inverse.report.tick_flops import (measured_flop_rate, tick_flops, tick_shapes,
                                            TickShapes)
from cbha_inverse.scene import load_scene
import numpy as np
import pytest


def _counted_band_cholesky_and_solve(size, kd, n_rhs, first, effector_columns):
    """Count the flops of a plain band Cholesky and the tick's forward sweeps, one by one."""
    flops = {'factor': 0, 'solve': 0}
    for j in range(size):
        below = min(kd, size - 1 - j)
        flops['factor'] += 1                              # the pivot's square root
        flops['factor'] += below                          # the column's scaling
        for b in range(1, below + 1):
            for _ in range(b, below + 1):
                flops['factor'] += 2                      # target -= column * weight
        # forward sweep of [r, J_aᵀ], and of J_eᵀ from its first nonzero row on
        for _ in range(n_rhs + (effector_columns if j >= first else 0)):
            flops['solve'] += 1 + 2 * below
    return flops


@pytest.mark.parametrize('size, kd, n_rhs, frames', [
    (96, 11, 7, (16,)), (36, 11, 9, (3, 6)), (30, 29, 3, (5,))])
def test_band_counts_equal_an_operation_by_operation_count(size, kd, n_rhs, frames):
    counted = _counted_band_cholesky_and_solve(size, kd, n_rhs, 6 * (min(frames) - 1),
                                               3 * len(frames))
    # links without cables: 144 block values per link
    shapes = TickShapes(size // 6, n_rhs - 1, len(frames), kd, 0, False, 0, 0, 144 * (size // 6),
                        0, frames)
    flops = tick_flops(shapes)
    assert flops['factor'] == counted['factor']
    assert flops['solve'] == counted['solve']
    assert flops['total'] == sum(v for key, v in flops.items() if key != 'total')
    # the Newton step's one-column backward sweep is in the update
    assert flops['update'] > sum(1 + 2 * min(kd, size - 1 - j) for j in range(size))


def test_the_cbha_tick_counts_its_links_cavities_and_band():
    scene = load_scene('cbha')
    solver = scene.make_inverse_solver()
    solver.step(scene.workspace_center)
    shapes = tick_shapes(solver)
    assert (shapes.n, shapes.m, shapes.k, shapes.kd) == (16, 6, 1, 11)
    # every link lies in one section: 3 of its 6 cavity columns are nonzero
    assert (shapes.cavities, shapes.points, shapes.spans) == (16 * 3, 0, 0)
    assert shapes.values == 16 * 144 and shapes.effector_frames == (16,)
    flops = tick_flops(shapes)
    # the band of N = 96, kd = 11 with 7 right-hand sides: N (kd² + 2kd + 1) minus the end
    assert 0.8 * 96 * 144 < flops['factor'] < 96 * 144
    assert flops['cables'] == 0
    # the links' lower triangles straight into the band, nothing scattered, the band zeroed
    assert flops['assembly'] == 15 * 78 + 21 + 96
    # the nonzero cavity columns (3 per link) cost about a third of the link pass
    assert flops['links'] > 16 * 3 * 207
    assert 50_000 < flops['total'] < 200_000


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
