"""
Static equilibrium under actuator loads, with their load stiffness (paper eq. 9, DESIGN §3).

``f(q) + f_ext + J_a(q)ᵀ λ = 0``: the actuation enters the package's one Newton engine
(:func:`cbha_inverse.core.newton.solve_chain`) as a follower load ``J_a(q)ᵀ λ`` with its exact
load stiffness ``-d(J_aᵀ λ)/dq`` (:meth:`cbha_inverse.core.actuation.ActuatorSet.load_tangent`).
Cable and pressure forces follow the structure; a Newton iteration that ignores their stiffness
(the structural tangent alone) sees a tendon-compressed backbone as unstable and fails to converge
beyond small tensions. This is the forward model of the scenes
(:meth:`cbha_inverse.scene.Scene.forward`) and of the simulated plant
(:class:`cbha_inverse.core.plant.StaticPlant`), the same linearisation the inverse solver uses
per tick, so the three agree.
"""

from cbha_inverse.core.newton import NewtonResult, solve_chain
import numpy as np

#: Result of :func:`solve_equilibrium` (``state``, ``converged``, ``iterations``,
#: ``residual_norm``, ``residual``, ``load_steps``, ``load_factor``, ``message``).
EquilibriumResult = NewtonResult


def actuator_loads(actuators, actuation):
    """
    Return the follower load and the exact load tangent of an actuation, for the Newton engine.

    The load stiffness is the exact one of each actuator group, ``load_tangent(...,
    symmetric=False)``: Newton's convergence is then quadratic (with the symmetric part alone it
    is linear, ~10x per iteration on the tendon trunks).

    Parameters
    ----------
    actuators : cbha_inverse.core.actuation.ActuatorSet
        The actuators (columns of ``J_aᵀ`` and their load stiffness).
    actuation : (m,) array_like  [N or Pa]
        Applied actuation in column order.

    Returns
    -------
    load_function : callable or None
        ``state -> (n, 6)`` wrenches ``J_a(q)ᵀ λ`` on frames 1..n (world axes); None when the
        actuation is zero.
    load_tangent : callable or None
        ``state -> (6n, 6n)`` load stiffness ``-d(J_aᵀ λ)/dq`` (None when the actuation is
        zero; the callable returns None when no group has a load stiffness).

    """
    a = np.asarray(actuation, dtype=float).reshape(-1)
    if not np.any(a):
        return None, None
    names = list(actuators.names)
    groups = [(g, np.array([names.index(name) for name in g.names], dtype=int))
              for g in actuators.groups if hasattr(g, 'load_tangent')]
    last = {}

    def columns(state):
        if last.get('state') is not state:
            last['state'] = state
            last['wrenches'] = actuators.evaluate(state.positions, state.rotations, False)[0]
        return last['wrenches']

    def load_function(state):
        return np.tensordot(a, columns(state)[:, 1:, :], axes=1)

    def load_tangent(state):
        total = None
        for group, cols in groups:
            part = group.load_tangent(state.positions, state.rotations, a[cols], False)
            total = part if total is None else total + part
        return total

    return load_function, load_tangent


def solve_equilibrium(model, actuators, actuation, external=None, initial_state=None, *,
                      tolerance=1e-10, absolute_tolerance=None, max_iterations=50,
                      max_load_steps=64, max_rotation_step=None, check_warnings=True):
    """
    Solve ``f(q) + f_ext + J_a(q)ᵀ λ = 0`` for the frames (paper eq. 9).

    Parameters
    ----------
    model : cbha_inverse.core.chain.ChainModel
        The chain.
    actuators : cbha_inverse.core.actuation.ActuatorSet
        The actuators.
    actuation : (m,) array_like  [N or Pa]
        Applied actuation.
    external : (n, 6) or (6n,) array_like, optional  [N, N*m]
        Constant external wrenches (gravity) on frames 1..n.
    initial_state : ChainState, optional
        Warm start (else the rest shape, with load stepping if needed).
    tolerance : float
        Relative tolerance of the engine's convergence test (:mod:`cbha_inverse.core.newton`).
    absolute_tolerance : float, optional  [N, N*m]
        Converge on ``|r|_2 <= absolute_tolerance`` instead.
    max_iterations : int
        Newton iterations per load step.
    max_load_steps : int
        Load steps allowed (a warm start counts as one).
    max_rotation_step : float, optional  [rad]
        Largest link rotation of a line search's first trial step.
    check_warnings : bool
        Check the equilibrium for warnings (:func:`cbha_inverse.core.newton.solve_chain`).

    Returns
    -------
    EquilibriumResult
        Never silently unconverged: check ``converged``.

    """
    n = model.n_links
    external = None if external is None else np.asarray(external, dtype=float).reshape(n, 6)
    load_function, load_tangent = actuator_loads(actuators, actuation)
    return solve_chain(model, external, load_function=load_function, load_tangent=load_tangent,
                       initial_state=initial_state, tolerance=tolerance,
                       absolute_tolerance=absolute_tolerance, max_iterations=max_iterations,
                       max_load_steps=max_load_steps, max_rotation_step=max_rotation_step,
                       check_warnings=check_warnings)
