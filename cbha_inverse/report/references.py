"""
Independent references for the stability and accuracy reports (no Newton engine inside).

- :func:`linear_tip_displacement`: the linear flexibility of a straight serial chain;
- :func:`elastica_tip`: the exact inextensible cantilever elastica under a dead tip force
  (first integral, quadrature);
- :func:`straight_beam_chain`: the straight Timoshenko chain the cases are built from.
"""

from cbha_inverse.core.chain import ChainModel
from cbha_inverse.core.links import timoshenko_compliance
import numpy as np
from scipy.integrate import quad
from scipy.optimize import brentq


def straight_beam_chain(n_links, length, youngs_modulus, poisson_ratio, radius,
                        stiffness_factors=None):
    """
    Return a straight chain of equal Timoshenko links along +x and its compliances.

    Parameters
    ----------
    n_links : int
        Links.
    length : float  [m]
        Chain length.
    youngs_modulus : float  [Pa]
        Young's modulus.
    poisson_ratio : float
        Poisson's ratio.
    radius : float  [m]
        Solid circular section.
    stiffness_factors : (n,) array_like, optional
        Multiply each link's stiffness (divide its compliance).

    Returns
    -------
    model : ChainModel
    compliances : (n, 6, 6) ndarray
    offsets : (n, 3) ndarray  [m]

    """
    comp = np.broadcast_to(timoshenko_compliance(length / n_links, youngs_modulus,
                                                 poisson_ratio, radius), (n_links, 6, 6)).copy()
    if stiffness_factors is not None:
        comp /= np.asarray(stiffness_factors, dtype=float)[:, None, None]
    offsets = np.tile([length / n_links, 0.0, 0.0], (n_links, 1))
    return ChainModel.from_compliances(comp, offsets), comp, offsets


def linear_tip_displacement(compliances, offsets, wrench):
    """
    Tip translation of a straight serial chain under a small tip wrench (linear flexibility).

    Link j carries the tip wrench transported to its end frame, ``(F, M + (p_tip - x_j+1) x F)``;
    its deformation ``C_j w_j`` moves the tip by ``d_t + d_r x (p_tip - x_j+1)``.

    Parameters
    ----------
    compliances : (n, 6, 6) ndarray
        Link compliances (base axes).
    offsets : (n, 3) ndarray  [m]
        Rest offsets (identity rest rotations).
    wrench : (6,) ndarray  [N, N*m]
        Tip wrench.

    Returns
    -------
    (3,) ndarray  [m]

    """
    ends = np.cumsum(offsets, axis=0)
    arms = ends[-1] - ends
    local = np.concatenate([np.broadcast_to(wrench[:3], arms.shape),
                            wrench[3:] + np.cross(arms, wrench[:3])], axis=1)
    deformation = np.einsum('nij,nj->ni', compliances, local)
    return (deformation[:, :3] + np.cross(deformation[:, 3:], arms)).sum(axis=0)


def elastica_tip(alpha):
    """
    Tip (x, y) / L of the inextensible cantilever elastica under a transverse dead tip force.

    ``alpha = P L^2 / EI``; clamped at s = 0 along +x, force along +y. From the first integral
    of ``theta'' = -alpha cos(theta)`` with a free tip (``theta'(1) = 0``),
    ``theta'^2 / 2 = alpha (sin theta_1 - sin theta)``: the tip angle theta_1 solves
    ``int_0^theta_1 d theta / sqrt(2 alpha (sin theta_1 - sin theta)) = 1`` (one root in
    (0, pi/2): the stable branch), then ``x = sqrt(2 sin theta_1 / alpha)`` and ``y`` is the
    same integral of ``sin theta``. With ``t = sqrt(sin theta_1 - sin theta)`` the integrals
    are ``sqrt(2 / alpha) int_0^sqrt(sin theta_1) g(theta) / cos(theta) dt``, smooth (peaked of
    width ``sqrt(1 - sin theta_1)`` at t = 0 for large alpha). Unlike shooting from the clamp,
    which finds other branches beyond alpha ~ 20, it holds up to alpha ~ 200 (beyond, the tip
    angle is within 1e-7 of pi/2 and the bracket fails: ValueError).

    Parameters
    ----------
    alpha : float
        Load parameter.

    Returns
    -------
    (2,) ndarray
        Tip position divided by the length.

    """
    def integral(theta_1, numerator):
        s_1 = np.sin(theta_1)

        def smooth(t):
            sin_theta = s_1 - t * t
            cos_theta = np.sqrt((1.0 - s_1 + t * t) * (1.0 + sin_theta))
            return numerator(sin_theta) / cos_theta
        end, width = np.sqrt(s_1), np.sqrt(1.0 - s_1)
        # split at the peak's width (where it lies inside) so that quad resolves it
        edges = [0.0, width, end] if width < end else [0.0, end]
        return np.sqrt(2.0 / alpha) * sum(
            quad(smooth, low, high, limit=200, epsabs=1e-15, epsrel=1e-12)[0]
            for low, high in zip(edges[:-1], edges[1:]))

    theta_1 = brentq(lambda t: integral(t, np.ones_like) - 1.0, 1e-12, 0.5 * np.pi - 1e-7,
                     xtol=1e-15)
    return np.array([np.sqrt(2.0 * np.sin(theta_1) / alpha), integral(theta_1, lambda v: v)])
