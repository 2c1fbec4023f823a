"""
A compiled loop of independent multiply-add chains: this machine's rate for the tick's arithmetic.

The control tick's kernels are short loops of scalar multiply-adds over small arrays; eight
independent chains give the rate such code reaches when nothing else limits it (no memory
traffic, no dependency stalls). :mod:`cbha_inverse.report.tick_flops` divides a tick's flop count
by it to state how far the measured tick is from its arithmetic bound.
"""

import numba


@numba.njit(cache=True)
def multiply_add_chains(n_steps, seed):
    """
    Run eight independent chains ``a <- a c + d`` for ``n_steps`` steps (16 flops per step).

    Parameters
    ----------
    n_steps : int
        Steps of every chain.
    seed : float
        Start value (a run-time value, so the compiler cannot fold the loop).

    Returns
    -------
    float
        The sum of the chains (keeps them alive).

    """
    c, d = 0.999999, 1e-7
    a0, a1, a2, a3 = seed, seed + 1.0, seed + 2.0, seed + 3.0
    a4, a5, a6, a7 = seed + 4.0, seed + 5.0, seed + 6.0, seed + 7.0
    for _ in range(n_steps):
        a0 = a0 * c + d
        a1 = a1 * c + d
        a2 = a2 * c + d
        a3 = a3 * c + d
        a4 = a4 * c + d
        a5 = a5 * c + d
        a6 = a6 * c + d
        a7 = a7 * c + d
    return a0 + a1 + a2 + a3 + a4 + a5 + a6 + a7
