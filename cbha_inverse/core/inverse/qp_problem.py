"""
Inverse model in constraint space (paper §IV, eq. 11-13; DESIGN §6 steps 2-3).

The mechanics linearised at the current state, ``K dq = r + J_aᵀ (λ - λ_prev)`` with the current
residual ``r = f(q) + f_ext + J_aᵀ λ_prev``, is projected onto the effectors and the actuators with
one multi-right-hand-side solve ``X = K⁻¹ [J_aᵀ, r]``:

    δ_e = W_ea λ + δ_e^free,   W_ea = J_e K⁻¹ J_aᵀ                         (eq. 11)
    δ_a = W_aa λ + δ_a^free,   W_aa = J_a K⁻¹ J_aᵀ                         (eq. 12)

where the free gaps are those of the linearised model with the actuation removed (``λ = 0``, the
paper's definition): ``δ_e^free = p_e - p_target + J_e K⁻¹ r - W_ea λ_prev``.

The actuation is the solution of the box-constrained QP (eq. 13 plus regularisation)

    min_λ  ½‖W_ea λ + δ_e^free‖² + ½ ε_E s_E λᵀ W_aa λ + ½ ε_P s_P ‖(λ - λ_prev)/σ‖²
    s.t.   max(lb, λ_prev - rate) ≤ λ ≤ min(ub, λ_prev + rate)

with ``σ`` the per-actuator range (so the problem is solved in dimensionless ``x = λ/σ``), ``s_E``
and ``s_P`` scale factors that give both terms the magnitude of the tracking term
(``s = trace(σ W_eaᵀ W_ea σ) / trace(σ W_aa σ)`` and ``trace(σ W_eaᵀ W_ea σ) / m``), so ``ε_E`` and
``ε_P`` are unit-free. ``λᵀ W_aa λ`` is the elastic energy the actuation stores in the structure:
it picks the least-effort solution among redundant ones (no co-contraction) and makes the QP
strictly convex; the proximal term smooths the actuation from tick to tick and vanishes at a fixed
point, so it adds no steady-state error. Defaults (see
:class:`cbha_inverse.core.inverse.results.InverseOptions`): ``ε_E = 1e-6`` (its bias on a
reachable target is a few micrometres at most), ``ε_P = 1e-4`` (enough to stop redundant
tendons from alternating between equivalent solutions on a saturated target).
"""

from typing import NamedTuple

from cbha_inverse.core._kernels import qp as qp_kernels
import numpy as np


class QPProblem(NamedTuple):
    """
    The actuation QP in dimensionless variables ``x = λ / σ`` (see the module docstring).

    Immutable (a named tuple: built every tick, five times cheaper than a frozen dataclass).

    Attributes
    ----------
    hessian : (m, m) ndarray
    gradient : (m,) ndarray
    lower, upper : (m,) ndarray
        Box bounds of ``x`` (actuator bounds intersected with the rate limits).
    scale : (m,) ndarray
        ``σ``: ``λ = σ x``.
    previous : (m,) ndarray
        ``x_prev``.
    tracking_hessian, tracking_gradient : (m, m), (m,) ndarray
        The tracking term alone (``½‖W_ea λ + δ_e^free‖²``, normalised), for saturation checks.

    """

    hessian: np.ndarray
    gradient: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    previous: np.ndarray
    tracking_hessian: np.ndarray
    tracking_gradient: np.ndarray


class QPMatrices(NamedTuple):
    """
    The parts of the actuation QP that depend only on the linearisation (not on the target).

    Attributes
    ----------
    hessian : (m, m) ndarray
        Full normalised Hessian (tracking + energy + proximal).
    tracking_hessian : (m, m) ndarray
        Normalised ``σ W_eaᵀ W_ea σ``.
    weighted_w : (3k, m) ndarray
        ``W_ea σ / norm`` (the gradient is ``weighted_wᵀ δ_free - ε_P x_prev``).
    scale : (m,) ndarray
        ``σ``.
    proximal_weight : float
        ``ε_P``.

    """

    hessian: np.ndarray
    tracking_hessian: np.ndarray
    weighted_w: np.ndarray
    scale: np.ndarray
    proximal_weight: float


def qp_matrices(w_ea, w_aa, scale, *, energy_weight=1e-6, proximal_weight=1e-4):
    """
    Return the normalised Hessian parts of the actuation QP (module docstring).

    Parameters
    ----------
    w_ea : (3k, m) ndarray
        Effector-actuator compliance.
    w_aa : (m, m) ndarray
        Actuator-actuator compliance.
    scale : (m,) ndarray
        ``σ``.
    energy_weight, proximal_weight : float
        ``ε_E``, ``ε_P`` (unit-free).

    Returns
    -------
    QPMatrices

    """
    hessian, tracking, weighted_w = qp_kernels.qp_hessians(
        w_ea, w_aa, scale, float(energy_weight), float(proximal_weight))
    return QPMatrices(hessian, tracking, weighted_w, scale, proximal_weight)


def qp_problem(matrices, delta_free, previous, lower_bounds, upper_bounds, rate_limit=None):
    """
    Return the QP of one tick from its matrices and the current free gap.

    Parameters
    ----------
    matrices : QPMatrices
        From :func:`qp_matrices`.
    delta_free : (3k,) ndarray  [m]
        ``δ_e^free``.
    previous : (m,) ndarray
        ``λ_prev``.
    lower_bounds, upper_bounds : (m,) ndarray
        Actuator bounds.
    rate_limit : (m,) ndarray or None
        Largest change per tick.

    Returns
    -------
    QPProblem

    """
    gradient, lower, upper, x_prev, tracking_gradient = qp_kernels.qp_vectors(
        matrices.weighted_w, float(matrices.proximal_weight), matrices.scale, delta_free,
        previous, lower_bounds, upper_bounds, rate_limit)
    return QPProblem(matrices.hessian, gradient, lower, upper, matrices.scale, x_prev,
                     matrices.tracking_hessian, tracking_gradient)
