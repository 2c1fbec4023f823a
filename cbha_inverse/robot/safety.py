"""
Input validation and fail-safe decisions of the nodes (pure, no ROS; see ``docs/nodes.md``).

The nodes call these functions on every message and before every publication:

- :func:`check_point` accepts a target or a measured point only if it is finite, in the expected
  frame and inside the configured workspace box;
- :func:`valve_order` checks a node's ``valve_names`` (the command order) against the scene's
  actuators once, at start;
- :func:`command_bounds` are the bounds of every command a node sends: the scene's actuator
  bounds within ``[0, max_pressure]``;
- :func:`check_command` is what a real valve driver does with an incoming command (exact length,
  finite, within ``[0, p_max]``);
- :func:`bounded_command` (:class:`CommandGate` for fixed bounds) is the last gate before a
  command is published: it never lets a NaN or an out-of-range pressure through;
- :class:`StalenessWatch`, :func:`stale_action` and :func:`controller_decision` decide when to
  hold or vent (stale feedback; a stale target stays the set-point), on a steady clock
  (``time.monotonic``) passed in by the caller, so that a bag replay or ``use_sim_time`` cannot
  fool the watchdog; :func:`watchdog_action` is what a watchdog tick then publishes;
  :class:`SilenceWarning` says when to warn that an input (the driver's readings) is missing.
"""

from dataclasses import dataclass
import math

from cbha_inverse.core.input_checks import vector_fault
import numpy as np

ACTIONS = ('hold', 'vent')


@dataclass(frozen=True)
class Check:
    """
    Outcome of an input check.

    Attributes
    ----------
    ok : bool
        Whether the input is accepted.
    reason : str
        ``'ok'`` or a short category (``'non_finite'``, ``'wrong_frame'``, ``'outside_workspace'``,
        ``'wrong_length'``, ``'out_of_range'``) used as a diagnostics counter key.
    detail : str
        Human-readable explanation for the (throttled) log.

    """

    ok: bool
    reason: str = 'ok'
    detail: str = ''


ACCEPTED = Check(True)


@dataclass(frozen=True)
class WorkspaceBox:
    """
    Axis-aligned box of plausible points [m] in the base frame.

    Parameters
    ----------
    lower, upper : (3,) array_like  [m]
        Corners, ``lower < upper`` component-wise, finite.

    """

    lower: tuple
    upper: tuple

    def __post_init__(self):
        """Validate the corners."""
        lower = np.asarray(self.lower, dtype=float)
        upper = np.asarray(self.upper, dtype=float)
        if lower.shape != (3,) or upper.shape != (3,):
            raise ValueError('workspace box corners must have 3 components each')
        if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
            raise ValueError('workspace box corners must be finite')
        if not np.all(lower < upper):
            raise ValueError(f'workspace box lower {lower.tolist()} must be below upper '
                             f'{upper.tolist()} in every axis')
        object.__setattr__(self, 'lower', tuple(float(v) for v in lower))
        object.__setattr__(self, 'upper', tuple(float(v) for v in upper))

    def contains(self, point):
        """Return whether a (3,) point lies inside the closed box (NaN: outside)."""
        values = point_floats(point)
        if values is None:
            raise ValueError(f'a workspace point has 3 components: {point!r}')
        # unpacked, no generator: this runs on every target and measurement (docs/nodes.md,
        # "Latency")
        x, y, z = values
        (x_low, y_low, z_low), (x_high, y_high, z_high) = self.lower, self.upper
        return x_low <= x <= x_high and y_low <= y <= y_high and z_low <= z <= z_high


def point_floats(point):
    """
    Return a point as three Python floats, or None when it is not three numbers.

    Parameters
    ----------
    point : (3,) array_like  [m]
        The point; a ``list`` of three ``float`` (a message's fields, as the nodes pass them)
        is returned as it is, without an array.

    Returns
    -------
    list of 3 float or None

    """
    if type(point) is list and len(point) == 3:
        x, y, z = point
        if type(x) is float and type(y) is float and type(z) is float:
            return point
    try:
        array = np.asarray(point, dtype=float)
    except (TypeError, ValueError):
        return None
    return array.tolist() if array.shape == (3,) else None


def check_point(point, frame_id, expected_frame, box):
    """
    Validate a target or a measured point.

    Parameters
    ----------
    point : (3,) array_like  [m]
        The point.
    frame_id : str
        Its header frame.
    expected_frame : str
        The only accepted frame (no TF here: points must already be in the base frame).
    box : WorkspaceBox or None
        Plausible region (None: any finite point, e.g. the end of a velocity vector).

    Returns
    -------
    Check
        Accepted, or the first reason for rejection (non-finite, wrong frame, outside box).

    """
    # three Python floats per message, no array: this runs on every target and measurement, where
    # each numpy call costs tens of microseconds with the caches cold (docs/nodes.md, "Latency")
    values = point_floats(point)
    if values is None or not all(map(math.isfinite, values)):
        shown = point if values is None else values
        return Check(False, 'non_finite', f'non-finite point {shown}')
    if frame_id != expected_frame:
        return Check(False, 'wrong_frame',
                     f'frame {frame_id!r} is not the expected {expected_frame!r}')
    if box is not None and not box.contains(values):
        return Check(False, 'outside_workspace',
                     f'point {[float(f"{v:.6g}") for v in values]} outside the workspace box '
                     f'{list(box.lower)}..{list(box.upper)}')
    return ACCEPTED


def valve_order(actuator_names, valve_names=None):
    """
    Return a node's command order and the scene actuator of each command entry.

    Parameters
    ----------
    actuator_names : sequence of str
        The scene's actuators, in scene order.
    valve_names : sequence of str, optional
        The command order (a node's ``valve_names``); None: the scene order.

    Returns
    -------
    valve_names : tuple of str
        The command order.
    order : (m,) int ndarray
        ``order[k]``: the scene index of command entry ``k`` (scene vector ``x`` as a command:
        ``x[order]``).

    Raises
    ------
    ValueError
        Unless ``valve_names`` is a permutation of the actuators.

    """
    names = tuple(actuator_names)
    valves = names if valve_names is None else tuple(valve_names)
    if sorted(valves) != sorted(names):
        raise ValueError(f'valve_names {list(valves)} must be a permutation of the scene '
                         f'actuators {list(names)}')
    return valves, np.array([names.index(name) for name in valves], dtype=int)


def command_bounds(lower_bounds, upper_bounds, max_pressure=None):
    """
    Return the bounds of the commands a node sends: actuator bounds a valve driver accepts.

    Parameters
    ----------
    lower_bounds, upper_bounds : (m,) array_like  [Pa or N]
        The scene's actuator bounds (in any order, e.g. a node's ``valve_names`` order).
    max_pressure : float, optional  [Pa]
        The driver's limit (a node's ``max_pressure``); None: no cap.

    Returns
    -------
    lower, upper : (m,) ndarray  [Pa or N]
        ``max(lower_bounds, 0)`` and ``min(upper_bounds, max_pressure)``.

    Raises
    ------
    ValueError
        If the cap lies below a lower bound.

    """
    lower = np.maximum(np.asarray(lower_bounds, dtype=float), 0.0)
    upper = np.array(upper_bounds, dtype=float)
    if max_pressure is not None:
        upper = np.minimum(upper, float(max_pressure))
    if np.any(lower > upper):
        if max_pressure is None:
            raise ValueError('an upper actuator bound lies below its lower bound (or below 0)')
        raise ValueError(f'max_pressure {max_pressure:g} Pa is below a lower actuator bound of '
                         'the scene')
    return lower, upper


def check_command(values, n_valves, max_pressure):
    """
    Validate an incoming pressure command as a valve driver does.

    Parameters
    ----------
    values : sequence of float  [Pa]
        The command (``Float64MultiArray.data``).
    n_valves : int
        Required length.
    max_pressure : float  [Pa]
        Largest accepted gauge pressure (``p_max``).

    Returns
    -------
    Check
        Accepted, or why not (wrong length, non-finite, out of ``[0, p_max]``).

    """
    _, key, detail = vector_fault(values, n_valves, 'pressure', 0.0, max_pressure, ' Pa')
    return ACCEPTED if key is None else Check(False, key, detail)


def check_displacement_command(values, n_drives, reach):
    """
    Validate an incoming tendon displacement command (position-controlled drives).

    Parameters
    ----------
    values : sequence of float  [m]
        The command (``Float64MultiArray.data``): drive displacements from rest.
    n_drives : int
        Required length.
    reach : float  [m]
        Largest accepted pull-in or let-out.

    Returns
    -------
    Check
        Accepted, or why not (wrong length, non-finite, out of ``[-reach, reach]``).

    """
    _, key, detail = vector_fault(values, n_drives, 'displacement', -reach, reach, ' m')
    return ACCEPTED if key is None else Check(False, key, detail)


def bounded_command(values, lower, upper):
    """
    Clip a command to its bounds; the last gate before publication.

    Parameters
    ----------
    values : (m,) array_like  [Pa]
        Proposed command.
    lower, upper : (m,) array_like  [Pa]
        Bounds (finite, ``lower <= upper``).

    Returns
    -------
    (m,) ndarray  [Pa]
        ``clip(values, lower, upper)``, guaranteed finite and within the bounds.

    Raises
    ------
    ValueError
        If ``values`` is not finite or not of length m (the caller must keep its last valid
        command: a NaN is never clipped into a plausible number), or the bounds are not finite
        with ``lower <= upper``.

    """
    return CommandGate(lower, upper)(values)


class CommandGate:
    """
    The last gate before publication, for fixed bounds: :func:`bounded_command` per command.

    A node that publishes at the tick rate builds one gate: the bounds are checked once, and a
    command (an (m,) float array) is checked and clipped as m Python floats, a few microseconds
    even with the caches cold where numpy's calls cost tens each (``docs/nodes.md``, "Latency").

    Parameters
    ----------
    lower, upper : (m,) array_like  [Pa]
        Bounds: finite, ``lower <= upper``.

    Raises
    ------
    ValueError
        On bounds of different lengths, not finite, or with ``lower > upper``.

    """

    def __init__(self, lower, upper):
        """Check the bounds once."""
        lower = np.asarray(lower, dtype=float).reshape(-1)
        upper = np.asarray(upper, dtype=float).reshape(-1)
        if lower.shape != upper.shape:
            raise ValueError(f'command bounds of {lower.size} and {upper.size} values')
        if not (np.isfinite(lower).all() and np.isfinite(upper).all() and (lower <= upper).all()):
            raise ValueError(f'command bounds must be finite with lower <= upper: '
                             f'{lower.tolist()}..{upper.tolist()}')
        self.size = lower.size
        self._lower = lower.tolist()
        self._upper = upper.tolist()

    def __call__(self, values):
        """
        Return the command clipped to the bounds.

        Parameters
        ----------
        values : (m,) array_like  [Pa]
            Proposed command.

        Returns
        -------
        (m,) float ndarray  [Pa]
            Finite, within the bounds.

        Raises
        ------
        ValueError
            If ``values`` is not finite or not of length m.

        """
        floats = None
        if type(values) is np.ndarray and values.dtype == np.float64 and values.ndim == 1:
            floats = values.tolist()
        if floats is None or len(floats) != self.size or not all(map(math.isfinite, floats)):
            # any other input, and every fault: the checks and words of the other inputs
            array, key, detail = vector_fault(values, self.size, 'values')
            if key is not None:
                raise ValueError(f'command: {detail}')
            floats = array.tolist()
        return np.array([low if value < low else high if value > high else value
                         for low, value, high in zip(self._lower, floats, self._upper)])


class StalenessWatch:
    """
    Age of the last valid input on a steady clock.

    Parameters
    ----------
    timeout : float  [s]
        Age beyond which the input is stale (> 0).

    """

    def __init__(self, timeout):
        """Start with no input received (stale)."""
        timeout = float(timeout)
        if not math.isfinite(timeout) or timeout <= 0.0:
            raise ValueError(f'timeout must be a finite number > 0, got {timeout}')
        self.timeout = timeout
        self.last = None

    def mark(self, now):
        """Record a valid input at steady time ``now`` [s]."""
        self.last = float(now)

    def age(self, now):
        """Return the age [s] of the last valid input (``inf`` if none yet)."""
        return math.inf if self.last is None else float(now) - self.last

    def stale(self, now):
        """Return whether no valid input arrived within ``timeout`` before ``now``."""
        return self.age(now) > self.timeout


def stale_action(feedback_stale, closed_loop, action):
    """
    Decide what the controller does this tick.

    A target that stops arriving is not stale in this sense: the last valid target stays the
    set-point and the model keeps converging to it. What holds or vents is stale *feedback*: a
    closed loop without a recent measurement cannot correct its model.

    Parameters
    ----------
    feedback_stale : bool
        No valid measurement within its timeout.
    closed_loop : bool
        Whether the controller needs feedback (closed-loop mode).
    action : str
        Configured reaction to stale feedback: ``'hold'`` (keep the last command) or ``'vent'``
        (command the safe pressure).

    Returns
    -------
    str
        ``'run'`` (solve and publish), ``'hold'`` or ``'vent'``.

    """
    if action not in ACTIONS:
        raise ValueError(f'action must be one of {ACTIONS}, got {action!r}')
    if closed_loop and feedback_stale:
        return action
    return 'run'


def controller_decision(enabled, has_target, feedback_stale, closed_loop, action,
                        has_feedback=True):
    """
    Decide what the controller does this tick, from its state and :func:`stale_action`.

    A closed loop that has never had a measurement waits (it has nothing to hold: no command
    was computed from feedback yet).

    Parameters
    ----------
    enabled : bool
        Whether commanding is enabled (``~/enable``).
    has_target : bool
        Whether a valid target has arrived.
    feedback_stale, closed_loop : bool
        See :func:`stale_action`.
    action : str
        ``'hold'`` or ``'vent'``, see :func:`stale_action`.
    has_feedback : bool
        Whether a valid measurement has ever arrived.

    Returns
    -------
    str
        ``'disabled'``, ``'waiting'`` (no target yet; closed loop: or no measurement yet),
        ``'run'``, ``'hold'`` or ``'vent'``.

    """
    if not enabled:
        return 'disabled'
    if not has_target or (closed_loop and not has_feedback):
        return 'waiting'
    return stale_action(feedback_stale, closed_loop, action)


class SilenceWarning:
    """
    When to warn that an input does not arrive.

    Once it is silent for its timeout, then at most every ``period`` while it stays silent.

    Parameters
    ----------
    timeout : float  [s]
        Silence (since the last input, or since ``start`` before the first) that is worth a
        warning.
    period : float  [s]
        Least time between two warnings of one silence (> 0).
    start : float  [s]
        Steady time at which the input could first arrive (the node's start).

    """

    def __init__(self, timeout, period, start):
        """Start silent since ``start``, not yet warned."""
        if not period > 0.0:
            raise ValueError(f'period must be > 0, got {period}')
        self.timeout = float(timeout)
        self.period = float(period)
        self.start = float(start)
        self.warned = None

    def due(self, now, last):
        """
        Return whether to warn now.

        Parameters
        ----------
        now : float  [s]
            Steady time.
        last : float or None  [s]
            Steady time of the last input (None: none yet).

        Returns
        -------
        bool
            True on the first tick of a silence beyond ``timeout``, then once every ``period``;
            an input ends the silence (the next one is warned again).

        """
        silent = now - (self.start if last is None else last)
        if silent <= self.timeout:
            self.warned = None
            return False
        if self.warned is None or now - self.warned >= self.period:
            self.warned = now
            return True
        return False


def watchdog_action(decision, publish_idle):
    """
    Return what a watchdog tick (steady clock) publishes for a decision.

    Parameters
    ----------
    decision : str
        ``'hold'``, ``'vent'``, ``'waiting'`` (no valid input yet), ``'run'`` or ``'disabled'``.
    publish_idle : bool
        Whether the vent command is published while waiting for the first valid input.

    Returns
    -------
    str or None
        ``'hold'`` (the last command again), ``'vent'`` (the safe command) or None (nothing: a
        running loop publishes on its own, a disabled one not at all).

    """
    if decision in ACTIONS:
        return decision
    if decision == 'waiting' and publish_idle:
        return 'vent'
    return None
