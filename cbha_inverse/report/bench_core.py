"""
Benchmark of the mechanics core (console script ``cbha_bench_core``).

Prints, measured in the same run on the same matrices:

1. the block-tridiagonal (BTD) solve table: factorisation + solve of n = 6 ... 10000 frames with
   6 and 20 right-hand sides, for LAPACK banded Cholesky (``dpbtrf``/``dpbtrs`` on ready band
   storage, half-bandwidth 11: the reference), dense LAPACK (``dpotrf``/``dpotrs`` on a ready
   dense matrix, skipped where it is too slow or too large), and this package's backends
   called from the (n, 6, 6) blocks (conversion included), with the ratio of the compiled
   (numba) backend to LAPACK banded, and ``'auto'`` and its ratio;
2. the control-tick pieces and static-solve times of a 17-frame chain (16 links).

The matrices are rest tangent stiffnesses of curved chains of Timoshenko links (SPD, full 6x6
blocks, realistic conditioning). Times are the minimum over repeats of the mean over an inner loop.
"""

import argparse
import os
import platform
import sys
import time

from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.chain import ChainModel, rest_state
from cbha_inverse.core.linalg import btd
from cbha_inverse.core.links import timoshenko_compliance
from cbha_inverse.core.so3 import so3_exp
from cbha_inverse.core.statics import solve_static
from cbha_inverse.core.system import EquilibriumSystem
import numpy as np
import scipy
from scipy.linalg import lapack

FULL_SIZES = (6, 16, 100, 1000, 10000)
QUICK_SIZES = (6, 16, 100, 1000)
RHS_COUNTS = (6, 20)
#: dense LAPACK is skipped above this many frames (a 6n x 6n matrix: 6000^2 doubles = 288 MB
#: at n = 1000 and seconds per factorisation)
DENSE_MAX_FRAMES = 200
OUR_METHODS = ('compiled', 'dense', 'banded')


def time_calls(funcs, budget):
    """
    Return the best mean time [s] of each function, measured in interleaved rounds.

    Each round times every function once over a batch of calls (batch sized to ~1/8 of the
    per-function budget, from a second call: the first may load numba kernels); the minimum over
    rounds is kept. Interleaving makes the comparison
    fair when the machine's load changes during the run (a shared 2-core machine here).

    Parameters
    ----------
    funcs : dict of str -> callable
        Called without arguments.
    budget : float  [s]
        Approximate time to spend per function.

    Returns
    -------
    dict of str -> float

    """
    numbers = {}
    for name, func in funcs.items():
        func()      # untimed: a first call may load compiled kernels from numba's cache
        start = time.perf_counter()
        func()
        first = max(time.perf_counter() - start, 1e-7)
        numbers[name] = max(1, int(budget / (8 * first)))
    rounds = 7 if max(numbers.values()) > 1 else 3
    best = dict.fromkeys(funcs, np.inf)
    for _ in range(rounds):
        for name, func in funcs.items():
            number = numbers[name]
            start = time.perf_counter()
            for _ in range(number):
                func()
            best[name] = min(best[name], (time.perf_counter() - start) / number)
    return best


def time_call(func, budget):
    """
    Return the best mean time [s] of ``func()`` (see :func:`time_calls`).

    Parameters
    ----------
    func : callable
        Called without arguments.
    budget : float  [s]
        Approximate total time to spend.

    Returns
    -------
    float

    """
    return time_calls({'f': func}, budget)['f']


def beam_chain(n_links, length=0.5, youngs_modulus=2.0e9, outer_radius=0.01,
               inner_radius=0.004):
    """
    Return a straight chain of ``n_links`` equal hollow Timoshenko links along +x.

    Parameters
    ----------
    n_links : int
        Number of links n (n + 1 frames).
    length : float  [m]
        Total length.
    youngs_modulus : float  [Pa]
        Young's modulus.
    outer_radius : float  [m]
        Tube outer radius.
    inner_radius : float  [m]
        Tube inner radius.

    Returns
    -------
    ChainModel

    """
    h = length / n_links
    comp = timoshenko_compliance(h, youngs_modulus, 0.35, outer_radius, inner_radius)
    return ChainModel.from_compliances(np.broadcast_to(comp, (n_links, 6, 6)),
                                       np.tile([h, 0.0, 0.0], (n_links, 1)),
                                       masses=np.full(n_links, 0.2 / n_links))


def bent_tangent(n_links, seed=0):
    """
    Return the (diagonal, upper) blocks of the rest tangent of a randomly curved chain.

    The links are the hollow Timoshenko links of :func:`beam_chain` with random small rest
    rotations (a space curve), so the blocks are full 6x6 and the matrix is SPD.

    Parameters
    ----------
    n_links : int
        Number of moving frames (= blocks).
    seed : int
        Seed of the random curvature.

    Returns
    -------
    tuple of ndarrays
        (n, 6, 6) and (n - 1, 6, 6).

    """
    straight = beam_chain(n_links)
    rng = np.random.default_rng(seed)
    rest_rot = so3_exp(rng.normal(scale=0.3 / np.sqrt(n_links), size=(n_links, 3)))
    model = ChainModel.from_compliances(straight.compliances, straight.rest_offsets,
                                        rest_rotations=rest_rot)
    system = EquilibriumSystem(model, ActuatorSet((), model.n_frames), np.zeros(6 * n_links))
    state = rest_state(model)
    tangent, _ = system.linearise(state.positions, state.rotations, np.zeros(0))
    return system.tridiagonal_blocks(tangent)


def btd_table(sizes, rhs_counts, budget, out):
    """
    Measure and print the BTD table; return its rows.

    Parameters
    ----------
    sizes : sequence of int
        Numbers of frames (blocks) n.
    rhs_counts : sequence of int
        Numbers of right-hand sides k.
    budget : float  [s]
        Timing budget per entry.
    out : file
        Where to print.

    Returns
    -------
    list of dict

    """
    rows = []
    head = (f"{'n':>6} {'k':>3} | {'LAPACK pb':>9} {'LAPACK po':>9} | {'compiled':>9} "
            f"{'c.ratio':>7} | "
            f"{'dense':>9} {'banded':>9} | {'auto':>9} "
            f"{'method':>8} {'ratio':>5} {'best':>5} {'r.conv':>6} | {'rel.err':>7}")
    print('BTD solve: factorisation + solve, times in microseconds; c.ratio = compiled / LAPACK '
          'banded (pb, on ready band storage); ratio = auto / pb; best = fastest of ours / pb; '
          'r.conv = auto / '
          'LAPACK banded including the block -> band conversion (the same input as ours)',
          file=out)
    print(head, file=out)
    print('-' * len(head), file=out)
    for n in sizes:
        diag, upper = bent_tangent(n)
        band = btd.to_lower_banded(diag, upper)
        # dense matrix for LAPACK, built outside the timed region
        dense = (np.asfortranarray(btd.to_dense(diag, upper))
                 if n <= DENSE_MAX_FRAMES else None)
        rng = np.random.default_rng(n)
        for k in rhs_counts:
            rhs = np.asfortranarray(rng.normal(size=(6 * n, k)))

            def lapack_banded():
                factor, info = lapack.dpbtrf(band, lower=1)
                return lapack.dpbtrs(factor, rhs, lower=1)[0]

            def lapack_banded_from_blocks():
                factor, info = lapack.dpbtrf(btd.to_lower_banded(diag, upper), lower=1)
                return lapack.dpbtrs(factor, rhs, lower=1)[0]

            def lapack_dense():
                factor, info = lapack.dpotrf(dense, lower=1, clean=0)
                return lapack.dpotrs(factor, rhs, lower=1)[0]

            ref = lapack_banded()
            funcs = {'pb': lapack_banded, 'pb+conv': lapack_banded_from_blocks}
            if dense is not None:
                funcs['po'] = lapack_dense
            for method in OUR_METHODS:
                if method != 'dense' or dense is not None:
                    funcs[method] = (lambda m=method: btd.factorize(diag, upper, m).solve(rhs))
            funcs['auto'] = lambda: btd.factorize(diag, upper).solve(rhs)
            row = {'n': n, 'k': k, 'po': None, 'dense': None}
            row.update(time_calls(funcs, budget))
            auto = btd.factorize(diag, upper)
            row['method'] = auto.method
            row['err'] = err = np.abs(auto.solve(rhs) - ref).max() / np.abs(ref).max()
            best = min(row[m] for m in OUR_METHODS if row[m] is not None)
            rows.append(row)

            def fmt(value):
                return f'{value * 1e6:9.1f}' if value is not None else f"{'skipped':>9}"

            print(f"{n:6d} {k:3d} | {fmt(row['pb'])} {fmt(row['po'])} | {fmt(row['compiled'])} "
                  f"{row['compiled'] / row['pb']:7.2f} | "
                  f"{fmt(row['dense'])} {fmt(row['banded'])} "
                  f"| {fmt(row['auto'])} {row['method']:>8} "
                  f"{row['auto'] / row['pb']:5.2f} "
                  f"{best / row['pb']:5.2f} {row['auto'] / row['pb+conv']:6.2f} | {err:7.1e}",
                  file=out)
            out.flush()
    print(f'dense LAPACK skipped above n = {DENSE_MAX_FRAMES} frames (6n x 6n dense matrix; '
          f'at n = 1000 it is 288 MB and seconds per factorisation).', file=out)
    print(f"'auto' uses {', '.join(sorted({row['method'] for row in rows}))} at these sizes.",
          file=out)
    return rows


def static_report(budget, out):
    """
    Measure and print the control-tick pieces and static solves of a 17-frame chain.

    Parameters
    ----------
    budget : float  [s]
        Timing budget per entry.
    out : file
        Where to print.

    Returns
    -------
    dict
        Name -> seconds.

    """
    model = beam_chain(16)
    length = 0.5
    ei = 2.0e9 * np.pi * (0.01 ** 4 - 0.004 ** 4) / 4.0
    rng = np.random.default_rng(7)
    # a deflected equilibrium (tip load PL^2/EI = 2 plus gravity), as in a control tick
    state = solve_static(model, tip_wrench=[0, 0, 2 * ei / length ** 2, 0, 0, 0],
                         gravity=[0, 0, -9.81], strict=True).state
    times = {}
    system = EquilibriumSystem(model, ActuatorSet((), model.n_frames), np.zeros(6 * 16))
    none = np.zeros(0)
    tangent = system.linearise(state.positions, state.rotations, none)[0]
    diagonal, upper = system.tridiagonal_blocks(tangent)
    fac = btd.factorize(diagonal, upper)
    rhs6 = rng.normal(size=(96, 6))
    rhs20 = rng.normal(size=(96, 20))
    times.update(time_calls({
        'linearise (compiled)': lambda: system.linearise(state.positions, state.rotations, none),
        f'factorize ({fac.method})': lambda: btd.factorize(diagonal, upper),
        'solve 6 RHS': lambda: fac.solve(rhs6),
        'solve 20 RHS': lambda: fac.solve(rhs20)}, budget))
    print('\nControl-tick pieces, 17-frame chain (16 links), microseconds:', file=out)
    for name, value in times.items():
        print(f'  {name:28s} {value * 1e6:9.1f}', file=out)
    tick = (times['linearise (compiled)'] + times[f'factorize ({fac.method})']
            + times['solve 20 RHS'])
    print(f"  {'tick (linearise+factor+20)':28s} {tick * 1e6:9.1f}", file=out)
    print('\nStatic solves, 17-frame chain (16 hollow Timoshenko links, L = 0.5 m):', file=out)
    print(f"  {'load case':34s} {'time ms':>8} {'iter':>5} {'steps':>5} {'residual N':>11} "
          f"{'tip deflection m':>17}", file=out)
    force = ei / length ** 2
    cases = (
        ('tip force PL^2/EI = 0.01 (linear)', {'tip_wrench': [0, 0.01 * force, 0, 0, 0, 0]}),
        ('tip force PL^2/EI = 1', {'tip_wrench': [0, force, 0, 0, 0, 0]}),
        ('tip force PL^2/EI = 5', {'tip_wrench': [0, 5 * force, 0, 0, 0, 0]}),
        ('tip force PL^2/EI = 10', {'tip_wrench': [0, 10 * force, 0, 0, 0, 0]}),
        ('tip moment 2 pi EI / L (circle)', {'tip_wrench': [0, 0, 0, 0, 0,
                                                            2 * np.pi * ei / length]}),
        ('gravity 9.81 m/s^2 (-z)', {'gravity': [0, 0, -9.81]}),
    )
    for name, kwargs in cases:
        res = solve_static(model, **kwargs)
        seconds = time_call(lambda kw=kwargs: solve_static(model, **kw), budget)
        times[name] = seconds
        tip = np.linalg.norm(res.positions[-1] - [length, 0, 0])
        print(f'  {name:34s} {seconds * 1e3:8.2f} {res.iterations:5d} {res.load_steps:5d} '
              f'{res.residual_norm:11.2e} {tip:17.6f}' + ('' if res.converged else
                                                          '  NOT CONVERGED'), file=out)
    return times


def main(argv=None):
    """
    Run the core benchmark and print the tables.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (``sys.argv[1:]`` by default).

    Returns
    -------
    int
        Exit status (0).

    """
    parser = argparse.ArgumentParser(prog='cbha_bench_core', description=__doc__.split('\n')[1])
    parser.add_argument('--quick', action='store_true',
                        help='n up to 1000 and shorter timing (about 10 s)')
    parser.add_argument('--sizes', type=int, nargs='+', help='numbers of frames n')
    parser.add_argument('--rhs', type=int, nargs='+', default=list(RHS_COUNTS),
                        help='numbers of right-hand sides')
    parser.add_argument('--budget', type=float, help='seconds of timing per table entry')
    args = parser.parse_args(argv)
    sizes = args.sizes or (QUICK_SIZES if args.quick else FULL_SIZES)
    budget = args.budget or (0.08 if args.quick else 0.25)
    out = sys.stdout
    print(f'cbha_bench_core: Python {platform.python_version()}, numpy {np.__version__}, '
          f'scipy {scipy.__version__}, {os.cpu_count()} CPUs, OPENBLAS_NUM_THREADS='
          f"{os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}", file=out)
    start = time.perf_counter()
    btd_table(sizes, args.rhs, budget, out)
    static_report(budget, out)
    print(f'\ntotal benchmark time {time.perf_counter() - start:.1f} s', file=out)
    return 0


if __name__ == '__main__':
    sys.exit(main())
