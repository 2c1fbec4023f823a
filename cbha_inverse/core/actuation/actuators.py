"""
The actuators of a scene: groups (cables, cavities) stacked in the scene's column order.

Every actuator contributes one column of the actuation Jacobian transpose ``J_aᵀ`` (paper eq. 9);
:class:`ActuatorSet` indexes the groups' columns (:mod:`cbha_inverse.core.actuation.cables`,
:mod:`cbha_inverse.core.actuation.condensed_cavities`, :mod:`cbha_inverse.core.actuation.cavities`)
and their bounds.
"""

import numpy as np


class ActuatorSet:
    """
    The actuators of a scene: groups (cables, cavities) stacked in column order.

    Parameters
    ----------
    groups : sequence
        Objects with ``names``, ``n_actuators``, ``lower_bounds``, ``upper_bounds`` and
        ``evaluate(positions, rotations) -> (wrenches (m_g, n + 1, 6), displacements (m_g,))``
        (:class:`CableGroup`, :class:`cbha_inverse.core.actuation.cavities.CavityGroup`,
        :class:`cbha_inverse.core.actuation.condensed_cavities.LinearCavityGroup`).
    n_frames : int
        Number of frames (base included).
    order : sequence of str, optional
        Actuator names in the wanted column order (default: group order).

    """

    def __init__(self, groups, n_frames, order=None):
        """Index the groups' columns in the requested order."""
        self.groups = tuple(g for g in groups if g.n_actuators)
        self.n_frames = int(n_frames)
        names = [name for g in self.groups for name in g.names]
        if len(set(names)) != len(names):
            raise ValueError(f'duplicate actuator names in {names}')
        order = list(names if order is None else order)
        if sorted(order) != sorted(names):
            raise ValueError(f'actuator order {order} does not match the actuators {names}')
        position = {name: k for k, name in enumerate(order)}
        self.names = tuple(order)
        self._columns = [np.array([position[name] for name in g.names], dtype=int)
                         for g in self.groups]
        self.lower_bounds = np.empty(len(order))
        self.upper_bounds = np.empty(len(order))
        for g, cols in zip(self.groups, self._columns):
            self.lower_bounds[cols] = g.lower_bounds
            self.upper_bounds[cols] = g.upper_bounds

    @property
    def n_actuators(self):
        """Return the number of actuators ``m``."""
        return len(self.names)
