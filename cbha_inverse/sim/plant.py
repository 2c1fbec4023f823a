"""
A quasi-static plant for simulation: warm-started solves of the chain equilibrium.

The simulated robot (``cbha_sim``) must not share the controller's model: it is built from the
same scene with a deliberate stiffness error and its own gravity (see
:func:`cbha_inverse.scene.load_scene`), and every plant tick solves the static equilibrium
(paper eq. 9) ``f(q) + f_ext + J_a(q)ᵀ λ = 0`` for the applied actuation ``λ`` with the package's
one static solver (:func:`cbha_inverse.core.statics.solve_static`, the compiled kernels of the
controller's tick): exact tangent including the actuators' load stiffness, line search, warm
start from the previous equilibrium and, should that fail, load stepping from the rest shape.

Obstacles (the scene's, or replaced at run time by :meth:`StaticPlant.set_obstacles`) push the
robot's collision spheres out with a frictionless penalty
(:class:`cbha_inverse.core.contact.PenaltyContact`: force ``k p n`` with its exact load
stiffness, through ``solve_static``'s ``load_function`` / ``load_tangent``); each update reports
its contacts (point, normal, penetration, force). Without obstacles the solve is the one above,
bit for bit. No ROS.
"""

from cbha_inverse.core.chain import rest_state
from cbha_inverse.core.contact import NO_CONTACTS, PenaltyContact
from cbha_inverse.core.loads import combined_hooks, Loads, static_loads
from cbha_inverse.core.obstacles import check_names
from cbha_inverse.core.statics import solve_static
import numpy as np


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
    contact_stiffness : float  [N/m]
        Penalty stiffness of the contacts with obstacles: a contact force ``F`` penetrates by
        ``F / contact_stiffness``.
    command_kind : str
        ``'tension'``: :meth:`update` takes the actuation (N or Pa); ``'displacement'``: the
        cables' drive displacements [m] (:attr:`cbha_inverse.scene.Scene.tendon_drives`; a
        scene whose actuators are all cables with a finite ``axial_stiffness``).

    Attributes
    ----------
    obstacles : tuple of cbha_inverse.core.obstacles.Obstacle
        The obstacles the plant touches (initially the scene's).
    contacts : cbha_inverse.core.contact.Contacts
        The contacts of the last update's state (none before the first).
    clearance : float  [m]
        The smallest gap of the last update's state between a collision sphere and an obstacle
        (:meth:`cbha_inverse.core.contact.CollisionSpheres.clearances`; negative: the deepest
        penetration); ``inf`` before the first update and without obstacles.

    Attributes
    ----------
    loads : cbha_inverse.core.loads.Loads
        The external loads on the plant (the scene's at start; :meth:`set_loads`).
    tensions : (m,) ndarray or None  [N]
        With ``command_kind='displacement'``: the cables' tensions at the last update.

    """

    def __init__(self, scene, tolerance=1e-8, max_iterations=20, max_rotation_step=None,
                 max_load_steps=16, contact_stiffness=1.0e4, command_kind='tension'):
        """Start at the rest shape with zero actuation."""
        if command_kind not in ('tension', 'displacement'):
            raise ValueError(f"command_kind must be 'tension' or 'displacement', got "
                             f'{command_kind!r}')
        self.command_kind = command_kind
        self.drives = None
        if command_kind == 'displacement':
            self.drives = scene.tendon_drives
            if self.drives is None or len(self.drives.names) != scene.actuators.n_actuators \
                    or not all(self.drives.axial_stiffness < float('inf')):
                raise ValueError(f'scene {scene.name}: displacement commands need every actuator '
                                 'a cable with a finite axial_stiffness')
        self.model = scene.model
        self.actuators = scene.actuators
        self.effectors = scene.effectors
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)
        self.max_rotation_step = (None if max_rotation_step is None
                                  else float(max_rotation_step))
        self.max_load_steps = int(max_load_steps)
        self.gravity = scene.gravity
        self._state = rest_state(self.model)
        self.collision = scene.collision
        self.contact_stiffness = float(contact_stiffness)
        self.contacts = NO_CONTACTS
        self.clearance = np.inf
        self.tensions = None if self.drives is None else np.zeros(len(self.drives.names))
        self.set_loads(scene.loads)
        self.set_obstacles(scene.obstacles)

    def set_loads(self, loads):
        """
        Replace the external loads on the plant; the next update reaches their equilibrium.

        Parameters
        ----------
        loads : cbha_inverse.core.loads.Loads
            The loads (``Loads()``: none), e.g. ``scene.loads.updated(...)``.

        Raises
        ------
        ValueError
            If a load's frame lies beyond the chain or a mass has no gravity.

        """
        if not isinstance(loads, Loads):
            raise ValueError(f'loads must be a Loads, got {type(loads).__name__}')
        self._applied = static_loads(loads, self.model.n_links, self.gravity)
        self.loads = loads

    def set_obstacles(self, obstacles):
        """
        Replace the obstacles (the next update sees them; an empty sequence removes them).

        Parameters
        ----------
        obstacles : sequence of cbha_inverse.core.obstacles.Obstacle
            The new obstacles, in the scene's base frame.

        Raises
        ------
        ValueError
            If two share a name, or the scene has no collision spheres
            (:attr:`cbha_inverse.scene.Scene.collision`) to touch them with.

        """
        obstacles = check_names(obstacles)
        if obstacles and self.collision is None:
            raise ValueError('the plant has no collision spheres (declare collision.radius in '
                             'the scene) to touch obstacles with')
        self._contact = (PenaltyContact(self.collision, obstacles, self.contact_stiffness,
                                        self.model.n_links) if obstacles else None)
        self.obstacles = obstacles

    def reset(self):
        """Return to the rest shape (the next update starts from it)."""
        self._state = rest_state(self.model)
        self.contacts = NO_CONTACTS
        self.clearance = np.inf
        if self.drives is not None:
            self.tensions = np.zeros(len(self.drives.names))

    def residual(self, actuation):
        """Return the equilibrium residual ``r`` (6n,) at the current state."""
        return self._solve(actuation, max_iterations=0, max_load_steps=1).residual.reshape(-1)

    def _solve(self, command, max_iterations, max_load_steps):
        """
        Solve from the current state (see :meth:`update`).

        Displacement-driven cables act as the actuators at the tensions of the last equilibrium
        (their exact load stiffness) plus the drives' correction
        (:meth:`cbha_inverse.core.actuation.drives.TendonDrives.correction_hooks`).
        """
        contact = self._contact
        applied = dict(self._applied)
        hooks = [(applied.pop('load_function'), applied.pop('load_tangent')),
                 (None, None) if contact is None else (contact.wrenches, contact.tangent)]
        actuation = command
        if self.drives is not None:
            hooks.append(self.drives.correction_hooks(command, self.tensions))
            actuation = self.tensions
        function, tangent = combined_hooks(*hooks)
        return solve_static(self.model, gravity=self.gravity, actuators=self.actuators,
                            actuation=actuation, effectors=self.effectors,
                            load_function=function, load_tangent=tangent,
                            load_step_limit=None if contact is None else contact.step_limit,
                            initial_state=self._state, absolute_tolerance=self.tolerance,
                            max_iterations=max_iterations, max_load_steps=max_load_steps,
                            max_rotation_step=self.max_rotation_step, check_warnings=False,
                            **applied)

    def update(self, actuation):
        """
        Move the plant to the equilibrium of an actuation (warm start: the current state).

        Parameters
        ----------
        actuation : (m,) array_like  [N or Pa, or m]
            Applied actuation in scene actuator order; with ``command_kind='displacement'`` the
            drives' displacements (:attr:`tensions` then holds the cables' tensions).

        Returns
        -------
        cbha_inverse.core.statics.StaticResult
            The state reached with its ``effector_positions`` (``converged`` False if the budget
            did not suffice; the next update continues from it).

        """
        res = self._solve(actuation, self.max_iterations, self.max_load_steps)
        self._state = res.state
        if self.drives is not None:
            self.tensions, _ = self.drives.tensions(res.state, actuation)
        self.contacts = (NO_CONTACTS if self._contact is None
                         else self._contact.contacts(res.state))
        self.clearance = (np.inf if self._contact is None else float(
            self.collision.clearances(res.state.positions, self.obstacles).min()))
        return res
