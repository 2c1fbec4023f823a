"""
What the user should know about a converged static equilibrium (paper eq. 9).

:func:`cbha_inverse.core.statics.solve_static` checks the state it returns
(:attr:`~cbha_inverse.core.statics.StaticResult.warnings`) for:

- a round-off limited convergence whose residual exceeds ``ROUNDOFF_WARNING`` (1e-4) of the
  applied load (:func:`roundoff_warnings`): a link too stiff relative to the load for its forces
  to be resolved in double precision;
- links strained beyond the small-strain range of their compliance (:func:`strain_warnings`):
  an axial deformation above ``STRAIN_LIMIT`` (10 %) of the rest length, or a rotation above
  ``ROTATION_LIMIT`` (0.5 rad) within one link. The links are linear elastic in their corotated
  frame; beyond those limits refine the chain (more, shorter links);
- a tangent that is not positive definite at the equilibrium (:func:`stability_warnings`): an
  unstable equilibrium, e.g. the straight shape under a compression above the buckling load.
"""

import numpy as np

#: a round-off limited residual above this fraction of the applied load gives a warning
ROUNDOFF_WARNING = 1e-4
#: largest axial link deformation, as a fraction of the rest length, before a warning
STRAIN_LIMIT = 0.1
#: largest rotation within one link [rad] before a warning
ROTATION_LIMIT = 0.5


def roundoff_warnings(measure, residual, applied, length):
    """
    Warn when a round-off limited residual is large against the applied load.

    Parameters
    ----------
    measure : float  [N]
        Convergence measure of the state (moments divided by ``length``).
    residual : (n, 6) ndarray  [N, N*m]
        The residual at frames 1..n.
    applied : (n, 6) ndarray  [N, N*m]
        The applied loads (dead, actuation and user loads) at frames 1..n.
    length : float  [m]
        Characteristic length ``L_c`` of the chain.

    Returns
    -------
    list of str
        Empty when the residual is within ``ROUNDOFF_WARNING`` of the largest applied load.

    """
    scaled = np.abs(applied)
    scaled[:, 3:] /= length
    largest = scaled.max()
    if not (largest > 0.0 and measure > ROUNDOFF_WARNING * largest):
        return []
    residual = np.abs(residual)
    residual[:, 3:] /= length
    worst = int(np.argmax(residual.max(axis=1))) + 1
    return [f'residual {measure:.3g} N is limited by round-off at frame {worst} '
            f'({measure / max(largest, np.finfo(float).tiny):.2g} of the applied '
            'load): its links are too stiff relative to the load to resolve their forces in '
            'double precision (stiffness ratio too large; merge the stiff link into its '
            'neighbour)']


def strain_warnings(model, offsets, rotation_vectors):
    """
    Warn about links deformed beyond the small-strain range of their compliance.

    Parameters
    ----------
    model : cbha_inverse.core.chain.ChainModel
        The chain.
    offsets : (n, 3) ndarray  [m]
        ``R_aᵀ (x_b - x_a)`` of every link at the state.
    rotation_vectors : (n, 3) ndarray  [rad]
        ``log(R_aᵀ R_b Q0ᵀ)`` of every link.

    Returns
    -------
    list of str
        Empty when every link's axial deformation (along its rest offset) is below
        ``STRAIN_LIMIT`` of its rest length and its rotation below ``ROTATION_LIMIT``.

    """
    rest = np.linalg.norm(model.rest_offsets, axis=1)
    safe = np.where(rest > 0.0, rest, 1.0)
    # axial: the transverse part of the offset change is mostly the chord turning with bending,
    # which the rotation limit covers
    strain = np.abs(np.einsum('ij,ij->i', offsets, model.rest_offsets) / safe - rest) / safe
    strain[rest == 0.0] = 0.0
    rotation = np.linalg.norm(rotation_vectors, axis=1)
    out = []
    worst = int(np.argmax(strain))
    if strain[worst] > STRAIN_LIMIT:
        out.append(f'link {worst} is strained axially by {strain[worst]:.3g} of its rest '
                   f'length (small-strain limit {STRAIN_LIMIT:g}): its linear compliance is not '
                   'accurate there')
    worst = int(np.argmax(rotation))
    if rotation[worst] > ROTATION_LIMIT:
        out.append(f'link {worst} turns by {rotation[worst]:.3g} rad within one link (limit '
                   f'{ROTATION_LIMIT:g} rad): use more, shorter links')
    return out


def stability_warnings(system, state, actuation, load=None):
    """
    Warn when the tangent at an equilibrium is not positive definite (possibly unstable).

    The symmetric part of the exact tangent (structure and the actuators' load stiffness, plus
    a user load stiffness) is factorised by Cholesky; a failure means a direction of
    decreasing stiffness. Under dead forces the equilibrium is then unstable (e.g. the straight
    shape above the buckling load); under moments or follower loads, which are not conservative
    in 3D, it is a warning sign rather than a proof.

    Parameters
    ----------
    system : cbha_inverse.core.system.EquilibriumSystem
        The evaluator of the chain and its actuators.
    state : cbha_inverse.core.chain.ChainState
        The equilibrium.
    actuation : (m,) ndarray  [N, Pa]
        The applied actuation.
    load : (6n, 6n) ndarray or None  [N/m, N, N*m/rad]
        Load stiffness of user follower loads at the full load.

    Returns
    -------
    list of str

    """
    tangent, _ = system.linearise(state.positions, state.rotations, actuation)
    if load is None:
        stable = system.factor(tangent) is not None
    else:
        lower = system.dense(tangent)
        load = np.asarray(load, dtype=float)
        matrix = lower + np.tril(lower, -1).T + 0.5 * (load + load.T)
        try:
            np.linalg.cholesky(matrix)
            stable = True
        except np.linalg.LinAlgError:
            stable = False
    if stable:
        return []
    return ['the tangent stiffness is not positive definite at this equilibrium: it may be '
            'unstable (a compression above the buckling load, lateral buckling under a large '
            'end moment, a snap-through) and the structure need not take the returned shape']
