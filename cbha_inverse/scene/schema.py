"""
The keys of a scene file: one declaration that the loader checks and the reference page shows.

Every block of a scene YAML (:func:`cbha_inverse.scene.load_scene`) declares its keys here, with
unit, default and meaning; the loader accepts exactly :func:`keys` of each block (a misspelt key
is refused with the nearest name), and ``docs/scene-schema.md`` is :func:`markdown`, printed by
``cbha_scene schema`` (a test compares the two). The solver block's keys are
the fields of :class:`cbha_inverse.core.inverse.results.InverseOptions`, documented there.
"""

from dataclasses import dataclass, fields
import re

from cbha_inverse.core.actuation.effectors import DEFAULT_ORIENTATION_LENGTH


@dataclass(frozen=True)
class Key:
    """One key of a block: its name, unit, default (empty: required) and meaning."""

    name: str
    unit: str
    default: str
    meaning: str


@dataclass(frozen=True)
class Block:
    """A block of the scene file: where it sits, what it is, its keys."""

    path: str
    summary: str
    keys: tuple


_R = ''    # required: no default


BLOCKS = {block.path: block for block in (
    Block('scene', 'The top level of a scene file.', (
        Key('name', '', 'the file name', 'Name of the scene (logs, reports).'),
        Key('description', '', "''", 'One paragraph for humans.'),
        Key('base_frame', '', 'cbha_base', 'TF name of the world frame of targets and poses.'),
        Key('gravity', 'm/s^2', '[0, 0, -9.81]',
            'In `base_frame` axes; `null`: none; `[0, 0, 0]` allowed.'),
        Key('chain', '', _R, 'The backbone: `chain` (beam_vertebrae) or `chain` (segments).'),
        Key('cables', '', 'none', 'Tendons: a list of `cable`.'),
        Key('cavities', '', 'none', 'Pressurised cavities of a segments chain: a list of '
            '`cavity`.'),
        Key('cavity_model', '', 'linear', '`linear` (condensed) or `mesh` (cavity surfaces).'),
        Key('actuator_order', '', 'cables, then cavities',
            'Actuator names in command (column) order.'),
        Key('effectors', '', _R, 'Points the inverse drives: a list of `effector`.'),
        Key('workspace_center', 'm', 'the effectors at rest',
            '`[x, y, z]`, `{actuation_fraction: f}` or `reachable_center` (see '
            '`workspace_center`).'),
        Key('solver', '', 'InverseOptions defaults', 'Defaults of the inverse: `solver`.'),
        Key('calibration', '', 'none', 'Identified corrections: `calibration`.'),
        Key('sensors', '', 'none', 'String potentiometers: a list of `sensor`.'),
        Key('loads', '', 'none', 'External forces, torques and masses: a list of `load`.'),
        Key('obstacles', '', 'none', 'Solids near the arm (docs/obstacles.md): a list of '
            '`obstacle`.'),
        Key('collision', '', "the chain's radius, per frame", "The robot's collision "
            'spheres: `collision`.'),
    )),
    Block('chain', 'Common to both chain types.', (
        Key('type', '', _R, '`beam_vertebrae` or `segments`.'),
    )),
    Block('chain (beam_vertebrae)', 'Timoshenko beams with vertebrae every '
          '`beams_per_interval` beams; or `sections`, each with these keys but `sections` (a '
          "key given at the chain level is every section's default).", (
              Key('n_vertebrae', '', _R, 'Vertebrae above the base.'),
              Key('beams_per_interval', '', _R, 'Beam elements between two vertebrae.'),
              Key('interval_length', 'm', _R, 'Distance between two vertebrae.'),
              Key('backbone', '', _R, 'The rod: `backbone`.'),
              Key('vertebra_mass', 'kg', '0', 'Mass of each vertebra disc.'),
              Key('sections', '', 'none', 'Parts of other spacing or backbone, base first.'),
          )),
    Block('backbone', 'The elastic rod of a beam_vertebrae chain.', (
        Key('youngs_modulus', 'Pa', _R, "Young's modulus."),
        Key('poisson_ratio', '', _R, "Poisson's ratio (shear modulus E / 2(1 + ν))."),
        Key('outer_radius', 'm', _R, 'Outer radius of the (tubular) section.'),
        Key('inner_radius', 'm', '0', 'Inner radius (0: solid).'),
        Key('density', 'kg/m^3', '0', 'Density of the rod (its weight under gravity).'),
    )),
    Block('chain (segments)', 'Condensed segments (`condense_segment`) in series.', (
        Key('sections', '', _R, 'A list of `segment section`, base first.'),
    )),
    Block('segment section', 'Identical segments in series.', (
        Key('name', '', _R, 'Section name (calibration, cavities).'),
        Key('segment', '', _R, 'Condensed segment YAML, relative to the scene file.'),
        Key('count', '', _R, 'How many segments.'),
    )),
    Block('cable', 'A tendon (frictionless), in straight spans between routing points on '
          'vertebrae; the straight form (`angle_deg`, `radius`, `end_vertebra`) or `points`.', (
              Key('name', '', _R, 'Actuator name.'),
              Key('max_tension', 'N', _R, 'Upper bound of the tension.'),
              Key('axial_stiffness', 'N', 'inf (inextensible)',
                  'EA: stretch of a displacement-driven cable.'),
              Key('points', '', 'none', 'Every routing point: a list of `cable point`.'),
              Key('angle_deg', 'deg', _R, 'Straight form: angle of the holes (figure).'),
              Key('radius', 'm', _R, 'Straight form: distance of the holes from the backbone.'),
              Key('end_vertebra', '', _R, 'Straight form: the last vertebra.'),
              Key('start_vertebra', '', '0', 'Straight form: the first vertebra (0: the base).'),
              Key('helix', '', 'none', 'Straight form wound as a helix: `helix`.'),
          )),
    Block('helix', 'A helical route.', (
        Key('pitch_deg_per_vertebra', 'deg', _R,
            'Angle advance per vertebra after `start_vertebra` (> 0: right-handed about +x).'),
    )),
    Block('cable point', 'One routing point of `points`.', (
        Key('vertebra', '', _R, 'Its vertebra (strictly increasing along the cable).'),
        Key('angle_deg', 'deg', _R, 'Angle of the hole (figure).'),
        Key('radius', 'm', _R, 'Distance from the backbone.'),
        Key('offset', 'm', 'none', '`[x, y, z]` in the vertebra frame instead of angle and '
            'radius.'),
    )),
    Block('cavity', 'A pressurised cavity of a segments section.', (
        Key('name', '', _R, 'Actuator name.'),
        Key('section', '', _R, 'The section whose segments it inflates.'),
        Key('cavity', '', _R, "The segment's cavity name."),
        Key('max_pressure', 'Pa', _R, 'Upper bound of the gauge pressure.'),
    )),
    Block('effector', 'A point the inverse drives, and for `axis` and `pose` the orientation '
          'of its frame (docs/effectors.md).', (
              Key('name', '', _R, 'Effector name (targets).'),
              Key('kind', '', 'point', '`point` (3 position rows), `axis` (+2 rows: a frame '
                  'axis toward a direction) or `pose` (+3 rows: the whole orientation).'),
              Key('frame', '', 'the tip', 'Frame index (1..n) or `tip`.'),
              Key('vertebra', '', 'none', 'Vertebra index instead of `frame`.'),
              Key('offset', 'm', '[0, 0, 0]', 'The point in the frame.'),
              Key('axis', '', '[1, 0, 0]', "The `axis` kind's axis, in the frame's axes "
                  '(normalised).'),
              Key('weights', '', 'all 1', 'Row weights: `weights`.'),
          )),
    Block('weights', "Weights of an effector's rows in the inverse's objective.", (
        Key('position', '', '1', 'One number, or one per position row (3), >= 0.'),
        Key('orientation', '', '1', 'One number, or one per rotational row (2 or 3), >= 0.'),
        Key('orientation_length', 'm', f'{DEFAULT_ORIENTATION_LENGTH:g}',
            '1 rad of orientation error weighs as this many metres of position error.'),
    )),
    Block('workspace_center', 'Suggested centre of target trajectories (mapping forms).', (
        Key('actuation_fraction', '', _R, 'The effectors with every actuator at this fraction '
            'of its range.'),
        Key('reachable_center', '', 'none', 'Centre of the sampled reachable set; '
            '`{samples: N}` (default 300).'),
    )),
    Block('reachable_center', 'The sampled reachable set of `workspace_center`.', (
        Key('samples', '', '300', 'Random actuations sampled.'),
    )),
    Block('sensor', 'A string potentiometer (length sensor) on the chain.', (
        Key('name', '', _R, 'Sensor name.'),
        Key('kind', '', _R, '`string_pot`.'),
        Key('points', '', 'none', 'Attachment points: a list of `sensor point`.'),
        Key('angle_deg', 'deg', _R, 'Straight form, as a cable.'),
        Key('radius', 'm', _R, 'Straight form, as a cable.'),
        Key('end_vertebra', '', _R, 'Straight form, as a cable.'),
        Key('start_vertebra', '', '0', 'Straight form, as a cable.'),
        Key('offset', 'reading', '0', 'Reading at zero length.'),
        Key('gain', 'reading/m', '1', 'Reading per metre.'),
        Key('noise_std', 'm', '0', 'Length noise of the simulated sensor.'),
    )),
    Block('sensor point', 'One attachment point of a sensor.', (
        Key('frame', '', _R, 'Frame index (or `vertebra`).'),
        Key('vertebra', '', _R, 'Vertebra index (or `frame`).'),
        Key('offset', 'm', '[0, 0, 0]', 'The point in the frame.'),
    )),
    Block('load', 'An external load at a frame origin (docs/loads.md): a wrench or a mass.', (
        Key('name', '', _R, 'Load name (topics, `--load`).'),
        Key('frame', '', _R, 'Frame index (1..n) or `tip` (or `vertebra`).'),
        Key('vertebra', '', _R, 'Vertebra index (or `frame`).'),
        Key('force', 'N', '[0, 0, 0]', 'Force.'),
        Key('torque', 'N*m', '[0, 0, 0]', 'Torque.'),
        Key('in', '', 'base', '`base`: dead, `base_frame` axes; `local`: turns with the frame.'),
        Key('mass', 'kg', 'none', 'A mass under the scene gravity (instead of a wrench).'),
    )),
    Block('obstacle', 'A solid the simulated arm touches (frictionless penalty); the inverse '
          'does not know it.', (
              Key('name', '', _R, 'Obstacle name (unique).'),
              Key('type', '', _R, '`plane` (the half-space below the xy plane of its pose), '
                  '`sphere`, `box`, `capsule` or `cylinder` (axis z, centred on the pose).'),
              Key('pose', '', 'identity', 'Its frame in `base_frame`: `pose`.'),
              Key('radius', 'm', _R, 'Sphere, capsule, cylinder.'),
              Key('length', 'm', _R, 'Capsule (segment), cylinder (between its caps).'),
              Key('size', 'm', _R, 'Box edges `[x, y, z]`.'),
          )),
    Block('pose', 'Pose of an obstacle in `base_frame`.', (
        Key('position', 'm', '[0, 0, 0]', 'Translation.'),
        Key('rpy', 'rad', '[0, 0, 0]', 'Roll, pitch, yaw (fixed axes x, y, z).'),
    )),
    Block('collision', "The robot's collision spheres, centred at frame origins.", (
        Key('radius', 'm', "the chain's", "Sphere radius (default: a beam's `outer_radius`, "
            "a segment's cavities)."),
        Key('per', '', 'frame', '`frame` (every frame) or `vertebra` (only the vertebrae).'),
    )),
    Block('calibration', 'Identified corrections (`cbha_identify`).', (
        Key('section_stiffness', '', 'none', "`{section: factor}` on a section's stiffness."),
        Key('actuator_gain', '', 'none', '`{actuator: factor}`: cavity area, cable force.'),
        Key('tip_payload_mass', 'kg', '0', 'A mass load at the last frame.'),
        Key('base_offset', 'm, rad', 'none', 'The chain base in `base_frame`: `base_offset`.'),
    )),
    Block('base_offset', 'Pose of the chain base (frame 0) in `base_frame`.', (
        Key('position', 'm', '[0, 0, 0]', 'Translation.'),
        Key('rpy', 'rad', '[0, 0, 0]', 'Roll, pitch, yaw (fixed axes x, y, z).'),
    )),
)}
"""Every block of a scene file, by the name the page and the loader's checks use."""


def keys(block):
    """
    Return the keys a block accepts.

    Parameters
    ----------
    block : str
        A key of :data:`BLOCKS`, or ``'solver'`` (the fields of ``InverseOptions``).

    Returns
    -------
    tuple of str

    """
    if block == 'solver':
        from cbha_inverse.core.inverse.results import InverseOptions
        return tuple(field.name for field in fields(InverseOptions))
    return tuple(key.name for key in BLOCKS[block].keys)


_CONVENTIONS = """\
## Conventions

- SI units throughout: m, kg, s, N, Pa, rad, except the angles named `*_deg` (degrees).
- The backbone runs along +x of every frame at rest; frame 0 (the base, vertebra 0) sits at the
  origin of `base_frame` (or at `calibration.base_offset`); targets and gravity are in
  `base_frame` axes.
- Vertebra `v` of a `beam_vertebrae` chain is frame `v * beams_per_interval` (summed over
  sections); in a `segments` chain every frame is a vertebra. `frame: tip` is the last frame.
- Actuator order (the columns of commands, bounds and logs): `actuator_order`, else the cables
  in file order, then the cavities.
- A hole at `angle_deg` and `radius` sits at `[0, radius cos(angle), radius sin(angle)]` in its
  vertebra's frame: angle 0 along +y, positive toward +z, right-handed about +x (the backbone,
  pointing out of the page):

```text
              +z   angle_deg = 90
               ^
               |
  180 ---------x--------> +y   angle_deg = 0
               |          (x: the backbone, out of the page)
               |
              270
```
"""


def markdown():
    """Return the reference page of the scene file (``docs/scene-schema.md``)."""
    from cbha_inverse.core.inverse.results import InverseOptions
    lines = ['# Scene file reference', '',
             'Every key of a scene YAML (`config/scenes/*.yaml`, `load_scene`), block by block. A',
             'key that is not listed is refused with the nearest name. This page is generated '
             'from',
             "the loader's own declaration (`cbha_scene schema > docs/scene-schema.md`).",
             'A guide with examples: [own-robot.md](own-robot.md).', '', _CONVENTIONS]
    for block in BLOCKS.values():
        lines += [f'## `{block.path}`', '', block.summary, '',
                  '| key | unit | default | meaning |', '|---|---|---|---|']
        lines += [f'| `{key.name}` | {key.unit} | {key.default or "required"} | {key.meaning} |'
                  for key in block.keys]
        lines.append('')
    lines += ['## `solver`', '',
              'Defaults of the inverse solver for this scene (node parameters override them):',
              'the fields of `InverseOptions` (`cbha_inverse/core/inverse/results.py`).', '',
              '| key | unit | default | meaning |', '|---|---|---|---|']
    documented = _attributes(InverseOptions.__doc__)
    for field in fields(InverseOptions):
        unit, meaning = documented.get(field.name, ('', ''))
        lines.append(f'| `{field.name}` | {unit} | {field.default} | {meaning} |')
    return '\n'.join(lines) + '\n'


def _attributes(docstring):
    """Return the unit and first sentence of each attribute of a numpydoc docstring, by name."""
    found, units, name = {}, {}, None
    for line in docstring.splitlines():
        head = re.match(r'^    (\w+) : (.*)$', line)
        if head:
            name = head.group(1)
            found[name] = ''
            unit = re.search(r'\[(.*?)\]', head.group(2))
            units[name] = unit.group(1) if unit else ''
        elif name is not None and line.startswith('        '):
            found[name] = (found[name] + ' ' + line.strip()).strip()
        elif line.strip():
            name = None
    return {key: (units[key], _plain(value.split('. ')[0].rstrip('.')) + '.')
            for key, value in found.items()}


def _plain(text):
    """Return reStructuredText as Markdown: roles and double backticks to code spans."""
    text = re.sub(r':\w+:`~?(?:[\w.]+\.)?(\w+)`', r'`\1`', text)
    return text.replace('``', '`').replace('|', '/')
