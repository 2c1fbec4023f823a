"""
Segment scenes: chains of condensed FEM segments with pressure cavities (the CBHA).

Imported by :func:`cbha_inverse.scene.load_scene` only for ``chain.type: segments``; reads the
segment YAMLs through :func:`cbha_inverse.fem.segment_io.load_segment` (no gmsh).
"""

from pathlib import Path

from cbha_inverse.core.actuation.cavities import Cavity, CavityGroup, CavityPart
from cbha_inverse.core.actuation.condensed_cavities import LinearCavityGroup
from cbha_inverse.core.chain import ChainModel
from cbha_inverse.core.sections import section_link_factors
from cbha_inverse.scene.schema import keys
import numpy as np


def segment_chain(chain, base_dir, stiffness_scale=1.0, calibration=None):
    """
    Build a chain of condensed segments in series.

    Parameters
    ----------
    chain : cbha_inverse.config_files.Section
        The scene's ``chain`` section: ``sections: [{name, segment, count}]`` (segment path
        relative to the scene file).
    base_dir : pathlib.Path
        Directory of the scene file.
    stiffness_scale : float
        Divides every compliance.
    calibration : cbha_inverse.scene.calibration.Calibration, optional
        Its ``section_stiffness`` factor of a section also divides that section's compliances
        (its ``tip_payload_mass`` is a load of the scene, not a mass of the chain).

    Returns
    -------
    model : cbha_inverse.core.chain.ChainModel
        The chain (frame 0 = base, one frame per vertebra after it).
    sections : dict
        ``name -> (first link index, count)``.
    parts : dict
        ``name -> segment`` (the loaded segment of each section, for its cavities).

    """
    from cbha_inverse.fem.segment_io import load_segment
    compliances, offsets, rotations, masses = [], [], [], []
    sections, parts = {}, {}
    factors = {} if calibration is None else calibration.section_stiffness
    items = chain.sections('sections')
    if not items:
        raise chain.error('sections', 'at least one section is needed')
    for item in items:
        item.only(*keys('segment section'))
        segment_path = Path(base_dir, item.text('segment'))
        if not segment_path.is_file():
            raise item.error('segment', f'no segment file {segment_path}')
        segment = load_segment(segment_path)
        count = item.integer('count', minimum=1)
        name = item.text('name')
        if name in sections:
            raise item.error('name', f'section {name!r} named twice')
        sections[name] = (len(compliances), count)
        parts[name] = segment
        for _ in range(count):
            compliances.append(np.asarray(segment.compliance, dtype=float))
            offsets.append(np.asarray(segment.rest_offset, dtype=float))
            rotations.append(np.asarray(segment.rest_rotation, dtype=float))
            masses.append(float(segment.mass))
    scales = stiffness_scale * section_link_factors(sections, factors, len(compliances))
    model = ChainModel.from_compliances(np.array(compliances) / scales[:, None, None],
                                        np.array(offsets),
                                        masses=np.array(masses),
                                        rest_rotations=np.array(rotations))
    return model, sections, parts


def cavity_surfaces(segment):
    """
    Return the cavity surfaces of a loaded segment as ``name -> (points, triangles)``.

    Parameters
    ----------
    segment : object
        A segment from :func:`cbha_inverse.fem.segment_io.load_segment`; its ``cavities`` is a
        mapping ``name -> (points, triangles)`` or a sequence of objects with ``name``,
        ``points``, ``triangles``.

    Returns
    -------
    dict
        ``name -> ((P, 3) ndarray [m], (T, 3) ndarray of int)`` in segment coordinates.

    """
    cavities = getattr(segment, 'cavities', None) or {}
    out = {}
    items = cavities.items() if hasattr(cavities, 'items') else (
        (c.name, c) for c in cavities)
    for name, value in items:
        if hasattr(value, 'points'):
            points, triangles = value.points, value.triangles
        else:
            points, triangles = value
        out[str(name)] = (np.asarray(points, dtype=float), np.asarray(triangles, dtype=int))
    return out


def cavity_group(items, sections, segments, n_frames, model='linear', gains=None):
    """
    Build the pressure actuators: one per (section, cavity), summed over the section's segments.

    Parameters
    ----------
    items : list of cbha_inverse.config_files.Section
        The scene's ``cavities``: ``{name, section, cavity, max_pressure}``.
    sections : dict
        ``name -> (first link index, count)`` from :func:`segment_chain`.
    segments : dict
        ``name -> segment`` from :func:`segment_chain`.
    n_frames : int
        Number of frames (base included).
    model : str
        ``'linear'`` (:class:`~cbha_inverse.core.actuation.condensed_cavities.LinearCavityGroup`,
        default) or ``'mesh'``
        (:class:`~cbha_inverse.core.actuation.cavities.CavityGroup`).
    gains : dict of str to float, optional
        Cavity name -> effective-area factor (``calibration.actuator_gain``; default 1).

    Returns
    -------
    LinearCavityGroup or CavityGroup

    """
    cavities = []
    for item in items:
        item.only(*keys('cavity'))
        section = item.text('section')
        if section not in sections:
            raise item.error('section', f'no chain section {section!r} (has {sorted(sections)})')
        first, count = sections[section]
        segment = segments[section]
        surfaces = cavity_surfaces(segment)
        cavity = item.text('cavity')
        if cavity not in surfaces:
            raise item.error('cavity', f'the segment of section {section!r} has no cavity '
                             f'{cavity!r} (has {sorted(surfaces)})')
        points, triangles = surfaces[cavity]
        offset = np.asarray(segment.rest_offset, dtype=float)
        rotation = np.asarray(segment.rest_rotation, dtype=float)
        parts = tuple(CavityPart(points, triangles, first + s, offset, rotation)
                      for s in range(count))
        name = item.text('name')
        cavities.append(Cavity(name, parts, item.number('max_pressure', positive=True),
                               (gains or {}).get(name, 1.0)))
    if model == 'linear':
        return LinearCavityGroup(cavities, n_frames)
    if model == 'mesh':
        return CavityGroup(cavities, n_frames)
    raise ValueError(f"cavity_model must be 'linear' or 'mesh', not {model!r}")
