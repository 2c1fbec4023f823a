"""
Calibrate the string potentiometers against the identified model (``docs/identify.md``).

A pot's raw reading is ``r = offset + gain * L(q)``
(:class:`cbha_inverse.core.sensors.StringPots`), ``L`` the routed length of the pot along the
backbone ``q``. At each quasi-static sample of a session that had a tip reference, ``q`` is the
identified model's equilibrium under the sample's pressures
(:class:`cbha_inverse.identify.fit.TipPredictor` with the fitted values): the model is fitted
first, to the tips alone, then the pots against it (``docs/identify.md`` says why). Given ``q``,
``(offset, gain)`` of each pot is a linear least-squares fit of its readings on ``[1, L]``; its
covariance is that of the regression, ``σ² (AᵀA)⁻¹`` (``σ`` from the residuals), plus the
model's uncertainty carried through the lengths: with ``J = dL/dp`` over the samples (finite
differences in the fitted values ``p``, covariance ``Σ``), ``G = -gain (AᵀA)⁻¹ AᵀJ`` adds
``G Σ Gᵀ``.

A pot whose length moves by less than ``min_range`` over the samples cannot separate its gain
from its offset: its gain stays the scene's (the prior) and only its offset is fitted (flagged).
A reading that follows another pot's routed length much better than its own (residual below
half, its own well above the noise) means the pot order is wrong (the driver's
``string_pot_names`` or the scene's ``sensors`` block): the calibration is refused.
"""

from dataclasses import dataclass

from cbha_inverse.identify.fit import TipPredictor
from cbha_inverse.identify.samples import IdentificationError
from cbha_inverse.scene import load_scene
import numpy as np


@dataclass(frozen=True)
class PotCalibration:
    """
    The fitted calibration of a scene's string pots.

    Attributes
    ----------
    names : tuple of str
        The scene's sensor names (``c``).
    offsets, gains : (c,) ndarray  [reading, reading / m]
        Fitted offset and gain of each pot (a gain not fitted is the scene's).
    offset_errors, gain_errors : (c,) ndarray  [reading, reading / m]
        Their standard errors (gain 0 where it was not fitted).
    correlations : (c,) ndarray  [-]
        Correlation of each pot's offset and gain estimates (0 where the gain was not fitted).
    gain_fitted : (c,) bool ndarray
        False where the lengths moved too little (the scene's gain kept).
    prior_offsets, prior_gains : (c,) ndarray  [reading, reading / m]
        The scene's calibration.
    length_ranges : (c,) ndarray  [m]
        Range of each pot's routed length over the samples.
    residuals : (c,) ndarray  [m]
        RMS of the reading residuals after the fit, in length (reading / gain).
    samples : int
        Samples with readings of every pot.
    warnings : tuple of str
        Pots not excited enough, loosely determined gains, residuals far above the noise.

    """

    names: tuple
    offsets: np.ndarray
    gains: np.ndarray
    offset_errors: np.ndarray
    gain_errors: np.ndarray
    correlations: np.ndarray
    gain_fitted: np.ndarray
    prior_offsets: np.ndarray
    prior_gains: np.ndarray
    length_ranges: np.ndarray
    residuals: np.ndarray
    samples: int
    warnings: tuple


def reading_columns(scene_names, reading_names):
    """
    Return, per scene pot, its column in the recorded readings (matched by name).

    Parameters
    ----------
    scene_names : sequence of str
        The scene's sensor names.
    reading_names : sequence of str
        The names of the recorded ``string_pots`` messages.

    Returns
    -------
    (c,) int ndarray

    Raises
    ------
    IdentificationError
        When the recording lacks a scene pot.

    """
    reading_names = list(reading_names)
    missing = [n for n in scene_names if n not in reading_names]
    if missing:
        raise IdentificationError(f'string_pots names {reading_names} lack the scene pots '
                                  f'{missing}: record them under the scene sensor names '
                                  '(robotino_bridge string_pot_names)')
    return np.array([reading_names.index(n) for n in scene_names], dtype=int)


def sample_lengths(scene_path, names, values, pressures, step=1e-4):
    """
    Return the routed pot lengths at the samples and their derivatives in the fitted values.

    Parameters
    ----------
    scene_path : str or os.PathLike
        The nominal scene (with a ``sensors`` block).
    names : sequence of str
        Fitted parameter names (:func:`cbha_inverse.identify.fit.parameter_names`).
    values : (p,) array_like  [-, m or s]
        Their fitted values.
    pressures : (N, m) ndarray or callable  [Pa]
        The samples' pressures (as :class:`~cbha_inverse.identify.fit.TipPredictor` takes them).
    step : float  [-]
        Relative finite-difference step of each value (of the value's size, at least 1e-2 of
        its unit: 1e-6 m or s for a base offset or a delay near 0).

    Returns
    -------
    lengths : (N, c) ndarray  [m]
    derivatives : (N, c, p) ndarray  [m per unit of each value]

    """
    values = np.asarray(values, dtype=float)
    predict = TipPredictor(scene_path, names, pressures, sensor_lengths=True)
    predict(values)
    lengths = predict.lengths.copy()
    derivatives = np.empty(lengths.shape + (len(values),))
    for k in range(len(values)):
        h = step * max(abs(values[k]), 1e-2)
        shifted = values.copy()
        shifted[k] += h
        predict(shifted)
        derivatives[:, :, k] = (predict.lengths - lengths) / h
    return lengths, derivatives


def calibrate_pots(scene_path, names, values, covariance, pressures, readings, reading_names,
                   *, min_range=2e-3, max_relative_error=0.1, residual_sigmas=5.0):
    """
    Fit each string pot's offset and gain to its readings along the identified model's backbone.

    Parameters
    ----------
    scene_path : str or os.PathLike
        The nominal scene (with a ``sensors`` block).
    names : sequence of str
        Fitted model parameter names.
    values : (p,) array_like
        Their fitted values (the model the pots are calibrated against).
    covariance : (p, p) array_like
        Their covariance (carried into the pots' standard errors).
    pressures : (N, m) ndarray or callable  [Pa]
        The samples' pressures (scene actuator order), or a function of the latency.
    readings : (N, k) array_like  [reading]
        Raw readings at the samples (NaN rows: not recorded; they are left out).
    reading_names : sequence of str
        The names of the ``k`` recorded columns.
    min_range : float  [m]
        A pot whose length moves less over the samples keeps the scene's gain.
    max_relative_error : float  [-]
        A fitted gain with a larger relative standard error is flagged.
    residual_sigmas : float  [-]
        A residual RMS above this many ``noise_std`` of the pot is flagged.

    Returns
    -------
    PotCalibration

    Raises
    ------
    IdentificationError
        Without sensors in the scene, with a scene pot not recorded, with fewer than 3 samples
        that have every reading, or when readings follow other pots' lengths (pot order).

    """
    scene = load_scene(scene_path)
    pots = scene.sensors
    if pots is None:
        raise IdentificationError(f'scene {scene.name} declares no sensors: nothing to '
                                  'calibrate the string_pots against')
    columns = reading_columns(pots.names, reading_names)
    readings = np.asarray(readings, dtype=float)[:, columns]
    rows = np.all(np.isfinite(readings), axis=1)
    if rows.sum() < 3:
        raise IdentificationError(f'{int(rows.sum())} quasi-static samples with every '
                                  'string-pot reading: record the pots with the tips')
    readings = readings[rows]
    subset = ((lambda latency: np.asarray(pressures(latency))[rows]) if callable(pressures)
              else np.asarray(pressures, dtype=float)[rows])
    lengths, derivatives = sample_lengths(scene_path, names, values, subset)
    _check_order(pots, lengths, readings)
    covariance = np.asarray(covariance, dtype=float)
    c = pots.n_sensors
    fit = {key: np.zeros(c) for key in ('offset', 'gain', 'offset_error', 'gain_error',
                                        'correlation', 'residual')}
    fitted = np.ptp(lengths, axis=0) >= min_range
    warnings = []
    for i, name in enumerate(pots.names):
        gain = pots.reading_gain[i] if not fitted[i] else None
        beta, cov, residual = _affine_fit(lengths[:, i], readings[:, i], derivatives[:, i],
                                          covariance, gain)
        fit['offset'][i], fit['offset_error'][i] = beta[0], np.sqrt(cov[0, 0])
        fit['gain'][i] = beta[1]
        if fitted[i]:
            fit['gain_error'][i] = np.sqrt(cov[1, 1])
            fit['correlation'][i] = cov[0, 1] / np.sqrt(cov[0, 0] * cov[1, 1])
        fit['residual'][i] = residual / abs(beta[1])
        span = np.ptp(lengths[:, i])
        if not fitted[i]:
            warnings.append(f'{name}: its length moves by {span * 1e3:.2f} mm only (< '
                            f"{min_range * 1e3:g} mm): gain kept at the scene's "
                            f'{beta[1]:g}, offset fitted; record a lap that bends its section')
        elif fit['gain_error'][i] > max_relative_error * abs(beta[1]):
            warnings.append(f'{name}: gain {beta[1]:.4g} +- {fit["gain_error"][i]:.3g}: loosely '
                            f'determined (relative standard error > {max_relative_error:.0%})')
        if fit['residual'][i] > residual_sigmas * pots.noise_std[i]:
            warnings.append(f'{name}: residual {fit["residual"][i] * 1e3:.3f} mm RMS, more than '
                            f'{residual_sigmas:g} noise_std ({pots.noise_std[i] * 1e3:g} mm): '
                            'the model or the routing does not explain its readings')
    return PotCalibration(pots.names, fit['offset'], fit['gain'], fit['offset_error'],
                          fit['gain_error'], fit['correlation'], fitted,
                          pots.reading_offset.copy(), pots.reading_gain.copy(),
                          np.ptp(lengths, axis=0), fit['residual'], int(rows.sum()),
                          tuple(warnings))


def _affine_fit(lengths, readings, derivatives, covariance, gain=None):
    """
    Fit ``readings = offset + gain * lengths`` (the gain given: the offset alone).

    Parameters
    ----------
    lengths : (N,) ndarray  [m]
        Routed lengths at the samples.
    readings : (N,) ndarray  [reading]
        The pot's readings there.
    derivatives : (N, p) ndarray
        ``dL/dp`` of the lengths in the model's fitted values.
    covariance : (p, p) ndarray
        Covariance of those values.
    gain : float, optional
        A gain to keep.

    Returns
    -------
    beta : (2,) ndarray  [reading, reading / m]
        Offset and gain.
    covariance : (2, 2) ndarray
        Of ``beta`` (zero row and column of the gain when it was kept).
    residual : float  [reading]
        RMS of the residuals.

    """
    n = len(lengths)
    design = np.stack([np.ones(n), lengths], axis=1)
    if gain is not None:
        design = design[:, :1]
        target = readings - gain * lengths
    else:
        target = readings
    solution = np.linalg.lstsq(design, target, rcond=None)[0]
    residuals = target - design @ solution
    dof = max(n - design.shape[1], 1)
    sigma2 = float(residuals @ residuals) / dof
    normal_inverse = np.linalg.inv(design.T @ design)
    slope = solution[1] if gain is None else gain
    # the lengths move with the model's values: d(solution) = -(AᵀA)⁻¹ Aᵀ slope dL
    carried = -slope * normal_inverse @ design.T @ derivatives
    beta_cov = sigma2 * normal_inverse + carried @ covariance @ carried.T
    beta = np.array([solution[0], slope])
    full = np.zeros((2, 2))
    full[:design.shape[1], :design.shape[1]] = beta_cov
    return beta, full, float(np.sqrt(np.mean(residuals ** 2)))


def _check_order(pots, lengths, readings, better=0.5, noise_sigmas=3.0):
    """
    Refuse readings that follow another pot's routed length much better than their own.

    Parameters
    ----------
    pots : cbha_inverse.core.sensors.StringPots
        The scene's pots (names, noise).
    lengths : (N, c) ndarray  [m]
        Routed lengths at the samples.
    readings : (N, c) ndarray  [reading]
        Readings in the scene's pot order (by name).
    better : float  [-]
        Another pot explains a reading when its residual is below this share of the own one.
    noise_sigmas : float  [-]
        ... and the own residual exceeds this many noise standard deviations.

    Raises
    ------
    IdentificationError
        Naming each pot and the one whose length its readings follow.

    """
    c = pots.n_sensors
    residual = np.empty((c, c))
    for i in range(c):
        for j in range(c):
            design = np.stack([np.ones(len(lengths)), lengths[:, j]], axis=1)
            fitted = design @ np.linalg.lstsq(design, readings[:, i], rcond=None)[0]
            residual[i, j] = np.sqrt(np.mean((readings[:, i] - fitted) ** 2))
    swapped = []
    for i in range(c):
        j = int(np.argmin(residual[i]))
        own_noise = noise_sigmas * pots.noise_std[i] * abs(pots.reading_gain[i])
        if j != i and residual[i, j] < better * residual[i, i] and residual[i, i] > own_noise:
            swapped.append(f'{pots.names[i]} follows the length of {pots.names[j]} (residual '
                           f'{residual[i, j]:.3g} against {residual[i, i]:.3g} on its own)')
    if swapped:
        raise IdentificationError('string-pot readings that follow another pot: '
                                  f'{"; ".join(swapped)}: the pot order is wrong (the driver\'s '
                                  "string_pot_names or the scene's sensors block)")


def report_lines(pots):
    """Return the text report's lines of a pot calibration."""
    lines = ['', f'string pots (reading = offset + gain * routed length along the identified '
             f'model; {pots.samples} samples): fitted +- standard error (scene value), length '
             'range over the samples, residual RMS in length:']
    for i, name in enumerate(pots.names):
        gain = (f'gain {pots.gains[i]:.5g} +- {pots.gain_errors[i]:.3g}' if pots.gain_fitted[i]
                else f'gain {pots.gains[i]:.5g} (kept)')
        lines.append(f'  {name:28s} offset {pots.offsets[i]:.5g} +- {pots.offset_errors[i]:.3g} '
                     f'({pots.prior_offsets[i]:g}), {gain} ({pots.prior_gains[i]:g}), '
                     f'correlation {pots.correlations[i]:+.3f}, range '
                     f'{pots.length_ranges[i] * 1e3:.2f} mm, residual '
                     f'{pots.residuals[i] * 1e3:.3f} mm')
    lines += ['string-pot warnings:' if pots.warnings else
              'string pots: every gain is determined by this data']
    lines += [f'  {w}' for w in pots.warnings]
    return lines


def pot_data(pots):
    """Return a pot calibration as plain data (the ``string_pots`` entry of the JSON file)."""
    return {'samples': pots.samples, 'warnings': list(pots.warnings), 'pots': {
        name: {'offset': float(pots.offsets[i]), 'offset_standard_error':
               float(pots.offset_errors[i]), 'gain': float(pots.gains[i]),
               'gain_standard_error': float(pots.gain_errors[i]),
               'gain_fitted': bool(pots.gain_fitted[i]),
               'offset_gain_correlation': float(pots.correlations[i]),
               'prior_offset': float(pots.prior_offsets[i]),
               'prior_gain': float(pots.prior_gains[i]),
               'length_range_m': float(pots.length_ranges[i]),
               'residual_m': float(pots.residuals[i])}
        for i, name in enumerate(pots.names)}}


def calibrated_sensor_items(items, pots):
    """
    Return a scene file's ``sensors`` items with the fitted offsets and gains (by name).

    Parameters
    ----------
    items : list of dict
        The ``sensors`` block as read from the scene file.
    pots : PotCalibration
        The fit.

    Returns
    -------
    list of dict
        Copies; items of sensors the fit does not name are unchanged.

    """
    fitted = {n: (float(o), float(g)) for n, o, g in zip(pots.names, pots.offsets, pots.gains)}
    out = []
    for item in items:
        item = dict(item)
        if item.get('name') in fitted:
            item['offset'], item['gain'] = fitted[item['name']]
        out.append(item)
    return out
