"""
Random valid robots for property tests: scene YAML dicts drawn from the parts of docs/own-robot.md.

:func:`robot_specs` is a hypothesis strategy of scene dicts: 1-4 sections of 2-8 segments (a
``segments`` chain of the condensed rod of ``docs/examples/rod_robot``) or vertebra intervals (a
``beam_vertebrae`` chain), 3-12 tendons at random angles and radii, each ending at the last
vertebra of a section, bounded by 2-20 N, a tip effector (sometimes a second one at a section
end), with or without gravity. :func:`random_robot_spec` draws the same robots from a numpy
generator (fixed seeds, no hypothesis: the stability report). :func:`load_robot` writes a dict
into a directory and loads it; it returns None for a robot that cannot hold its own weight.

Plausibility (so that most robots are neither absurdly floppy nor rigid): a beam backbone's
bending stiffness is chosen so that its tendons at full tension bend the chain by 0.5-3 rad
toward the side where they bend it most (:func:`bending_moment`, a linear estimate), stiffer
where needed so that it droops by at most 15 % of its length under its own weight and every
tendon at full tension strains it by at most 8 %; a condensed chain has the rod's stiffness, at
most 16 segments (0.32 m), and tendon bounds scaled down (to no less than 2 N) so that they bend
it by at most 3 rad and strain it by at most 8 %.
"""

import math
from pathlib import Path

import numpy as np
import yaml

ROD_GEOMETRY = Path(__file__).resolve().parents[2] / 'docs' / 'examples' / 'rod_robot' / (
    'rod_geometry.yaml')
"""The guide's rod segment (20 mm long, R 6 mm, E 20 MPa): condensed once per test session."""
ROD_LENGTH = 0.02
"""Length of one condensed rod segment [m]."""
ROD_BENDING = 0.022
"""Bending stiffness EI of the condensed rod [N m^2] (its compliance's rotation block)."""
ROD_AXIAL = 2260.0
"""Axial stiffness EA of the condensed rod [N]."""
MAX_DROOP = 0.15
"""Largest droop of a beam backbone under its own weight, fraction of its length (linear)."""
MAX_STRAIN = 0.08
"""Largest axial strain of the backbone with every tendon at full tension (linear)."""
MAX_SEGMENTS = 16
"""Most condensed segments in one chain (0.32 m: the rod droops ~25 % of that under gravity)."""
BEND_RANGE = (0.5, 3.0)
"""Bending [rad] of the chain with every tendon at full tension, toward the side where they bend
it most (linear estimate ``sum T r L cos / EI``)."""
STAGGERS = (0.0, 40.0, 60.0)
"""Stagger angles [deg] per section of the three-section regression robot."""


def condense_rod(directory):
    """
    Condense the guide's rod segment into ``directory``; return the segment file's path.

    Parameters
    ----------
    directory : pathlib.Path
        Where ``rod_segment.yaml`` is written (gmsh, about 0.3 s).

    Returns
    -------
    pathlib.Path

    """
    from cbha_inverse.fem.cli import main as condense_main
    path = Path(directory) / 'rod_segment.yaml'
    condense_main([str(ROD_GEOMETRY), '--output', str(path)])
    return path


def bending_moment(tendons, interval):
    """
    Return the largest bending of a chain by its tendons at full tension, times EI [N m^2].

    ``max over directions u of sum_i T_i r_i L_i max(0, cos(angle_i - u))``: each tendon's
    moment times the length it bends (base to its end vertebra), the tendons on the far side
    slack; divided by the backbone's EI it is the tip's bending angle (linear estimate).
    """
    directions = np.deg2rad(np.arange(0.0, 360.0, 5.0))
    total = np.zeros_like(directions)
    for t in tendons:
        lever = t['max_tension'] * t['radius'] * interval * t['end_vertebra']
        total += lever * np.maximum(np.cos(np.deg2rad(t['angle_deg']) - directions), 0.0)
    return float(total.max())


def robot_spec(draw_int, draw_float, draw_bool, segment=None):
    """
    Build one random robot's scene dict from three drawing functions.

    The same construction serves hypothesis (:func:`robot_specs`) and numpy generators
    (:func:`random_robot_spec`).

    Parameters
    ----------
    draw_int : callable
        ``draw_int(low, high)`` -> int in ``[low, high]``.
    draw_float : callable
        ``draw_float(low, high)`` -> float in ``[low, high]``.
    draw_bool : callable
        ``draw_bool(p)`` -> bool, True with probability about ``p``.
    segment : pathlib.Path or None
        The condensed rod segment (:func:`condense_rod`); None draws beam chains only.

    Returns
    -------
    dict
        A scene dict (``docs/own-robot.md``); the segment path is absolute.

    """
    condensed = segment is not None and draw_bool(0.5)
    n_sections = draw_int(1, 4)
    most = min(8, max(2, MAX_SEGMENTS // n_sections)) if condensed else 8
    counts = [draw_int(2, most) for _ in range(n_sections)]
    ends = [int(end) for end in np.cumsum(counts)]
    spec = {'name': 'random_robot',
            'gravity': [0.0, 0.0, -9.81] if draw_bool(0.7) else [0.0, 0.0, 0.0],
            'workspace_center': {'actuation_fraction': 0.3}}
    n_tendons = draw_int(3, 12)
    tendons = []
    for index in range(n_tendons):
        end = int(ends[draw_int(0, n_sections - 1)])
        tendons.append({'name': f'tendon_{index}', 'angle_deg': round(draw_float(0.0, 360.0), 3),
                        'radius': round(draw_float(0.006, 0.016), 5), 'end_vertebra': end,
                        'max_tension': round(draw_float(2.0, 20.0), 3)})
    bend = draw_float(*BEND_RANGE)
    if condensed:
        spec['chain'] = {'type': 'segments', 'sections': [
            {'name': f'section_{i}', 'segment': str(segment), 'count': int(c)}
            for i, c in enumerate(counts)]}
        # every tendon pulling bends the rod by at most BEND_RANGE[1], strains it by MAX_STRAIN
        scale = min(1.0, BEND_RANGE[1] * ROD_BENDING / bending_moment(tendons, ROD_LENGTH),
                    MAX_STRAIN * ROD_AXIAL / sum(t['max_tension'] for t in tendons))
        for tendon in tendons:
            tendon['max_tension'] = round(max(tendon['max_tension'] * scale, 2.0), 3)
        interval = ROD_LENGTH
    else:
        total = draw_float(0.06, 0.3)
        interval = float(total / ends[-1])
        outer = draw_float(0.004, 0.008)
        inner = outer * draw_float(0.0, 0.6) if draw_bool(0.3) else 0.0
        moment = bending_moment(tendons, interval)
        second_moment = math.pi * (outer ** 4 - inner ** 4) / 4.0
        area = math.pi * (outer ** 2 - inner ** 2)
        density = round(draw_float(900.0, 1300.0), 1)
        vertebra_mass = round(draw_float(0.0, 0.006), 5)
        weight = 9.81 * (density * area + vertebra_mass / interval)     # N/m
        youngs_modulus = max(
            moment / bend / second_moment,
            # the backbone holds its own weight: linear droop w L^3 / 8 EI below MAX_DROOP L
            weight * total ** 3 / (8.0 * MAX_DROOP * second_moment),
            # every tendon at full tension strains it axially by at most MAX_STRAIN
            sum(t['max_tension'] for t in tendons) / (MAX_STRAIN * area))
        spec['chain'] = {
            'type': 'beam_vertebrae', 'n_vertebrae': int(ends[-1]),
            'beams_per_interval': 1 if ends[-1] > 16 else draw_int(1, 2),
            'interval_length': round(interval, 6),
            'vertebra_mass': vertebra_mass,
            'backbone': {'youngs_modulus': float(f'{youngs_modulus:.4g}'),
                         'poisson_ratio': 0.45, 'outer_radius': round(outer, 5),
                         'inner_radius': round(inner, 5), 'density': density}}
    spec['cables'] = tendons
    spec['effectors'] = [{'name': 'tip', 'frame': 'tip',
                          'offset': [round(draw_float(0.0, 0.5) * interval, 5), 0.0, 0.0]}]
    if n_sections > 1 and draw_bool(0.25):
        vertebra = int(ends[draw_int(0, n_sections - 2)])
        spec['effectors'].insert(0, {'name': 'middle', 'vertebra': vertebra,
                                     'offset': [0.0, 0.0, 0.0]})
    return spec


def robot_specs(segment=None):
    """
    Return a hypothesis strategy of random robot scene dicts (:func:`robot_spec`).

    Parameters
    ----------
    segment : pathlib.Path or None
        The condensed rod segment; None draws beam chains only.

    Returns
    -------
    hypothesis.strategies.SearchStrategy

    """
    from hypothesis import strategies as st

    @st.composite
    def specs(draw):
        return robot_spec(lambda lo, hi: draw(st.integers(lo, hi)),
                          lambda lo, hi: draw(st.floats(lo, hi, allow_nan=False)),
                          lambda p: draw(st.integers(0, 99)) < round(100 * p), segment)
    return specs()


def random_robot_spec(seed, segment=None):
    """
    Return the random robot of a seed (numpy's generator; the same parts as :func:`robot_specs`).

    Parameters
    ----------
    seed : int
        Seed of ``numpy.random.default_rng``.
    segment : pathlib.Path or None
        The condensed rod segment; None draws beam chains only.

    Returns
    -------
    dict

    """
    rng = np.random.default_rng(seed)
    return robot_spec(lambda lo, hi: int(rng.integers(lo, hi + 1)),
                      lambda lo, hi: float(rng.uniform(lo, hi)),
                      lambda p: bool(rng.random() < p), segment)


def staggered_robot(segment, stagger_deg):
    """
    Return the three-section regression robot: 3 x 4 condensed rod segments (0.24 m).

    Nine tendons, three per section at 120 deg, each section's set turned by ``stagger_deg``
    from the one below, radius 12 mm, ending at vertebrae 4, 8 and 12, 0..10 N; gravity.
    Before the equilibrium check of the solver it limit-cycled 25 mm off its own equilibrium on a
    target 40 mm from the workspace centre toward (0, -1, -1) (:func:`staggered_target`).

    Parameters
    ----------
    segment : pathlib.Path
        The condensed rod segment.
    stagger_deg : float
        Turn of each section's tendons from the section below [deg].

    Returns
    -------
    dict

    """
    cables = [{'name': f'section_{s}_{j}', 'angle_deg': 120.0 * j + stagger_deg * s,
               'radius': 0.012, 'end_vertebra': 4 * (s + 1), 'max_tension': 10.0}
              for s in range(3) for j in range(3)]
    return {'name': f'staggered_{stagger_deg:g}', 'gravity': [0.0, 0.0, -9.81],
            'chain': {'type': 'segments', 'sections': [
                {'name': f'section_{s}', 'segment': str(segment), 'count': 4}
                for s in range(3)]},
            'cables': cables, 'effectors': [{'name': 'tip', 'frame': 'tip',
                                             'offset': [0.0, 0.0, 0.0]}],
            'workspace_center': {'actuation_fraction': 0.3}}


def staggered_target(scene):
    """Return the regression robot's target: 40 mm from the workspace centre toward (0,-1,-1)."""
    return scene.workspace_center + 0.04 * np.array([0.0, -1.0, -1.0]) / math.sqrt(2.0)


def write_robot(spec, directory, name='robot.yaml'):
    """Write a scene dict as YAML into ``directory``; return the file's path."""
    path = Path(directory) / name
    path.write_text(yaml.safe_dump(spec, sort_keys=False), encoding='utf-8')
    return path


def load_robot(spec, directory, **options):
    """
    Write and load a robot; return ``(scene, path)``, or None if it cannot hold its own weight.

    A robot holds its weight when the static solves of its rest shape and of its workspace
    centre converge.

    Parameters
    ----------
    spec : dict
        A scene dict.
    directory : pathlib.Path
        Where the YAML is written.
    **options
        Passed to :func:`cbha_inverse.scene.load_scene` (e.g. ``stiffness_scale``).

    Returns
    -------
    tuple of (Scene, pathlib.Path) or None

    """
    from cbha_inverse.scene import load_scene
    path = write_robot(spec, directory)
    scene = load_scene(path, **options)
    try:
        scene.rest_effector_positions
        scene.workspace_center
    except RuntimeError:
        return None
    return scene, path
