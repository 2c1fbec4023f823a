"""The shape estimator's options and the result of one update (:mod:`~.estimate.shape`)."""

from dataclasses import dataclass
import math
from typing import NamedTuple

import numpy as np


@dataclass(frozen=True)
class EstimatorOptions:
    """
    Options of :class:`ShapeEstimator` (SI units).

    Attributes
    ----------
    pressure_std : float  [Pa]
        Prior standard deviation of the actuation's offset ``δ`` about the measured pressure.
    gain_std : float  [-]
        Prior standard deviation of the actuation's gain error ``g``.
    gain_walk_std : float  [-]
        Random walk of ``g`` per update.
    offset_walk_std : float  [Pa]
        Random walk of ``δ`` per update, with measured pressures.
    pressure_change_walk : float  [-]
        ... plus this fraction of the measured pressure change since the previous update.
    actuation_walk_std : float  [Pa]
        Random walk of ``δ`` (the actuation itself) per update without measured pressures.
    predict_pressure_change : float  [Pa]
        An update whose measured pressures changed by more than this (any actuator) since the
        previous one first takes Newton steps (at most ``initial_newton_steps``, no pot used)
        to the equilibrium of the prior's actuation at them: a step of the pressures moves the
        arm further than one linearisation predicts, and the pots would take the difference
        for a gain or offset error.
    initial_actuation_std : float  [Pa]
        Random walk of ``δ`` of an update after one that was not settled (as from far away).
    settle_sigma : float
        An update is settled when the median pot (of those not stuck) is within this many
        standard deviations of its prediction; only after a settled update is the outlier test
        applied and the walk the small one.
    payload_std : float or None  [kg]
        Prior standard deviation of an unknown mass at the last frame (a payload, its weight
        along the scene's gravity); None: no such unknown.
    payload_walk_std : float  [kg]
        Random walk of the payload per update.
    weight_std : float or None  [kg]
        Prior standard deviation of an error of the arm's own weight, spread as its lumped
        masses (one kg of it: the arm's weight over its mass): a plant softer than the model
        sags under gravity as if heavier, which no gain or offset of the actuation reproduces
        (the pots would fit and the tip stay off along gravity); None: no such unknown. With
        ``payload_std`` too, both are unknowns: the pots see a weight spread along the arm
        and one at its tip differently as the pose changes.
    weight_walk_std : float  [kg]
        Random walk of the weight error per update.
    section_stiffness_std : float or None  [-]
        Prior standard deviation of a relative stiffness error ``σ_j`` of every chain section
        (the links of section ``j`` are ``1 + σ_j`` times as stiff as the model's): a
        stiffer inner and a softer outer section distribute the sag between and within the
        sections in a way no weight or tip mass reproduces. The linearisation is that of the
        scaled chain (the residual's link forces and the tangent), the pots' column of
        ``σ_j`` is ``J_s K⁻¹ ∂r/∂σ_j``; the factors ``1 + σ_j`` are kept within 0.5-2 (an
        update far from the equilibrium can drive one toward a chain without stiffness).
        None: no such unknown. Needs the scene's sections.
    section_stiffness_walk_std : float  [-]
        Random walk of each ``σ_j`` per update.
    outlier_sigma : float
        A pot whose innovation exceeds this many standard deviations is dropped for the update.
    stuck_window : int
        Updates over which a stuck pot is looked for (0: never).
    stuck_tolerance : float  [m]
        A pot that moved less than this over the window is stuck ...
    motion_threshold : float  [m]
        ... while the median of the others moved more than this.
    length_range : (float, float)
        Accepted lengths, as factors of each pot's rest length.
    max_pressure : float  [Pa]
        Measured pressures above this (or below ``-max_pressure``) are rejected.
    iterations : int
        Linearisations per settled update (iterated Kalman update from the same prior).
    settle_iterations : int
        ... per update after one that was not settled (from far away: the pots' linear model
        is not yet that of the equilibrium).
    initial_newton_steps : int
        Largest number of Newton steps of the first update toward the equilibrium of the
        prior's actuation, before the pots are used.
    max_rotation_step : float  [rad]
        Largest frame rotation of one step (the control tick's limit).

    """

    pressure_std: float = 1.0e4
    gain_std: float = 0.2
    gain_walk_std: float = 1.0e-4
    offset_walk_std: float = 10.0
    pressure_change_walk: float = 0.0
    actuation_walk_std: float = 20000.0
    predict_pressure_change: float = 2000.0
    initial_actuation_std: float = 5.0e4
    settle_sigma: float = 4.0
    payload_std: float = None
    payload_walk_std: float = 1.0e-4
    weight_std: float = None
    weight_walk_std: float = 1.0e-6
    section_stiffness_std: float = None
    section_stiffness_walk_std: float = 1.0e-5
    outlier_sigma: float = 8.0
    stuck_window: int = 25
    stuck_tolerance: float = 2.0e-5
    motion_threshold: float = 2.0e-3
    length_range: tuple = (0.5, 1.5)
    max_pressure: float = 1.0e6
    iterations: int = 1
    settle_iterations: int = 5
    initial_newton_steps: int = 20
    max_rotation_step: float = 0.2


class ShapeEstimate(NamedTuple):
    """
    One update of :class:`ShapeEstimator`.

    Attributes
    ----------
    status : str
        ``'ok'``, ``'degraded'`` (a pot dropped) or ``'rejected'`` (the input; nothing changed).
    reason : str
        Why it was rejected or degraded (empty when ``'ok'``).
    effector_positions : (k, 3) ndarray  [m]
        The scene's effectors (the tip last) at the estimated equilibrium.
    tip_covariance : (3, 3) ndarray  [m^2]
        Of the last effector, from the posterior of ``x`` (linear).
    lengths : (c,) ndarray  [m]
        Measured pot lengths.
    residuals : (c,) ndarray  [m]
        Measured minus estimated length of every pot (the dropped ones too).
    active : (c,) ndarray of bool
        The pots used.
    rank : int
        Directions of ``x`` the active pots determine (the numerical rank of their whitened
        ``W_sx``).
    actuation : (m,) ndarray  [Pa, N]
        Estimated effective actuation.
    payload : float  [kg]
        Estimated payload at the last frame (0 without that unknown).
    weight : float  [kg]
        Estimated error of the arm's own weight (0 without that unknown).
    seconds : float
        Time of the update.
    section_stiffness : (s,) ndarray  [-]
        Estimated stiffness factor ``1 + σ_j`` of every chain section, the estimator's
        ``section_names`` order (empty without that unknown).

    """

    status: str
    reason: str
    effector_positions: np.ndarray
    tip_covariance: np.ndarray
    lengths: np.ndarray
    residuals: np.ndarray
    active: np.ndarray
    rank: int
    actuation: np.ndarray
    payload: float
    weight: float
    seconds: float
    section_stiffness: np.ndarray

    @property
    def degraded(self):
        """Return whether a pot was dropped from the fit."""
        return self.status == 'degraded'

    @property
    def tip(self):
        """Return the last effector's position (3,) [m]."""
        return self.effector_positions[-1]

    @property
    def confidence(self):
        """Return the tip's standard deviation ``sqrt(trace(tip_covariance))`` [m]."""
        return math.sqrt(max(float(np.trace(self.tip_covariance)), 0.0))
