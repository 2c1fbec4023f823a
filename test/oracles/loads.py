"""Actuator follower loads and their load stiffness as callables (numpy oracle)."""

import numpy as np
from oracles.actuation import oracle


def actuator_loads(actuators, actuation):
    """
    Return the follower load ``J_a(q)ᵀ λ`` and its exact load tangent as callables.

    Built from the numpy ``evaluate`` / ``load_tangent`` of the actuator groups, for
    ``solve_static(load_function=..., load_tangent=...)``: an independent route to the loads the
    compiled kernels evaluate when ``actuators`` are passed.

    Parameters
    ----------
    actuators : cbha_inverse.core.actuation.actuators.ActuatorSet
        The actuators.
    actuation : (m,) array_like  [N or Pa]
        Applied actuation in column order.

    Returns
    -------
    load_function : callable
        ``state -> (n, 6)`` wrenches on frames 1..n (world axes).
    load_tangent : callable
        ``state -> (6n, 6n)`` load stiffness ``-d(J_aᵀ λ)/dq``.

    """
    a = np.asarray(actuation, dtype=float).reshape(-1)
    actuators = oracle(actuators)

    def load_function(state):
        wrenches = actuators.evaluate(state.positions, state.rotations, False)[0]
        return np.tensordot(a, wrenches[:, 1:, :], axes=1)

    def load_tangent(state):
        return actuators.load_tangent(state.positions, state.rotations, a, symmetric=False)

    return load_function, load_tangent
