"""
Discretisation check of a scene: the same robot on a finer chain, and how far its tip moves.

A ``beam_vertebrae`` chain is refined by doubling ``beams_per_interval`` (the vertebrae, cables,
sensors, effectors and loads stay where they are: a point given by ``frame: N``
moves to frame ``2 N``, the same point of the backbone). A ``segments`` chain is refined by
recondensing each of its segment files with half the mesh size (``condense_segment``, tens of
seconds per segment): :func:`segment_sources` finds the geometry file each segment was condensed
from (the one whose ``inputs_sha256`` the segment stores) and the command that recondenses it.
The refined scene is a modified copy of the scene file in a temporary folder, loaded by
:func:`cbha_inverse.scene.load_scene`; :func:`compare` solves both at the same actuations.
"""

from dataclasses import dataclass
import io
from pathlib import Path
import tempfile

from cbha_inverse.config_files import read_yaml
import numpy as np
import yaml

REFINEMENT = 2
"""Beams per interval multiply by this; mesh sizes divide by it."""


@dataclass(frozen=True)
class SegmentSource:
    """
    A segment file of a ``segments`` chain and how to recondense it finer.

    Attributes
    ----------
    sections : tuple of str
        The chain sections that use the file.
    segment : pathlib.Path
        The condensed segment YAML.
    geometry : pathlib.Path or None
        The geometry YAML it was condensed from (None: none found whose inputs match).
    order : int
        Element order of the condensation.
    mesh_size : float  [m]
        Element size of the condensation.
    seconds : float  [s]
        How long that condensation took.

    """

    sections: tuple
    segment: Path
    geometry: Path
    order: int
    mesh_size: float
    seconds: float

    @property
    def fine_mesh_size(self):
        """float: the refined element size [m]."""
        return self.mesh_size / REFINEMENT

    def command(self, output):
        """Return the ``condense_segment`` command that writes the finer segment to ``output``."""
        geometry = 'GEOMETRY.yaml' if self.geometry is None else shown(self.geometry)
        return (f'condense_segment {geometry} --order {self.order} '
                f'--mesh-size {self.fine_mesh_size:g} --output {output}')


def shown(path):
    """Return a path as the user would type it: relative to the current folder if inside it."""
    path = Path(path)
    try:
        return path.resolve().relative_to(Path.cwd().resolve())
    except ValueError:
        return path


@dataclass(frozen=True)
class Comparison:
    """
    The effectors of a scene and of its refined copy at the same actuations.

    Attributes
    ----------
    parameter : str
        What was refined (``beams_per_interval``, ``mesh_size``).
    coarse_value, fine_value : str
        Its value in the scene and in the refined copy, with the unit (``2``, ``0.25 mm``).
    labels : tuple of str
        One name per actuation (``rest``, ``half range``, ...).
    actuations : (a, m) ndarray  [N or Pa]
    coarse, fine : (a, k, 3) ndarray  [m]
        Effector positions of the scene and of the refined scene.
    converged : (a, 2) ndarray of bool
        Whether each of the two forward solves converged.

    """

    parameter: str
    coarse_value: str
    fine_value: str
    labels: tuple
    actuations: np.ndarray
    coarse: np.ndarray
    fine: np.ndarray
    converged: np.ndarray

    @property
    def refinement(self):
        """str: what was refined, in words (``beams_per_interval 2 -> 4``)."""
        return f'{self.parameter} {self.coarse_value} -> {self.fine_value}'

    @property
    def movement(self):
        """Return how far each effector moves between the discretisations, (a, k) [m]."""
        return np.linalg.norm(self.fine - self.coarse, axis=-1)


def scene_data(path):
    """Return the parsed scene file (a dict; ``cbha_inverse.errors.ConfigError`` if broken)."""
    return read_yaml(path)


def refined_beam_data(data, factor=REFINEMENT):
    """
    Return a copy of a ``beam_vertebrae`` scene with ``beams_per_interval`` times ``factor``.

    Parameters
    ----------
    data : dict
        The scene file as parsed (:func:`scene_data`), already loaded once without error.
    factor : int
        Refinement factor.

    Returns
    -------
    dict
        The refined scene (effector, sensor and load points given by ``frame: N`` at frame
        ``factor * N``, the same point of the backbone).

    """
    refined = yaml.safe_load(yaml.safe_dump(data))
    refined['chain']['beams_per_interval'] = factor * int(data['chain']['beams_per_interval'])
    points = list(refined.get('effectors') or []) + list(refined.get('loads') or [])
    for sensor in refined.get('sensors') or []:
        points += sensor.get('points') or []
    for point in points:
        if isinstance(point.get('frame'), int) and 'vertebra' not in point:
            point['frame'] *= factor
    return refined


def segment_sources(scene_path, data):
    """
    Return the segment files of a ``segments`` scene with the geometry each was condensed from.

    The geometry is the YAML file, next to the scene, next to the segment (or one folder up), or
    the package's CBHA geometry, whose ``inputs_sha256`` (file bytes, element order, mesh size,
    package version) is the one the segment file stores.

    Parameters
    ----------
    scene_path : pathlib.Path
        The scene file.
    data : dict
        The scene file as parsed, already loaded once without error.

    Returns
    -------
    list of SegmentSource
        One per distinct segment file, in chain order.

    """
    from cbha_inverse.fem.segment_io import inputs_sha256, load_segment
    from cbha_inverse.fem.segment_spec import cbha_geometry_path
    sections = {}
    for item in data['chain']['sections']:
        path = (Path(scene_path).parent / item['segment']).resolve()
        sections.setdefault(path, []).append(item['name'])
    sources = []
    for path, names in sections.items():
        meta = load_segment(path).metadata
        order, mesh_size = int(meta['element_order']), float(meta['mesh_size'])
        version = str(meta.get('package_version', ''))
        folders = {Path(scene_path).parent.resolve(), path.parent, path.parent.parent}
        candidates = [p for folder in sorted(folders) for p in sorted(folder.glob('*.yaml'))
                      if p.resolve() != path] + [cbha_geometry_path()]
        geometry = next((p for p in candidates if p.is_file() and inputs_sha256(
            p, order, mesh_size, version) == meta.get('inputs_sha256')), None)
        sources.append(SegmentSource(tuple(names), path, geometry, order, mesh_size,
                                     float(meta.get('condensation_seconds', 0.0))))
    return sources


def recondensed_data(scene_path, data, sources, folder, out):
    """
    Recondense every segment of a ``segments`` scene finer and return the refined scene.

    Parameters
    ----------
    scene_path : pathlib.Path
        The scene file.
    data : dict
        The scene file as parsed.
    sources : list of SegmentSource
        Its segments (:func:`segment_sources`), each with a geometry.
    folder : pathlib.Path
        Where the refined segments are written.
    out : file-like
        Where the progress of ``condense_segment`` is printed (one line per segment).

    Returns
    -------
    dict
        The scene with every ``segment`` pointing at its refined file (absolute paths).

    Raises
    ------
    ValueError
        If a segment's geometry was not found.

    """
    from cbha_inverse.fem.cli import run
    refined_paths = {}
    for index, source in enumerate(sources):
        if source.geometry is None:
            raise ValueError(f'no geometry file found for {source.segment}')
        target = Path(folder, f'refined_{index}', source.segment.name)
        progress = io.StringIO()
        refined_paths[source.segment] = run(source.geometry, output=target, order=source.order,
                                            mesh_size=source.fine_mesh_size, out=progress)
        for line in progress.getvalue().splitlines():
            print(f'  recondensed {shown(source.segment)}: '
                  + line.removeprefix(f'{target}: '), file=out)
    refined = yaml.safe_load(yaml.safe_dump(data))
    for item in refined['chain']['sections']:
        path = (Path(scene_path).parent / item['segment']).resolve()
        item['segment'] = str(Path(refined_paths[path]).resolve())
    return refined


def load_data(data, folder, name='refined.yaml'):
    """
    Write a scene dict to ``folder`` and load it.

    Parameters
    ----------
    data : dict
        A scene whose file paths are absolute (``beam_vertebrae`` scenes name none).
    folder : path-like
        A folder of the caller's (a temporary one).
    name : str
        The file name.

    Returns
    -------
    cbha_inverse.scene.Scene

    """
    from cbha_inverse.scene import load_scene
    path = Path(folder, name)
    path.write_text(yaml.safe_dump(data, sort_keys=False, width=99))
    return load_scene(path)


def refined_beam_scene(scene_path, factor=REFINEMENT):
    """
    Load a ``beam_vertebrae`` scene with ``factor`` times its beams per interval.

    Parameters
    ----------
    scene_path : path-like
        The scene file.
    factor : int
        Refinement factor.

    Returns
    -------
    scene : cbha_inverse.scene.Scene
    change : tuple of str
        ``('beams_per_interval', coarse, fine)``.

    """
    data = scene_data(scene_path)
    per = int(data['chain']['beams_per_interval'])
    with tempfile.TemporaryDirectory(prefix='cbha_refine_') as folder:
        scene = load_data(refined_beam_data(data, factor), folder, Path(scene_path).name)
    return scene, ('beams_per_interval', str(per), str(factor * per))


def representative_actuations(scene, extra=None):
    """
    Return the actuations of the check: rest, every actuator at half range, and ``extra``.

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        The scene.
    extra : (m,) array_like, optional  [N or Pa]
        One more actuation (e.g. the one of ``--actuation``).

    Returns
    -------
    labels : tuple of str
    actuations : (a, m) ndarray  [N or Pa]

    """
    low, high = scene.lower_bounds, scene.upper_bounds
    labels = ['rest', 'half range']
    actuations = [np.clip(np.zeros_like(low), low, high), low + 0.5 * (high - low)]
    if extra is not None:
        labels.append('given actuation')
        actuations.append(np.asarray(extra, dtype=float))
    return tuple(labels), np.array(actuations)


def compare(scene, refined, change, labels, actuations):
    """
    Solve a scene and its refined copy at the same actuations.

    Parameters
    ----------
    scene, refined : cbha_inverse.scene.Scene
        The two discretisations of one robot (same actuators and effectors).
    change : tuple of str
        What was refined: parameter, coarse and fine value (:class:`Comparison`).
    labels : tuple of str
        A name per actuation.
    actuations : (a, m) array_like  [N or Pa]
        Where to compare, within the bounds.

    Returns
    -------
    Comparison

    """
    if refined.actuator_names != scene.actuator_names or (
            refined.effector_names != scene.effector_names):
        raise ValueError('the refined scene has other actuators or effectors')
    coarse, fine, converged = [], [], []
    for actuation in np.asarray(actuations, dtype=float):
        first, second = scene.forward(actuation), refined.forward(actuation)
        coarse.append(first.effector_positions)
        fine.append(second.effector_positions)
        converged.append((first.converged, second.converged))
    return Comparison(*change, tuple(labels), np.array(actuations, dtype=float),
                      np.array(coarse), np.array(fine), np.array(converged, dtype=bool))


def recommendation(comparison, tolerance):
    """
    Return the one-line verdict of a comparison.

    Parameters
    ----------
    comparison : Comparison
        The two discretisations.
    tolerance : float  [m]
        The effector movement below which the coarse one is converged.

    Returns
    -------
    str

    """
    if not comparison.converged.all():
        return 'unknown: a forward solve did not converge'
    worst = float(comparison.movement.max())
    fine = f'{comparison.parameter} {comparison.fine_value}'
    if worst < tolerance:
        return (f'converged: {fine} moves the effectors at most {1e3 * worst:.3f} mm, '
                f'below {1e3 * tolerance:g} mm')
    return (f'refine: {fine} moves the effectors {1e3 * worst:.3f} mm, above '
            f'{1e3 * tolerance:g} mm (use it, and check again)')
