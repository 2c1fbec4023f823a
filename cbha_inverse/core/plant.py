"""
A quasi-static plant for simulation: warm-started Newton solves of the chain equilibrium.

The simulated robot (``cbha_sim``) must not share the controller's model: it is built from the
same scene with a deliberate stiffness error and its own gravity (see
:func:`cbha_inverse.scene.load_scene`), and every plant tick solves the static equilibrium
(paper eq. 9) ``f(q) + f_ext + J_a(q)ᵀ λ = 0`` for the applied actuation ``λ`` by Newton's method
from the previous equilibrium: ``K(q) dq = r(q)``, ``q ← q ⊞ dq`` with
``r = f(q) + f_ext + J_aᵀ λ`` and ``K = -dr/dq`` (structural tangent of the fused chain kernel plus
the cables' load stiffness). Pure numpy, no ROS.
"""

from dataclasses import dataclass

from cbha_inverse.core.chain import rest_state
from cbha_inverse.core.kernel import ChainKernel, DenseCholesky, fast_retract
import numpy as np


@dataclass(frozen=True)
class PlantResult:
    """
    Equilibrium reached by one plant update.

    Attributes
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    effector_positions : (k, 3) ndarray  [m]
        Effector points.
    iterations : int
        Newton iterations of this update.
    residual_norm : float  [N, N*m]
        Equilibrium residual norm at the end.
    converged : bool
        Whether ``residual_norm <= tolerance``.

    """

    positions: np.ndarray
    effector_positions: np.ndarray
    iterations: int
    residual_norm: float
    converged: bool


class StaticPlant:
    """
    Quasi-static chain under actuation, solved by warm-started Newton iterations.

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        The plant's scene (load it with the model error wanted, e.g. ``stiffness_scale=0.9``).
    tolerance : float  [N, N*m]
        Residual norm at which an update stops.
    max_iterations : int
        Newton iterations per update at most (the next update continues from there).
    max_rotation_step : float  [rad]
        Largest frame rotation per Newton step (keeps far jumps robust).

    """

    def __init__(self, scene, tolerance=1e-8, max_iterations=20, max_rotation_step=0.3):
        """Start at the rest shape with zero actuation."""
        self.model = scene.model
        self.actuators = scene.actuators
        self.effectors = scene.effectors
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)
        self.max_rotation_step = float(max_rotation_step)
        self._kernel = ChainKernel(self.model)
        external = np.zeros((self.model.n_links, 6))
        if scene.gravity is not None:
            external[:, :3] = np.asarray(self.model.masses, dtype=float)[:, None] * scene.gravity
        self._external = external.reshape(-1)
        state = rest_state(self.model)
        self._positions = np.array(state.positions, dtype=float)
        self._rotations = np.array(state.rotations, dtype=float)

    def residual(self, actuation):
        """Return the equilibrium residual ``r`` (6n,) at the current state."""
        internal = self._kernel.internal(self._positions, self._rotations)
        wrenches, _ = self.actuators.evaluate(self._positions, self._rotations)
        return (np.asarray(internal).reshape(-1) + self._external
                + actuation @ wrenches[:, 1:, :].reshape(wrenches.shape[0], -1))

    def update(self, actuation):
        """
        Move the plant to the equilibrium of an actuation (warm start: the current state).

        Parameters
        ----------
        actuation : (m,) array_like  [N or Pa]
            Applied actuation in scene actuator order.

        Returns
        -------
        PlantResult
            The state reached (``converged`` False if ``max_iterations`` did not suffice; the next
            update continues from it).

        """
        actuation = np.asarray(actuation, dtype=float)
        residual_norm = np.inf
        iterations = 0
        for iterations in range(self.max_iterations + 1):
            internal, tangent = self._kernel.linearise(self._positions, self._rotations)
            wrenches, _ = self.actuators.evaluate(self._positions, self._rotations)
            jat = wrenches[:, 1:, :].reshape(wrenches.shape[0], -1)
            residual = internal.reshape(-1) + self._external + actuation @ jat
            residual_norm = float(np.linalg.norm(residual))
            if residual_norm <= self.tolerance or iterations == self.max_iterations:
                break
            load = self.actuators.load_tangent(self._positions, self._rotations, actuation)
            matrix = tangent + load if load is not None else tangent.copy()
            try:
                step = DenseCholesky(matrix).solve(residual)
            except np.linalg.LinAlgError:
                _, material = self._kernel.linearise(self._positions, self._rotations,
                                                     geometric=False)
                step = DenseCholesky(material.copy()).solve(residual)
            increments = step.reshape(-1, 6)
            largest = np.sqrt(np.max(np.einsum('ij,ij->i', increments[:, 3:], increments[:, 3:])))
            if largest > self.max_rotation_step:
                increments = increments * (self.max_rotation_step / largest)
            self._positions, self._rotations = fast_retract(self._positions, self._rotations,
                                                            increments)
        return PlantResult(self._positions.copy(),
                           self.effectors.positions(self._positions, self._rotations),
                           iterations, residual_norm, residual_norm <= self.tolerance)
