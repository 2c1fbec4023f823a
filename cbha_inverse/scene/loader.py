"""
The scene loader: a YAML file that names the chain, actuators and effectors of a run.

``load_scene(path)`` builds only what the scene names: a beam-and-tendon scene imports neither
gmsh nor meshio nor OpenCV; a segment scene (the CBHA) reads condensed segments through
:func:`cbha_inverse.fem.segment_io.load_segment`, imported only then.

Scene YAML schema (SI units)::

    name: str
    description: str
    base_frame: str                      # TF name of the world (default cbha_base)
    gravity: [gx, gy, gz] or null        # m/s^2, base_frame axes (+x along the backbone at rest);
                                         # null: none; absent: [0, 0, -9.81]
    chain:                               # one of two types
      type: beam_vertebrae               # Timoshenko beams, vertebrae every `beams_per_interval`
      n_vertebrae, beams_per_interval, interval_length, vertebra_mass, backbone: {youngs_modulus,
      poisson_ratio, outer_radius, inner_radius, density}
      # or, for parts of other spacing or backbone, base first (chain-level keys: defaults):
      sections: [{n_vertebrae, interval_length, beams_per_interval, vertebra_mass, backbone}]
    chain:
      type: segments                     # condensed segments in series
      sections: [{name, segment: <path relative to the scene file>, count}]
    cables:                              # tendons (frictionless), in one of two forms:
      - {name, max_tension, angle_deg, radius, end_vertebra,   # straight (see below): through
         start_vertebra (0), helix: {pitch_deg_per_vertebra}}  # every vertebra start → end
      - {name, max_tension, points: [{vertebra, angle_deg, radius} or {vertebra, offset}, ...]}
        # each with axial_stiffness: EA [N] (default inextensible; displacement drives need it)
    cavities: [{name, section, cavity: <segment cavity name>, max_pressure}]
    cavity_model: linear | mesh          # core.actuation.condensed_cavities / .cavities
    actuator_order: [names]              # column order (default: cables, then cavities)
    effectors:                           # docs/effectors.md
      - {name, kind: point | axis | pose (point), frame: <int or 'tip'> or vertebra: <int>,
         offset: [x, y, z] (0), axis: [x, y, z] (axis kind only; frame axes, default +x),
         weights: {position: w or [wx, wy, wz] (1), orientation: w or one per rotational row
                   (1), orientation_length: m (0.1)}}
        # point: 3 position rows; axis: + 2 rows turning the frame's axis onto a target
        # direction; pose: + 3 rows turning the frame onto a target orientation
    workspace_center: [x, y, z], {actuation_fraction: f} or reachable_center  # see below
    sensors:                             # string potentiometers (core.sensors), optional
      - {name, kind: string_pot, angle_deg, radius, end_vertebra, start_vertebra (0)}  # or
      - {name, kind: string_pot, points: [{vertebra or frame, offset: [x, y, z]}, ...]}
        # each with offset [reading], gain [reading / m], noise_std [m] (length noise)
    loads:                               # external loads at frame origins (docs/loads.md)
      - {name, frame: <int or 'tip'> or vertebra: <int>, force: [fx, fy, fz], # N
         torque: [tx, ty, tz], in: base | local}   # N*m; base: dead, base_frame axes (default);
                                                   # local: follower, turns with the frame
      - {name, frame or vertebra, mass: kg}        # a mass under the scene's gravity
    solver: {energy_weight, proximal_weight, rate_limit, relinearize_every, ...}  # defaults
    calibration:                         # identified corrections (cbha_identify), optional
      section_stiffness: {<section name>: factor}    # stiffness factor of a segments section
      actuator_gain: {<actuator name>: factor}       # cavity effective area, cable force/N
      tip_payload_mass: kg                           # a mass load at the last frame
      base_offset: {position: [x, y, z], rpy: [r, p, y]}  # chain base in base_frame, m / rad
    obstacles:                           # solids near the arm (scene.obstacles), optional
      - {name, type: plane | sphere | box | capsule | cylinder,
         pose: {position: [x, y, z], rpy: [r, p, y]},  # obstacle frame in base_frame, m / rad
         radius, length, size: [x, y, z]}              # the sizes its type takes, m
    collision: {radius: m, per: frame | vertebra}  # robot spheres at frame origins (optional)

``workspace_center`` is the suggested centre of target trajectories (``Scene.workspace_center``):
explicit coordinates of the last effector; ``{actuation_fraction: f}``, the effectors with every
actuator at ``f`` of its range; or ``reachable_center`` (``{reachable_center: {samples: N}}``,
default 300 samples), the centre of the sampled reachable set
(:func:`cbha_inverse.scene.reach.sample_reachable_set`: a reached position around which the
largest circle fits in the hull of the reach), computed when first read (a few tenths of a
second), deterministic. Without it: the effectors at rest.

A cable runs in straight spans between routing points fixed to vertebrae (vertebra 0 is the
base; a vertebra is the frame every ``beams_per_interval`` beams, or every frame of a
``segments`` chain), in routing order from its actuator end. A point at ``radius`` [m] from the
backbone and ``angle_deg`` lies at ``[0, radius cos(angle), radius sin(angle)]`` in its
vertebra's frame: angle 0 along +y, positive toward +z (right-handed about +x, the backbone).
The straight form (the shorthand) routes through every vertebra from ``start_vertebra`` (default
0) to ``end_vertebra`` at one angle and radius; ``helix: {pitch_deg_per_vertebra: p}`` advances
the angle by ``p`` degrees per vertebra after ``start_vertebra`` (``angle_deg`` is the angle
there; ``p > 0`` winds right-handed about +x). ``points`` lists every routing point, the first
included (``{vertebra: 0, ...}`` for a cable pulled from the base: nothing is implied), at least
two, vertebrae strictly increasing; ``offset: [x, y, z]`` [m] in the vertebra frame replaces
``angle_deg`` and ``radius`` (>= 0). A cable gives ``points`` or the straight form, not both.

Frame 0 of the chain (the base) sits at the origin of ``base_frame``, or at
``calibration.base_offset`` when given: every frame, routing and effector point moves with it,
as does an explicit ``workspace_center``; gravity and targets stay in ``base_frame`` axes.

``obstacles`` and ``collision`` (:mod:`cbha_inverse.scene.obstacles`, ``docs/obstacles.md``):
a plane is the half-space below the xy plane of its pose (free side +z); a sphere of
``radius``, a box of edges ``size``, a capsule (``radius`` around a segment of ``length``) and a
cylinder (``radius``, ``length`` between flat caps) are centred on their pose, axis z. The robot
touches them through spheres centred at its frames' origins (``per: frame``, the default, or
only at the vertebrae), of ``radius``, or without it of the chain's own radius (a beam's
``outer_radius``, a segment's cavities).

Scenes shipped in ``config/scenes``: ``tendon_6f_8c`` and ``tendon_10f_16c`` (the paper's Fig. 6
trunks, Timoshenko beams and cables), ``cbha`` (16 condensed bellows segments, 6 cavities) and
``rao2021_tdcr`` (the two-segment tendon robot of Rao et al. 2021, docs/benchmark-rao2021.md).
"""

from pathlib import Path

from cbha_inverse.config_files import read_section
from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.actuation.cables import Cable, CableGroup
from cbha_inverse.core.actuation.effectors import (DEFAULT_ORIENTATION_LENGTH, KINDS,
                                                   ORIENTATION_ROWS, PointEffectors)
from cbha_inverse.core.chain import ChainModel
from cbha_inverse.core.links import timoshenko_compliance
from cbha_inverse.core.loads import Load, Loads
from cbha_inverse.core.sensors import StringPots
from cbha_inverse.paths import config_path
from cbha_inverse.scene.calibration import check_names, read_calibration
from cbha_inverse.scene.obstacles import read_collision, read_obstacles, segment_radii
from cbha_inverse.scene.scene import Scene
from cbha_inverse.scene.schema import keys
import numpy as np


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
    spec = read_section(path).only(*keys('scene'))
    calibrated = read_calibration(spec).combined(calibration)
    chain = spec.section('chain')
    kind = chain.text('type', choices=('beam_vertebrae', 'segments'))
    chain.only(*keys('chain'), *keys(f'chain ({kind})'))
    if kind == 'beam_vertebrae':
        model = _beam_chain(chain, stiffness_scale)
        vertebra_frames, sections, parts = _vertebra_frames(chain), {}, {}
        own_radii = _beam_radii(chain)
    else:
        from cbha_inverse.scene.segments import segment_chain
        model, sections, parts = segment_chain(chain, path.parent, stiffness_scale, calibrated)
        vertebra_frames = np.arange(model.n_frames)
        own_radii = segment_radii(sections, parts, model.n_frames)
    obstacles = read_obstacles(spec)
    collision = read_collision(spec, model.n_frames, vertebra_frames, own_radii)
    if obstacles and collision is None:
        raise spec.error('collision', 'the chain has no size of its own (a segment without '
                         'cavities): declare collision.radius for the obstacles')
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
    sensors = _sensors(spec.sections('sensors', []), model, vertebra_frames)
    g = _gravity(spec) if gravity is None else gravity
    loads = _loads(spec, model, vertebra_frames, g, calibrated.tip_payload_mass)
    workspace = _workspace(spec, len(actuators.names))
    if isinstance(workspace, tuple):
        workspace = tuple(base_rotation @ np.asarray(workspace) + base_position)
    return Scene(spec.text('name', path.stem), model, actuators, effectors, g,
                 description=spec.text('description', ''),
                 base_frame=spec.text('base_frame', 'cbha_base'),
                 workspace=workspace, solver_defaults=_solver_defaults(spec),
                 section_names=tuple(sections), section_links=sections,
                 actuator_sections=tuple(section_of.get(n) for n in actuators.names),
                 calibration=calibrated, sensors=sensors, path=path, loads=loads,
                 obstacles=obstacles, collision=collision)


def _gravity(spec):
    """
    Return the scene's gravity [m/s^2]: ``null`` is none (None), absent is Earth's along -z.

    Parameters
    ----------
    spec : cbha_inverse.config_files.Section
        The scene file.

    Returns
    -------
    tuple of 3 floats, or None

    """
    if 'gravity' in spec.data and spec.data['gravity'] is None:
        return None
    return spec.vector('gravity', 3, (0.0, 0.0, -9.81))


def _actuator_set(spec, groups, n_frames):
    """Build the actuator set in the scene's ``actuator_order`` (names checked)."""
    order = spec.data.get('actuator_order')
    try:
        return ActuatorSet(groups, n_frames, order)
    except ValueError as exc:
        raise spec.error('actuator_order', str(exc)) from None


def _workspace(spec, n_actuators):
    """
    Return ``workspace_center``: None, three coordinates, or its kind as a dict.

    ``{'actuation_fraction': f}``, or ``{'reachable_center': samples}`` for ``reachable_center``
    and ``{reachable_center: {samples: N}}``.
    """
    if not spec.has('workspace_center'):
        return None
    value = spec.data['workspace_center']
    if isinstance(value, str) and value != 'reachable_center':
        raise spec.error('workspace_center', 'must be [x, y, z], {actuation_fraction: f} or '
                         f'reachable_center, got {value!r}')
    if not isinstance(value, (str, dict)):
        return spec.vector('workspace_center', 3)
    center = spec.section('workspace_center') if isinstance(value, dict) else None
    if center is not None:
        center.only(*keys('workspace_center'))
        if 'reachable_center' not in center.data:
            return {'actuation_fraction': center.number('actuation_fraction', minimum=0.0)}
        if 'actuation_fraction' in center.data:
            raise spec.error('workspace_center',
                             'give actuation_fraction or reachable_center, not both')
    from cbha_inverse.scene.reach import DEFAULT_SAMPLES, fewest_samples
    samples = max(DEFAULT_SAMPLES, fewest_samples(n_actuators))
    if center is not None and center.data['reachable_center'] is not None:
        reach = center.section('reachable_center').only(*keys('reachable_center'))
        samples = reach.integer('samples', samples, minimum=fewest_samples(n_actuators))
    return {'reachable_center': samples}


def _solver_defaults(spec):
    """Return the scene's ``solver`` section, its keys checked against ``InverseOptions``."""
    if not spec.has('solver'):
        return None
    solver = spec.section('solver').only(*keys('solver'))
    return dict(solver.data)


def _beam_sections(chain):
    """
    Return the parts of a ``beam_vertebrae`` chain, base first: its sections, or itself.

    A chain of several parts lists them under ``sections``; a key given at the chain level
    (e.g. ``beams_per_interval``) is every section's default.
    """
    if not chain.has('sections'):
        return [chain]
    sections = chain.sections('sections')
    if not sections:
        raise chain.error('sections', 'needs at least one section')
    for key in ('n_vertebrae', 'interval_length'):
        if chain.has(key):
            raise chain.error(key, 'give it per section (the chain has sections)')
    defaults = {key: chain.data[key] for key in ('beams_per_interval', 'backbone',
                                                 'vertebra_mass') if chain.has(key)}
    for section in sections:
        section.only(*(key for key in keys('chain (beam_vertebrae)') if key != 'sections'))
        for key, value in defaults.items():
            section.data.setdefault(key, value)
    return sections


def _vertebra_frames(chain):
    """Frame index of vertebra v (0 = base) for a beam_vertebrae chain."""
    frames = [0]
    for part in _beam_sections(chain):
        per = part.integer('beams_per_interval', minimum=1)
        for _ in range(part.integer('n_vertebrae', minimum=1)):
            frames.append(frames[-1] + per)
    return np.array(frames)


def _beam_radii(chain):
    """Return the backbone's outer radius at every frame of a beam_vertebrae chain [m]."""
    radii = []
    for part in _beam_sections(chain):
        per = part.integer('beams_per_interval', minimum=1)
        beams = part.integer('n_vertebrae', minimum=1) * per
        radius = part.section('backbone').number('outer_radius', positive=True)
        radii += [radius] * (beams + (0 if radii else 1))     # the base takes the first part's
    return np.array(radii)


def _beam_chain(chain, stiffness_scale):
    """Build the chain of Timoshenko beams of a ``beam_vertebrae`` scene (section by section)."""
    compliances, lengths, masses = [], [], []
    for part in _beam_sections(chain):
        n_v = part.integer('n_vertebrae', minimum=1)
        per = part.integer('beams_per_interval', minimum=1)
        b = part.section('backbone').only(*keys('backbone'))
        length = part.number('interval_length', positive=True) / per
        outer = b.number('outer_radius', positive=True)
        inner = b.number('inner_radius', 0.0, minimum=0.0)
        if inner >= outer:
            raise b.error('inner_radius', f'must be below outer_radius {outer:g}, got {inner:g}')
        c = timoshenko_compliance(length, b.number('youngs_modulus', positive=True),
                                  b.number('poisson_ratio', minimum=-1.0), outer, inner)
        n = n_v * per
        area = np.pi * (outer ** 2 - inner ** 2)
        part_masses = np.full(n, b.number('density', 0.0, minimum=0.0) * area * length)
        part_masses[per - 1::per] += part.number('vertebra_mass', 0.0, minimum=0.0)
        compliances.append(np.broadcast_to(c / stiffness_scale, (n, 6, 6)))
        lengths.append(np.full(n, length))
        masses.append(part_masses)
    masses = np.concatenate(masses)
    offsets = np.zeros((masses.size, 3))
    offsets[:, 0] = np.concatenate(lengths)
    return ChainModel.from_compliances(np.concatenate(compliances), offsets, masses=masses)


def _cables(items, vertebra_frames, gains=None):
    """Build each cable on its route (:func:`_cable_route`)."""
    cables = []
    for item in items:
        item.only(*keys('cable'))
        frames, offsets = _cable_route(item, vertebra_frames)
        name = item.text('name')
        cables.append(Cable(name, frames, offsets, item.number('max_tension', positive=True),
                            (gains or {}).get(name, 1.0),
                            item.number('axial_stiffness', np.inf, positive=True)))
    return cables


_STRAIGHT_KEYS = ('angle_deg', 'radius', 'end_vertebra', 'start_vertebra', 'helix')
"""The keys of a cable's straight (or helical) form, which ``points`` replaces."""


def _cable_route(item, vertebra_frames):
    """
    Return the routing ``(frames (P,), offsets (P, 3) [m])`` of a scene's cable.

    ``points`` (:func:`_point_route`) or the straight form (:func:`_vertebra_route`), which a
    ``helix: {pitch_deg_per_vertebra}`` winds around the backbone.
    """
    if item.has('points'):
        for key in _STRAIGHT_KEYS:
            if key in item.data:
                raise item.error(key, 'give points or the straight form (angle_deg, radius, '
                                 'end_vertebra), not both')
        return _point_route(item, vertebra_frames)
    pitch = 0.0
    if item.has('helix'):
        helix = item.section('helix').only(*keys('helix'))
        pitch = helix.number('pitch_deg_per_vertebra')
    return _vertebra_route(item, vertebra_frames, pitch)


def _point_route(item, vertebra_frames):
    """
    Return the routing of a cable's ``points``, in routing order from the actuator end.

    Each point is ``{vertebra, angle_deg, radius}`` (at ``radius`` from the backbone,
    ``angle_deg`` from +y toward +z, as the straight form) or ``{vertebra, offset: [x, y, z]}``
    (in the vertebra frame); the vertebrae strictly increase, the first one is the actuator end
    (the base, 0, for a cable pulled from there: it is not implied).
    """
    points = item.sections('points')
    if len(points) < 2:
        raise item.error('points', f'a cable needs >= 2 routing points, got {len(points)}')
    frames, offsets = [], []
    previous = -1
    for point in points:
        point.only(*keys('cable point'))
        vertebra = point.integer('vertebra', minimum=0)
        if vertebra >= len(vertebra_frames):
            raise point.error('vertebra', f'{vertebra} outside 0..{len(vertebra_frames) - 1}')
        if vertebra <= previous:
            raise point.error('vertebra', f"{vertebra} must lie above the previous point's "
                              f'{previous} (routing order from the base)')
        previous = vertebra
        if point.has('offset'):
            for key in ('angle_deg', 'radius'):
                if key in point.data:
                    raise point.error(key, 'give offset or angle_deg and radius, not both')
            offset = np.array(point.vector('offset', 3))
        else:
            offset = _radial_offset(point.number('angle_deg'),
                                    point.number('radius', minimum=0.0))
        frames.append(vertebra_frames[vertebra])
        offsets.append(offset)
    return np.array(frames), np.array(offsets)


def _radial_offset(angle_deg, radius):
    """Return the offset ``[0, r cos a, r sin a]`` [m] of a point at ``angle_deg`` from +y."""
    angle = np.deg2rad(angle_deg)
    return np.array([0.0, radius * np.cos(angle), radius * np.sin(angle)])


def _vertebra_route(item, vertebra_frames, pitch_deg=0.0):
    """
    Return the routing of ``{angle_deg, radius, end_vertebra[, start_vertebra]}``.

    The route runs through every vertebra from ``start_vertebra`` (default 0, the base) to
    ``end_vertebra``, at ``radius`` from the backbone, ``angle_deg`` from +y toward +z at
    ``start_vertebra``, the angle advancing by ``pitch_deg`` per vertebra after it (a helix,
    right-handed about +x for a positive pitch; 0: straight, parallel to the backbone).
    """
    angle_deg = item.number('angle_deg')
    radius = item.number('radius', positive=True)
    end = item.integer('end_vertebra')
    if not 1 <= end < len(vertebra_frames):
        raise item.error('end_vertebra', f'{end} outside 1..{len(vertebra_frames) - 1}')
    start = item.integer('start_vertebra', 0, minimum=0)
    if start >= end:
        raise item.error('start_vertebra', f'{start} must lie below end_vertebra {end}')
    frames = vertebra_frames[start:end + 1]
    offsets = np.array([_radial_offset(angle_deg + pitch_deg * k, radius)
                        for k in range(len(frames))])
    return frames, offsets


def _sensors(items, model, vertebra_frames):
    """Build the scene's string potentiometers (None when it names no sensor)."""
    if not items:
        return None
    names, frames, offsets = [], [], []
    calibration = {'offset': [], 'gain': [], 'noise_std': []}
    for item in items:
        item.only(*keys('sensor'))
        item.text('kind', choices=('string_pot',))
        name = item.text('name')
        if name in names:
            raise item.error('name', f'sensor {name!r} named twice')
        if item.has('points'):
            points = item.sections('points')
            if len(points) < 2:
                raise item.error('points', 'a string pot needs >= 2 attachment points')
            route = [_point_frame(point.only(*keys('sensor point')), model,
                                  vertebra_frames) for point in points]
            route_frames = [frame for frame, _ in route]
            route_offsets = [offset for _, offset in route]
        else:
            route_frames, route_offsets = _vertebra_route(item, vertebra_frames)
        names.append(name)
        frames.append(route_frames)
        offsets.append(route_offsets)
        calibration['offset'].append(item.number('offset', 0.0))
        gain = item.number('gain', 1.0)
        if gain == 0.0:
            raise item.error('gain', 'must be non-zero (reading per metre)')
        calibration['gain'].append(gain)
        calibration['noise_std'].append(item.number('noise_std', 1.0e-4, positive=True))
    return StringPots(names, frames, offsets, model.n_frames, calibration['offset'],
                      calibration['gain'], calibration['noise_std'])


def _point_frame(item, model, vertebra_frames):
    """Return ``(frame, offset)`` of a point given by ``vertebra`` or ``frame`` (int or tip)."""
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
    return frame, item.vector('offset', 3, (0.0, 0.0, 0.0))


PAYLOAD_LOAD = 'tip_payload_mass'
"""The name of the mass load that ``calibration.tip_payload_mass`` puts at the last frame."""


def _loads(spec, model, vertebra_frames, gravity, payload_mass):
    """
    Build the scene's loads: its ``loads`` block and ``calibration.tip_payload_mass``.

    A load is a wrench ``{name, frame or vertebra, force, torque, in: base | local}`` (either
    of force and torque may be left out: zero) or a mass ``{name, frame or vertebra, mass}``;
    frame 0 (the base) takes none, a mass needs the scene's gravity.
    """
    items = []
    for item in spec.sections('loads', []):
        item.only(*keys('load'))
        name = item.text('name')
        if name in [load.name for load in items] or (name == PAYLOAD_LOAD and payload_mass):
            raise item.error('name', f'load {name!r} named twice')
        if item.has('frame') and item.has('vertebra'):
            raise item.error('vertebra', 'give frame or vertebra, not both')
        frame, _ = _point_frame(item, model, vertebra_frames)
        if frame == 0:
            raise item.error('vertebra' if item.has('vertebra') else 'frame',
                             'the base (frame 0) does not move: a load there does nothing')
        if item.has('mass'):
            for key in ('force', 'torque', 'in'):
                if key in item.data:
                    raise item.error(key, 'give a mass or a wrench (force, torque, in), not '
                                     'both')
            if gravity is None:
                raise item.error('mass', 'a mass needs gravity (the scene has gravity: null)')
            items.append(Load.of_mass(name, frame, item.number('mass', minimum=0.0)))
            continue
        if not (item.has('force') or item.has('torque')):
            raise item.error('force', 'a load needs force, torque or mass')
        items.append(Load.of_wrench(name, frame, item.vector('force', 3, (0.0, 0.0, 0.0)),
                                    item.vector('torque', 3, (0.0, 0.0, 0.0)),
                                    item.text('in', 'base', choices=('base', 'local'))))
    if payload_mass > 0.0:
        if gravity is None:
            raise spec.error('calibration.tip_payload_mass',
                             'a mass needs gravity (the scene has gravity: null)')
        items.append(Load.of_mass(PAYLOAD_LOAD, 'tip', payload_mass))
    return Loads(tuple(items))


def _effectors(items, model, vertebra_frames):
    """Build the effectors: points, with the orientation rows of ``axis`` and ``pose`` kinds."""
    names, frames, offsets, kinds, axes = [], [], [], [], []
    weights = {'position': [], 'orientation': [], 'orientation_length': []}
    for item in items:
        item.only(*keys('effector'))
        frame, offset = _point_frame(item, model, vertebra_frames)
        name = item.text('name')
        if name in names:
            raise item.error('name', f'effector {name!r} named twice')
        kind = item.text('kind', 'point', choices=KINDS)
        if kind != 'axis' and item.has('axis'):
            raise item.error('axis', f'only an axis effector has an axis (this one is a {kind})')
        axis = item.vector('axis', 3, (1.0, 0.0, 0.0))
        if not any(axis):
            raise item.error('axis', 'must not be zero')
        names.append(name)
        frames.append(frame)
        offsets.append(offset)
        kinds.append(kind)
        axes.append(axis)
        for key, value in _effector_weights(item, kind).items():
            weights[key].append(value)
    return PointEffectors(names, frames, offsets, model.n_frames, kinds=kinds, axes=axes,
                          position_weights=weights['position'],
                          orientation_weights=weights['orientation'],
                          orientation_lengths=weights['orientation_length'])


def _effector_weights(item, kind):
    """
    Return an effector's ``weights``: ``position``, ``orientation``, ``orientation_length``.

    ``position`` (default 1) and ``orientation`` (default 1) are unit-free, each a number or one
    per row (3 position rows; 2 rotational rows for ``axis``, 3 for ``pose``), >= 0;
    ``orientation_length`` [m] > 0 (default
    :data:`~cbha_inverse.core.actuation.effectors.DEFAULT_ORIENTATION_LENGTH`): one radian of
    orientation error weighs as that many metres of position error (``docs/effectors.md``).
    """
    weights = item.section('weights', None)
    values = {'position': 1.0, 'orientation': 1.0,
              'orientation_length': DEFAULT_ORIENTATION_LENGTH}
    if weights is None:
        return values
    weights.only(*keys('weights'))
    if kind == 'point':
        for key in ('orientation', 'orientation_length'):
            if key in weights.data:
                raise weights.error(key, 'a point effector has no orientation rows')
    values['orientation_length'] = weights.number('orientation_length',
                                                  DEFAULT_ORIENTATION_LENGTH, positive=True)
    for key, rows in (('position', 3), ('orientation', ORIENTATION_ROWS[kind])):
        value = weights.data.get(key)
        if isinstance(value, list):
            values[key] = weights.vector(key, rows)
            if min(values[key]) < 0.0:
                raise weights.error(key, f'must be >= 0, got {list(values[key])}')
        else:
            values[key] = weights.number(key, 1.0, minimum=0.0)
    return values
