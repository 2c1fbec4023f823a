"""
The chain's sections: which links a section's stiffness factor scales, and how.

A chain built of sections (the CBHA's two, ``Scene.section_links``: ``name -> (first link
index, count)`` in chain order) carries one stiffness factor per section on its links: a scene's
``calibration.section_stiffness`` builds the chain with them
(:func:`cbha_inverse.scene.segments.segment_chain`), the shape estimator estimates them
(:class:`cbha_inverse.estimate.shape.ShapeEstimator`, ``section_stiffness_std``) and the inverse
solver takes them into its model
(:meth:`cbha_inverse.core.inverse.solver.InverseSolver.set_section_stiffness`). All of them read
the membership of :func:`link_sections` and the per-link factors of
:func:`section_link_factors`.
"""

import math

import numpy as np

SECTION_FACTOR_BOUNDS = (0.5, 2.0)
"""The least and the largest section stiffness (or actuator gain) factor a model takes [-]."""


def link_sections(sections, n_links):
    """
    Return the chain section of every link: the membership a section's stiffness factor acts on.

    Parameters
    ----------
    sections : dict
        ``name -> (first link index, count)`` (:func:`cbha_inverse.scene.segments.segment_chain`,
        :attr:`cbha_inverse.scene.scene.Scene.section_links`), in chain order.
    n_links : int
        Links of the chain.

    Returns
    -------
    (n_links,) int ndarray
        Index of each link's section in ``sections``' order, -1 for a link of none.

    """
    out = np.full(n_links, -1, dtype=np.int64)
    for index, (first, count) in enumerate(sections.values()):
        out[first:first + count] = index
    return out


def section_link_factors(sections, factors, n_links):
    """
    Return the stiffness factor of every link: its section's entry of ``factors``, else 1.

    Parameters
    ----------
    sections : dict
        ``name -> (first link index, count)``, as :func:`link_sections`.
    factors : dict of str to float
        Section name -> factor on its links' stiffness (a name not given: 1).
    n_links : int
        Links of the chain.

    Returns
    -------
    (n_links,) ndarray  [-]

    """
    per_section = np.array([factors.get(name, 1.0) for name in sections] + [1.0])
    return per_section[link_sections(sections, n_links)]


def check_section_factors(factors, n_sections, what='section'):
    """
    Check a vector of section stiffness (or actuator gain) factors; return why it is refused.

    Parameters
    ----------
    factors : array_like
        One factor per section [-], in the sections' chain order (or one per actuator).
    n_sections : int
        Sections of the chain (or actuators).
    what : str
        What the factors scale, for the detail (``'section'``, ``'actuator gain'``).

    Returns
    -------
    tuple of str or None
        ``(reason, detail)``, the reason ``'wrong_length'``, ``'not_finite'`` or
        ``'out_of_range'`` (outside :data:`SECTION_FACTOR_BOUNDS`); None when accepted.

    """
    values = np.asarray(factors, dtype=float).reshape(-1)
    if values.size != n_sections or np.ndim(factors) > 1:
        return 'wrong_length', f'{values.size} {what} factors, expected {n_sections}'
    if not np.all(np.isfinite(values)):
        return 'not_finite', f'{what} factors {values.tolist()} are not finite'
    low, high = SECTION_FACTOR_BOUNDS
    if np.any(values < low) or np.any(values > high):
        return 'out_of_range', (f'{what} factors {values.tolist()} outside '
                                f'[{low:g}, {high:g}]')
    return None


def rate_limited(current, target, max_change):
    """
    Return ``target`` reached from ``current`` by at most ``max_change`` per entry.

    Parameters
    ----------
    current, target : (s,) ndarray
        The values now and the values asked for.
    max_change : float or None
        Largest change of an entry (None: all the way).

    Returns
    -------
    (s,) ndarray

    Raises
    ------
    ValueError
        If ``max_change`` is negative or not finite.

    """
    if max_change is None:
        return np.array(target, dtype=float)
    if not (math.isfinite(max_change) and max_change >= 0.0):
        raise ValueError(f'max_change must be a non-negative number, got {max_change}')
    return current + np.clip(target - current, -max_change, max_change)


class SectionStiffness:
    """
    The links' stiffness of a model whose sections carry stiffness factors (a solver's copy).

    Parameters
    ----------
    nominal : (n, 6, 6) ndarray
        The model's link stiffness (``ChainModel.stiffnesses``), factors 1.
    sections : dict
        ``name -> (first link index, count)`` in chain order (:func:`link_sections`).

    Attributes
    ----------
    stiffness : (n, 6, 6) ndarray
        A read-only view of the scaled stiffness, for
        :class:`cbha_inverse.core.system.EquilibriumSystem` (``stiffness=``): read-only as the
        model's own, so the compiled kernels see the type they were compiled for.
    names : tuple of str
        The sections, in the order of the factors.
    factors : (s,) ndarray  [-]
        The factors applied (a copy).

    """

    def __init__(self, nominal, sections):
        """Start from the nominal stiffness (every factor 1)."""
        self._nominal = np.array(nominal, dtype=float)
        self._scaled = self._nominal.copy()
        self.stiffness = self._scaled.view()
        self.stiffness.setflags(write=False)
        self._sections = dict(sections)
        self.names = tuple(self._sections)
        self._factors = np.ones(len(self.names))

    @property
    def factors(self):
        """Return the factors applied, (s,) [-]."""
        return self._factors.copy()

    def apply(self, factors, max_change=None):
        """
        Scale each section's links by its factor (toward it by at most ``max_change``).

        Parameters
        ----------
        factors : (s,) array_like  [-]
            Stiffness factor of each section (1: the model's), in :attr:`names` order.
        max_change : float or None  [-]
            Move each factor toward ``factors`` by at most this (None: all the way).

        Returns
        -------
        (s,) ndarray  [-]
            The factors now applied.

        Raises
        ------
        ValueError
            If ``factors`` is not ``s`` finite values within :data:`SECTION_FACTOR_BOUNDS`, or
            ``max_change`` is negative or not finite.

        """
        refused = check_section_factors(factors, len(self.names))
        if refused is not None:
            raise ValueError(refused[1])
        target = np.asarray(factors, dtype=float).reshape(-1)
        self._factors = rate_limited(self._factors, target, max_change)
        scales = section_link_factors(self._sections, dict(zip(self.names, self._factors)),
                                      self._nominal.shape[0])
        np.multiply(self._nominal, scales[:, None, None], out=self._scaled)
        return self.factors
