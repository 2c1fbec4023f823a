"""
What the inverse solver's model takes from outside while it runs: payload, sections, gains.

:class:`ModelTerms` is the part of :class:`cbha_inverse.core.inverse.solver.InverseSolver` that
changes the model between ticks: a known (e.g. estimated) tip payload in its loads, the chain
sections' stiffness factors on its links, the cavities' gains on their effective area. Each
replaces the previous value, comes rate-limited on request (an estimated value should come in
small steps: each change of the model is a step of the commanded actuation, and in a loop on an
estimate that step disturbs the estimate it came from) and makes the next tick relinearise.
"""

import math

from cbha_inverse.core.sections import check_section_factors, rate_limited
import numpy as np


class ModelTerms:
    """
    The model updates of :class:`~cbha_inverse.core.inverse.solver.InverseSolver` (a mixin).

    It reads the solver's ``_external``, ``_unloaded``, ``_payload``, ``_gravity``,
    ``_sections`` (:class:`cbha_inverse.core.sections.SectionStiffness`), ``_gains``, ``_tick``
    (its :class:`~cbha_inverse.core.system.EquilibriumSystem`), ``_m``, ``options`` and
    ``_age``.
    """

    def set_payload(self, mass, max_change=None):
        """
        Add a known mass at the last frame to the model's loads (e.g. an estimated payload).

        The tick's equilibrium then carries its weight (a load in ``f_ext`` of paper eq. 9, the
        same as a scene's ``tip_payload_mass``), so the QP compensates it in the model instead
        of leaving it to the closed loop's correction. It replaces the previous one; the next
        linearisation uses it (a node calls :meth:`prepare` right after, so that the target ->
        command path does not pay for it; an unchanged payload keeps the linearisation). An
        estimated payload should come in small steps (``max_change``): each change of the
        model's load is a step of the commanded actuation, and in a loop on an estimate that
        step disturbs the estimate it came from.

        Parameters
        ----------
        mass : float  [kg]
            The payload (0: none).
        max_change : float or None  [kg]
            Move the model's payload toward ``mass`` by at most this (None: all the way).

        Returns
        -------
        float  [kg]
            The payload now in the model's loads.

        Raises
        ------
        ValueError
            If ``mass`` is not finite, or the model has no gravity.

        """
        mass = float(mass)
        if not math.isfinite(mass):
            raise ValueError(f'payload must be finite, got {mass}')
        if self._gravity is None:
            raise ValueError('a payload needs the scene gravity')
        if max_change is not None:
            mass = self._payload + min(max(mass - self._payload, -max_change), max_change)
        if mass == self._payload:
            # the loads already carry it: the linearisation (prepared or not) stays valid
            return mass
        self._payload = mass
        size = self._external.size
        self._external[size - 6:size - 3] = self._unloaded[size - 6:size - 3] + mass * (
            self._gravity)
        self._age = self.options.relinearize_every
        return mass

    @property
    def payload(self):
        """Return the payload in the model's loads [kg] (:meth:`set_payload`)."""
        return self._payload

    def set_section_stiffness(self, factors, max_change=None):
        """
        Scale each chain section's link stiffness in the model (e.g. estimated factors).

        The links of section ``j`` become ``factors[j]`` times as stiff as the model's (as a
        scene's ``calibration.section_stiffness`` builds them), so the QP compensates a
        section's stiffness error in the model instead of leaving it to the closed loop's
        correction. It replaces the previous factors; the next linearisation uses them. As for
        :meth:`set_payload`, estimated factors should come in small steps (``max_change``).

        Parameters
        ----------
        factors : (s,) array_like  [-]
            One factor per section, :attr:`section_names` order (1: the model's stiffness).
        max_change : float or None  [-]
            Move each factor toward ``factors`` by at most this (None: all the way).

        Returns
        -------
        (s,) ndarray  [-]
            The factors now in the model.

        Raises
        ------
        ValueError
            If ``factors`` is not one finite value per section within
            :data:`cbha_inverse.core.sections.SECTION_FACTOR_BOUNDS` (a model without
            sections takes none), or ``max_change`` is negative or not finite.

        """
        applied = self._sections.apply(factors, max_change)
        self._age = self.options.relinearize_every
        return applied

    def set_actuator_gain(self, gains, max_change=None):
        """
        Scale each condensed cavity's effective area in the model (e.g. estimated gains).

        Cavity ``j`` then acts ``gains[j]`` times as strongly per Pa as the scene built it (as a
        scene's ``calibration.actuator_gain``); rate-limited and relinearised as
        :meth:`set_section_stiffness`.

        Parameters
        ----------
        gains : (m,) array_like  [-]
            One gain per actuator, :attr:`actuator_names` order (1: the scene's).
        max_change : float or None  [-]
            Move each gain toward ``gains`` by at most this (None: all the way).

        Returns
        -------
        (m,) ndarray  [-]
            The gains now in the model.

        Raises
        ------
        ValueError
            If ``gains`` is not one finite value per actuator within
            :data:`cbha_inverse.core.sections.SECTION_FACTOR_BOUNDS`, ``max_change`` is
            negative or not finite, or the actuators are not condensed cavities.

        """
        refused = check_section_factors(gains, self._m, 'actuator gain')
        if refused is not None:
            raise ValueError(refused[1])
        applied = rate_limited(self._gains, np.asarray(gains, dtype=float), max_change)
        self._tick.scale_cavities(applied)
        self._gains = applied
        self._age = self.options.relinearize_every
        return applied.copy()

    @property
    def actuator_gain(self):
        """Return the actuators' gains in the model, (m,) [-] (:meth:`set_actuator_gain`)."""
        return self._gains.copy()

    @property
    def section_stiffness(self):
        """Return the sections' stiffness factors in the model, (s,) [-]."""
        return self._sections.factors
