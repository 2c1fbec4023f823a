"""
Fit a scene's calibration to quasi-static samples through its forward model.

Parameters ``θ`` are the logarithms of the calibration factors (per section stiffness, per
cavity gain: positive by construction, relative steps). For each ``θ`` the scene is loaded with
that calibration (:func:`cbha_inverse.scene.load_scene`, the one builder) and every sample's tip
is predicted by ``scene.forward`` (warm-started from the previous prediction of that sample).
``scipy.optimize.least_squares`` minimises the robust (``soft_l1``) sum of squared tip errors
with finite-difference Jacobians, plus a Gaussian prior on ``θ`` (each factor within ``×/÷
exp(prior_sigma)`` of the nominal scene at one standard deviation: the nominal model is a
model of this arm), so that what the data cannot see stays at the nominal value instead of
drifting along a flat valley of the cost. Standard errors come from the posterior covariance
``σ² (JᵀJ + σ²/σₚ² I)⁻¹`` at the solution (``σ`` from the residuals; without a prior
``σ² (JᵀJ)⁻¹``). A parameter whose relative standard error exceeds ``max_relative_error``, one
that the prior rather than the data determines, and a group of parameters correlated beyond
``max_correlation`` (only their combination is seen), are reported as warnings.
"""

from dataclasses import dataclass

from cbha_inverse.identify.samples import IdentificationError
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.calibration import Calibration
import numpy as np
from scipy.optimize import least_squares


@dataclass(frozen=True)
class Identification:
    """
    The result of a fit.

    Attributes
    ----------
    names : tuple of str
        Parameter names (``section_stiffness.<section>``, ``actuator_gain.<cavity>``).
    values : (p,) ndarray  [-]
        Fitted factors (on top of the scene's own calibration).
    standard_errors : (p,) ndarray  [-]
        Their standard errors.
    correlation : (p, p) ndarray  [-]
        Correlation matrix of the estimates.
    rms_before, rms_after : float  [m]
        Tip error RMS (norm per sample) with the nominal and the fitted calibration.
    predicted_before, predicted_after : (N, 3) ndarray  [m]
        Predicted tips.
    noise : float  [m]
        Residual standard deviation per axis at the solution.
    warnings : tuple of str
        Identifiability warnings (empty: every parameter is separable).
    evaluations : int
        Forward-model evaluations of the whole sample set.
    calibration : cbha_inverse.scene.calibration.Calibration
        The scene's calibration with the fit applied (what the identified scene carries).
    prior_sigma : float or None  [-]
        The prior's standard deviation on each log factor (None: no prior).
    directions : (p, p) ndarray  [-]
        Columns: the principal combinations of the log factors (eigenvectors of the data's
        information ``JᵀJ / σ²``), the least determined first.
    data_share : (p,) ndarray  [-]
        Share of the information along each direction that comes from the data,
        ``λ σₚ² / (1 + λ σₚ²)`` for the information eigenvalue ``λ`` (1: the data alone, 0: the
        prior alone; without a prior, ones).

    """

    names: tuple
    values: np.ndarray
    standard_errors: np.ndarray
    correlation: np.ndarray
    rms_before: float
    rms_after: float
    predicted_before: np.ndarray
    predicted_after: np.ndarray
    noise: float
    warnings: tuple
    evaluations: int
    calibration: Calibration
    prior_sigma: object
    directions: np.ndarray
    data_share: np.ndarray


def parameter_names(scene):
    """Return the fitted parameters of a scene: its sections' stiffness, its cavities' gains."""
    cavities = [name for group in scene.actuators.groups
                if hasattr(group, 'cavities') for name in group.names]
    return (tuple(f'section_stiffness.{s}' for s in scene.section_names)
            + tuple(f'actuator_gain.{c}' for c in cavities))


def calibration_of(names, factors):
    """Return the :class:`Calibration` of named factors."""
    tables = {'section_stiffness': {}, 'actuator_gain': {}}
    for name, value in zip(names, factors):
        kind, item = name.split('.', 1)
        tables[kind][item] = float(value)
    return Calibration(tables['section_stiffness'], tables['actuator_gain'])


class TipPredictor:
    """
    Predicted tips of the samples for calibration factors (the fit's model).

    Parameters
    ----------
    scene_path : str or os.PathLike
        The nominal scene.
    names : sequence of str
        Parameter names (:func:`parameter_names`).
    pressures : (N, m) ndarray  [Pa]
        Sample pressures in the scene's actuator order.
    progress : callable, optional
        Called with a line of text after each evaluation.

    """

    def __init__(self, scene_path, names, pressures, progress=None):
        self.scene_path = scene_path
        self.names = tuple(names)
        self.pressures = np.asarray(pressures, dtype=float)
        self.progress = progress
        self.evaluations = 0
        self._states = [None] * len(self.pressures)

    def __call__(self, factors):
        """Return the (N, 3) predicted tips [m] for the factors (p,)."""
        scene = load_scene(self.scene_path, calibration=calibration_of(self.names, factors))
        tips = np.empty((len(self.pressures), 3))
        for i, pressure in enumerate(self.pressures):
            result = scene.forward(np.clip(pressure, scene.lower_bounds, scene.upper_bounds),
                                   initial_state=self._states[i])
            if not result.converged:
                result = scene.forward(np.clip(pressure, scene.lower_bounds,
                                               scene.upper_bounds))
            if not result.converged:
                raise IdentificationError(f'the forward model does not converge at sample {i} '
                                          f'for factors {np.round(factors, 4).tolist()}')
            self._states[i] = result.state
            tips[i] = result.effector_positions[-1]
        self.evaluations += 1
        return tips


def identify(scene_path, pressures, tips, *, prior_sigma=0.5, max_relative_error=0.1,
             max_correlation=0.98, noise_scale=0.5e-3, progress=None, max_evaluations=40):
    """
    Fit per-section stiffness and per-cavity gain factors to measured tips.

    Parameters
    ----------
    scene_path : str or os.PathLike
        The nominal scene (its own calibration, if any, is the starting point).
    pressures : (N, m) ndarray  [Pa]
        Valve pressures of the samples, in the scene's actuator order.
    tips : (N, 3) ndarray  [m]
        Measured tips.
    prior_sigma : float or None  [-]
        Standard deviation of the Gaussian prior on each log factor (0.5: the arm within a
        factor ``exp(0.5) = 1.65`` of the nominal scene at one standard deviation). ``None``:
        no prior (plain least squares; directions the data does not see then drift).
    max_relative_error : float  [-]
        A factor with a larger relative standard error is flagged.
    max_correlation : float  [-]
        Factors correlated beyond this are flagged as a group.
    noise_scale : float  [m]
        Residual size beyond which the ``soft_l1`` loss down-weights a sample (outliers); also
        the first guess of the measurement noise that weighs the prior.
    progress : callable, optional
        Receives a line of text per evaluation.
    max_evaluations : int
        Budget of each least-squares pass (function evaluations, Jacobians not counted).

    Returns
    -------
    Identification

    Raises
    ------
    IdentificationError
        With fewer samples than parameters, or when the data does not determine every
        parameter (a zero or rank-deficient Jacobian: too little excitation; the prior does not
        hide that).
    ValueError
        On a ``prior_sigma`` that is not finite and positive.

    """
    if prior_sigma is not None and not (np.isfinite(prior_sigma) and prior_sigma > 0.0):
        raise ValueError(f'prior_sigma must be finite and > 0 (or None), got {prior_sigma}')
    nominal = load_scene(scene_path)
    names = parameter_names(nominal)
    pressures = np.asarray(pressures, dtype=float)
    tips = np.asarray(tips, dtype=float)
    if not names:
        raise IdentificationError(f'scene {nominal.name}: nothing to identify (no sections or '
                                  'cavities)')
    if len(tips) < len(names):
        raise IdentificationError(f'{len(tips)} quasi-static samples for {len(names)} '
                                  'parameters: record a longer session')
    predict = TipPredictor(scene_path, names, pressures)

    def data_residuals(theta):
        error = predict(np.exp(theta)) - tips
        if progress is not None:
            progress(f'  evaluation {predict.evaluations}: tip RMS '
                     f'{_rms(error) * 1e3:.3f} mm')
        return error.reshape(-1)

    theta = np.zeros(len(names))
    start = data_residuals(theta)
    before = start.reshape(-1, 3) + tips
    _check_excitation(names, _jacobian(predict, theta, tips, start))
    # the prior weighs like sigma_noise / prior_sigma against a tip residual; the noise is
    # known only after a fit: guess, fit, and refit once if the residuals say otherwise
    noise_weight, converged = noise_scale, True
    for _ in range(3):
        weight = 0.0 if prior_sigma is None else noise_weight / prior_sigma
        solution = least_squares(
            lambda t: np.concatenate([data_residuals(t), weight * t]), theta, loss='soft_l1',
            f_scale=noise_scale, diff_step=1e-4, x_scale=0.1, max_nfev=max_evaluations)
        theta, converged = solution.x, solution.status > 0
        fun = solution.fun[:tips.size]
        sigma = float(np.sqrt(np.sum(fun ** 2) / max(tips.size - len(names), 1)))
        if prior_sigma is None or abs(sigma / noise_weight - 1.0) < 0.25:
            break
        noise_weight = sigma
    jacobian = _jacobian(predict, theta, tips, fun)
    _check_excitation(names, jacobian)
    covariance = _posterior_covariance(jacobian, sigma, prior_sigma)
    se_theta = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    correlation = covariance / np.outer(se_theta, se_theta)
    directions, data_share = _principal_directions(jacobian, sigma, prior_sigma)
    values = np.exp(theta)
    standard_errors = values * se_theta
    warnings = [] if converged else [
        f'the solver stopped at its budget of {max_evaluations} evaluations before converging']
    warnings += _identifiability_warnings(names, values, standard_errors, correlation,
                                          directions, data_share, max_relative_error,
                                          max_correlation)
    after = fun.reshape(-1, 3) + tips
    fitted = calibration_of(names, values)
    return Identification(names, values, standard_errors, correlation, _rms(before - tips),
                          _rms(after - tips), before, after, sigma, tuple(warnings),
                          predict.evaluations, nominal.calibration.combined(fitted),
                          prior_sigma, directions, data_share)


def _posterior_covariance(jacobian, sigma, prior_sigma):
    """
    Return the covariance of ``θ``: ``σ² (JᵀJ + σ²/σₚ² I)⁻¹`` (``σ² (JᵀJ)⁺`` without prior).

    Parameters
    ----------
    jacobian : (n, p) ndarray  [m]
        Unweighted Jacobian of the tip residuals in ``θ``.
    sigma : float  [m]
        Residual standard deviation per axis.
    prior_sigma : float or None  [-]
        The prior's standard deviation on each ``θ``.

    Returns
    -------
    (p, p) ndarray  [-]

    """
    scale = np.linalg.norm(jacobian, axis=0)
    normal = (jacobian / scale).T @ (jacobian / scale)
    if prior_sigma is None:
        return np.linalg.pinv(normal) / np.outer(scale, scale) * sigma ** 2
    normal += np.diag((sigma / prior_sigma) ** 2 / scale ** 2)
    return np.linalg.inv(normal) / np.outer(scale, scale) * sigma ** 2


def _principal_directions(jacobian, sigma, prior_sigma):
    """
    Return the principal combinations of the log factors and the data's share along each.

    Parameters
    ----------
    jacobian : (n, p) ndarray  [m]
        Unweighted Jacobian of the tip residuals in ``θ``.
    sigma : float  [m]
        Residual standard deviation per axis.
    prior_sigma : float or None  [-]
        The prior's standard deviation on each ``θ``.

    Returns
    -------
    directions : (p, p) ndarray  [-]
        Unit eigenvectors (columns) of the information ``JᵀJ / σ²``, the smallest first.
    data_share : (p,) ndarray  [-]
        ``λ σₚ² / (1 + λ σₚ²)`` per direction (ones without a prior).

    """
    information, directions = np.linalg.eigh(jacobian.T @ jacobian / sigma ** 2)
    information = np.maximum(information, 0.0)
    if prior_sigma is None:
        return directions, np.ones(len(information))
    ratio = information * prior_sigma ** 2
    return directions, ratio / (1.0 + ratio)


def _identifiability_warnings(names, values, standard_errors, correlation, directions,
                              data_share, max_relative_error, max_correlation):
    """
    Return the warnings: loose factors, combinations the prior sets, correlated groups.

    A factor is flagged when its relative standard error exceeds ``max_relative_error``; a
    principal combination whose information comes less than half from the data is named (the
    prior, i.e. the nominal scene, sets it); factors linked by correlations beyond
    ``max_correlation`` form one group (connected components), reported once.
    """
    warnings = []
    for n, v, se in zip(names, values, standard_errors):
        if se > max_relative_error * v:
            warnings.append(f'{n} = {v:.4f} +- {se:.4f}: loosely determined (relative '
                            f'standard error {se / v:.0%} > {max_relative_error:.0%})')
    for share, direction in zip(data_share, directions.T):
        if share < 0.5:
            terms = ' '.join(f'{c:+.2f} log {n}' for c, n in zip(direction, names)
                             if abs(c) > 0.1)
            warnings.append(f'the combination {terms} is set mostly by the prior (the nominal '
                            f'scene): the data carries {share:.0%} of its information')
    linked = np.abs(correlation) > max_correlation
    group_of = list(range(len(names)))
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if linked[i, j]:
                old, new = group_of[j], group_of[i]
                group_of = [new if g == old else g for g in group_of]
    for g in sorted(set(group_of)):
        members = [n for n, k in zip(names, group_of) if k == g]
        if len(members) > 1:
            warnings.append(f'{", ".join(members)}: correlated beyond {max_correlation} (their '
                            'combination is seen, not each one: e.g. the gains relative to the '
                            'stiffness)')
    return warnings


def _check_excitation(names, jacobian, rank_tolerance=1e-6):
    """
    Refuse data that cannot determine every parameter (a zero or rank-deficient Jacobian).

    Raises
    ------
    IdentificationError
        Naming the parameters the data does not see, or those of the undetermined combination.

    """
    scale = np.linalg.norm(jacobian, axis=0)
    dead = [n for n, s in zip(names, scale) if not s > 1e-12]
    hint = ('; record a circle plus a pure extension (every tube pressurised alike, held a '
            'few seconds at a few levels)')
    if dead:
        raise IdentificationError('too little excitation: the data does not depend on '
                                  f'{", ".join(dead)}{hint}')
    _, singular, vt = np.linalg.svd(jacobian / scale, full_matrices=False)
    if singular[-1] < rank_tolerance * singular[0]:
        involved = [n for n, c in zip(names, vt[-1]) if abs(c) > 0.2]
        raise IdentificationError('too little excitation: only combinations of '
                                  f'{", ".join(involved)} are seen (Jacobian rank '
                                  f'{int(np.sum(singular >= rank_tolerance * singular[0]))} of '
                                  f'{len(names)}){hint}')


def _jacobian(predict, theta, tips, residual, step=1e-4):
    """
    Return the forward-difference Jacobian of the plain tip residuals in ``θ``.

    ``least_squares`` returns the Jacobian weighted by the robust loss; the standard errors
    need the unweighted one.
    """
    columns = []
    for k in range(len(theta)):
        shifted = np.array(theta, dtype=float)
        shifted[k] += step
        columns.append(((predict(np.exp(shifted)) - tips).reshape(-1) - residual) / step)
    return np.stack(columns, axis=1)


def _rms(error):
    """Return the RMS of the per-sample error norms [m]."""
    error = np.asarray(error, dtype=float).reshape(-1, 3)
    return float(np.sqrt(np.mean(np.sum(error ** 2, axis=1))))
