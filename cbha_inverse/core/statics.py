"""
Quasi-static equilibrium of a frame chain under dead and follower loads (DESIGN §3, §11).

:func:`solve_static` solves ``f(q) + f_ext = 0`` (paper eq. 9; actuation enters through
``load_function`` and its ``load_tangent``) for the poses of frames 1..n. It is the public face of
the package's one Newton engine, :func:`cbha_inverse.core.newton.solve_chain` (exact tangent,
deformation-coordinate updates, line search, material-tangent fallback, load stepping; its module
docstring states the method and the convergence test). This module adds the dead loads (tip and
frame wrenches, gravity on the lumped masses) and the public result type.
"""

from dataclasses import dataclass

from cbha_inverse.core.chain import ChainState, checked_array
from cbha_inverse.core.newton import solve_chain
import numpy as np


class StaticConvergenceError(RuntimeError):
    """A static solve did not converge (raised only by strict solves); ``.result`` holds it."""

    def __init__(self, result):
        super().__init__(result.message)
        self.result = result


@dataclass(frozen=True, eq=False)
class StaticResult:
    """
    Result of :func:`solve_static`.

    Attributes
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins, frame 0 = base.
    quaternions : (n + 1, 4) ndarray
        Frame orientations (x, y, z, w).
    rotations : (n + 1, 3, 3) ndarray
        Frame rotation matrices.
    state : ChainState
        The same poses as a state (e.g. to warm-start the next solve).
    converged : bool
        True only if the full load was reached and the residual test passed.
    iterations : int
        Total Newton iterations over all load steps.
    residual_norm : float  [N]
        Max-norm of the scaled residual (moments / chain length) of the returned state under
        the full load.
    load_steps : int
        Load steps attempted (successful and failed).
    load_factor : float
        Fraction of the load in equilibrium at the returned state (1.0 when converged).
    message : str
        What happened, in words.
    warnings : tuple of str
        What the user should know about a converged state: round-off limited residual, an
        unstable equilibrium (buckling), links strained beyond their small-strain range
        (:mod:`cbha_inverse.core.newton`).

    """

    positions: np.ndarray
    quaternions: np.ndarray
    rotations: np.ndarray
    state: ChainState
    converged: bool
    iterations: int
    residual_norm: float
    load_steps: int
    load_factor: float
    message: str
    warnings: tuple = ()


def external_wrenches(model, tip_wrench=None, frame_wrenches=None, gravity=None):
    """
    Dead external wrenches on frames 1..n (world axes, at the frame origins).

    Parameters
    ----------
    model : ChainModel
        The chain (masses are lumped at frames 1..n).
    tip_wrench : (6,) array_like, optional  [N, N*m]
        Added at the last frame.
    frame_wrenches : (n, 6) array_like, optional  [N, N*m]
        Wrench on each of frames 1..n.
    gravity : (3,) array_like, optional  [m/s^2]
        Acceleration of gravity; force ``m_i g`` on frame i.

    Returns
    -------
    (n, 6) ndarray

    """
    n = model.n_links
    ext = np.zeros((n, 6))
    if frame_wrenches is not None:
        ext += checked_array(frame_wrenches, (n, 6), 'frame_wrenches')
    if tip_wrench is not None:
        ext[-1] += checked_array(tip_wrench, (6,), 'tip_wrench')
    if gravity is not None:
        ext[:, :3] += model.masses[:, None] * checked_array(gravity, (3,), 'gravity')
    return ext


def solve_static(model, tip_wrench=None, frame_wrenches=None, gravity=None, *,
                 load_function=None, load_tangent=None, initial_state=None, tolerance=1e-10,
                 max_iterations=50, max_load_steps=64, strict=False):
    """
    Solve for the static equilibrium of a chain under dead and follower loads (paper eq. 9).

    Parameters
    ----------
    model : ChainModel
        The chain; frame 0 is fixed.
    tip_wrench : (6,) array_like, optional  [N, N*m]
        Dead wrench at the last frame, world axes.
    frame_wrenches : (n, 6) array_like, optional  [N, N*m]
        Dead wrenches at frames 1..n, world axes.
    gravity : (3,) array_like, optional  [m/s^2]
        Acting on the masses lumped at frames 1..n (force only).
    load_function : callable, optional
        ``load_function(state) -> (n, 6)`` extra configuration-dependent wrenches (world axes,
        at frames 1..n), e.g. cables or pressure; scaled by the load factor like the dead loads.
    load_tangent : callable, optional
        ``load_tangent(state) -> (6n, 6n)`` ndarray: the load stiffness ``-d load_function / dq``
        over frames 1..n (world-axis increments as in ``retract``, at the full load).
        :func:`cbha_inverse.core.equilibrium.actuator_loads` returns both callables for a
        scene's actuators. Without it the follower loads are not differentiated, which
        converges slowly and stalls under large cable tensions or pressures.
    initial_state : ChainState, optional
        Warm start (e.g. the previous solution): Newton on the full load from it; if that
        fails, load stepping from the rest shape (the default start).
    tolerance : float
        Relative residual tolerance (see :mod:`cbha_inverse.core.newton`).
    max_iterations : int
        Newton iterations allowed per load step.
    max_load_steps : int
        Load steps allowed (attempts, successful or not).
    strict : bool
        Raise :class:`StaticConvergenceError` instead of returning an unconverged result.

    Returns
    -------
    StaticResult
        ``converged`` is False (with a message) if the full load was not reached; the state is
        then the last equilibrium found (at ``load_factor`` < 1) or the last iterate.

    Raises
    ------
    ValueError
        If a load or the gravity has the wrong shape or is not finite, or ``initial_state``
        does not match the model.
    StaticConvergenceError
        With ``strict``, if the solve did not converge.

    """
    res = solve_chain(model, external_wrenches(model, tip_wrench, frame_wrenches, gravity),
                      load_function=load_function, load_tangent=load_tangent,
                      initial_state=initial_state, tolerance=tolerance,
                      max_iterations=max_iterations, max_load_steps=max_load_steps)
    state = res.state
    result = StaticResult(state.positions, state.quaternions, state.rotations, state,
                          res.converged, res.iterations, res.residual_norm, res.load_steps,
                          res.load_factor, res.message, res.warnings)
    if strict and not result.converged:
        raise StaticConvergenceError(result)
    return result
