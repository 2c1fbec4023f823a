"""
Compliance links between two 6-DoF frames: the Timoshenko beam compliance (paper eq. 2-4).

A link joins frame a (= frame i) to frame b (= frame i+1). Its data are a symmetric positive
definite 6x6 stiffness ``K = C^-1`` (C as the paper defines it: frame a clamped, loads at the
origin of frame b, all in frame-a axes; paper eq. 2-4) and the rest transform of frame
b seen from frame a (offset ``d0``, rotation ``Q0``). Two sources give C: the closed form of a
Timoshenko beam here, or a condensed FEM segment (:mod:`cbha_inverse.fem.condensation`).

The corotational link force and its tangent (paper eq. 4-8) are computed by the compiled pass
over the links, :func:`cbha_inverse.core._kernels.links.link_pass` (its module docstring states
the equations).
"""

import numpy as np

#: Largest accepted asymmetry of a compliance, ``max |C_ij - C_ji| / sqrt(C_ii C_jj)``, before it
#: is symmetrised: the round-off of a condensation (a sparse solve of ~1e5 unknowns and a 6 x 6
#: inversion, condition up to ~1e8) stays below it, while any modelling error (a wrong coupling,
#: a transposed offset) is far above.
COMPLIANCE_SYMMETRY_TOLERANCE = 1e-8


def checked_compliance(compliance, name='compliance'):
    """
    Check that a 6x6 compliance is finite, symmetric at round-off level and positive definite.

    The one validation of a link compliance (Timoshenko, condensed, read from a segment YAML or
    given to :meth:`cbha_inverse.core.chain.ChainModel.from_compliances`).

    Parameters
    ----------
    compliance : (6, 6) array_like  [m/N, 1/N, rad/(N*m)]
        The compliance C.
    name : str
        What to call it in the error message.

    Returns
    -------
    sym : (6, 6) ndarray
        ``(C + Cᵀ) / 2``.
    asymmetry : float
        ``max |C_ij - C_ji| / sqrt(C_ii C_jj)`` before symmetrising.

    Raises
    ------
    numpy.linalg.LinAlgError
        (a ``ValueError``) naming ``name``: not (6, 6), not finite, asymmetric beyond
        :data:`COMPLIANCE_SYMMETRY_TOLERANCE`, or not positive definite.

    """
    c = np.asarray(compliance, dtype=float)
    if c.shape != (6, 6):
        raise np.linalg.LinAlgError(f'{name} must have shape (6, 6), got {c.shape}')
    if not np.all(np.isfinite(c)):
        raise np.linalg.LinAlgError(f'{name} is not finite (NaN or inf)')
    diagonal = np.diag(c)
    if np.any(diagonal <= 0.0):
        raise np.linalg.LinAlgError(f'{name} is not positive definite (non-positive diagonal '
                                    'term)')
    scale = 1.0 / np.sqrt(diagonal)
    asymmetry = float(np.max(np.abs(c - c.T) * np.outer(scale, scale)))
    if asymmetry > COMPLIANCE_SYMMETRY_TOLERANCE:
        raise np.linalg.LinAlgError(
            f'{name} is asymmetric beyond round-off: {asymmetry:.3e} > '
            f'{COMPLIANCE_SYMMETRY_TOLERANCE:.0e}')
    sym = 0.5 * (c + c.T)
    smallest = np.linalg.eigvalsh(sym * np.outer(scale, scale))[0]
    if smallest <= 0.0:
        raise np.linalg.LinAlgError(f'{name} is not positive definite (smallest scaled '
                                    f'eigenvalue {smallest:.3e})')
    return sym, asymmetry


def cowper_shear_coefficient(poisson_ratio, outer_radius, inner_radius=0.0):
    """
    Cowper's shear coefficient of a solid or hollow circular section.

    ``kappa = 6 (1 + nu) (1 + m^2)^2 / ((7 + 6 nu) (1 + m^2)^2 + (20 + 12 nu) m^2)``, ``m =
    r_i / r_o`` (Cowper 1966); ``m = 0`` gives the solid value ``6 (1 + nu) / (7 + 6 nu)``.

    Parameters
    ----------
    poisson_ratio : float
        Poisson's ratio nu.
    outer_radius : float  [m]
        Outer radius r_o.
    inner_radius : float  [m]
        Inner radius r_i (0 for a solid section).

    Returns
    -------
    float

    """
    nu = float(poisson_ratio)
    m2 = (float(inner_radius) / float(outer_radius)) ** 2
    a = (1.0 + m2) ** 2
    return 6.0 * (1.0 + nu) * a / ((7.0 + 6.0 * nu) * a + (20.0 + 12.0 * nu) * m2)


def timoshenko_compliance(length, youngs_modulus, poisson_ratio, outer_radius, inner_radius=0.0):
    """
    Compliance of a straight Timoshenko beam along local +x (paper eq. 2-4).

    Frame a is clamped at x = 0; loads (Fx, Fy, Fz, Mx, My, Mz) act at the origin of frame b
    (x = L), displacements (dx, dy, dz, rx, ry, rz) are measured there, all in frame-a axes::

        C[0,0] = L/(EA)   C[3,3] = L/(GJ)   C[1,1] = C[2,2] = L^3/(3EI) + L/(kappa G A)
        C[4,4] = C[5,5] = L/(EI)   C[1,5] = C[5,1] = L^2/(2EI)   C[2,4] = C[4,2] = -L^2/(2EI)

    with G = E / (2 (1 + nu)), J = 2 I the polar moment and kappa Cowper's coefficient.

    Parameters
    ----------
    length : float  [m]
        Beam length L.
    youngs_modulus : float  [Pa]
        Young's modulus E.
    poisson_ratio : float
        Poisson's ratio nu.
    outer_radius : float  [m]
        Outer radius r_o.
    inner_radius : float  [m]
        Inner radius r_i, 0 for a solid section.

    Returns
    -------
    (6, 6) ndarray  [m/N, 1/N, rad/(N*m)]

    """
    length = float(length)
    e_mod = float(youngs_modulus)
    r_o = float(outer_radius)
    r_i = float(inner_radius)
    if not all(np.isfinite([length, e_mod, r_o, r_i, float(poisson_ratio)])):
        raise ValueError('length, youngs_modulus, poisson_ratio and radii must be finite')
    if length <= 0.0 or e_mod <= 0.0 or r_o <= 0.0 or not 0.0 <= r_i < r_o:
        raise ValueError('need length > 0, youngs_modulus > 0 and 0 <= inner < outer radius')
    if not -1.0 < poisson_ratio < 0.5:
        raise ValueError('poisson_ratio must lie in (-1, 0.5)')
    area = np.pi * (r_o ** 2 - r_i ** 2)
    inertia = np.pi * (r_o ** 4 - r_i ** 4) / 4.0
    shear_modulus = e_mod / (2.0 * (1.0 + poisson_ratio))
    kappa = cowper_shear_coefficient(poisson_ratio, r_o, r_i)
    ei = e_mod * inertia
    c = np.zeros((6, 6))
    c[0, 0] = length / (e_mod * area)
    c[1, 1] = c[2, 2] = length ** 3 / (3.0 * ei) + length / (kappa * shear_modulus * area)
    c[3, 3] = length / (shear_modulus * 2.0 * inertia)
    c[4, 4] = c[5, 5] = length / ei
    c[1, 5] = c[5, 1] = length ** 2 / (2.0 * ei)
    c[2, 4] = c[4, 2] = -length ** 2 / (2.0 * ei)
    return c
