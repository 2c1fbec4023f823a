"""
A scene's ``calibration`` block: the identified corrections of a nominal model.

The CBHA's dimensions and materials are not published, so a nominal scene is off; the block
holds what :mod:`cbha_inverse.identify` fits from a recorded session, applied at load time by
:func:`cbha_inverse.scene.load_scene` while the chain and the actuators are built (one code
path: the calibrated scene is an ordinary scene)::

    calibration:
      section_stiffness: {inner: 0.85, outer: 1.1}   # stiffness factor per chain section [-]
      actuator_gain: {inner_over: 0.95, tip_0: 1.1}  # per cavity (effective area) or cable [-]
      tip_payload_mass: 0.02                          # extra mass at the last frame [kg]
      base_offset: {position: [0.0, 0.002, 0.0], rpy: [0.0, 0.0, 0.01]}  # chain base [m, rad]

Every key is optional; a factor not named is 1, an offset not given is zero. Factors must be
finite and positive, names must be sections of a ``segments`` chain and actuators (cavities or
cables) of the scene. A cavity's gain scales its wrench per pascal and its volume; a cable's
scales its force per newton of command (the cable pulls with ``gain * tension``). The base
offset is the pose of the chain's base in the scene's ``base_frame`` (what a tracker measures
in; roll, pitch, yaw about fixed x, y, z as in URDF): the whole chain with its routing and
effector points moves rigidly, gravity stays fixed in ``base_frame``.
"""

from dataclasses import dataclass, field
import math

from cbha_inverse.config_files import Section
from cbha_inverse.core.so3 import rpy_from_so3, so3_from_rpy
from cbha_inverse.scene.schema import keys
import numpy as np

_ZERO = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Calibration:
    """
    Corrections of a nominal scene (all identity by default).

    Attributes
    ----------
    section_stiffness : dict of str to float  [-]
        Chain section name -> factor on the link stiffness of its segments (divides their
        compliance).
    actuator_gain : dict of str to float  [-]
        Actuator name -> factor on its effect per unit command: a cavity's wrench per unit
        pressure and volume (effective area), a cable's force per unit tension.
    tip_payload_mass : float  [kg]
        Mass at the last frame (a gripper, a load): the scene's mass load ``tip_payload_mass``
        (:attr:`cbha_inverse.scene.scene.Scene.loads`, ``docs/loads.md``).
    base_position : (3,) tuple of float  [m]
        Origin of the chain's base in the scene's ``base_frame`` (``base_offset.position``).
    base_rpy : (3,) tuple of float  [rad]
        Orientation of the chain's base in ``base_frame``: roll, pitch, yaw about the fixed
        x, y, z axes, ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (``base_offset.rpy``).

    """

    section_stiffness: dict = field(default_factory=dict)
    actuator_gain: dict = field(default_factory=dict)
    tip_payload_mass: float = 0.0
    base_position: tuple = _ZERO
    base_rpy: tuple = _ZERO

    def __post_init__(self):
        """Check factors (finite, > 0), the mass (finite, >= 0) and the offset (3 finite)."""
        for label, values in (('section_stiffness', self.section_stiffness),
                              ('actuator_gain', self.actuator_gain)):
            for name, value in values.items():
                check_factor(f'{label}.{name}', value)
        if not (math.isfinite(self.tip_payload_mass) and self.tip_payload_mass >= 0.0):
            raise ValueError(f'tip_payload_mass must be finite and >= 0, got '
                             f'{self.tip_payload_mass}')
        for label in ('base_position', 'base_rpy'):
            object.__setattr__(self, label, finite_triple(label, getattr(self, label)))

    def base_pose(self):
        """
        Return the pose of the chain's base in ``base_frame``, ``T_s_b`` (s: ``base_frame``).

        Returns
        -------
        position : (3,) ndarray  [m]
            ``p_s_b``.
        rotation : (3, 3) ndarray
            ``R_s_b`` of :attr:`base_rpy`.

        """
        return np.array(self.base_position), so3_from_rpy(self.base_rpy)

    def combined(self, other):
        """
        Return this calibration followed by ``other`` (factors multiply, masses add).

        The base offsets compose as transforms, ``other`` in the axes of this one's base:
        ``T = T_self T_other`` (``p = p_self + R_self p_other``, ``R = R_self R_other``), as a
        correction measured on the calibrated scene is applied on top of it.

        Parameters
        ----------
        other : Calibration or None
            Applied on top (e.g. a simulated plant's errors on top of a scene's calibration).

        Returns
        -------
        Calibration

        """
        if other is None:
            return self
        return Calibration(_product(self.section_stiffness, other.section_stiffness),
                           _product(self.actuator_gain, other.actuator_gain),
                           self.tip_payload_mass + other.tip_payload_mass,
                           *_composed(self, other))

    def as_yaml(self):
        """Return the block as plain data for a scene file (identity entries kept)."""
        return {'section_stiffness': {k: float(v) for k, v in self.section_stiffness.items()},
                'actuator_gain': {k: float(v) for k, v in self.actuator_gain.items()},
                'tip_payload_mass': float(self.tip_payload_mass),
                'base_offset': {'position': list(self.base_position),
                                'rpy': list(self.base_rpy)}}


def check_factor(label, value):
    """
    Return a correction factor, checked finite and positive.

    Parameters
    ----------
    label : str
        What it is, for the error (``'actuator_gain.outer_left'``, a node parameter's name).
    value : float  [-]
        The factor.

    Returns
    -------
    float

    Raises
    ------
    ValueError
        Unless ``value`` is finite and > 0.

    """
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f'{label} must be finite and > 0, got {value}')
    return value


def finite_triple(label, value):
    """
    Return three finite numbers (a position, angles, a gravity vector) as a tuple of floats.

    Parameters
    ----------
    label : str
        What it is, for the error (``'base_position'``, a node parameter's name).
    value : (3,) array_like
        The numbers.

    Returns
    -------
    (3,) tuple of float
        Without negative zeros.

    Raises
    ------
    ValueError
        Unless ``value`` is 3 finite numbers.

    """
    array = np.asarray(value, dtype=float)
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ValueError(f'{label} must be 3 finite numbers, got {value}')
    return tuple(float(v) + 0.0 for v in array)  # + 0.0: no -0.0


def _composed(first, second):
    """Return the base offset (position, rpy) of ``T_first T_second`` (exact if one is zero)."""
    if second.base_position == _ZERO and second.base_rpy == _ZERO:
        return first.base_position, first.base_rpy
    if first.base_position == _ZERO and first.base_rpy == _ZERO:
        return second.base_position, second.base_rpy
    p_first, r_first = first.base_pose()
    p_second, r_second = second.base_pose()
    return tuple(p_first + r_first @ p_second), tuple(rpy_from_so3(r_first @ r_second))


def _product(first, second):
    """Multiply two name -> factor mappings (a missing name is 1)."""
    out = dict(first)
    for name, value in second.items():
        out[name] = out.get(name, 1.0) * value
    return out


def read_calibration(spec):
    """
    Read and validate the ``calibration`` block of a scene.

    Parameters
    ----------
    spec : cbha_inverse.config_files.Section
        The scene file's top level.

    Returns
    -------
    Calibration
        Identity when the scene has no block.

    Raises
    ------
    cbha_inverse.errors.ConfigError
        On an unknown key, a factor that is not a finite positive number, a negative mass or
        an offset entry that is not 3 finite numbers (names are checked against the chain and
        the actuators by :func:`check_names`).

    """
    if not spec.has('calibration'):
        return Calibration()
    block = spec.section('calibration')
    known = keys('calibration')
    block.only(*known)
    factors = []
    for key in known[:2]:
        values = {}
        if block.has(key):
            table = block.section(key)
            for name in table.data:
                values[str(name)] = table.number(name, positive=True)
        factors.append(values)
    offset = block.section('base_offset', None) or Section(block.path, {},
                                                           block.key('base_offset'))
    offset.only(*keys('base_offset'))
    return Calibration(*factors, block.number('tip_payload_mass', 0.0, minimum=0.0),
                       offset.vector('position', 3, _ZERO), offset.vector('rpy', 3, _ZERO))


def check_names(spec, calibration, sections, actuators):
    """
    Check that the calibration names exist in the scene.

    Parameters
    ----------
    spec : cbha_inverse.config_files.Section
        The scene file's top level (for the error's file and key).
    calibration : Calibration
        The block read by :func:`read_calibration`.
    sections : iterable of str
        The chain's section names (none for a ``beam_vertebrae`` chain).
    actuators : iterable of str
        The scene's actuator names (cavities and cables).

    Raises
    ------
    cbha_inverse.errors.ConfigError
        Naming the first unknown section or actuator.

    """
    block = Section(spec.path, spec.data.get('calibration') or {}, 'calibration')
    for key, names, what in (('section_stiffness', set(sections), 'chain section'),
                             ('actuator_gain', set(actuators), 'actuator')):
        for name in getattr(calibration, key):
            if name not in names:
                raise block.error(f'{key}.{name}', f'no {what} {name!r} in the scene (has '
                                  f'{sorted(names)})')
