"""
The named excitation programs of a scene whose actuators are grouped by chain section.

The sections are :attr:`cbha_inverse.scene.Scene.actuator_sections` (e.g. the CBHA's inner and
outer tubes):

- ``<section>_bends`` (``outer_bends``, ``inner_bends``): for each actuator k of that section, k
  at its upper bound, the section's other actuators at their lower bounds, every other
  actuator at mid range;
- ``bends``: the bends of every section, in chain order;
- ``extension``: every actuator at the fractions :data:`EXTENSION_FRACTIONS` of its range;
- ``all``: ``extension`` then ``bends``.

Holding each section bent to its extremes for a few seconds pins its absolute stiffness, which
a circle lap alone determines only weakly (``docs/identify.md``).
"""

from cbha_inverse.identify.excitation.program import check_bounds
import numpy as np

EXTENSION_FRACTIONS = (0.0, 0.25, 0.5, 0.75, 1.0)
"""Fractions of each actuator's range held by the ``extension`` program."""


def section_groups(actuator_sections):
    """
    Group actuators by chain section.

    Parameters
    ----------
    actuator_sections : sequence of (str or None)
        The section of each actuator (:attr:`cbha_inverse.scene.Scene.actuator_sections`).

    Returns
    -------
    dict of str to tuple of int
        Section -> its actuators' indices, sections in order of first appearance.

    """
    groups = {}
    for k, section in enumerate(actuator_sections):
        if section is not None:
            groups.setdefault(section, []).append(k)
    return {name: tuple(indices) for name, indices in groups.items()}


def bend_holds(lower, upper, groups, sections=None, names=None):
    """
    Return the holds that bend each section to its extremes, one actuator at a time.

    For each section s (in order) and each actuator k of s: k at its upper bound, the other
    actuators of s at their lower bounds, every actuator outside s at mid range.

    Parameters
    ----------
    lower, upper : (m,) array_like  [Pa]
        Actuator bounds.
    groups : mapping of str to sequence of int
        Section -> actuator indices (:func:`section_groups`).
    sections : sequence of str, optional
        The sections to bend (default: all of ``groups``, in its order).
    names : sequence of str, optional
        Actuator names for the labels (default ``'actuator k'``).

    Returns
    -------
    holds : (n, m) ndarray  [Pa]
    labels : tuple of str

    """
    lower, upper = check_bounds(lower, upper)
    mid = 0.5 * (lower + upper)
    sections = list(groups) if sections is None else list(sections)
    rows, labels = [], []
    for section in sections:
        members = np.asarray(groups[section], dtype=int)
        for k in members:
            row = mid.copy()
            row[members] = lower[members]
            row[k] = upper[k]
            rows.append(row)
            label = names[k] if names is not None else f'actuator {k}'
            labels.append(f'{section} bend: {label} max, other {section} min, rest mid')
    if not rows:
        raise ValueError('no section with actuators to bend')
    return np.array(rows), tuple(labels)


def extension_holds(lower, upper, fractions=EXTENSION_FRACTIONS):
    """
    Return the holds of a pure extension: every actuator at the same fraction of its range.

    Parameters
    ----------
    lower, upper : (m,) array_like  [Pa]
        Actuator bounds.
    fractions : sequence of float
        Fractions in [0, 1], one hold each.

    Returns
    -------
    holds : (len(fractions), m) ndarray  [Pa]
        ``lower + f (upper - lower)``.
    labels : tuple of str

    """
    lower, upper = check_bounds(lower, upper)
    fractions = np.asarray(fractions, dtype=float).reshape(-1)
    if fractions.size == 0 or not np.all((fractions >= 0.0) & (fractions <= 1.0)):
        raise ValueError(f'fractions must lie in [0, 1], got {fractions.tolist()}')
    holds = lower + fractions[:, None] * (upper - lower)
    return holds, tuple(f'extension: every actuator at {f:g} of its range' for f in fractions)


def program_names(actuator_sections):
    """
    Return the named programs available for a scene.

    Parameters
    ----------
    actuator_sections : sequence of (str or None)
        The section of each actuator.

    Returns
    -------
    tuple of str
        ``'extension'``, and with sections ``'bends'``, ``'all'`` and one
        ``'<section>_bends'`` per section.

    """
    sections = tuple(section_groups(actuator_sections))
    if not sections:
        return ('extension',)
    return ('all', 'bends', 'extension') + tuple(f'{s}_bends' for s in sections)


def named_holds(name, lower, upper, actuator_sections, names=None):
    """
    Return the holds of a named program (see the module).

    Parameters
    ----------
    name : str
        One of :func:`program_names`.
    lower, upper : (m,) array_like  [Pa]
        Actuator bounds.
    actuator_sections : sequence of (str or None)
        The section of each actuator.
    names : sequence of str, optional
        Actuator names, for the labels.

    Returns
    -------
    holds : (n, m) ndarray  [Pa]
    labels : tuple of str

    Raises
    ------
    ValueError
        If ``name`` is not a program of this scene.

    """
    known = program_names(actuator_sections)
    if name not in known:
        raise ValueError(f'unknown excitation program {name!r} (this scene has {list(known)}, '
                         'or give a YAML file of holds)')
    groups = section_groups(actuator_sections)
    if name == 'extension':
        return extension_holds(lower, upper)
    if name == 'bends':
        return bend_holds(lower, upper, groups, names=names)
    if name == 'all':
        extension, extension_labels = extension_holds(lower, upper)
        bends, bend_labels = bend_holds(lower, upper, groups, names=names)
        return np.vstack([extension, bends]), extension_labels + bend_labels
    return bend_holds(lower, upper, groups, [name[:-len('_bends')]], names=names)
