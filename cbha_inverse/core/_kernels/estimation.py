"""
Compiled Kalman step of the shape estimator on string-potentiometer lengths.

:func:`length_update` is the one implementation of the estimator's update
(:mod:`cbha_inverse.estimate.shape`): the unknowns ``z`` (effective actuation and payload,
scaled) follow a random walk; the prior is the previous estimate and, when measured, the
pressures; the measurements are the pot lengths, linear in ``z`` through
``W_sz = J_s K⁻¹ [J_aᵀ, J_μᵀ] diag(scale)`` of one linearisation of the equilibrium.
"""

import math

import numba
import numpy as np


@numba.njit(cache=True)
def length_update(moved, ell0, lengths, noise, scale, z_previous, z_prior, covariance, walk,
                  pressures,
                  pressure_weight, outlier_sigma, gate, stuck):
    """
    Return the posterior of one update and the pots' innovations.

    Parameters
    ----------
    moved : (c, 1 + u) ndarray
        ``J_s K⁻¹ [r, J_aᵀ, J_μᵀ]`` [m, m/Pa, m/kg].
    ell0 : (c,) ndarray  [m]
        Pot lengths at the linearisation.
    lengths : (c,) ndarray  [m]
        Measured lengths.
    noise : (c,) ndarray  [m]
        Their standard deviations.
    scale : (u,) ndarray
        Unit of every unknown (``x = scale z``).
    z_previous : (u,) ndarray
        The previous estimate (scaled), where the step starts.
    z_prior : (u,) ndarray
        The predicted mean (scaled): the previous estimate moved by the measured change of the
        pressures since it.
    covariance : (u, u) ndarray
        Its covariance (scaled).
    walk : (u,) ndarray
        Variance of the random walk per update (scaled).
    pressures : (p,) ndarray
        Measured first ``p`` unknowns, scaled (``p = 0``: none measured).
    pressure_weight : float
        Inverse variance of a scaled pressure measurement.
    outlier_sigma : float
        Drop a pot whose innovation exceeds this many standard deviations (when ``gate``).
    gate : bool
        Apply the innovation test.
    stuck : (c,) bool ndarray
        Pots left out whatever their innovation.

    Returns
    -------
    z : (u,) ndarray
        Posterior mean (scaled).
    posterior : (u, u) ndarray
        Posterior covariance (scaled).
    predicted : (c,) ndarray  [m]
        Linear prediction of the lengths at ``z``.
    ratio : (c,) ndarray
        ``|innovation| / its standard deviation`` against the prior.
    active : (c,) bool ndarray
        Pots used.
    w_sz : (c, u) ndarray  [m]
        The pots' sensitivity to ``z``.

    """
    c, width = moved.shape
    u = width - 1
    w_sz = np.empty((c, u))
    base = np.empty(c)
    for i in range(c):
        acc = ell0[i] + moved[i, 0]
        for j in range(u):
            w_sz[i, j] = moved[i, 1 + j] * scale[j]
            acc -= w_sz[i, j] * z_previous[j]
        base[i] = acc
    grown = covariance.copy()
    for j in range(u):
        grown[j, j] += walk[j]
    information = np.linalg.inv(grown)
    vector = information @ z_prior
    for j in range(pressures.size):
        information[j, j] += pressure_weight
        vector[j] += pressure_weight * pressures[j]
    prior = np.linalg.inv(information)
    prior_mean = prior @ vector
    ratio = np.empty(c)
    active = np.empty(c, dtype=np.bool_)
    for i in range(c):
        spread = noise[i] * noise[i]
        innovation = lengths[i] - base[i]
        for j in range(u):
            innovation -= w_sz[i, j] * prior_mean[j]
            for k in range(u):
                spread += w_sz[i, j] * prior[j, k] * w_sz[i, k]
        ratio[i] = abs(innovation) / math.sqrt(spread)
        active[i] = not stuck[i] and not (gate and ratio[i] > outlier_sigma)
    for i in range(c):
        if active[i]:
            weight = 1.0 / (noise[i] * noise[i])
            for j in range(u):
                vector[j] += weight * w_sz[i, j] * (lengths[i] - base[i])
                for k in range(u):
                    information[j, k] += weight * w_sz[i, j] * w_sz[i, k]
    posterior = np.linalg.inv(information)
    z = posterior @ vector
    predicted = base + w_sz @ z
    return z, posterior, predicted, ratio, active, w_sz
