"""
The loaded scene: chain model, actuators, effectors and gravity, with its forward solve.

Built by :func:`cbha_inverse.scene.loader.load_scene` from a scene YAML; immutable. Frame 0 of
the chain (the base) sits at the origin of ``base_frame``, or at the calibration's base offset
(:mod:`cbha_inverse.scene.calibration`); gravity and targets are in ``base_frame`` axes.
"""

from functools import cached_property
from pathlib import Path

from cbha_inverse.core.actuation.cables import CableGroup, RoutedLengths
from cbha_inverse.core.actuation.drives import TendonDrives
from cbha_inverse.core.chain import rest_state
from cbha_inverse.core.inverse.solver import InverseOptions, InverseSolver
from cbha_inverse.core.loads import combined_hooks, Loads, static_loads
from cbha_inverse.core.statics import solve_static
from cbha_inverse.scene.calibration import Calibration
import numpy as np


class Scene:
    """
    A loaded scene: chain model, actuators, effectors and gravity (immutable).

    Build it with :func:`cbha_inverse.scene.load_scene`.

    Attributes
    ----------
    name : str
    description : str
    base_frame : str
    model : cbha_inverse.core.chain.ChainModel
    actuators : cbha_inverse.core.actuation.actuators.ActuatorSet
    effectors : cbha_inverse.core.actuation.effectors.PointEffectors
        Points, with the orientation rows of ``axis`` and ``pose`` kinds (``docs/effectors.md``).
    gravity : (3,) ndarray or None  [m/s^2]
        In ``base_frame`` axes (the world of the solvers).
    actuator_names, effector_names : tuple of str
    lower_bounds, upper_bounds : (m,) ndarray  [N or Pa]
    section_names : tuple of str
        Chain sections of a ``segments`` chain, in chain order (empty for beams).
    section_links : dict
        ``name -> (first link index, count)`` of those sections, in chain order: the links a
        section's stiffness factor scales
        (:func:`cbha_inverse.core.sections.link_sections`).
    actuator_sections : tuple of (str or None)
        The chain section of each actuator, scene actuator order: a cavity's ``section``, None
        for a cable.
    calibration : cbha_inverse.scene.calibration.Calibration
        The corrections applied at load (the file's block and the caller's, combined; its base
        offset is ``model.base_position`` / ``model.base_rotation``).
    sensors : cbha_inverse.core.sensors.StringPots or None
        The string potentiometers of the scene's ``sensors`` block (None without one).
    loads : cbha_inverse.core.loads.Loads
        The external loads of the scene's ``loads`` block and its
        ``calibration.tip_payload_mass`` (a mass named ``tip_payload_mass``), checked against
        the chain and the gravity (``docs/loads.md``).
    path : pathlib.Path or None
        The scene file.
    obstacles : tuple of cbha_inverse.core.obstacles.Obstacle
        The solids of the scene's ``obstacles`` block, in ``base_frame`` (empty without one).
    collision : cbha_inverse.core.contact.CollisionSpheres or None
        The robot's collision spheres (``collision`` block or the chain's own radius; None
        when neither gives one).

    """

    def __init__(self, name, model, actuators, effectors, gravity, *, description='',
                 base_frame='cbha_base', workspace=None, solver_defaults=None,
                 section_names=(), actuator_sections=None, calibration=None, sensors=None,
                 path=None, section_links=None, loads=None, obstacles=(), collision=None):
        """Store the parts (use :func:`cbha_inverse.scene.load_scene`)."""
        self.name = name
        self.description = description
        self.base_frame = base_frame
        self.model = model
        self.actuators = actuators
        self.effectors = effectors
        self.gravity = None if gravity is None else np.asarray(gravity, dtype=float)
        self.actuator_names = tuple(actuators.names)
        self.effector_names = tuple(effectors.names)
        self.lower_bounds = np.array(actuators.lower_bounds, dtype=float)
        self.upper_bounds = np.array(actuators.upper_bounds, dtype=float)
        self.section_names = tuple(section_names)
        self.section_links = dict(section_links or {})
        if set(self.section_links) - set(self.section_names):
            raise ValueError('section_links names a section not in section_names')
        self.actuator_sections = (tuple(actuator_sections) if actuator_sections is not None
                                  else (None,) * len(self.actuator_names))
        if len(self.actuator_sections) != len(self.actuator_names):
            raise ValueError('actuator_sections needs one entry per actuator')
        self.calibration = Calibration() if calibration is None else calibration
        self.sensors = sensors
        self.loads = (Loads() if loads is None else loads).checked(model.n_links, self.gravity)
        self.path = None if path is None else Path(path)
        self.obstacles = tuple(obstacles)
        self.collision = collision
        self._workspace = workspace
        self._solver_defaults = dict(solver_defaults or {})

    def __repr__(self):
        """Summarise the scene."""
        return (f'Scene({self.name!r}: {self.model.n_links} links, '
                f'{len(self.actuator_names)} actuators, {len(self.effector_names)} effectors)')

    def forward(self, actuation, *, loads=None, initial_state=None, tolerance=1e-10,
                strict=False, check_warnings=True):
        """
        Solve the static equilibrium under an actuation (paper eq. 9).

        Uses :func:`cbha_inverse.core.statics.solve_static` (the package's one static solver,
        with the actuators' load stiffness, line search, load stepping), which evaluates the
        same compiled kernels as the inverse solver.

        Parameters
        ----------
        actuation : (m,) array_like  [N or Pa]
            Tensions / gauge pressures in actuator order (must lie within the bounds).
        loads : cbha_inverse.core.loads.Loads, optional
            The external loads (default: the scene's, :attr:`loads`; ``Loads()``: none;
            ``scene.loads.updated(...)`` adds to them). Follower loads come with their exact
            load stiffness (:func:`cbha_inverse.core.loads.static_loads`).
        initial_state : ChainState, optional
            Warm start.
        tolerance : float
            Relative tolerance of the static solver (:mod:`cbha_inverse.core.statics`).
        strict : bool
            Raise ``RuntimeError`` when the solve does not converge.
        check_warnings : bool
            Check the equilibrium for the static solver's warnings (strain, stability,
            round-off: ``warnings`` of the result); False leaves ``warnings`` empty and saves
            about a quarter of a warm-started solve, for callers that only read the shape.

        Returns
        -------
        cbha_inverse.core.statics.StaticResult
            The equilibrium with its ``effector_positions`` and ``actuation`` (``converged``
            says whether it was reached).

        Raises
        ------
        ValueError
            On an actuation of the wrong size, not finite or outside the bounds, or a load
            beyond the chain or a mass without gravity.

        """
        a = np.asarray(actuation, dtype=float).reshape(-1)
        if a.size != len(self.actuator_names) or not np.all(np.isfinite(a)):
            raise ValueError(f'actuation must be {len(self.actuator_names)} finite values')
        if np.any(a < self.lower_bounds - 1e-9 * np.abs(self.upper_bounds)) or np.any(
                a > self.upper_bounds * (1.0 + 1e-9)):
            raise ValueError('actuation outside the actuator bounds')
        applied = static_loads(self.loads if loads is None else loads, self.model.n_links,
                               self.gravity)
        res = solve_static(self.model, gravity=self.gravity, actuators=self.actuators,
                           actuation=a, effectors=self.effectors, initial_state=initial_state,
                           tolerance=tolerance, check_warnings=check_warnings, **applied)
        if strict and not res.converged:
            raise RuntimeError(f'forward solve of {self.name} did not converge: {res.message}')
        return res

    def forward_displacements(self, displacements, *, initial_state=None, tolerance=1e-10,
                              strict=False):
        """
        Solve the static equilibrium of the cables driven by displacement.

        Under the scene's :attr:`loads`, each cable's tension follows from its stretch
        (:attr:`tendon_drives`, a cable let out beyond its path is slack); the cables act as in
        :meth:`forward`, through the same static solver.

        Parameters
        ----------
        displacements : (c,) array_like  [m]
            Drive displacements from the straight chain's cable lengths, in scene actuator
            order (pulled in: negative).
        initial_state : ChainState, optional
            Warm start.
        tolerance : float
            Relative tolerance of the static solver.
        strict : bool
            Raise ``RuntimeError`` when the solve does not converge.

        Returns
        -------
        cbha_inverse.core.statics.StaticResult
            The equilibrium (its ``actuation`` is zero: the tensions are
            ``tendon_drives.tensions(result.state, displacements)``; ``warnings`` unchecked).
            When one solve does not converge, the drives move in smaller steps from the
            start; ``converged`` is False if a step of 1/1024 of the way fails too.

        Raises
        ------
        ValueError
            If the scene has actuators other than cables, a cable without a finite
            ``axial_stiffness``, or a displacement is not finite.

        """
        drives = self.tendon_drives
        if drives is None or len(drives.names) != len(self.actuator_names):
            raise ValueError(f'scene {self.name}: displacement commands need a scene whose '
                             'actuators are all cables')
        d = np.asarray(displacements, dtype=float).reshape(-1)
        drives.tensions(rest_state(self.model), d)       # the door: shape, NaN, stiffness
        # Newton's tangent: the cables' exact load stiffness at the tensions of the last
        # equilibrium (the actuators' own, as in forward) plus the stretch stiffness; the loads
        # are exactly the drives' (the actuators' part plus the difference). The drives move in
        # steps when one jump does not converge (a stiff cable pulled in far from the start
        # pulls with a large force at the first iterate).
        state = rest_state(self.model) if initial_state is None else initial_state
        reached, step, res = 0.0, 1.0, None
        held, _ = drives.tensions(state, 0.0 * d)
        while reached < 1.0 and step >= 1.0 / 1024:
            trial = min(1.0, reached + step)
            res = self._displaced(drives, trial * d, held, state, tolerance)
            if res.converged:
                state, reached, step = res.state, trial, 2.0 * step
                held, _ = drives.tensions(state, trial * d)
            else:
                step /= 2.0
        if strict and not res.converged:
            raise RuntimeError(f'forward solve of {self.name} did not converge: {res.message}')
        return res

    def _displaced(self, drives, displacements, tensions, initial_state, tolerance):
        """Solve the drives' equilibrium with the cables' own load stiffness at ``tensions``."""
        applied = static_loads(self.loads, self.model.n_links, self.gravity)
        function, tangent = combined_hooks(
            (applied.pop('load_function'), applied.pop('load_tangent')),
            drives.correction_hooks(displacements, tensions))
        return solve_static(self.model, gravity=self.gravity, actuators=self.actuators,
                            actuation=tensions, effectors=self.effectors, load_function=function,
                            load_tangent=tangent, initial_state=initial_state,
                            tolerance=tolerance, max_load_steps=8, check_warnings=False,
                            **applied)

    def cable_lengths(self, state):
        """
        Return the routed length of every cable (tendon) at a state, and its gradient.

        The sum of each cable's straight spans between its routing points
        (:class:`cbha_inverse.core.actuation.cables.RoutedLengths`, the geometry of the
        cables' forces); a tendon's displacement from a pose is the difference of two
        lengths (pulled in: negative).

        Parameters
        ----------
        state : cbha_inverse.core.chain.ChainState
            The frames, e.g. the ``state`` of a :meth:`forward` result.

        Returns
        -------
        names : tuple of str
            The cables, in scene actuator order (cavities left out).
        lengths : (c,) ndarray  [m]
        jacobian : (c, 6n) ndarray  [-, m/rad]
            ``d(length)/dq`` in the retract increments ``(dx_f, dθ_f)`` of frames 1..n (a copy).

        Raises
        ------
        ValueError
            If the scene has no cable.

        """
        routes = self.tendon_routes
        if routes is None:
            raise ValueError(f'scene {self.name} has no cable')
        lengths, jacobian = routes.lengths_and_jacobian(state.positions, state.rotations)
        return routes.names, lengths, jacobian.copy()

    @cached_property
    def tendon_drives(self):
        """
        Return the cables as displacement-commanded drives (None: the scene has no cable).

        :class:`cbha_inverse.core.actuation.drives.TendonDrives` with the rest lengths of the
        straight chain as built (:func:`cbha_inverse.core.chain.rest_state`: zero
        displacement) and each cable's ``axial_stiffness``.
        """
        routes = self.tendon_routes
        if routes is None:
            return None
        straight = rest_state(self.model)
        rest_lengths, _ = routes.lengths_and_jacobian(straight.positions, straight.rotations)
        return TendonDrives(routes, rest_lengths)

    @cached_property
    def tendon_routes(self):
        """Return the cables' routed lengths in actuator order (None: the scene has no cable)."""
        cables = {cable.name: cable for group in self.actuators.groups
                  if isinstance(group, CableGroup) for cable in group.cables}
        ordered = [cables[name] for name in self.actuator_names if name in cables]
        return RoutedLengths(CableGroup(ordered, self.model.n_frames)) if ordered else None

    @cached_property
    def rest_effector_positions(self):
        """(k, 3) effector positions at zero actuation (under the scene's gravity)."""
        return self.forward(np.clip(np.zeros(len(self.actuator_names)), self.lower_bounds,
                                    self.upper_bounds), strict=True).effector_positions

    @cached_property
    def workspace_center(self):
        """
        (k, 3) suggested centre of target trajectories [m].

        From the scene's ``workspace_center``: explicit coordinates (tip effector, moved with
        the calibration's base offset; other effectors at rest), ``{actuation_fraction: f}``
        = the effectors at the uniform actuation ``lower + f (upper - lower)``, or
        ``reachable_center`` = the last effector at the centre of its sampled reachable set
        (:func:`cbha_inverse.scene.reach.sample_reachable_set`, computed here on first read,
        deterministic; other effectors at rest). Without it: the rest effector positions. For
        the CBHA this is the tip at mid pressure in every tube, around which the paper's 60 mm
        circle in the y-z plane is reachable.
        """
        spec = self._workspace
        if spec is None:
            return self.rest_effector_positions.copy()
        if isinstance(spec, dict) and 'reachable_center' in spec:
            from cbha_inverse.scene.reach import sample_reachable_set
            center = self.rest_effector_positions.copy()
            center[-1] = sample_reachable_set(self, spec['reachable_center']).center
            return center
        if isinstance(spec, dict):
            f = float(spec.get('actuation_fraction', 0.0))
            a = self.lower_bounds + f * (self.upper_bounds - self.lower_bounds)
            return self.forward(a, strict=True).effector_positions
        center = self.rest_effector_positions.copy()
        center[-1] = np.asarray(spec, dtype=float)
        return center

    def make_inverse_solver(self, **options):
        """
        Build the per-tick inverse solver of this scene (the tick of ``docs/design.md``).

        Parameters
        ----------
        **options
            Fields of :class:`cbha_inverse.core.inverse.solver.InverseOptions` (``energy_weight``,
            ``proximal_weight``, ``rate_limit``, ``qp_solver``, ``newton_steps``, ...); the
            scene's ``solver`` section gives the defaults.

        Returns
        -------
        cbha_inverse.core.inverse.solver.InverseSolver
            Starts at rest; ``step(targets (k, 3))`` returns a ``TickResult`` (``axis`` and
            ``pose`` effectors: ``step(targets, directions=..., quaternions=...)``); its
            ``set_section_stiffness`` takes one factor per entry of :attr:`section_links`; the
            scene's :attr:`obstacles` and :attr:`collision` spheres give its obstacle rows
            (``docs/obstacles.md``).

        """
        merged = {**self._solver_defaults, **options}
        if merged.get('rate_limit') is not None:
            merged['rate_limit'] = tuple(np.broadcast_to(
                np.asarray(merged['rate_limit'], dtype=float), (len(self.actuator_names),)))
        return InverseSolver(self.model, self.actuators, self.effectors, gravity=self.gravity,
                             options=InverseOptions(**merged), sections=self.section_links,
                             loads=self.loads, obstacles=self.obstacles,
                             collision=self.collision)
