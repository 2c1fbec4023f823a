"""
Fit a scene's calibration to quasi-static samples through its forward model.

The fitted parameters are named (:func:`parameter_names`): per-section stiffness and
per-actuator (cavity or cable) gain factors, optionally the position of the chain's base in
``base_frame`` (``base_position.x|y|z``: a tracker registration error) and the command ->
valve ``latency`` (when the sample pressures are given as a function of it). The fit works in
coordinates ``θ`` of similar size: the logarithm of each factor (positive by construction,
relative steps), the base position in steps of :data:`POSITION_STEP` and the latency in steps of
:data:`LATENCY_STEP` from its starting value. For each ``θ`` the scene is loaded with that
calibration (:func:`cbha_inverse.scene.load_scene`, the one builder) and every sample's tip is
predicted by ``scene.forward`` (warm-started from the previous prediction of that sample).
``scipy.optimize.least_squares`` minimises the robust (``soft_l1``) sum of squared tip errors
with finite-difference Jacobians, plus a Gaussian prior on ``θ`` around the nominal scene
(each factor within ``×/÷ exp(prior_sigma)`` at one standard deviation: the nominal model is
a model of this arm), so that what the data cannot see stays at the nominal value instead of
drifting along a flat valley of the cost. Standard errors come from the posterior covariance
``σ² (JᵀJ + σ² Σₚ⁻¹)⁻¹`` at the solution (``σ`` from the residuals; without a prior
``σ² (JᵀJ)⁺``). A parameter whose relative standard error exceeds ``max_relative_error``, a
combination that the prior rather than the data determines, and a group of parameters
correlated beyond ``max_correlation`` (only their combination is seen), are reported as
warnings.
"""

from dataclasses import dataclass

from cbha_inverse.identify.samples import IdentificationError
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.calibration import Calibration
import numpy as np
from scipy.optimize import least_squares

FACTOR_KINDS = ('section_stiffness', 'actuator_gain')
POSITION_STEP = 0.01
"""Base position per fit coordinate [m]."""
LATENCY_STEP = 0.005
"""Latency per fit coordinate [s]."""
_AXES = 'xyz'


@dataclass(frozen=True)
class Identification:
    """
    The result of a fit.

    Attributes
    ----------
    names : tuple of str
        Parameter names (:func:`parameter_names`).
    values : (p,) ndarray  [-, m or s]
        Fitted values: factors (on top of the scene's own calibration), base position [m],
        latency [s].
    standard_errors : (p,) ndarray  [-, m or s]
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
    prior_sigmas : (p,) ndarray  [-, m or s]
        The prior's standard deviation of each parameter (``inf``: no prior).
    directions : (p, p) ndarray  [-]
        Columns: the principal combinations of the fit coordinates ``θ`` scaled by their prior
        (eigenvectors of the data's information), the least determined first.
    data_share : (p,) ndarray  [-]
        Share of the information along each direction that comes from the data (1: the data
        alone, 0: the prior alone; ones without a prior).
    direction_errors : (p,) ndarray  [-]
        Posterior standard error along each direction (in the scaled coordinates).

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
    prior_sigmas: np.ndarray
    directions: np.ndarray
    data_share: np.ndarray
    direction_errors: np.ndarray

    def value(self, name):
        """Return the fitted value of a named parameter."""
        return float(self.values[self.names.index(name)])


def parameter_names(scene, *, base_position=False, latency=False):
    """
    Return the fitted parameters of a scene.

    Parameters
    ----------
    scene : cbha_inverse.scene.Scene
        The nominal scene.
    base_position : bool
        Add ``base_position.x|y|z`` (the chain base in ``base_frame``).
    latency : bool
        Add ``latency`` (command -> valve delay).

    Returns
    -------
    tuple of str
        ``section_stiffness.<section>`` per chain section, ``actuator_gain.<actuator>`` per
        actuator (a cavity's effective area, a cable's force per newton), then the optional
        ones.

    """
    return (tuple(f'section_stiffness.{s}' for s in scene.section_names)
            + tuple(f'actuator_gain.{a}' for a in scene.actuator_names)
            + (tuple(f'base_position.{a}' for a in _AXES) if base_position else ())
            + (('latency',) if latency else ()))


def _is_factor(name):
    """Whether a parameter is a positive factor (fitted in log space)."""
    return name.split('.', 1)[0] in FACTOR_KINDS


def _steps(names):
    """Return the size of one fit coordinate per parameter (0 for the log factors)."""
    return np.array([0.0 if _is_factor(n) else POSITION_STEP if n.startswith('base_position.')
                     else LATENCY_STEP for n in names])


def values_of(names, theta, start_latency=0.0):
    """
    Return the parameter values of fit coordinates ``θ``.

    Parameters
    ----------
    names : sequence of str
        Parameter names.
    theta : (p,) array_like  [-]
        Fit coordinates.
    start_latency : float  [s]
        The latency at ``θ = 0``.

    Returns
    -------
    (p,) ndarray  [-, m or s]

    """
    theta = np.asarray(theta, dtype=float)
    steps = _steps(names)
    offset = np.array([start_latency if n == 'latency' else 0.0 for n in names])
    return np.where(steps == 0.0, np.exp(theta), offset + steps * theta)


def calibration_of(names, values):
    """Return the :class:`Calibration` of named values (the latency is not part of it)."""
    tables = {kind: {} for kind in FACTOR_KINDS}
    position = [0.0, 0.0, 0.0]
    for name, value in zip(names, values):
        kind, _, item = name.partition('.')
        if kind in tables:
            tables[kind][item] = float(value)
        elif kind == 'base_position':
            position[_AXES.index(item)] = float(value)
    return Calibration(tables['section_stiffness'], tables['actuator_gain'],
                       base_position=tuple(position))


class TipPredictor:
    """
    Predicted tips of the samples for parameter values (the fit's model).

    Parameters
    ----------
    scene_path : str or os.PathLike
        The nominal scene.
    names : sequence of str
        Parameter names (:func:`parameter_names`).
    pressures : (N, m) ndarray or callable  [Pa]
        Sample pressures in the scene's actuator order, or a function of the latency [s]
        returning them (required when ``names`` has ``latency``).
    sensor_lengths : bool
        Also keep the routed length of each of the scene's sensors at every sample of the last
        evaluation (:attr:`lengths`, (N, c) [m]).

    """

    def __init__(self, scene_path, names, pressures, sensor_lengths=False):
        self.scene_path = scene_path
        self.names = tuple(names)
        self.pressures = pressures if callable(pressures) else np.asarray(pressures, float)
        if 'latency' in self.names and not callable(pressures):
            raise ValueError('fitting the latency needs the pressures as a function of it')
        self.evaluations = 0
        self.sensor_lengths = sensor_lengths
        self.lengths = None
        self._states = None

    def __call__(self, values):
        """Return the (N, 3) predicted tips [m] for the parameter values (p,)."""
        pressures = (np.asarray(self.pressures(values[self.names.index('latency')]), float)
                     if callable(self.pressures) else self.pressures)
        if pressures.ndim != 2 or not np.all(np.isfinite(pressures)):
            raise ValueError(f'the sample pressures must be a finite (N, m) array, got shape '
                             f'{pressures.shape}')
        scene = load_scene(self.scene_path, calibration=calibration_of(self.names, values))
        if self._states is None:
            self._states = [None] * len(pressures)
        tips = np.empty((len(pressures), 3))
        if self.sensor_lengths:
            self.lengths = np.empty((len(pressures), scene.sensors.n_sensors))
        for i, pressure in enumerate(pressures):
            # the fit reads the shape only: no check of the equilibrium's warnings
            result = scene.forward(np.clip(pressure, scene.lower_bounds, scene.upper_bounds),
                                   initial_state=self._states[i], check_warnings=False)
            if not result.converged:
                result = scene.forward(np.clip(pressure, scene.lower_bounds,
                                               scene.upper_bounds), check_warnings=False)
            if not result.converged:
                raise IdentificationError(f'the forward model does not converge at sample {i} '
                                          f'for {dict(zip(self.names, np.round(values, 4)))}')
            self._states[i] = result.state
            tips[i] = result.effector_positions[-1]
            if self.sensor_lengths:
                self.lengths[i] = scene.sensors.lengths(result.state.positions,
                                                        result.state.rotations)
        self.evaluations += 1
        return tips


def identify(scene_path, pressures, tips, *, prior_sigma=0.5, base_position=False,
             base_position_sigma=0.01, latency=None, latency_sigma=0.01,
             max_relative_error=0.1, max_correlation=0.98, noise_scale=0.5e-3, progress=None,
             max_evaluations=40):
    """
    Fit per-section stiffness and per-actuator gain factors (and optionally more) to measured tips.

    Parameters
    ----------
    scene_path : str or os.PathLike
        The nominal scene (its own calibration, if any, is the starting point).
    pressures : (N, m) ndarray or callable  [Pa]
        Valve pressures of the samples, in the scene's actuator order; or, to fit the latency,
        a function of the latency [s] returning them.
    tips : (N, 3) ndarray  [m]
        Measured tips.
    prior_sigma : float or None  [-]
        Standard deviation of the Gaussian prior on each log factor (0.5: the arm within a
        factor ``exp(0.5) = 1.65`` of the nominal scene at one standard deviation). ``None``:
        no prior (plain least squares; directions the data does not see then drift).
    base_position : bool
        Also fit the chain base's position in ``base_frame`` (a registration error of the
        tracker).
    base_position_sigma : float or None  [m]
        Prior standard deviation of each base coordinate (None: no prior).
    latency : float or None  [s]
        Starting value of the latency, fitted when given (``pressures`` must then be callable).
    latency_sigma : float or None  [s]
        Prior standard deviation of the latency around its starting value (None: no prior).
    max_relative_error : float  [-]
        A factor with a larger relative standard error is flagged.
    max_correlation : float  [-]
        Parameters correlated beyond this are flagged as a group.
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
        With fewer samples than parameters, or when the data does not determine every factor
        (a zero or rank-deficient Jacobian: too little excitation; the prior does not hide
        that).
    ValueError
        On tips or pressures of the wrong shape or not finite, a prior standard deviation that
        is not finite and positive, or a latency without callable pressures.

    """
    for label, value in (('prior_sigma', prior_sigma), ('base_position_sigma',
                                                        base_position_sigma),
                         ('latency_sigma', latency_sigma)):
        if value is not None and not (np.isfinite(value) and value > 0.0):
            raise ValueError(f'{label} must be finite and > 0 (or None), got {value}')
    if latency is not None and not (np.isfinite(latency) and latency >= 0.0):
        raise ValueError(f'latency must be finite and >= 0, got {latency}')
    nominal = load_scene(scene_path)
    names = parameter_names(nominal, base_position=base_position,
                            latency=latency is not None)
    tips = np.asarray(tips, dtype=float)
    if tips.ndim != 2 or tips.shape[1] != 3 or not np.all(np.isfinite(tips)):
        raise ValueError(f'tips must be a finite (N, 3) array, got shape {tips.shape}')
    if not callable(pressures):
        pressures = np.asarray(pressures, dtype=float)
        width = len(nominal.actuator_names)
        if pressures.shape != (len(tips), width) or not np.all(np.isfinite(pressures)):
            raise ValueError(f'pressures must be a finite ({len(tips)}, {width}) array (one row '
                             f'per tip, scene actuator order), got shape {pressures.shape}')
    if not any(_is_factor(n) for n in names):
        raise IdentificationError(f'scene {nominal.name}: nothing to identify (no sections or '
                                  'cavities)')
    if len(tips) < len(names):
        raise IdentificationError(f'{len(tips)} quasi-static samples for {len(names)} '
                                  'parameters: record a longer session')
    steps = _steps(names)
    fd_steps = np.array([1e-3 if n == 'latency' else 1e-4 for n in names])
    sigma_of = {'base_position': base_position_sigma, 'latency': latency_sigma}
    prior = np.array([(prior_sigma if _is_factor(n) else sigma_of[n.split('.')[0]]) or np.inf
                      for n in names], dtype=float)
    prior = np.where(steps == 0.0, prior, prior / np.where(steps == 0.0, 1.0, steps))
    start_latency = 0.0 if latency is None else float(latency)
    predict = TipPredictor(scene_path, names, pressures)

    def model(theta):
        return predict(values_of(names, theta, start_latency))

    def data_residuals(theta):
        error = model(theta) - tips
        if progress is not None:
            progress(f'  evaluation {predict.evaluations}: tip RMS '
                     f'{_rms(error) * 1e3:.3f} mm')
        return error.reshape(-1)

    theta = np.zeros(len(names))
    start = data_residuals(theta)
    before = start.reshape(-1, 3) + tips
    checked = np.array([_is_factor(n) or not np.isfinite(p) for n, p in zip(names, prior)])
    _check_excitation(names, _jacobian(model, theta, tips, start, fd_steps), checked)
    # the prior weighs like sigma_noise / prior_sigma against a tip residual; the noise is
    # known only after a fit: guess, fit, and refit once if the residuals say otherwise
    noise_weight, converged = noise_scale, True
    for _ in range(3):
        weight = noise_weight / prior
        solution = least_squares(
            lambda t: np.concatenate([data_residuals(t), weight * t]), theta, loss='soft_l1',
            f_scale=noise_scale, diff_step=fd_steps, x_scale=0.1, max_nfev=max_evaluations)
        theta, converged = solution.x, solution.status > 0
        fun = solution.fun[:tips.size]
        sigma = float(np.sqrt(np.sum(fun ** 2) / max(tips.size - len(names), 1)))
        if not np.any(np.isfinite(prior)) or abs(sigma / noise_weight - 1.0) < 0.25:
            break
        noise_weight = sigma
    jacobian = _jacobian(model, theta, tips, fun, fd_steps)
    _check_excitation(names, jacobian, checked)
    covariance = _posterior_covariance(jacobian, sigma, prior)
    se_theta = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    correlation = covariance / np.outer(se_theta, se_theta)
    directions, data_share = _principal_directions(jacobian, sigma, prior)
    scaling = np.where(np.isfinite(prior), prior, 1.0)
    scaled_covariance = covariance / np.outer(scaling, scaling)
    direction_errors = np.sqrt(np.maximum(np.einsum('ik,ij,jk->k', directions,
                                                    scaled_covariance, directions), 0.0))
    values = values_of(names, theta, start_latency)
    standard_errors = np.where(steps == 0.0, values * se_theta, steps * se_theta)
    warnings = [] if converged else [
        f'the solver stopped at its budget of {max_evaluations} evaluations before converging']
    warnings += _identifiability_warnings(names, values, standard_errors, correlation,
                                          directions, data_share, max_relative_error,
                                          max_correlation)
    after = fun.reshape(-1, 3) + tips
    fitted = calibration_of(names, values)
    prior_sigmas = prior * np.where(steps == 0.0, 1.0, steps)
    return Identification(names, values, standard_errors, correlation, _rms(before - tips),
                          _rms(after - tips), before, after, sigma, tuple(warnings),
                          predict.evaluations, nominal.calibration.combined(fitted),
                          prior_sigmas, directions, data_share, direction_errors)


def _posterior_covariance(jacobian, sigma, prior):
    """
    Return the covariance of ``θ``: ``σ² (JᵀJ + σ² diag(σₚ)⁻²)⁻¹`` (``σ² (JᵀJ)⁺`` without prior).

    Parameters
    ----------
    jacobian : (n, p) ndarray  [m]
        Unweighted Jacobian of the tip residuals in ``θ``.
    sigma : float  [m]
        Residual standard deviation per axis.
    prior : (p,) ndarray  [-]
        The prior's standard deviation of each ``θ`` (``inf``: none).

    Returns
    -------
    (p, p) ndarray  [-]

    """
    scale = np.linalg.norm(jacobian, axis=0)
    scale = np.where(scale > 0.0, scale, 1.0)
    normal = (jacobian / scale).T @ (jacobian / scale)
    normal += np.diag((sigma / prior) ** 2 / scale ** 2)
    return np.linalg.pinv(normal) / np.outer(scale, scale) * sigma ** 2


def _principal_directions(jacobian, sigma, prior):
    """
    Return the principal combinations of ``θ`` (scaled by the prior) and the data's share.

    In coordinates ``θ / σₚ`` (``σₚ = 1`` where there is no prior) the prior's information is
    the identity on the parameters that have one; the eigenvectors ``v`` of the data's
    information ``S JᵀJ S / σ²`` (``S = diag(σₚ)``, eigenvalue ``λ``) get the data share
    ``λ / (λ + vᵀ D v)``, ``D`` marking the parameters with a prior.

    Parameters
    ----------
    jacobian : (n, p) ndarray  [m]
        Unweighted Jacobian of the tip residuals in ``θ``.
    sigma : float  [m]
        Residual standard deviation per axis.
    prior : (p,) ndarray  [-]
        The prior's standard deviation of each ``θ`` (``inf``: none).

    Returns
    -------
    directions : (p, p) ndarray  [-]
        Unit eigenvectors (columns), the least determined (smallest share) first.
    data_share : (p,) ndarray  [-]

    """
    has_prior = np.isfinite(prior)
    scaled = jacobian * np.where(has_prior, prior, 1.0)
    information, directions = np.linalg.eigh(scaled.T @ scaled / sigma ** 2)
    information = np.maximum(information, 0.0)
    penalty = (directions ** 2 * has_prior[:, None]).sum(axis=0)
    share = np.where(penalty > 0.0, information / (information + penalty), 1.0)
    order = np.argsort(share, kind='stable')
    return directions[:, order], share[order]


def _identifiability_warnings(names, values, standard_errors, correlation, directions,
                              data_share, max_relative_error, max_correlation):
    """
    Return the warnings: loose factors, combinations the prior sets, correlated groups.

    A factor is flagged when its relative standard error exceeds ``max_relative_error``; a
    principal combination whose information comes less than half from the data is named (the
    prior, i.e. the nominal scene, sets it); parameters linked by correlations beyond
    ``max_correlation`` form one group (connected components), reported once.
    """
    warnings = []
    for n, v, se in zip(names, values, standard_errors):
        if _is_factor(n) and se > max_relative_error * v:
            warnings.append(f'{n} = {v:.4f} +- {se:.4f}: loosely determined (relative '
                            f'standard error {se / v:.0%} > {max_relative_error:.0%})')
    for share, direction in zip(data_share, directions.T):
        if share < 0.5:
            terms = ' '.join(f'{c:+.2f} {"log " if _is_factor(n) else ""}{n}'
                             for c, n in zip(direction, names) if abs(c) > 0.1)
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


def _check_excitation(names, jacobian, checked, rank_tolerance=1e-6):
    """
    Refuse data that cannot determine the checked parameters (zero or rank-deficient Jacobian).

    Parameters
    ----------
    names : sequence of str
        Parameter names.
    jacobian : (n, p) ndarray  [m]
        Tip residual Jacobian in ``θ``.
    checked : (p,) bool ndarray
        The parameters the data must determine (the factors, and any without a prior).
    rank_tolerance : float  [-]
        Smallest singular value of the column-normalised Jacobian, relative to the largest.

    Raises
    ------
    IdentificationError
        Naming the parameters the data does not see, or those of the undetermined combination.

    """
    names = [n for n, c in zip(names, checked) if c]
    jacobian = jacobian[:, checked]
    scale = np.linalg.norm(jacobian, axis=0)
    dead = [n for n, s in zip(names, scale) if not s > 1e-12]
    hint = ('; record a circle plus poses held a few seconds (see the README: what excitation '
            'makes the parameters identifiable)')
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


def _jacobian(model, theta, tips, residual, steps=None):
    """
    Return the forward-difference Jacobian of the plain tip residuals in ``θ``.

    ``least_squares`` returns the Jacobian weighted by the robust loss; the standard errors
    need the unweighted one.
    """
    steps = np.full(len(theta), 1e-4) if steps is None else steps
    columns = []
    for k in range(len(theta)):
        shifted = np.array(theta, dtype=float)
        shifted[k] += steps[k]
        columns.append(((model(shifted) - tips).reshape(-1) - residual) / steps[k])
    return np.stack(columns, axis=1)


def _rms(error):
    """Return the RMS of the per-sample error norms [m]."""
    error = np.asarray(error, dtype=float).reshape(-1, 3)
    return float(np.sqrt(np.mean(np.sum(error ** 2, axis=1))))
