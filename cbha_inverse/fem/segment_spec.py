"""
Typed segment geometry files (``meshes/*_geometry.yaml``), read and validated in one place.

A geometry YAML (``name``, ``kind``, ``geometry``, ``material``, ``mesh``) becomes a frozen
:class:`SegmentSpec` whose ``geometry`` is a :class:`BellowsGeometry` (``kind:
bellows_segment``, the CBHA) or a :class:`CylinderGeometry` (``kind: cylinder``, the test
segment). :func:`read_segment_spec` is the only reader: every key the condensation uses is
checked there, and a bad file raises ``ConfigError(path, key, problem)``. The meshing, the
cavity surfaces, the condensation, the ``condense_segment`` command and the reports take the
typed objects. The segment cache hashes the file's bytes
(:func:`cbha_inverse.fem.segment_io.inputs_sha256`), not these objects.

The package's CBHA geometry is ``meshes/cbha_segment_geometry.yaml``
(:func:`cbha_geometry_path`); its condensed segment, named after the ``name:`` field, is
``config/segments/cbha_segment.yaml``.
"""

from dataclasses import dataclass
from pathlib import Path

from cbha_inverse.config_files import read_section
from cbha_inverse.paths import meshes_path

KINDS = ('bellows_segment', 'cylinder')


@dataclass(frozen=True)
class Material:
    """
    Linear elastic material of a segment.

    Attributes
    ----------
    name : str
        Label written to the segment YAML.
    youngs_modulus : float  [Pa]
        Young's modulus (> 0).
    poisson_ratio : float
        Poisson's ratio in (-1, 0.5).
    density : float  [kg/m^3]
        Density (>= 0).

    """

    name: str
    youngs_modulus: float
    poisson_ratio: float
    density: float = 0.0

    def as_dict(self):
        """Return the material as the ``material`` mapping of a segment YAML."""
        return {'name': self.name, 'youngs_modulus': self.youngs_modulus,
                'poisson_ratio': self.poisson_ratio, 'density': self.density}


@dataclass(frozen=True)
class MeshSettings:
    """
    Meshing parameters of a segment.

    Attributes
    ----------
    mesh_size : float  [m]
        Target element size (> 0).
    order : {1, 2}
        Element order.

    """

    mesh_size: float
    order: int = 2


@dataclass(frozen=True)
class Tube:
    """
    One bellows tube of a segment.

    Attributes
    ----------
    name : str
        Cavity name (the actuator's).
    angle_deg : float  [deg]
        Angle of the tube centre in the y-z plane, from +y towards +z.

    """

    name: str
    angle_deg: float


@dataclass(frozen=True)
class BellowsGeometry:
    """
    Corrugated bellows tubes between two rigid vertebrae (the CBHA segment).

    Segment coordinates: axis +x, lower vertebra frame at the origin, upper frame at
    ``(segment_length, 0, 0)``.

    Attributes
    ----------
    segment_length : float  [m]
        Vertebra-to-vertebra distance ``L``.
    vertebra_thickness : float  [m]
        Thickness ``t_v`` of a rigid vertebra (frames at vertebra mid-planes).
    tube_pitch_radius : float  [m]
        Distance of the tube axes from the segment axis.
    tube_mean_radius : float  [m]
        Mean inner radius of a tube.
    corrugation_amplitude : float  [m]
        Half-height of the sinusoidal corrugation.
    corrugation_periods : int
        Corrugation waves between the vertebra faces.
    wall_thickness : float  [m]
        Tube wall, measured radially.
    tubes : tuple of Tube
        The tubes, in cavity order.
    vertebra_mass : float  [kg]
        Rigid mass lumped at the upper frame.

    """

    segment_length: float
    vertebra_thickness: float
    tube_pitch_radius: float
    tube_mean_radius: float
    corrugation_amplitude: float
    corrugation_periods: int
    wall_thickness: float
    tubes: tuple[Tube, ...]
    vertebra_mass: float = 0.0

    @property
    def wall_start(self):
        """Return the abscissa of the lower vertebra face, ``t_v / 2`` [m]."""
        return 0.5 * self.vertebra_thickness

    @property
    def wall_end(self):
        """Return the abscissa of the upper vertebra face, ``L - t_v / 2`` [m]."""
        return self.segment_length - 0.5 * self.vertebra_thickness

    @property
    def corrugation_pitch(self):
        """Return the length of one corrugation wave [m]."""
        return (self.wall_end - self.wall_start) / self.corrugation_periods


@dataclass(frozen=True)
class CylinderGeometry:
    """
    A solid or hollow circular cylinder with rigid end faces (the test segment).

    Attributes
    ----------
    length : float  [m]
        Segment length.
    outer_radius : float  [m]
        Outer radius.
    inner_radius : float  [m]
        Inner radius (0 for a solid cylinder, below ``outer_radius``).

    """

    length: float
    outer_radius: float
    inner_radius: float = 0.0


@dataclass(frozen=True)
class SegmentSpec:
    """
    A validated segment geometry file.

    Attributes
    ----------
    path : pathlib.Path
        The file it was read from.
    name : str
        Segment name (``<name>.yaml`` is the condensed segment).
    kind : {'bellows_segment', 'cylinder'}
        Geometry kind.
    geometry : BellowsGeometry or CylinderGeometry
        The shape.
    material : Material
        The material.
    mesh : MeshSettings
        The meshing parameters.

    """

    path: Path
    name: str
    kind: str
    geometry: BellowsGeometry | CylinderGeometry
    material: Material
    mesh: MeshSettings


def cbha_geometry_path():
    """
    Return the package's CBHA segment geometry file (the default of ``condense_segment``).

    Returns
    -------
    pathlib.Path
        ``meshes/cbha_segment_geometry.yaml`` of the source checkout or the install.

    """
    return meshes_path('cbha_segment_geometry.yaml')


def read_segment_spec(path):
    """
    Read and validate a segment geometry YAML.

    Parameters
    ----------
    path : str or os.PathLike
        The geometry YAML (``meshes/*_geometry.yaml`` format: ``name``, ``kind``,
        ``geometry``, ``material``, ``mesh``).

    Returns
    -------
    SegmentSpec
        The typed file.

    Raises
    ------
    cbha_inverse.errors.ConfigError
        Naming the file and the key that is missing, mistyped or out of range.

    """
    path = Path(path)
    spec = read_section(path).only('name', 'kind', 'geometry', 'material', 'mesh')
    name = spec.text('name')
    kind = spec.text('kind', 'bellows_segment', choices=KINDS)
    mesh = spec.section('mesh').only('mesh_size', 'order')
    mesh_size = mesh.number('mesh_size', positive=True)
    order = mesh.integer('order', 2)
    if order not in (1, 2):
        raise mesh.error('order', f'must be 1 or 2, got {order}')
    material = spec.section('material').only('name', 'youngs_modulus', 'poisson_ratio',
                                             'density')
    youngs_modulus = material.number('youngs_modulus', positive=True)
    poisson = material.number('poisson_ratio')
    if not -1.0 < poisson < 0.5:
        raise material.error('poisson_ratio', f'must lie in (-1, 0.5), got {poisson:g}')
    density = material.number('density', 0.0, minimum=0.0)
    typed_material = Material(material.text('name', name), youngs_modulus, poisson, density)
    shape = spec.section('geometry')
    if kind == 'cylinder':
        shape.only('length', 'outer_radius', 'inner_radius')
        outer = shape.number('outer_radius', positive=True)
        length = shape.number('length', positive=True)
        inner = shape.number('inner_radius', 0.0, minimum=0.0)
        if inner >= outer:
            raise shape.error('inner_radius', 'must be below outer_radius')
        geometry = CylinderGeometry(length, outer, inner)
    else:
        geometry = _bellows_geometry(shape)
    return SegmentSpec(path, name, kind, geometry, typed_material, MeshSettings(mesh_size, order))


def _bellows_geometry(shape):
    """Return the :class:`BellowsGeometry` of a checked ``geometry`` section."""
    keys = ('segment_length', 'vertebra_thickness', 'tube_pitch_radius', 'tube_mean_radius',
            'corrugation_amplitude', 'wall_thickness')
    shape.only(*keys, 'corrugation_periods', 'vertebra_mass', 'tubes')
    lengths = {key: shape.number(key, positive=True) for key in keys}
    periods = shape.integer('corrugation_periods', minimum=1)
    vertebra_mass = shape.number('vertebra_mass', 0.0, minimum=0.0)
    tubes = shape.sections('tubes')
    if not tubes:
        raise shape.error('tubes', 'at least one tube is needed')
    if not lengths['vertebra_thickness'] < lengths['segment_length']:
        raise shape.error('vertebra_thickness', 'must be below segment_length')
    return BellowsGeometry(
        corrugation_periods=periods, vertebra_mass=vertebra_mass,
        tubes=tuple(Tube(tube.only('name', 'angle_deg').text('name'), tube.number('angle_deg'))
                    for tube in tubes),
        **lengths)
