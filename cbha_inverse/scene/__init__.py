"""
Scenes: a YAML file that names the chain, actuators and effectors of a run (DESIGN §1, §11).

``load_scene(path)`` builds only what the scene names: a beam-and-tendon scene imports neither
gmsh nor meshio nor OpenCV; a segment scene (the CBHA) reads condensed segments through
:func:`cbha_inverse.fem.segment_io.load_segment`, imported only then.

Scene YAML schema (SI units)::

    name: str
    description: str
    base_frame: str                      # TF name of the world (default cbha_base)
    gravity: [gx, gy, gz] or null        # m/s^2, base_frame axes (+x along the backbone at rest)
    chain:                               # one of two types
      type: beam_vertebrae               # Timoshenko beams, vertebrae every `beams_per_interval`
      n_vertebrae, beams_per_interval, interval_length, vertebra_mass, backbone: {youngs_modulus,
      poisson_ratio, outer_radius, inner_radius, density}
    chain:
      type: segments                     # condensed segments in series
      sections: [{name, segment: <path relative to the scene file>, count}]
    cables: [{name, angle_deg, radius, end_vertebra, max_tension}]       # routed base → end
    cavities: [{name, section, cavity: <segment cavity name>, max_pressure}]
    cavity_model: linear | mesh          # core.actuation.condensed_cavities / .cavities
    actuator_order: [names]              # column order (default: cables, then cavities)
    effectors: [{name, frame: <int or 'tip'> or vertebra: <int>, offset: [x, y, z]}]
    workspace_center: [x, y, z] or {actuation_fraction: f}
    solver: {energy_weight, proximal_weight, rate_limit, relinearize_every, ...}  # defaults
    calibration:                         # identified corrections (cbha_identify), optional
      section_stiffness: {<section name>: factor}    # stiffness factor of a segments section
      actuator_gain: {<actuator name>: factor}       # cavity effective area, cable force/N
      tip_payload_mass: kg                           # mass added at the last frame
      base_offset: {position: [x, y, z], rpy: [r, p, y]}  # chain base in base_frame, m / rad

Frame 0 of the chain (the base) sits at the origin of ``base_frame``, or at
``calibration.base_offset`` when given: every frame, routing and effector point moves with it,
as does an explicit ``workspace_center``; gravity and targets stay in ``base_frame`` axes.

Scenes shipped in ``config/scenes``: ``tendon_6f_8c`` and ``tendon_10f_16c`` (the paper's Fig. 6
trunks, Timoshenko beams and cables) and ``cbha`` (16 condensed bellows segments, 6 cavities).
"""

from dataclasses import fields
from functools import cached_property
from pathlib import Path

from cbha_inverse.config_files import read_section
from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.actuation.cables import Cable, CableGroup
from cbha_inverse.core.actuation.effectors import PointEffectors
from cbha_inverse.core.chain import ChainModel
from cbha_inverse.core.inverse.solver import InverseOptions, InverseSolver
from cbha_inverse.core.links import timoshenko_compliance
from cbha_inverse.core.statics import solve_static
from cbha_inverse.paths import config_path
from cbha_inverse.scene.calibration import Calibration, check_names, read_calibration
import numpy as np


class Scene:
    """
    A loaded scene: chain model, actuators, effectors and gravity (immutable).

    Build it with :func:`load_scene`.

    Attributes
    ----------
    name : str
    description : str
    base_frame : str
    model : cbha_inverse.core.chain.ChainModel
    actuators : cbha_inverse.core.actuation.actuators.ActuatorSet
    effectors : cbha_inverse.core.actuation.effectors.PointEffectors
    gravity : (3,) ndarray or None  [m/s^2]
        In ``base_frame`` axes (the world of the solvers).
    actuator_names, effector_names : tuple of str
    lower_bounds, upper_bounds : (m,) ndarray  [N or Pa]
    section_names : tuple of str
        Chain sections of a ``segments`` chain, in chain order (empty for beams).
    actuator_sections : tuple of (str or None)
        The chain section of each actuator, scene actuator order: a cavity's ``section``, None
        for a cable.
    calibration : cbha_inverse.scene.calibration.Calibration
        The corrections applied at load (the file's block and the caller's, combined; its base
        offset is ``model.base_position`` / ``model.base_rotation``).
    path : pathlib.Path or None
        The scene file.

    """

    def __init__(self, name, model, actuators, effectors, gravity, *, description='',
                 base_frame='cbha_base', workspace=None, solver_defaults=None,
                 section_names=(), actuator_sections=None, calibration=None, path=None):
        """Store the parts (use :func:`load_scene`)."""
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
        self.actuator_sections = (tuple(actuator_sections) if actuator_sections is not None
                                  else (None,) * len(self.actuator_names))
        if len(self.actuator_sections) != len(self.actuator_names):
            raise ValueError('actuator_sections needs one entry per actuator')
        self.calibration = Calibration() if calibration is None else calibration
        self.path = None if path is None else Path(path)
        self._workspace = workspace
        self._solver_defaults = dict(solver_defaults or {})

    def __repr__(self):
        """Summarise the scene."""
        return (f'Scene({self.name!r}: {self.model.n_links} links, '
                f'{len(self.actuator_names)} actuators, {len(self.effector_names)} effectors)')

    def forward(self, actuation, *, initial_state=None, tolerance=1e-10, strict=False):
        """
        Solve the static equilibrium under an actuation (paper eq. 9).

        Uses :func:`cbha_inverse.core.statics.solve_static` (the package's one static solver,
        with the actuators' load stiffness, line search, load stepping), which evaluates the
        same compiled kernels as the inverse solver.

        Parameters
        ----------
        actuation : (m,) array_like  [N or Pa]
            Tensions / gauge pressures in actuator order (must lie within the bounds).
        initial_state : ChainState, optional
            Warm start.
        tolerance : float
            Relative tolerance of the static solver (:mod:`cbha_inverse.core.statics`).
        strict : bool
            Raise ``RuntimeError`` when the solve does not converge.

        Returns
        -------
        cbha_inverse.core.statics.StaticResult
            The equilibrium with its ``effector_positions`` and ``actuation`` (``converged``
            says whether it was reached).

        """
        a = np.asarray(actuation, dtype=float).reshape(-1)
        if a.size != len(self.actuator_names) or not np.all(np.isfinite(a)):
            raise ValueError(f'actuation must be {len(self.actuator_names)} finite values')
        if np.any(a < self.lower_bounds - 1e-9 * np.abs(self.upper_bounds)) or np.any(
                a > self.upper_bounds * (1.0 + 1e-9)):
            raise ValueError('actuation outside the actuator bounds')
        res = solve_static(self.model, gravity=self.gravity, actuators=self.actuators,
                           actuation=a, effectors=self.effectors, initial_state=initial_state,
                           tolerance=tolerance)
        if strict and not res.converged:
            raise RuntimeError(f'forward solve of {self.name} did not converge: {res.message}')
        return res

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
        the calibration's base offset; other effectors at rest), or ``{actuation_fraction: f}``
        = the effectors at the uniform actuation ``lower + f (upper - lower)``. Without it: the
        rest effector positions. For the CBHA this is the tip at mid pressure in every tube,
        around which the paper's 60 mm circle in the y-z plane is reachable.
        """
        spec = self._workspace
        if spec is None:
            return self.rest_effector_positions.copy()
        if isinstance(spec, dict):
            f = float(spec.get('actuation_fraction', 0.0))
            a = self.lower_bounds + f * (self.upper_bounds - self.lower_bounds)
            return self.forward(a, strict=True).effector_positions
        center = self.rest_effector_positions.copy()
        center[-1] = np.asarray(spec, dtype=float)
        return center

    def make_inverse_solver(self, **options):
        """
        Build the per-tick inverse solver of this scene (DESIGN §6).

        Parameters
        ----------
        **options
            Fields of :class:`cbha_inverse.core.inverse.solver.InverseOptions` (``energy_weight``,
            ``proximal_weight``, ``rate_limit``, ``qp_solver``, ``newton_steps``, ...); the
            scene's ``solver`` section gives the defaults.

        Returns
        -------
        cbha_inverse.core.inverse.solver.InverseSolver
            Starts at rest; ``step(targets (k, 3))`` returns a ``TickResult``.

        """
        merged = {**self._solver_defaults, **options}
        if merged.get('rate_limit') is not None:
            merged['rate_limit'] = tuple(np.broadcast_to(
                np.asarray(merged['rate_limit'], dtype=float), (len(self.actuator_names),)))
        return InverseSolver(self.model, self.actuators, self.effectors, gravity=self.gravity,
                             options=InverseOptions(**merged))


def resolve_scene_path(path):
    """
    Return the YAML path of a scene given a path or a bare name (``'cbha'``).

    Parameters
    ----------
    path : str or os.PathLike
        A file path, or a scene name looked up in ``config/scenes/``.

    Returns
    -------
    pathlib.Path

    """
    p = Path(path)
    if p.is_file():
        return p
    named = config_path('scenes', p.name if p.suffix == '.yaml' else f'{p.name}.yaml')
    if named.is_file():
        return named
    raise FileNotFoundError(f'no scene {path!s} (nor {named})')


def load_scene(path, *, stiffness_scale=1.0, gravity=None, calibration=None):
    """
    Load a scene YAML and build only what it names.

    Parameters
    ----------
    path : str or os.PathLike
        Scene file, or a name in ``config/scenes`` (``'tendon_6f_8c'``, ``'cbha'``).
    stiffness_scale : float
        Multiplies every link stiffness (divides the compliances), e.g. to model a stiffer or
        softer robot than the nominal one.
    gravity : (3,) array_like, optional  [m/s^2]
        Overrides the scene's gravity (``[0, 0, 0]`` disables it).
    calibration : cbha_inverse.scene.calibration.Calibration, optional
        Applied on top of the scene's own ``calibration`` block (factors multiply, masses add,
        base offsets compose, see :meth:`Calibration.combined`), e.g. the deliberate errors of a
        simulated plant.

    Returns
    -------
    Scene

    Raises
    ------
    FileNotFoundError
        If no scene of that path or name exists.
    cbha_inverse.errors.ConfigError
        If the scene (or a segment file it names) is not valid YAML, misses a key or has a value
        of the wrong type or range: the message names the file and the key.

    """
    if not stiffness_scale > 0.0:
        raise ValueError('stiffness_scale must be positive')
    path = resolve_scene_path(path)
    spec = read_section(path)
    calibrated = read_calibration(spec).combined(calibration)
    chain = spec.section('chain')
    kind = chain.text('type', choices=('beam_vertebrae', 'segments'))
    if kind == 'beam_vertebrae':
        model = _beam_chain(chain, stiffness_scale, calibrated.tip_payload_mass)
        vertebra_frames, sections, parts = _vertebra_frames(chain), {}, {}
    else:
        from cbha_inverse.scene.segments import segment_chain
        model, sections, parts = segment_chain(chain, path.parent, stiffness_scale, calibrated)
        vertebra_frames = np.arange(model.n_frames)
    base_position, base_rotation = calibrated.base_pose()
    model = model.transformed(base_position, base_rotation)
    check_names(spec, calibrated, sections,
                [item.data.get('name') for key in ('cavities', 'cables')
                 for item in spec.sections(key, []) if isinstance(item.data.get('name'), str)])
    groups = []
    if spec.has('cables'):
        groups.append(CableGroup(_cables(spec.sections('cables'), vertebra_frames,
                                         calibrated.actuator_gain), model.n_frames))
    if spec.has('cavities'):
        from cbha_inverse.scene.segments import cavity_group
        groups.append(cavity_group(spec.sections('cavities'), sections, parts, model.n_frames,
                                   spec.text('cavity_model', 'linear',
                                             choices=('linear', 'mesh')),
                                   calibrated.actuator_gain))
    if not groups:
        raise spec.error('cables', 'a scene needs cables or cavities (no actuator)')
    actuators = _actuator_set(spec, groups, model.n_frames)
    section_of = {item.data.get('name'): item.data.get('section')
                  for item in spec.sections('cavities', [])}
    effector_items = spec.sections('effectors')
    if not effector_items:
        raise spec.error('effectors', 'at least one effector is needed')
    effectors = _effectors(effector_items, model, vertebra_frames)
    g = spec.vector('gravity', 3, (0.0, 0.0, -9.81)) if gravity is None else gravity
    workspace = _workspace(spec)
    if isinstance(workspace, tuple):
        workspace = tuple(base_rotation @ np.asarray(workspace) + base_position)
    return Scene(spec.text('name', path.stem), model, actuators, effectors, g,
                 description=spec.text('description', ''),
                 base_frame=spec.text('base_frame', 'cbha_base'),
                 workspace=workspace, solver_defaults=_solver_defaults(spec),
                 section_names=tuple(sections),
                 actuator_sections=tuple(section_of.get(n) for n in actuators.names),
                 calibration=calibrated, path=path)


def _actuator_set(spec, groups, n_frames):
    """Build the actuator set in the scene's ``actuator_order`` (names checked)."""
    order = spec.data.get('actuator_order')
    try:
        return ActuatorSet(groups, n_frames, order)
    except ValueError as exc:
        raise spec.error('actuator_order', str(exc)) from None


def _workspace(spec):
    """Return ``workspace_center``: None, three coordinates or ``{actuation_fraction: f}``."""
    if not spec.has('workspace_center'):
        return None
    if isinstance(spec.data['workspace_center'], dict):
        center = spec.section('workspace_center')
        return {'actuation_fraction': center.number('actuation_fraction', minimum=0.0)}
    return spec.vector('workspace_center', 3)


def _solver_defaults(spec):
    """Return the scene's ``solver`` section, its keys checked against ``InverseOptions``."""
    if not spec.has('solver'):
        return None
    solver = spec.section('solver')
    known = {f.name for f in fields(InverseOptions)}
    for key in solver.data:
        if key not in known:
            raise solver.error(key, f'unknown solver option (known: {sorted(known)})')
    return dict(solver.data)


def _vertebra_frames(chain):
    """Frame index of vertebra v (0 = base) for a beam_vertebrae chain."""
    return (np.arange(chain.integer('n_vertebrae', minimum=1) + 1)
            * chain.integer('beams_per_interval', minimum=1))


def _beam_chain(chain, stiffness_scale, tip_payload_mass=0.0):
    """Build the chain of Timoshenko beams of a ``beam_vertebrae`` scene."""
    n_v = chain.integer('n_vertebrae', minimum=1)
    per = chain.integer('beams_per_interval', minimum=1)
    b = chain.section('backbone')
    length = chain.number('interval_length', positive=True) / per
    outer = b.number('outer_radius', positive=True)
    inner = b.number('inner_radius', 0.0, minimum=0.0)
    if inner >= outer:
        raise b.error('inner_radius', f'must be below outer_radius {outer:g}, got {inner:g}')
    c = timoshenko_compliance(length, b.number('youngs_modulus', positive=True),
                              b.number('poisson_ratio', minimum=-1.0), outer, inner)
    n = n_v * per
    area = np.pi * (outer ** 2 - inner ** 2)
    masses = np.full(n, b.number('density', 0.0, minimum=0.0) * area * length)
    masses[per - 1::per] += chain.number('vertebra_mass', 0.0, minimum=0.0)
    masses[-1] += tip_payload_mass
    offsets = np.tile([length, 0.0, 0.0], (n, 1))
    return ChainModel.from_compliances(np.broadcast_to(c / stiffness_scale, (n, 6, 6)), offsets,
                                       masses=masses)


def _cables(items, vertebra_frames, gains=None):
    """Route each cable from the base through every vertebra up to its end vertebra."""
    cables = []
    for item in items:
        angle = np.deg2rad(item.number('angle_deg'))
        radius = item.number('radius', positive=True)
        end = item.integer('end_vertebra')
        if not 1 <= end < len(vertebra_frames):
            raise item.error('end_vertebra', f'{end} outside 1..{len(vertebra_frames) - 1}')
        frames = vertebra_frames[:end + 1]
        offset = np.array([0.0, radius * np.cos(angle), radius * np.sin(angle)])
        name = item.text('name')
        cables.append(Cable(name, frames, np.tile(offset, (len(frames), 1)),
                            item.number('max_tension', positive=True),
                            (gains or {}).get(name, 1.0)))
    return cables


def _effectors(items, model, vertebra_frames):
    """Build the effector points."""
    names, frames, offsets = [], [], []
    for item in items:
        if item.has('vertebra'):
            vertebra = item.integer('vertebra', minimum=0)
            if vertebra >= len(vertebra_frames):
                raise item.error('vertebra', f'{vertebra} outside 0..{len(vertebra_frames) - 1}')
            frame = int(vertebra_frames[vertebra])
        elif item.data.get('frame', 'tip') == 'tip':
            frame = model.n_links
        else:
            frame = item.integer('frame', minimum=0)
            if frame > model.n_links:
                raise item.error('frame', f'{frame} outside 0..{model.n_links} (or tip)')
        names.append(item.text('name'))
        frames.append(frame)
        offsets.append(item.vector('offset', 3, (0.0, 0.0, 0.0)))
    return PointEffectors(names, frames, offsets, model.n_frames)
