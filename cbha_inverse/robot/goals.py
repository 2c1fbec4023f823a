"""
Trajectory goals of named effectors: validation, approach, interpolation, tolerances (no ROS).

The functional core of the ``~/follow_trajectory`` action of ``inverse_solver``
(``docs/commanding.md``). A goal gives, for some of the scene's effectors, positions at times
from its start (the ``multi_dof_trajectory`` of ``control_msgs/FollowJointTrajectory``:
``joint_names`` are effector names, ``transforms[i].translation`` their positions). It runs as
one piecewise-linear path per effector sampled at the solver's ticks:

1. an approach from where the effectors are when the goal starts to its first waypoint, no
   faster than ``approach_speed`` (the goal's times are shifted later when its first
   ``time_from_start`` leaves too little time for that);
2. straight lines between the waypoints, at their times;
3. the last waypoint held until every effector is within its goal tolerance (success), or
   ``goal_time_tolerance`` after the last time has passed (goal tolerance violated).

While the path runs, an effector farther than its path tolerance from its desired position
aborts the goal. Tolerances are distances [m] per effector (``JointTolerance.position`` of the
effector's name): > 0 a bound, 0 the node's default, < 0 none. The positions are (k, 3)
batch-first in the scene's base frame, in goal order (``TrajectoryGoal.effectors``); an
orientation of each effector would be one more array of the same layout beside ``positions``
(and its tolerance beside the distance ones).

The result codes are those of ``control_msgs/action/FollowJointTrajectory.Result``.
"""

from dataclasses import dataclass
import math

import numpy as np

SUCCESSFUL = 0
INVALID_GOAL = -1
INVALID_JOINTS = -2
PATH_TOLERANCE_VIOLATED = -4
GOAL_TOLERANCE_VIOLATED = -5
CODE_NAMES = {SUCCESSFUL: 'SUCCESSFUL', INVALID_GOAL: 'INVALID_GOAL',
              INVALID_JOINTS: 'INVALID_JOINTS', PATH_TOLERANCE_VIOLATED: 'PATH_TOLERANCE_VIOLATED',
              GOAL_TOLERANCE_VIOLATED: 'GOAL_TOLERANCE_VIOLATED'}
"""The name of each result code."""


class GoalError(ValueError):
    """A goal refused before it runs: ``code`` (a result code) and the reason (the message)."""

    def __init__(self, code, text):
        super().__init__(text)
        self.code = code


@dataclass(frozen=True)
class GoalOutcome:
    """
    How a goal ended.

    Attributes
    ----------
    code : int
        A result code (:data:`SUCCESSFUL`, ...).
    text : str
        What happened, with the effector and its distance.
    errors : (k,) ndarray  [m]
        Each effector's distance to its desired position at the end.

    """

    code: int
    text: str
    errors: np.ndarray

    @property
    def succeeded(self):
        """Whether the goal was reached."""
        return self.code == SUCCESSFUL


@dataclass(frozen=True, eq=False)
class TrajectoryGoal:
    """
    A checked goal.

    Attributes
    ----------
    effectors : tuple of str
        The effectors the goal moves, in its order (k of them).
    indices : (k,) ndarray of int
        Their indices in the scene's effector order.
    times : (n,) ndarray  [s]
        The waypoints' times from the goal's start, >= 0 and strictly increasing.
    positions : (n, k, 3) ndarray  [m]
        The waypoints (base frame).
    path_tolerance, goal_tolerance : (k,) ndarray  [m]
        Per effector (``inf``: none).
    goal_time_tolerance : float  [s]
        Time after the last waypoint's time the goal tolerance may take to be met.

    """

    effectors: tuple
    indices: np.ndarray
    times: np.ndarray
    positions: np.ndarray
    path_tolerance: np.ndarray
    goal_tolerance: np.ndarray
    goal_time_tolerance: float


def _tolerances(tolerances, effectors, default, what):
    """Return the (k,) tolerances [m] of a goal from ``name -> value`` (see the module doc)."""
    unknown = sorted(set(tolerances) - set(effectors))
    if unknown:
        raise GoalError(INVALID_JOINTS, f'{what} names {unknown}, not effectors of the goal '
                        f'{list(effectors)}')
    values = []
    for name in effectors:
        value = float(tolerances.get(name, 0.0))
        if math.isnan(value):
            raise GoalError(INVALID_GOAL, f'{what} of {name} is NaN')
        value = default if value == 0.0 else value
        values.append(math.inf if value <= 0.0 else value)
    return np.array(values)


def make_goal(scene_effectors, effectors, times, positions, *, path_tolerance=None,
              goal_tolerance=None, goal_time_tolerance=0.0, defaults=(0.0, 0.001, 1.0),
              reach=None, reach_margin=0.0):
    """
    Check a goal and return it as a :class:`TrajectoryGoal`.

    Parameters
    ----------
    scene_effectors : sequence of str
        The scene's effector names.
    effectors : sequence of str
        The goal's effectors (``joint_names``), each once.
    times : (n,) array_like  [s]
        The waypoints' times from the start (``time_from_start``).
    positions : (n, k, 3) array_like  [m]
        The waypoints.
    path_tolerance, goal_tolerance : dict, optional
        ``effector name -> distance [m]`` (> 0 a bound, 0 or absent the default, < 0 none).
    goal_time_tolerance : float  [s]
        > 0 the time allowed after the last waypoint, 0 the default.
    defaults : tuple of float
        The defaults: path tolerance [m], goal tolerance [m], goal time tolerance [s]
        (a path or goal tolerance <= 0: none).
    reach : sequence or None
        One object per scene effector with ``outside_distance(points) -> (n,) [m]``
        (:meth:`cbha_inverse.scene.reach.ReachableSet.outside_distance`), or None: no check.
    reach_margin : float  [m]
        A waypoint up to this far beyond the reach is accepted.

    Returns
    -------
    TrajectoryGoal

    Raises
    ------
    GoalError
        ``INVALID_JOINTS`` for no, unknown or repeated effector names; ``INVALID_GOAL`` for a
        goal without waypoints, of the wrong shape, with a non-finite value, times that are
        negative or not strictly increasing, or a waypoint beyond the reach (named, with its
        distance).

    """
    effectors = tuple(str(name) for name in effectors)
    scene_effectors = tuple(scene_effectors)
    if not effectors:
        raise GoalError(INVALID_JOINTS, 'the goal names no effector (multi_dof_trajectory.'
                        f'joint_names); the scene has {list(scene_effectors)}')
    unknown = [name for name in effectors if name not in scene_effectors]
    if unknown:
        raise GoalError(INVALID_JOINTS, f'unknown effectors {unknown}; the scene has '
                        f'{list(scene_effectors)}')
    if len(set(effectors)) != len(effectors):
        raise GoalError(INVALID_JOINTS, f'effectors named twice in {list(effectors)}')
    times = np.asarray(times, dtype=float).reshape(-1)
    positions = np.asarray(positions, dtype=float)
    if times.size == 0:
        raise GoalError(INVALID_GOAL, 'the goal has no waypoint')
    if positions.shape != (times.size, len(effectors), 3):
        raise GoalError(INVALID_GOAL, f'waypoints must have shape ({times.size}, '
                        f'{len(effectors)}, 3), got {positions.shape}')
    if not np.all(np.isfinite(times)):
        raise GoalError(INVALID_GOAL, f'waypoint {int(np.argmin(np.isfinite(times)))}: '
                        'time_from_start is not finite')
    bad = ~np.all(np.isfinite(positions), axis=(1, 2))
    if np.any(bad):
        raise GoalError(INVALID_GOAL, f'waypoint {int(np.argmax(bad))}: a position is not '
                        'finite')
    if times[0] < 0.0:
        raise GoalError(INVALID_GOAL, f'waypoint 0: time_from_start {times[0]:g} s < 0')
    steps = np.diff(times)
    if np.any(steps <= 0.0):
        i = int(np.argmax(steps <= 0.0)) + 1
        raise GoalError(INVALID_GOAL, f'waypoint {i}: time_from_start {times[i]:g} s does not '
                        f'come after that of waypoint {i - 1} ({times[i - 1]:g} s)')
    indices = np.array([scene_effectors.index(name) for name in effectors])
    if reach is not None:
        for j, index in enumerate(indices):
            distance = np.asarray(reach[index].outside_distance(positions[:, j]))
            far = distance > reach_margin
            if np.any(far):
                i = int(np.argmax(distance))
                raise GoalError(INVALID_GOAL, f'waypoint {i}: {effectors[j]} at '
                                f'{np.round(positions[i, j], 4).tolist()} m is '
                                f'{1e3 * distance[i]:.1f} mm beyond its reachable set '
                                f'({int(np.count_nonzero(far))} waypoints beyond it)')
    default_path, default_goal, default_time = (float(v) for v in defaults)
    time_tolerance = float(goal_time_tolerance)
    if not time_tolerance >= 0.0 or not math.isfinite(time_tolerance):
        raise GoalError(INVALID_GOAL, f'goal_time_tolerance {time_tolerance:g} s is not a '
                        'finite number >= 0')
    return TrajectoryGoal(
        effectors=effectors, indices=indices, times=times, positions=positions,
        path_tolerance=_tolerances(path_tolerance or {}, effectors, default_path,
                                   'path_tolerance'),
        goal_tolerance=_tolerances(goal_tolerance or {}, effectors, default_goal,
                                   'goal_tolerance'),
        goal_time_tolerance=time_tolerance or default_time)


@dataclass(frozen=True, eq=False)
class GoalPlan:
    """
    The path a goal runs: knots at times from its start, linear in between.

    Attributes
    ----------
    times : (n + 1,) ndarray  [s]
        0 (the start) then the waypoints' times, delayed by ``delay``.
    positions : (n + 1, k, 3) ndarray  [m]
        The start positions, then the waypoints.
    delay : float  [s]
        How much later than their ``time_from_start`` the waypoints come (a slow approach).

    """

    times: np.ndarray
    positions: np.ndarray
    delay: float

    @property
    def end_time(self):
        """Return the last waypoint's time from the start [s]."""
        return float(self.times[-1])

    def desired(self, elapsed):
        """
        Return the desired positions at a time from the start.

        Parameters
        ----------
        elapsed : float  [s]
            Time from the goal's start (before 0: the start, after the end: the last
            waypoint).

        Returns
        -------
        (k, 3) ndarray  [m]

        """
        return interpolate(self.times, self.positions, elapsed)


def interpolate(times, positions, time):
    """
    Return the piecewise-linear interpolation of knots at one time (held beyond the ends).

    Parameters
    ----------
    times : (n,) ndarray  [s]
        Non-decreasing knot times (a repeated time: a jump, the later knot from it on).
    positions : (n, ...) ndarray
        The knots.
    time : float  [s]
        When (finite).

    Returns
    -------
    (...) ndarray
        The interpolated value.

    """
    time = float(time)
    if not math.isfinite(time):
        raise ValueError(f'time must be finite, got {time}')
    after = int(np.searchsorted(times, time, side='right'))
    if after == 0:
        return positions[0].copy()
    if after == len(times):
        return positions[-1].copy()
    t0, t1 = times[after - 1], times[after]
    fraction = (time - t0) / (t1 - t0)
    return positions[after - 1] + fraction * (positions[after] - positions[after - 1])


def plan_goal(goal, start, approach_speed):
    """
    Return the path of a goal from where its effectors are.

    The approach to the first waypoint takes the longest effector's distance divided by
    ``approach_speed``; when the first waypoint's time is shorter, every waypoint comes that
    much later (``GoalPlan.delay``), so no effector approaches faster.

    Parameters
    ----------
    goal : TrajectoryGoal
        The checked goal.
    start : (k, 3) array_like  [m]
        The goal's effectors now (goal order).
    approach_speed : float  [m/s]
        Bound on the approach's speed (> 0).

    Returns
    -------
    GoalPlan

    """
    start = np.asarray(start, dtype=float)
    if start.shape != goal.positions.shape[1:] or not np.all(np.isfinite(start)):
        raise ValueError(f'start must be {goal.positions.shape[1:]} finite positions, got '
                         f'{start.shape}')
    approach_speed = float(approach_speed)
    if not approach_speed > 0.0 or not math.isfinite(approach_speed):
        raise ValueError(f'approach_speed must be a finite number > 0, got {approach_speed}')
    distance = float(np.max(np.linalg.norm(goal.positions[0] - start, axis=1)))
    delay = max(0.0, distance / approach_speed - float(goal.times[0]))
    return GoalPlan(times=np.concatenate([[0.0], goal.times + delay]),
                    positions=np.concatenate([start[None], goal.positions]), delay=delay)


class GoalMonitor:
    """
    Check a running goal against its tolerances, one tick at a time.

    Parameters
    ----------
    goal : TrajectoryGoal
    plan : GoalPlan

    """

    def __init__(self, goal, plan):
        self.goal = goal
        self.plan = plan

    def check(self, elapsed, actual):
        """
        Return how the goal ended at a tick, or None while it runs.

        Parameters
        ----------
        elapsed : float  [s]
            Time from the goal's start.
        actual : (k, 3) array_like  [m]
            Where the effectors are (goal order).

        Returns
        -------
        GoalOutcome or None
            ``PATH_TOLERANCE_VIOLATED`` while the path runs (up to its last waypoint's time),
            ``SUCCESSFUL`` once at or after that time every effector is within its goal
            tolerance, ``GOAL_TOLERANCE_VIOLATED`` when that has not happened
            ``goal_time_tolerance`` after it.

        """
        goal, end = self.goal, self.plan.end_time
        errors = np.linalg.norm(np.asarray(actual, dtype=float) - self.plan.desired(elapsed),
                                axis=1)
        if elapsed <= end:
            over = errors > goal.path_tolerance
            if np.any(over):
                j = int(np.argmax(errors - goal.path_tolerance))
                return GoalOutcome(PATH_TOLERANCE_VIOLATED, (
                    f'{goal.effectors[j]} {1e3 * errors[j]:.2f} mm from its path at '
                    f'{elapsed:.2f} s (path tolerance {1e3 * goal.path_tolerance[j]:.2f} mm)'),
                    errors)
        if elapsed < end:
            return None
        if np.all(errors <= goal.goal_tolerance):
            return GoalOutcome(SUCCESSFUL, 'reached: ' + _errors_text(goal, errors), errors)
        if elapsed > end + goal.goal_time_tolerance:
            j = int(np.argmax(errors - goal.goal_tolerance))
            return GoalOutcome(GOAL_TOLERANCE_VIOLATED, (
                f'{goal.effectors[j]} still {1e3 * errors[j]:.2f} mm from its goal '
                f'{goal.goal_time_tolerance:.2f} s after the last waypoint (goal tolerance '
                f'{1e3 * goal.goal_tolerance[j]:.2f} mm)'), errors)
        return None


def _errors_text(goal, errors):
    return ', '.join(f'{name} {1e3 * e:.2f} mm' for name, e in zip(goal.effectors, errors))
