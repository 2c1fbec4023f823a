"""
A scene's ``obstacles`` and ``collision`` blocks (``docs/obstacles.md``).

``obstacles`` lists primitive solids posed in ``base_frame``
(:class:`cbha_inverse.core.obstacles.Obstacle`)::

    obstacles:
      - {name: table, type: plane, pose: {position: [0, 0, -0.06]}}
      - {name: post, type: cylinder, radius: 0.02, length: 0.3,
         pose: {position: [0.2, 0.08, 0.0], rpy: [0, 0, 0]}}

``collision`` declares the robot's collision spheres, centred at frame origins
(:class:`cbha_inverse.core.contact.CollisionSpheres`)::

    collision: {radius: 0.025, per: frame}   # per: frame (every frame 1..n) or vertebra

Without ``radius`` the spheres take the chain's own size: a beam chain's backbone
``outer_radius``; a segment chain's largest distance of a cavity surface from the segment axis,
per section (the outer surface of the cavities: the tubes' walls add their thickness). A segment
without cavities has no size of its own: a scene with obstacles then declares ``radius``.
"""

from cbha_inverse.core.contact import CollisionSpheres
from cbha_inverse.core.obstacles import check_names, obstacle_from_rpy, SHAPE_SIZES, SHAPES
from cbha_inverse.scene.schema import keys
import numpy as np


def read_obstacles(spec):
    """
    Return the obstacles of a scene's ``obstacles`` list (empty without one).

    Parameters
    ----------
    spec : cbha_inverse.config_files.Section
        The scene file.

    Returns
    -------
    tuple of cbha_inverse.core.obstacles.Obstacle

    Raises
    ------
    cbha_inverse.errors.ConfigError
        On an unknown key (the nearest known one named), a missing or wrong size, a bad pose
        or a name given twice.

    """
    obstacles = []
    for item in spec.sections('obstacles', []):
        item.only(*keys('obstacle'))
        name = item.text('name')
        shape = item.text('type', choices=SHAPES)
        pose = item.section('pose', None)
        position, rpy = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        if pose is not None:
            pose.only(*keys('pose'))
            position, rpy = pose.vector('position', 3, position), pose.vector('rpy', 3, rpy)
        sizes = {}
        for key in ('radius', 'length', 'size'):
            if key not in SHAPE_SIZES[shape]:
                if item.has(key):
                    raise item.error(key, f'a {shape} takes no {key} (its sizes: '
                                     f'{", ".join(SHAPE_SIZES[shape]) or "none"})')
                continue
            if key == 'size':
                sizes[key] = item.vector(key, 3)
                if min(sizes[key]) <= 0.0:
                    raise item.error(key, f'edges must be > 0, got {list(sizes[key])}')
            elif key == 'length' and shape == 'capsule':
                sizes[key] = item.number(key, minimum=0.0)   # 0: a sphere
            else:
                sizes[key] = item.number(key, positive=True)
        try:
            obstacles.append(obstacle_from_rpy(name, shape, position, rpy, **sizes))
        except ValueError as exc:
            raise item.error('type', str(exc)) from None
    try:
        return check_names(obstacles)
    except ValueError as exc:
        raise spec.error('obstacles', str(exc)) from None


def read_collision(spec, n_frames, vertebra_frames, default_radii):
    """
    Return the robot's collision spheres (None when no radius is known).

    Parameters
    ----------
    spec : cbha_inverse.config_files.Section
        The scene file.
    n_frames : int
        Frames of the chain (base included).
    vertebra_frames : (v + 1,) array_like of int
        The frame of each vertebra (0: the base).
    default_radii : (n_frames,) array_like or None  [m]
        The chain's own radius at each frame (module docstring), None when it has none.

    Returns
    -------
    cbha_inverse.core.contact.CollisionSpheres or None

    Raises
    ------
    cbha_inverse.errors.ConfigError
        On an unknown key, a non-positive radius or an unknown ``per``.

    """
    block = spec.section('collision', None)
    per, radius = 'frame', None
    if block is not None:
        block.only(*keys('collision'))
        radius = block.number('radius', None, positive=True)
        per = block.text('per', 'frame', choices=('frame', 'vertebra'))
    frames = (np.arange(1, n_frames) if per == 'frame'
              else np.asarray(vertebra_frames, dtype=int)[1:])
    if radius is not None:
        return CollisionSpheres(frames, np.full(frames.size, radius))
    if default_radii is None:
        return None
    return CollisionSpheres(frames, np.asarray(default_radii, dtype=float)[frames])


def segment_radii(sections, parts, n_frames):
    """
    Return each frame's radius in a segment chain: the cavities' largest distance from the axis.

    Parameters
    ----------
    sections : dict
        ``name -> (first link index, count)``.
    parts : dict
        ``name -> segment`` (its cavity surfaces in segment coordinates, axis +x).
    n_frames : int
        Frames of the chain (base included).

    Returns
    -------
    (n_frames,) ndarray or None  [m]
        Frame ``i`` (the upper vertebra of link ``i - 1``) takes its link's section's radius
        (frame 0 that of the first section); None when a section's segment has no cavity.

    """
    from cbha_inverse.scene.segments import cavity_surfaces
    radii = np.zeros(n_frames)
    for name, (first, count) in sections.items():
        surfaces = cavity_surfaces(parts[name])
        if not surfaces:
            return None
        radius = max(float(np.hypot(points[:, 1], points[:, 2]).max())
                     for points, _ in surfaces.values())
        radii[first + 1:first + count + 1] = radius
        if first == 0:
            radii[0] = radius
    return radii
