"""
A scene's ``calibration`` block: the identified corrections of a nominal model.

The CBHA's dimensions and materials are not published, so a nominal scene is off; the block
holds what :mod:`cbha_inverse.identify` fits from a recorded session, applied at load time by
:func:`cbha_inverse.scene.load_scene` while the chain and the actuators are built (one code
path: the calibrated scene is an ordinary scene)::

    calibration:
      section_stiffness: {inner: 0.85, outer: 1.1}   # stiffness factor per chain section [-]
      actuator_gain: {inner_over: 0.95}              # effective-area factor per cavity [-]
      tip_payload_mass: 0.02                          # extra mass at the last frame [kg]

Every key is optional; a factor not named is 1. Factors must be finite and positive, names must
be sections of a ``segments`` chain and cavities of the scene.
"""

from dataclasses import dataclass, field
import math

from cbha_inverse.config_files import Section


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
        Cavity name -> factor on its wrench per unit pressure (effective area).
    tip_payload_mass : float  [kg]
        Mass added at the last frame (a gripper, a load).

    """

    section_stiffness: dict = field(default_factory=dict)
    actuator_gain: dict = field(default_factory=dict)
    tip_payload_mass: float = 0.0

    def __post_init__(self):
        """Check that factors are finite and positive, the mass finite and non-negative."""
        for label, values in (('section_stiffness', self.section_stiffness),
                              ('actuator_gain', self.actuator_gain)):
            for name, value in values.items():
                if not (math.isfinite(value) and value > 0.0):
                    raise ValueError(f'{label}.{name} must be finite and > 0, got {value}')
        if not (math.isfinite(self.tip_payload_mass) and self.tip_payload_mass >= 0.0):
            raise ValueError(f'tip_payload_mass must be finite and >= 0, got '
                             f'{self.tip_payload_mass}')

    def combined(self, other):
        """
        Return this calibration followed by ``other`` (factors multiply, masses add).

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
                           self.tip_payload_mass + other.tip_payload_mass)

    def as_yaml(self):
        """Return the block as plain data for a scene file (identity entries kept)."""
        return {'section_stiffness': {k: float(v) for k, v in self.section_stiffness.items()},
                'actuator_gain': {k: float(v) for k, v in self.actuator_gain.items()},
                'tip_payload_mass': float(self.tip_payload_mass)}


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
        On an unknown key, a factor that is not a finite positive number or a negative mass
        (names are checked against the chain and the actuators by :func:`check_names`).

    """
    if not spec.has('calibration'):
        return Calibration()
    block = spec.section('calibration')
    known = ('section_stiffness', 'actuator_gain', 'tip_payload_mass')
    for key in block.data:
        if key not in known:
            raise block.error(key, f'unknown calibration key (known: {list(known)})')
    factors = []
    for key in known[:2]:
        values = {}
        if block.has(key):
            table = block.section(key)
            for name in table.data:
                values[str(name)] = table.number(name, positive=True)
        factors.append(values)
    return Calibration(*factors, block.number('tip_payload_mass', 0.0, minimum=0.0))


def check_names(spec, calibration, sections, cavities):
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
    cavities : iterable of str
        The scene's cavity names.

    Raises
    ------
    cbha_inverse.errors.ConfigError
        Naming the first unknown section or cavity.

    """
    block = Section(spec.path, spec.data.get('calibration') or {}, 'calibration')
    for key, names, what in (('section_stiffness', set(sections), 'chain section'),
                             ('actuator_gain', set(cavities), 'cavity')):
        for name in getattr(calibration, key):
            if name not in names:
                raise block.error(f'{key}.{name}', f'no {what} {name!r} in the scene (has '
                                  f'{sorted(names)})')
