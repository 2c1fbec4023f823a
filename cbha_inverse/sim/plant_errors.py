"""
The deliberate model errors of the simulated plant, as a scene calibration (no ROS).

``cbha_sim`` must not share the controller's model: on top of a global ``stiffness_scale`` its
plant has per-section stiffness errors, per-cavity effective-area errors and a base offset (the
registration error a tracker measures the tip with). :func:`plant_errors` turns those node
parameters into a :class:`cbha_inverse.scene.calibration.Calibration` that
:func:`cbha_inverse.scene.load_scene` applies like an identified one.
"""

from cbha_inverse.scene.calibration import Calibration, check_factor, finite_triple


def _per_name(label, names, scales):
    """Return ``{name: factor}`` of the factors that differ from 1 (one value: every name)."""
    values = [float(v) for v in scales]
    if len(values) == 1 and (names or values[0] == 1.0):
        values = values * len(names)
    if len(values) != len(names):
        raise ValueError(f'{label} needs 1 or {len(names)} values ({list(names)}), got '
                         f'{len(scales)}')
    return {name: check_factor(label, value) for name, value in zip(names, values)
            if value != 1.0}


def plant_errors(section_names, valve_names, section_scales, gain_scales,
                 base_offset=(0.0, 0.0, 0.0)):
    """
    Turn the per-section and per-valve error parameters into a scene calibration.

    Parameters
    ----------
    section_names : sequence of str
        The scene's chain sections, in order.
    valve_names : sequence of str
        The command order.
    section_scales : sequence of float  [-]
        One stiffness factor per section, or one for all.
    gain_scales : sequence of float  [-]
        One effective-area factor per valve (cavity), or one for all.
    base_offset : (3,) sequence of float  [m]
        Position of the plant's chain base in ``base_frame``.

    Returns
    -------
    cbha_inverse.scene.calibration.Calibration
        Only the factors that differ from 1 (a scene without sections or cavities accepts ones).

    Raises
    ------
    ValueError
        On a wrong count, a factor that is not finite and positive, or an offset that is not 3
        finite numbers (the message names the parameter).

    """
    return Calibration(_per_name('section_stiffness_scale', section_names, section_scales),
                       _per_name('cavity_gain_scale', valve_names, gain_scales),
                       base_position=finite_triple('base_offset', base_offset))
