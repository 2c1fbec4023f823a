"""
A quasi-static plant for simulation: warm-started solves of the chain equilibrium.

The simulated robot (``cbha_sim``) must not share the controller's model: it is built from the
same scene with a deliberate stiffness error and its own gravity (see
:func:`cbha_inverse.scene.load_scene`), and every plant tick solves the static equilibrium
(paper eq. 9) ``f(q) + f_ext + J_a(q)ᵀ λ = 0`` for the applied actuation ``λ`` with the package's
Newton engine (:func:`cbha_inverse.core.equilibrium.solve_equilibrium`): exact tangent including
the actuators' load stiffness (LU, material-tangent fallback), line search, warm start from the
previous equilibrium and, should that fail, load stepping from the rest shape. Pure numpy, no ROS.
"""

from dataclasses import dataclass

from cbha_inverse.core.assembly import internal_wrenches
from cbha_inverse.core.chain import rest_state
from cbha_inverse.core.equilibrium import actuator_loads, solve_equilibrium
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
        Residual norm ``|r|_2`` at which an update stops.
    max_iterations : int
        Newton iterations per load step at most (the warm start is one; if it fails, load
        stepping from rest takes over, at most ``max_load_steps`` steps).
    max_rotation_step : float, optional  [rad]
        Largest link rotation of a line search's first trial step; None (default): full Newton
        steps, the line search and the material-tangent fallback keep far jumps robust (a
        limit of 0.3 rad costs ~50 % more iterations on the CBHA's jumps from rest).
    max_load_steps : int
        Load steps of an update at most (warm start included).

    """

    def __init__(self, scene, tolerance=1e-8, max_iterations=20, max_rotation_step=None,
                 max_load_steps=16):
        """Start at the rest shape with zero actuation."""
        self.model = scene.model
        self.actuators = scene.actuators
        self.effectors = scene.effectors
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)
        self.max_rotation_step = (None if max_rotation_step is None
                                  else float(max_rotation_step))
        self.max_load_steps = int(max_load_steps)
        external = np.zeros((self.model.n_links, 6))
        if scene.gravity is not None:
            external[:, :3] = np.asarray(self.model.masses, dtype=float)[:, None] * scene.gravity
        self._external = external
        self._state = rest_state(self.model)

    def reset(self):
        """Return to the rest shape (the next update starts from it)."""
        self._state = rest_state(self.model)

    def residual(self, actuation):
        """Return the equilibrium residual ``r`` (6n,) at the current state."""
        internal = internal_wrenches(self.model, self._state)
        load_function, _ = actuator_loads(self.actuators, actuation)
        loads = 0.0 if load_function is None else load_function(self._state)
        return (internal + self._external + loads).reshape(-1)

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
            The state reached (``converged`` False if the budget did not suffice; the next
            update continues from it).

        """
        res = solve_equilibrium(self.model, self.actuators, actuation, self._external,
                                self._state, absolute_tolerance=self.tolerance,
                                max_iterations=self.max_iterations,
                                max_load_steps=self.max_load_steps,
                                max_rotation_step=self.max_rotation_step,
                                check_warnings=False)
        self._state = res.state
        positions, rotations = res.state.positions, res.state.rotations
        return PlantResult(np.array(positions), self.effectors.positions(positions, rotations),
                           res.iterations, res.residual_norm, res.converged)
