"""
Position-controlled tendon drives: displacements of the cables' ends and the tensions they make.

A tendon drive (a motor with an encoder) commands where the cable's end is, not its tension.
With the routed length ``L(q)`` of a cable (:class:`cbha_inverse.core.actuation.cables.
RoutedLengths`) and its axial stiffness ``EA`` [N] (linear elastic, strain relative to the
unstretched length), a cable under tension ``λ`` along a path of length ``L`` has the
unstretched length

    ``ℓ0 = L / (1 + λ / EA)``    (``ℓ0 = L`` for an inextensible cable, ``EA = inf``),

and the drive's displacement from the rest pose is ``d = ℓ0 - L_rest`` (pulled in: negative),
``L_rest`` the routed length at rest (zero tension). Conversely, a commanded displacement gives
``ℓ0 = L_rest + d`` and the tension

    ``λ = EA max(0, L / ℓ0 - 1)``,

the cable slack by ``ℓ0 - L`` when that is positive. The tension acts on the chain as a cable's
force does (paper eq. 9): the generalized load ``-gain λ dL/dq`` (``dL/dq = -J_a`` without
friction). :meth:`TendonDrives.loads` and :meth:`TendonDrives.load_stiffness` are the
configuration-dependent load and its stiffness of a displacement-commanded chain, for
:func:`cbha_inverse.core.statics.solve_static`.
"""

from cbha_inverse.core.chain import checked_array
import numpy as np


def unstretched_lengths(path_lengths, tensions, axial_stiffness):
    """
    Return the unstretched cable lengths ``ℓ0 = L / (1 + λ / EA)``.

    Parameters
    ----------
    path_lengths : (c,) ndarray  [m]
        Routed lengths ``L``.
    tensions : (c,) ndarray  [N]
        Tensions ``λ >= 0``.
    axial_stiffness : (c,) ndarray  [N]
        ``EA`` of each cable (``inf``: inextensible).

    Returns
    -------
    (c,) ndarray  [m]

    """
    return path_lengths / (1.0 + tensions / axial_stiffness)


def tensions_of_lengths(path_lengths, unstretched, axial_stiffness):
    """
    Return the tensions ``λ = EA max(0, L / ℓ0 - 1)`` and the slack ``max(0, ℓ0 - L)``.

    Parameters
    ----------
    path_lengths : (c,) ndarray  [m]
        Routed lengths ``L``.
    unstretched : (c,) ndarray  [m]
        Unstretched lengths ``ℓ0 > 0``.
    axial_stiffness : (c,) ndarray  [N]
        ``EA`` of each cable (finite).

    Returns
    -------
    tensions : (c,) ndarray  [N]
    slack : (c,) ndarray  [m]

    """
    stretch = path_lengths - unstretched
    return (axial_stiffness * np.maximum(stretch, 0.0) / unstretched,
            np.maximum(-stretch, 0.0))


class TendonDrives:
    """
    The cables of a scene driven by displacement (position-controlled drives).

    Parameters
    ----------
    routes : cbha_inverse.core.actuation.cables.RoutedLengths
        The cables' routed lengths.
    rest_lengths : (c,) array_like  [m]
        Routed lengths at the rest pose (``d = 0``).
    axial_stiffness : (c,) array_like, optional  [N]
        ``EA`` of each cable, > 0 (``inf``: inextensible; a displacement-commanded chain needs
        finite values). Default: the cables' own (``Cable.axial_stiffness``).

    """

    def __init__(self, routes, rest_lengths, axial_stiffness=None):
        """Validate and store the rest lengths and stiffnesses."""
        self.routes = routes
        self.names = routes.names
        c = len(self.names)
        self.rest_lengths = checked_array(rest_lengths, (c,), 'rest_lengths')
        if np.any(self.rest_lengths <= 0.0):
            raise ValueError(f'rest_lengths must be > 0, got {self.rest_lengths}')
        if axial_stiffness is None:
            axial_stiffness = routes.group.axial_stiffness
        self.axial_stiffness = np.asarray(axial_stiffness, dtype=float).reshape(-1)
        if self.axial_stiffness.shape != (c,) or np.any(np.isnan(self.axial_stiffness)) or \
                np.any(self.axial_stiffness <= 0.0):
            raise ValueError(f'axial_stiffness must be {c} values > 0 (inf allowed), got '
                             f'{self.axial_stiffness}')
        self.gains = routes.group.gains

    def displacements(self, state, tensions):
        """
        Return the drive displacements that hold ``tensions`` at a pose.

        Parameters
        ----------
        state : cbha_inverse.core.chain.ChainState
            The pose (e.g. the state of an equilibrium under these tensions).
        tensions : (c,) array_like  [N]
            The cables' tensions, >= 0.

        Returns
        -------
        (c,) ndarray  [m]
            ``ℓ0 - L_rest`` (pulled in: negative).

        """
        tensions = checked_array(tensions, (len(self.names),), 'tensions')
        lengths, _ = self.routes.lengths_and_jacobian(state.positions, state.rotations)
        return unstretched_lengths(lengths, np.maximum(tensions, 0.0),
                                   self.axial_stiffness) - self.rest_lengths

    def tensions(self, state, displacements):
        """
        Return the tensions and slack of commanded displacements at a pose.

        Parameters
        ----------
        state : cbha_inverse.core.chain.ChainState
            The pose.
        displacements : (c,) array_like  [m]
            Drive displacements from rest.

        Returns
        -------
        tensions : (c,) ndarray  [N]
        slack : (c,) ndarray  [m]

        Raises
        ------
        ValueError
            If a cable is inextensible, or a displacement not finite or leaves no cable.

        """
        lengths, _ = self.routes.lengths_and_jacobian(state.positions, state.rotations)
        return tensions_of_lengths(lengths, self._unstretched(displacements),
                                   self._finite_stiffness())

    def loads(self, state, displacements):
        """
        Return the cables' wrenches on frames 1..n under commanded displacements.

        Parameters
        ----------
        state : cbha_inverse.core.chain.ChainState
            The pose.
        displacements : (c,) array_like  [m]
            Drive displacements from rest.

        Returns
        -------
        (n, 6) ndarray  [N, N*m]
            ``-(dL/dq)ᵀ (gain λ)`` per frame, world axes (a ``load_function`` of
            :func:`cbha_inverse.core.statics.solve_static`).

        """
        jacobian, tensions = self._pull(state, displacements)
        return -(jacobian.T @ (self.gains * tensions)).reshape(-1, 6)

    def load_stiffness(self, state, displacements):
        """
        Return the stiffness of the cables' stretch, ``(dL/dq)ᵀ diag(gain EA / ℓ0) dL/dq``.

        The taut cables' part of ``-d loads / dq`` (a ``load_tangent`` of
        :func:`cbha_inverse.core.statics.solve_static`); the part from the routing's curvature
        at constant tension (``λ d²L/dq²``) is left out: it is small beside the stretch
        stiffness of a tendon, and Newton's iterations still converge (to the same
        equilibrium, a little more slowly).

        Parameters
        ----------
        state : cbha_inverse.core.chain.ChainState
            The pose.
        displacements : (c,) array_like  [m]
            Drive displacements from rest.

        Returns
        -------
        (6n, 6n) ndarray  [N/m, N, N*m]

        """
        lengths, jacobian = self.routes.lengths_and_jacobian(state.positions, state.rotations)
        unstretched = self._unstretched(displacements)
        taut = lengths > unstretched
        weights = np.where(taut, self.gains * self._finite_stiffness() / unstretched, 0.0)
        return jacobian.T @ (weights[:, None] * jacobian)

    def correction_hooks(self, displacements, tensions):
        """
        Return the drives' loads less those of fixed tensions, as ``solve_static`` hooks.

        With the actuators' own follower loads at ``tensions`` (their exact load stiffness,
        :func:`cbha_inverse.core.statics.solve_static`'s ``actuators``), these hooks make the
        loads exactly the drives' (:meth:`loads`); the tangent adds the stretch stiffness
        (:meth:`load_stiffness`), exact where the drives' tensions equal ``tensions``.

        Parameters
        ----------
        displacements : (c,) array_like  [m]
            Drive displacements from rest.
        tensions : (c,) array_like  [N]
            The tensions given to the actuators.

        Returns
        -------
        load_function, load_tangent : callable

        """
        held = self.gains * checked_array(tensions, (len(self.names),), 'tensions')

        def function(state):
            jacobian, pulled = self._pull(state, displacements)
            return -(jacobian.T @ (self.gains * pulled - held)).reshape(-1, 6)

        return function, lambda state: self.load_stiffness(state, displacements)

    def _pull(self, state, displacements):
        """Return ``dL/dq`` (c, 6n) at a pose and the tensions (c,) [N] of displacements."""
        lengths, jacobian = self.routes.lengths_and_jacobian(state.positions, state.rotations)
        tensions, _ = tensions_of_lengths(lengths, self._unstretched(displacements),
                                          self._finite_stiffness())
        return jacobian, tensions

    def _unstretched(self, displacements):
        unstretched = self.rest_lengths + checked_array(displacements, (len(self.names),),
                                                        'displacements')
        if np.any(unstretched <= 0.0):
            raise ValueError(f'displacements {displacements} leave no cable (rest lengths '
                             f'{self.rest_lengths})')
        return unstretched

    def _finite_stiffness(self):
        if not np.all(np.isfinite(self.axial_stiffness)):
            raise ValueError('a displacement-commanded cable needs a finite axial stiffness')
        return self.axial_stiffness
