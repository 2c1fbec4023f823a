"""
External loads on the chain's frames: forces, torques and masses (``f_ext`` of paper eq. 9).

A :class:`Load` acts at the origin of one frame (1..n, or ``'tip'``: the last frame) and is one
of three kinds:

- a **dead** wrench, fixed in the base frame's axes (the world of the solvers): it keeps its
  direction whatever the chain does (a cable pulling over a pulley, a weight);
- a **follower** wrench, fixed in the frame's own axes: it turns with the frame (a thruster, a
  tool reaction along the tip's axis); in the world it is ``[R_i f; R_i t]``;
- a **mass** [kg], a dead force ``m g`` under the scene's gravity ``g`` (a payload).

:class:`Loads` is an immutable set of named loads (a scene's ``loads`` block, its
``calibration.tip_payload_mass``, a run-time wrench over ROS). Two functions map it onto what
the static solver (:func:`cbha_inverse.core.statics.solve_static`) and the controller take:
:func:`dead_wrenches` gives the (n, 6) world wrenches of the dead loads and masses
(``frame_wrenches``), :func:`follower_hooks` the ``load_function`` and its exact
``load_tangent`` of the follower loads. Wrenches are ``[F; M]`` [N, N*m] at the frame origin
(``docs/design.md``, conventions).
"""

from dataclasses import dataclass
import math

from cbha_inverse.core.chain import checked_array
from cbha_inverse.core.so3 import hat
import numpy as np

FRAMES = ('base', 'local')
"""The axes a wrench can be given in: the base frame's (dead) or its frame's own (follower)."""


@dataclass(frozen=True)
class Load:
    """
    One named load at the origin of one frame.

    Build it with :meth:`wrench` or :meth:`weight`.

    Attributes
    ----------
    name : str
        Unique within a :class:`Loads`.
    frame : int or str
        The frame it acts on: 1..n, or ``'tip'`` (the last frame, n).
    wrench : (6,) tuple of float  [N, N*m]
        ``(Fx, Fy, Fz, Mx, My, Mz)`` in the axes of ``axes`` (zero for a mass).
    axes : str
        ``'base'`` (a dead wrench) or ``'local'`` (a follower wrench, the frame's axes).
    mass : float  [kg]
        A mass under the scene's gravity (0 for a wrench).

    """

    name: str
    frame: object
    wrench: tuple = (0.0,) * 6
    axes: str = 'base'
    mass: float = 0.0

    def __post_init__(self):
        """Check the name, the frame, the axes, the wrench (6 finite) and the mass (>= 0)."""
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f'a load needs a non-empty name, got {self.name!r}')
        frame = self.frame
        if frame != 'tip' and (isinstance(frame, bool) or not isinstance(
                frame, (int, np.integer)) or frame < 1):
            raise ValueError(f"load {self.name!r}: frame must be 'tip' or an index >= 1 "
                             f'(frame 0, the base, does not move), got {frame!r}')
        if self.axes not in FRAMES:
            raise ValueError(f"load {self.name!r}: axes must be 'base' or 'local', got "
                             f'{self.axes!r}')
        wrench = checked_array(self.wrench, (6,), f'load {self.name!r}: wrench')
        object.__setattr__(self, 'wrench', tuple(float(v) + 0.0 for v in wrench))
        object.__setattr__(self, 'frame', frame if frame == 'tip' else int(frame))
        mass = float(self.mass)
        if not (math.isfinite(mass) and mass >= 0.0):
            raise ValueError(f'load {self.name!r}: mass must be finite and >= 0, got {mass}')
        if mass > 0.0 and any(wrench):
            raise ValueError(f'load {self.name!r}: a mass or a wrench, not both')
        object.__setattr__(self, 'mass', mass)

    @classmethod
    def of_wrench(cls, name, frame, force=(0.0, 0.0, 0.0), torque=(0.0, 0.0, 0.0),
                  axes='base'):
        """
        Return a wrench load.

        Parameters
        ----------
        name : str
            Its name.
        frame : int or 'tip'
            The frame it acts on (1..n).
        force : (3,) array_like  [N]
            At the frame origin.
        torque : (3,) array_like  [N*m]
            About the frame origin.
        axes : {'base', 'local'}
            Dead (base-frame axes) or follower (the frame's axes).

        Returns
        -------
        Load

        """
        force = checked_array(force, (3,), f'load {name!r}: force')
        torque = checked_array(torque, (3,), f'load {name!r}: torque')
        return cls(name, frame, tuple(np.concatenate([force, torque])), axes)

    @classmethod
    def of_mass(cls, name, frame, mass):
        """
        Return a mass [kg] at a frame, loaded by the scene's gravity.

        Parameters
        ----------
        name : str
            Its name.
        frame : int or 'tip'
            The frame it hangs on (1..n).
        mass : float  [kg]
            Finite, >= 0.

        Returns
        -------
        Load

        """
        return cls(name, frame, mass=mass)

    def frame_index(self, n_links):
        """Return the frame index (1..n) in a chain of ``n_links`` links; raise if beyond."""
        if self.frame == 'tip':
            return n_links
        if self.frame > n_links:
            raise ValueError(f'load {self.name!r}: frame {self.frame} outside 1..{n_links} '
                             '(or tip)')
        return self.frame


@dataclass(frozen=True)
class Loads:
    """
    An immutable set of named loads (:class:`Load`); empty by default.

    Attributes
    ----------
    items : tuple of Load
        In order; names are unique.

    """

    items: tuple = ()

    def __post_init__(self):
        """Check the items (Load instances, unique names)."""
        items = tuple(self.items)
        names = [item.name for item in items if isinstance(item, Load)]
        if len(names) != len(items):
            raise ValueError('Loads takes Load items')
        twice = sorted({name for name in names if names.count(name) > 1})
        if twice:
            raise ValueError(f'load {twice[0]!r} named twice')
        object.__setattr__(self, 'items', items)

    def __len__(self):
        """Return the number of loads."""
        return len(self.items)

    def __bool__(self):
        """Return whether there is a load."""
        return bool(self.items)

    @property
    def names(self):
        """Return the loads' names, in order."""
        return tuple(item.name for item in self.items)

    @property
    def has_followers(self):
        """Return whether a load is a follower wrench (``axes='local'``)."""
        return any(item.axes == 'local' and any(item.wrench) for item in self.items)

    @property
    def has_masses(self):
        """Return whether a load is a mass."""
        return any(item.mass > 0.0 for item in self.items)

    def updated(self, *loads):
        """
        Return these loads with ``loads`` put in: a load of the same name is replaced.

        Parameters
        ----------
        *loads : Load or Loads
            The loads to put in (a new name is appended).

        Returns
        -------
        Loads

        """
        new = [item for group in loads
               for item in (group.items if isinstance(group, Loads) else (group,))]
        by_name = {item.name: item for item in new}
        kept = [by_name.pop(item.name, item) for item in self.items]
        return Loads(tuple(kept) + tuple(item for item in new if item.name in by_name))

    def without(self, name):
        """Return these loads without the one named ``name`` (unchanged if there is none)."""
        return Loads(tuple(item for item in self.items if item.name != name))

    def checked(self, n_links, gravity):
        """
        Return these loads after checking them against a chain and its gravity.

        Raises
        ------
        ValueError
            If a frame lies beyond the chain, or a mass has no gravity to load it.

        """
        for item in self.items:
            item.frame_index(n_links)
            if item.mass > 0.0 and gravity is None:
                raise ValueError(f'load {item.name!r}: a mass needs gravity (the scene has '
                                 'none)')
        return self


def dead_wrenches(loads, n_links, gravity=None):
    """
    Return the world wrenches of the dead loads and masses on frames 1..n.

    The ``frame_wrenches`` of :func:`cbha_inverse.core.statics.solve_static`: each dead wrench
    as given (base-frame axes), each mass ``m g``; the follower loads are left out
    (:func:`follower_hooks`).

    Parameters
    ----------
    loads : Loads
        The loads.
    n_links : int
        Links of the chain (n).
    gravity : (3,) array_like or None  [m/s^2]
        The scene's gravity (needed by a mass).

    Returns
    -------
    (n, 6) ndarray  [N, N*m]

    Raises
    ------
    ValueError
        As :meth:`Loads.checked`.

    """
    loads.checked(n_links, gravity)
    out = np.zeros((n_links, 6))
    for item in loads.items:
        row = item.frame_index(n_links) - 1
        if item.mass > 0.0:
            out[row, :3] += item.mass * checked_array(gravity, (3,), 'gravity')
        elif item.axes == 'base':
            out[row] += item.wrench
    return out


class FollowerLoads:
    """
    The follower wrenches of a :class:`Loads` as functions of the state, with their tangent.

    ``wrenches(rotations)`` is ``[R_i f; R_i t]`` at each loaded frame (world axes), and
    ``tangent(rotations)`` its load stiffness ``-d/dq`` in the increments of
    :func:`cbha_inverse.core.chain.retract` (``R_i <- exp(dθ_i) R_i``): since
    ``d(R_i f) = dθ_i × R_i f``, the block of frame i's wrench against its rotation is
    ``[[R_i f]×; [R_i t]×]`` (rows force, torque), every other block zero (the load acts at the
    frame origin, which the wrench moves with).

    Parameters
    ----------
    loads : Loads
        The loads (only the follower wrenches are kept).
    n_links : int
        Links of the chain (n).

    """

    def __init__(self, loads, n_links):
        """Gather the follower wrenches per frame."""
        self.n_links = n_links
        rows, local = [], []
        for item in loads.items:
            if item.axes == 'local' and any(item.wrench):
                rows.append(item.frame_index(n_links) - 1)
                local.append(item.wrench)
        self.rows = np.array(rows, dtype=np.int64)
        self.local = np.array(local, dtype=float).reshape(-1, 2, 3)

    def __bool__(self):
        """Return whether there is a follower wrench."""
        return bool(self.rows.size)

    def _world(self, rotations):
        """Return each follower's force and torque in world axes, (k, 2, 3)."""
        rotations = np.asarray(rotations, dtype=float)[self.rows + 1]
        return np.einsum('kab,kjb->kja', rotations, self.local)

    def wrenches(self, rotations):
        """
        Return the follower wrenches on frames 1..n in world axes.

        Parameters
        ----------
        rotations : (n + 1, 3, 3) array_like
            The frame rotations (frame 0 = base).

        Returns
        -------
        (n, 6) ndarray  [N, N*m]

        """
        out = np.zeros((self.n_links, 6))
        np.add.at(out, self.rows, self._world(rotations).reshape(-1, 6))
        return out

    def tangent(self, rotations):
        """
        Return the load stiffness ``-d wrenches / dq`` over frames 1..n (dense).

        Parameters
        ----------
        rotations : (n + 1, 3, 3) array_like
            The frame rotations.

        Returns
        -------
        (6n, 6n) ndarray  [N, N*m] per rad

        """
        out = np.zeros((6 * self.n_links, 6 * self.n_links))
        for row, (force, torque) in zip(self.rows, self._world(rotations)):
            rotation = slice(6 * row + 3, 6 * row + 6)
            out[6 * row:6 * row + 3, rotation] += hat(force)
            out[6 * row + 3:6 * row + 6, rotation] += hat(torque)
        return out


def follower_hooks(loads, n_links):
    """
    Return the ``load_function`` and ``load_tangent`` of the follower loads, or (None, None).

    The hooks of :func:`cbha_inverse.core.statics.solve_static` (:class:`FollowerLoads`): the
    static solver then converges quadratically under follower loads too.

    Parameters
    ----------
    loads : Loads
        The loads.
    n_links : int
        Links of the chain (n).

    Returns
    -------
    load_function : callable or None
        ``state -> (n, 6)`` world wrenches.
    load_tangent : callable or None
        ``state -> (6n, 6n)``.

    """
    followers = FollowerLoads(loads, n_links)
    if not followers:
        return None, None
    return (lambda state: followers.wrenches(state.rotations),
            lambda state: followers.tangent(state.rotations))


def combined_hooks(*hooks):
    """
    Return one ``load_function, load_tangent`` pair: the sum of several.

    For :func:`~cbha_inverse.core.statics.solve_static`, which takes one pair: the loads of a
    :class:`Loads`, tendon drives, contact, ... together.

    Parameters
    ----------
    *hooks : (callable or None, callable or None)
        ``(load_function, load_tangent)`` pairs; None parts are left out.

    Returns
    -------
    load_function, load_tangent : callable or None
        None when no pair has one.

    """
    functions = [function for function, _ in hooks if function is not None]
    tangents = [tangent for _, tangent in hooks if tangent is not None]

    def function(state):
        return sum(part(state) for part in functions)

    def tangent(state):
        parts = [part(state) for part in tangents]
        parts = [part for part in parts if part is not None]
        return sum(parts) if parts else None

    return (function if functions else None), (tangent if tangents else None)


def static_loads(loads, n_links, gravity=None):
    """
    Return the keyword arguments of :func:`~cbha_inverse.core.statics.solve_static` for loads.

    ``frame_wrenches`` (:func:`dead_wrenches`), ``load_function`` and ``load_tangent``
    (:func:`follower_hooks`): the one mapping of a :class:`Loads` onto the static solver (the
    scenes' forward model, the simulated plant, the controller's restoration of equilibrium).

    Parameters
    ----------
    loads : Loads or None
        The loads (None: none).
    n_links : int
        Links of the chain (n).
    gravity : (3,) array_like or None  [m/s^2]
        The scene's gravity (needed by a mass; the chain's own weight is not included here).

    Returns
    -------
    dict

    Raises
    ------
    ValueError
        If ``loads`` is not a :class:`Loads`, or as :meth:`Loads.checked`.

    """
    loads = Loads() if loads is None else loads
    if not isinstance(loads, Loads):
        raise ValueError(f'loads must be a Loads, got {type(loads).__name__}')
    function, tangent = follower_hooks(loads, n_links)
    return {'frame_wrenches': dead_wrenches(loads, n_links, gravity),
            'load_function': function, 'load_tangent': tangent}
