"""
Segment YAML files (config/segments/<name>.yaml) and their cavity surfaces: write, read, cache.

The reader never imports gmsh; cavity surfaces are legacy VTK files read with meshio.
"""

from dataclasses import dataclass
import hashlib
import json
from pathlib import Path

from cbha_inverse import __version__
from cbha_inverse.config_files import check_keys, read_yaml
from cbha_inverse.core.links import checked_compliance
from cbha_inverse.errors import ConfigError
import numpy as np
import yaml

#: Units of every number in a segment YAML.
UNITS = {'length': 'm', 'mass': 'kg', 'force': 'N', 'moment': 'N*m', 'angle': 'rad',
         'pressure': 'Pa', 'compliance': '[m/N, rad/(N*m)] in the lower frame axes'}


@dataclass(frozen=True)
class Cavity:
    """
    Closed triangle surface of one pressure cavity in segment coordinates.

    Attributes
    ----------
    name : str
        Cavity (tube) name.
    points : (P, 3) ndarray  [m]
        Vertices.
    triangles : (T, 3) int ndarray
        Triangles with outward normals (right-hand rule).

    """

    name: str
    points: np.ndarray
    triangles: np.ndarray


@dataclass(frozen=True)
class Segment:
    """
    A condensed segment as read from its YAML: one compliance link of the chain.

    Attributes
    ----------
    name : str
        Segment name.
    compliance : (6, 6) ndarray  [m/N, rad/(N m)]
        C in the paper's convention.
    rest_offset : (3,) ndarray  [m]
        Upper frame origin in lower frame axes.
    rest_rotation : (3, 3) ndarray
        Upper frame axes in lower frame axes.
    mass : float  [kg]
        Mass lumped at the upper frame.
    cavities : tuple of Cavity
        Pressure cavities (empty for a plain segment).
    metadata : dict
        The remaining YAML fields (material, element order, mesh size, counts, sha256, ...).

    """

    name: str
    compliance: np.ndarray
    rest_offset: np.ndarray
    rest_rotation: np.ndarray
    mass: float
    cavities: tuple
    metadata: dict

    @property
    def stiffness(self):
        """Return the 6x6 stiffness K = C^-1."""
        return np.linalg.inv(self.compliance)


def inputs_sha256(geometry_path, order, mesh_size, version=__version__):
    """
    Return the sha256 identifying a condensation: geometry file bytes, mesh parameters, version.

    Parameters
    ----------
    geometry_path : path-like
        Geometry YAML.
    order : int
        Element order.
    mesh_size : float  [m]
        Element size.
    version : str
        Package version.

    Returns
    -------
    str
        Hex digest.

    """
    digest = hashlib.sha256(Path(geometry_path).read_bytes())
    params = {'order': int(order), 'mesh_size': float(mesh_size), 'version': str(version)}
    digest.update(json.dumps(params, sort_keys=True).encode())
    return digest.hexdigest()


def cached_segment(path, sha256):
    """
    Return True if the segment YAML at ``path`` exists and was made from the same inputs.

    Parameters
    ----------
    path : path-like
        Segment YAML.
    sha256 : str
        Expected ``inputs_sha256``.

    Returns
    -------
    bool
        Whether the file (and its cavity files) can be reused.

    """
    path = Path(path)
    if not path.is_file():
        return False
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError:
        return False
    if not isinstance(data, dict) or data.get('inputs_sha256') != sha256:
        return False
    return all((path.parent / c['file']).is_file() for c in data.get('cavities', []))


def write_cavity(path, points, triangles):
    """
    Write a closed triangle surface as a binary legacy VTK file (meshio).

    Parameters
    ----------
    path : path-like
        Output ``.vtk`` path.
    points : (P, 3) ndarray  [m]
        Vertices.
    triangles : (T, 3) int ndarray
        Triangles.

    """
    import meshio
    meshio.write(str(path), meshio.Mesh(np.asarray(points, float),
                                        [('triangle', np.asarray(triangles, np.int64))]),
                 file_format='vtk', binary=True)


def read_cavity(path):
    """
    Read a triangle surface written by :func:`write_cavity`.

    Parameters
    ----------
    path : path-like
        ``.vtk`` (or any meshio-readable) surface file.

    Returns
    -------
    points : (P, 3) ndarray  [m]
        Vertices.
    triangles : (T, 3) int ndarray
        Triangles.

    """
    import meshio
    mesh = meshio.read(str(path))
    tris = [c.data for c in mesh.cells if c.type == 'triangle']
    if not tris:
        raise ValueError(f'{path}: no triangles')
    return np.asarray(mesh.points, float), np.vstack(tris).astype(np.int64)


def write_segment(path, segment, *, name, material, inputs_sha256, cavities=(), notes=()):
    """
    Write a segment YAML (yaml.safe_dump) and its cavity surface files beside it.

    Parameters
    ----------
    path : path-like
        Output ``<dir>/<name>.yaml``.
    segment : CondensedSegment
        Condensation result.
    name : str
        Segment name.
    material : dict
        Material mapping (name, youngs_modulus, poisson_ratio, density).
    inputs_sha256 : str
        Hash of the inputs (:func:`inputs_sha256`).
    cavities : sequence of (name, points, triangles)
        Cavity surfaces, written as ``<name>_cavity_<cavity>.vtk``.
    notes : sequence of str
        Free-text provenance notes.

    Returns
    -------
    pathlib.Path
        The YAML path.

    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    entries = []
    for cav_name, points, triangles in cavities:
        file_name = f'{name}_cavity_{cav_name}.vtk'
        write_cavity(path.parent / file_name, points, triangles)
        entries.append({'name': str(cav_name), 'file': file_name})
    data = {
        'name': str(name),
        'units': dict(UNITS),
        'compliance': np.asarray(segment.compliance, float).tolist(),
        'rest_offset': np.asarray(segment.rest_offset, float).tolist(),
        'rest_rotation': np.asarray(segment.rest_rotation, float).tolist(),
        'mass_kg': float(segment.mass),
        'material': {k: (float(v) if isinstance(v, (int, float)) else str(v))
                     for k, v in material.items()},
        'element_order': int(segment.element_order),
        'mesh_size': float(segment.mesh_size),
        'n_nodes': int(segment.n_nodes),
        'n_elements': int(segment.n_elements),
        'inputs_sha256': str(inputs_sha256),
        'package_version': __version__,
        'condensation_seconds': round(float(segment.timings.get('total', 0.0)), 3),
        'cavities': entries,
        'notes': [str(n) for n in notes],
    }
    path.write_text(yaml.safe_dump(data, sort_keys=False, width=99))
    return path


SEGMENT_KEYS = ('name', 'units', 'compliance', 'rest_offset', 'rest_rotation', 'mass_kg',
                'material', 'element_order', 'mesh_size', 'n_nodes', 'n_elements',
                'inputs_sha256', 'package_version', 'condensation_seconds', 'cavities', 'notes')
"""The keys of a segment file, as :func:`write_segment` writes them."""


_SEGMENTS = {}
"""Loaded segments by resolved path: ``(files, their digests, Segment)`` (:func:`load_segment`)."""
_MAX_SEGMENTS = 64


def _file_digest(path):
    """Return a digest of a file's bytes (reading them costs little beside parsing them)."""
    return hashlib.blake2b(path.read_bytes(), digest_size=16).digest()


def load_segment(path):
    """
    Read a segment YAML (and its cavity surfaces) without gmsh, once per version of the files.

    A process keeps what it read: a later call with the same path returns the same
    :class:`Segment` while the bytes of the YAML and of its cavity files are unchanged, e.g. one
    scene load per model evaluation of ``cbha_identify``. Its arrays are read-only.

    Parameters
    ----------
    path : path-like
        ``config/segments/<name>.yaml``.

    Returns
    -------
    Segment
        Compliance, rest transform, mass, cavities and metadata.

    Raises
    ------
    cbha_inverse.errors.ConfigError
        If the file is not valid YAML, a field is missing or malformed, or the compliance is not
        a symmetric positive definite 6x6 matrix.

    """
    path = Path(path)
    key = path.resolve()
    kept = _SEGMENTS.get(key)
    if kept is not None:
        files, digests, segment = kept
        try:
            if digests == tuple(_file_digest(file) for file in files):
                return segment
        except OSError:
            pass
    files = [path]
    segment = _read_segment(path, files)
    for array in (segment.compliance, segment.rest_offset, segment.rest_rotation,
                  *(a for cavity in segment.cavities for a in (cavity.points, cavity.triangles))):
        array.flags.writeable = False
    if len(_SEGMENTS) >= _MAX_SEGMENTS:
        _SEGMENTS.clear()
    _SEGMENTS[key] = (files, tuple(_file_digest(file) for file in files), segment)
    return segment


def _read_segment(path, files):
    """Read and check a segment YAML and its cavity surfaces; append the surfaces to ``files``."""
    data = read_yaml(path)
    check_keys(path, data, SEGMENT_KEYS)
    arrays = {}
    for key, shape in (('compliance', (6, 6)), ('rest_offset', (3,)), ('rest_rotation', (3, 3))):
        if data.get(key) is None:
            raise ConfigError(path, key, 'missing')
        try:
            arrays[key] = np.array(data[key], dtype=float)
        except (TypeError, ValueError):
            arrays[key] = None
        if arrays[key] is None or arrays[key].shape != shape or not np.all(
                np.isfinite(arrays[key])):
            raise ConfigError(path, key, f'must be a {shape} array of finite numbers')
    compliance, offset, rotation = (arrays['compliance'], arrays['rest_offset'],
                                    arrays['rest_rotation'])
    mass = data.get('mass_kg')
    if isinstance(mass, bool) or not isinstance(mass, (int, float)) or not mass >= 0.0:
        raise ConfigError(path, 'mass_kg', f'must be a number >= 0, got {mass!r}')
    mass = float(mass)
    try:
        compliance, _ = checked_compliance(compliance, 'the matrix')
    except np.linalg.LinAlgError as exc:
        raise ConfigError(path, 'compliance', str(exc)) from None
    cavities = []
    for i, item in enumerate(data.get('cavities') or []):
        if not (isinstance(item, dict) and isinstance(item.get('name'), str)
                and isinstance(item.get('file'), str)):
            raise ConfigError(path, f'cavities[{i}]', 'needs a name and a file (strings)')
        check_keys(path, item, ('name', 'file'), f'cavities[{i}]')
        surface = path.parent / item['file']
        if not surface.is_file():
            raise ConfigError(path, f'cavities[{i}].file', f'no cavity surface {surface}')
        files.append(surface)
        cavities.append(Cavity(item['name'], *read_cavity(surface)))
    cavities = tuple(cavities)
    known = {'name', 'compliance', 'rest_offset', 'rest_rotation', 'mass_kg', 'cavities'}
    metadata = {k: v for k, v in data.items() if k not in known}
    return Segment(str(data.get('name', path.stem)), compliance, offset, rotation, mass,
                   cavities, metadata)


def chain_from_segments(segments, base_position=None, base_rotation=None):
    """
    Build a ``ChainModel`` from condensed segments (a chain of compliance links).

    Parameters
    ----------
    segments : sequence of Segment or CondensedSegment
        Link i joins frame i to frame i + 1; its mass is lumped at frame i + 1.
    base_position : (3,) array_like, optional  [m]
        Base frame origin.
    base_rotation : (3, 3) array_like, optional
        Base frame axes.

    Returns
    -------
    cbha_inverse.core.chain.ChainModel
        The chain.

    """
    from cbha_inverse.core.chain import ChainModel
    return ChainModel.from_compliances(
        np.array([s.compliance for s in segments]), np.array([s.rest_offset for s in segments]),
        masses=np.array([s.mass for s in segments]),
        rest_rotations=np.array([s.rest_rotation for s in segments]),
        base_position=base_position, base_rotation=base_rotation)
