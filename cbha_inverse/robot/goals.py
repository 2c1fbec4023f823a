"""
Trajectory goals of named effectors: validation, approach, interpolation, tolerances (no ROS).

The functional core of the ``~/follow_trajectory`` action of ``inverse_solver``
(``docs/commanding.md``). A goal gives, for some of the scene's effectors, poses at times from
its start (the ``multi_dof_trajectory`` of ``control_msgs/FollowJointTrajectory``:
``joint_names`` are effector names, ``transforms[i]`` their poses). It runs as one path per
effector sampled at the solver's ticks:

1. an approach from where the effectors are when the goal starts to its first waypoint, no
   faster than ``approach_speed`` (an angle counts as ``orientation_length`` times it, the
   length one radian weighs as in the QP, ``docs/effectors.md``; the goal's times are shifted
   later when its first ``time_from_start`` leaves too little time for that);
2. between the waypoints, straight lines for the positions and the geodesic (slerp) for the
   orientations, at their times;
3. the last waypoint held until every effector is within its goal tolerances (success), or
   ``goal_time_tolerance`` after the last time has passed (goal tolerance violated).

What the orientation of a waypoint (``transforms[i].rotation``, a unit quaternion) drives
depends on the effector's kind (:mod:`cbha_inverse.core.actuation.effectors`): a ``pose``
effector's frame turns to it, an ``axis`` effector's axis ``u`` to ``R u`` (the rotation about
that axis is free: the path turns the axis along the great circle), a ``point`` effector
ignores it.

While the path runs, an effector farther than its path tolerance from its desired position, or
turned farther than its path angle tolerance from its desired orientation, aborts the goal.
Tolerances are distances [m] and angles [rad] per effector: > 0 a bound, 0 the node's default,
< 0 none; a goal angle tolerance < 0 frees the orientation (it is neither driven nor checked:
the effector keeps its orientation target). Arrays are batch-first in the scene's base frame,
in goal order (``TrajectoryGoal.effectors``).

The result codes are those of ``control_msgs/action/FollowJointTrajectory.Result``.
"""

from dataclasses import dataclass
import math

from cbha_inverse.core.actuation.effectors import rotation_of_quaternion
from cbha_inverse.core.so3 import shortest_rotation, so3_exp, so3_log, so3_slerp
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

DEFAULT_ORIENTATION_LENGTH = 0.1
"""``orientation_length`` [m] of the effectors of a goal made from names only (as the QP's)."""


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
        What happened, with the effector and its distance (and angle).
    errors : (k,) ndarray  [m]
        Each effector's distance to its desired position at the end.
    angles : (k,) ndarray or None  [rad]
        Each effector's angle to its desired orientation at the end (0 for an effector whose
        orientation the goal does not drive).

    """

    code: int
    text: str
    errors: np.ndarray
    angles: np.ndarray = None

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
    rotations : (n, k, 3, 3) ndarray
        The waypoints' orientations (base frame; identity when the goal gives none).
    kinds : tuple of str
        Each effector's kind (``point``, ``axis``, ``pose``).
    axes : (k, 3) ndarray
        The axis ``u`` of each ``axis`` effector in its frame (``+x`` for other kinds).
    orientation_lengths : (k,) ndarray  [m]
        The length one radian counts as on the approach.
    oriented : (k,) ndarray of bool
        Whether the goal drives the effector's orientation (an ``axis`` or ``pose`` effector
        whose goal angle tolerance is not < 0).
    path_angle_tolerance, goal_angle_tolerance : (k,) ndarray  [rad]
        Per effector (``inf``: none).

    """

    effectors: tuple
    indices: np.ndarray
    times: np.ndarray
    positions: np.ndarray
    path_tolerance: np.ndarray
    goal_tolerance: np.ndarray
    goal_time_tolerance: float
    rotations: np.ndarray
    kinds: tuple
    axes: np.ndarray
    orientation_lengths: np.ndarray
    oriented: np.ndarray
    path_angle_tolerance: np.ndarray
    goal_angle_tolerance: np.ndarray


def _tolerances(tolerances, effectors, default, what):
    """Return the (k,) tolerances of a goal from ``name -> value`` (see the module doc)."""
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


def _scene_kinds(scene_effectors):
    """Return names, kinds, axes and orientation lengths of names or of ``PointEffectors``."""
    if hasattr(scene_effectors, 'kinds'):
        return (tuple(scene_effectors.names), tuple(scene_effectors.kinds),
                np.asarray(scene_effectors.axes, dtype=float),
                np.asarray(scene_effectors.orientation_lengths, dtype=float))
    names = tuple(scene_effectors)
    return (names, ('point',) * len(names), np.tile([1.0, 0.0, 0.0], (len(names), 1)),
            np.full(len(names), DEFAULT_ORIENTATION_LENGTH))


def _waypoint_rotations(quaternions, n, effectors):
    """Return the (n, k, 3, 3) rotations of (n, k, 4) unit quaternions, each checked."""
    k = len(effectors)
    if quaternions is None:
        return np.tile(np.eye(3), (n, k, 1, 1))
    quaternions = np.asarray(quaternions, dtype=float)
    if quaternions.shape != (n, k, 4):
        raise GoalError(INVALID_GOAL, f'waypoint orientations must have shape ({n}, {k}, 4), '
                        f'got {quaternions.shape}')
    rotations = np.empty((n, k, 3, 3))
    for i in range(n):
        for j, name in enumerate(effectors):
            try:
                rotations[i, j] = rotation_of_quaternion(quaternions[i, j],
                                                         f'waypoint {i}: rotation of {name}')
            except ValueError as exc:
                raise GoalError(INVALID_GOAL, str(exc)) from None
    return rotations


def make_goal(scene_effectors, effectors, times, positions, *, quaternions=None,
              frame_transform=None, path_tolerance=None, goal_tolerance=None,
              path_angle_tolerance=None, goal_angle_tolerance=None, goal_time_tolerance=0.0,
              defaults=(0.0, 0.001, 1.0), angle_defaults=(0.0, 0.0175), reach=None,
              reach_margin=0.0):
    """
    Check a goal and return it as a :class:`TrajectoryGoal`.

    Parameters
    ----------
    scene_effectors : sequence of str or cbha_inverse.core.actuation.effectors.PointEffectors
        The scene's effector names (each then a ``point``), or its effectors (their kinds, axes
        and ``orientation_lengths``).
    effectors : sequence of str
        The goal's effectors (``joint_names``), each once.
    times : (n,) array_like  [s]
        The waypoints' times from the start (``time_from_start``).
    positions : (n, k, 3) array_like  [m]
        The waypoints (in the goal's frame).
    quaternions : (n, k, 4) array_like, optional
        The waypoints' orientations ``(x, y, z, w)`` (in the goal's frame), each a unit
        quaternion within :data:`~cbha_inverse.core.actuation.effectors.QUATERNION_TOLERANCE`
        (normalised). None: the identity.
    frame_transform : tuple, optional
        ``(R (3, 3), t (3,))`` of the goal's frame in the base frame (``p_base = R p + t``),
        applied to the checked positions and orientations. None: the goal is in the base frame.
    path_tolerance, goal_tolerance : dict, optional
        ``effector name -> distance [m]`` (> 0 a bound, 0 or absent the default, < 0 none).
    path_angle_tolerance, goal_angle_tolerance : dict, optional
        ``effector name -> angle [rad]`` (> 0 a bound, 0 or absent the default, < 0 none; a
        goal angle tolerance < 0 frees the orientation). A bound > 0 on a ``point`` effector is
        refused (it has no orientation); the others are ignored for it.
    goal_time_tolerance : float  [s]
        > 0 the time allowed after the last waypoint, 0 the default.
    defaults : tuple of float
        The defaults: path tolerance [m], goal tolerance [m], goal time tolerance [s]
        (a path or goal tolerance <= 0: none).
    angle_defaults : tuple of float
        The default path and goal angle tolerances [rad] (<= 0: none).
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
        goal without waypoints, of the wrong shape, with a non-finite value, a rotation that is
        not a unit quaternion (the waypoint named), times that are negative or not strictly
        increasing, a waypoint beyond the reach (named, with its distance), or an angle
        tolerance of a ``point`` effector.

    """
    effectors = tuple(str(name) for name in effectors)
    scene_names, scene_kinds, scene_axes, scene_lengths = _scene_kinds(scene_effectors)
    if not effectors:
        raise GoalError(INVALID_JOINTS, 'the goal names no effector (multi_dof_trajectory.'
                        f'joint_names); the scene has {list(scene_names)}')
    unknown = [name for name in effectors if name not in scene_names]
    if unknown:
        raise GoalError(INVALID_JOINTS, f'unknown effectors {unknown}; the scene has '
                        f'{list(scene_names)}')
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
    rotations = _waypoint_rotations(quaternions, times.size, effectors)
    if times[0] < 0.0:
        raise GoalError(INVALID_GOAL, f'waypoint 0: time_from_start {times[0]:g} s < 0')
    steps = np.diff(times)
    if np.any(steps <= 0.0):
        i = int(np.argmax(steps <= 0.0)) + 1
        raise GoalError(INVALID_GOAL, f'waypoint {i}: time_from_start {times[i]:g} s does not '
                        f'come after that of waypoint {i - 1} ({times[i - 1]:g} s)')
    if frame_transform is not None:
        frame_rotation, frame_origin = (np.asarray(v, dtype=float) for v in frame_transform)
        positions = positions @ frame_rotation.T + frame_origin
        rotations = frame_rotation @ rotations
    indices = np.array([scene_names.index(name) for name in effectors])
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
    kinds = tuple(scene_kinds[i] for i in indices)
    path_angle_tolerance, goal_angle_tolerance = path_angle_tolerance or {}, \
        goal_angle_tolerance or {}
    for what, given in (('path angle tolerance', path_angle_tolerance),
                        ('goal angle tolerance', goal_angle_tolerance)):
        for name, kind in zip(effectors, kinds):
            if kind == 'point' and float(given.get(name, 0.0)) > 0.0:
                raise GoalError(INVALID_GOAL, f'{what} of {name}: a point effector has no '
                                'orientation to bound')
    path_angles = _tolerances(path_angle_tolerance, effectors, float(angle_defaults[0]),
                              'path angle tolerance')
    goal_angles = _tolerances(goal_angle_tolerance, effectors, float(angle_defaults[1]),
                              'goal angle tolerance')
    oriented = np.array([kind != 'point' and not float(goal_angle_tolerance.get(name, 0.0)) < 0.0
                         for name, kind in zip(effectors, kinds)])
    path_angles[~oriented] = math.inf
    goal_angles[~oriented] = math.inf
    return TrajectoryGoal(
        effectors=effectors, indices=indices, times=times, positions=positions,
        path_tolerance=_tolerances(path_tolerance or {}, effectors, default_path,
                                   'path_tolerance'),
        goal_tolerance=_tolerances(goal_tolerance or {}, effectors, default_goal,
                                   'goal_tolerance'),
        goal_time_tolerance=time_tolerance or default_time, rotations=rotations, kinds=kinds,
        axes=scene_axes[indices], orientation_lengths=scene_lengths[indices], oriented=oriented,
        path_angle_tolerance=path_angles, goal_angle_tolerance=goal_angles)


def orientation_errors(goal, desired, actual):
    """
    Return the rotation from each effector's actual orientation to its desired one.

    What an effector's kind constrains (module doc): an ``axis`` effector, the shortest rotation
    from its axis ``R_a u`` to the desired ``R_d u``; a ``pose`` effector, ``log(R_d R_aᵀ)``;
    an effector whose orientation the goal does not drive, none (zero).

    Parameters
    ----------
    goal : TrajectoryGoal
        The goal (its kinds, axes and which effectors it orients).
    desired, actual : (k, 3, 3) array_like
        The effectors' frame rotations (base frame).

    Returns
    -------
    (k, 3) ndarray  [rad]
        Rotation vectors in the base frame's axes (their norms: the angles).

    """
    desired, actual = np.asarray(desired, dtype=float), np.asarray(actual, dtype=float)
    errors = np.zeros((len(goal.effectors), 3))
    for j, kind in enumerate(goal.kinds):
        if not goal.oriented[j]:
            continue
        if kind == 'axis':
            errors[j] = shortest_rotation(actual[j] @ goal.axes[j], desired[j] @ goal.axes[j])
        else:
            errors[j] = so3_log(desired[j] @ actual[j].T)
    return errors


@dataclass(frozen=True, eq=False)
class GoalPlan:
    """
    The path a goal runs: knots at times from its start, linear (slerp) in between.

    Attributes
    ----------
    times : (n + 1,) ndarray  [s]
        0 (the start) then the waypoints' times, delayed by ``delay``.
    positions : (n + 1, k, 3) ndarray  [m]
        The start positions, then the waypoints.
    delay : float  [s]
        How much later than their ``time_from_start`` the waypoints come (a slow approach).
    rotations : (n + 1, k, 3, 3) ndarray
        The start orientations, then the waypoints'; those of an ``axis`` effector turned the
        least that carries its axis there (each knot from the previous one), so that the slerp
        between two knots turns the axis along the great circle.

    """

    times: np.ndarray
    positions: np.ndarray
    delay: float
    rotations: np.ndarray

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

    def desired_rotations(self, elapsed):
        """
        Return the desired orientations at a time from the start (slerp between the knots).

        Parameters
        ----------
        elapsed : float  [s]
            As :meth:`desired`.

        Returns
        -------
        (k, 3, 3) ndarray
            Frame rotations (base frame).

        """
        return interpolate(self.times, self.rotations, elapsed, slerp=True)


def interpolate(times, positions, time, slerp=False):
    """
    Return the piecewise-linear interpolation of knots at one time (held beyond the ends).

    Parameters
    ----------
    times : (n,) ndarray  [s]
        Non-decreasing knot times (a repeated time: a jump, the later knot from it on).
    positions : (n, ...) ndarray
        The knots (rotation matrices ``(n, ..., 3, 3)`` with ``slerp``).
    time : float  [s]
        When (finite).
    slerp : bool
        Interpolate rotations along the geodesic (:func:`cbha_inverse.core.so3.so3_slerp`).

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
    if slerp:
        return so3_slerp(positions[after - 1], positions[after], fraction)
    return positions[after - 1] + fraction * (positions[after] - positions[after - 1])


def plan_goal(goal, start, approach_speed, start_rotations=None):
    """
    Return the path of a goal from where its effectors are.

    The approach to the first waypoint takes the longest effector's distance, or angle times
    its ``orientation_length`` when longer, divided by ``approach_speed``; when the first
    waypoint's time is shorter, every waypoint comes that much later (``GoalPlan.delay``), so
    no effector approaches faster.

    Parameters
    ----------
    goal : TrajectoryGoal
        The checked goal.
    start : (k, 3) array_like  [m]
        The goal's effectors now (goal order).
    approach_speed : float  [m/s]
        Bound on the approach's speed (> 0).
    start_rotations : (k, 3, 3) array_like, optional
        The orientations of the effectors' frames now (goal order); None: the first
        waypoint's (no turn on the approach).

    Returns
    -------
    GoalPlan

    """
    start = np.asarray(start, dtype=float)
    if start.shape != goal.positions.shape[1:] or not np.all(np.isfinite(start)):
        raise ValueError(f'start must be {goal.positions.shape[1:]} finite positions, got '
                         f'{start.shape}')
    start_rotations = (goal.rotations[0] if start_rotations is None
                       else np.asarray(start_rotations, dtype=float))
    if start_rotations.shape != goal.rotations.shape[1:] or not np.all(
            np.isfinite(start_rotations)):
        raise ValueError(f'start_rotations must be {goal.rotations.shape[1:]} finite, got '
                         f'{start_rotations.shape}')
    approach_speed = float(approach_speed)
    if not approach_speed > 0.0 or not math.isfinite(approach_speed):
        raise ValueError(f'approach_speed must be a finite number > 0, got {approach_speed}')
    rotations = np.concatenate([start_rotations[None], goal.rotations])
    for j, kind in enumerate(goal.kinds):
        if kind == 'axis':
            for i in range(1, len(rotations)):
                turn = shortest_rotation(rotations[i - 1, j] @ goal.axes[j],
                                         rotations[i, j] @ goal.axes[j])
                rotations[i, j] = so3_exp(turn) @ rotations[i - 1, j]
    angles = np.linalg.norm(orientation_errors(goal, goal.rotations[0], start_rotations), axis=1)
    distance = float(np.max(np.maximum(np.linalg.norm(goal.positions[0] - start, axis=1),
                                       goal.orientation_lengths * angles)))
    delay = max(0.0, distance / approach_speed - float(goal.times[0]))
    return GoalPlan(times=np.concatenate([[0.0], goal.times + delay]),
                    positions=np.concatenate([start[None], goal.positions]), delay=delay,
                    rotations=rotations)


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

    def check(self, elapsed, actual, actual_rotations=None):
        """
        Return how the goal ended at a tick, or None while it runs.

        Parameters
        ----------
        elapsed : float  [s]
            Time from the goal's start.
        actual : (k, 3) array_like  [m]
            Where the effectors are (goal order).
        actual_rotations : (k, 3, 3) array_like, optional
            The orientations of their frames; None: as desired (no angle is checked).

        Returns
        -------
        GoalOutcome or None
            ``PATH_TOLERANCE_VIOLATED`` while the path runs (up to its last waypoint's time),
            ``SUCCESSFUL`` once at or after that time every effector is within its goal
            tolerances, ``GOAL_TOLERANCE_VIOLATED`` when that has not happened
            ``goal_time_tolerance`` after it.

        """
        goal, end = self.goal, self.plan.end_time
        errors = np.linalg.norm(np.asarray(actual, dtype=float) - self.plan.desired(elapsed),
                                axis=1)
        desired_rotations = self.plan.desired_rotations(elapsed)
        angles = np.linalg.norm(orientation_errors(
            goal, desired_rotations,
            desired_rotations if actual_rotations is None else actual_rotations), axis=1)
        if elapsed <= end:
            over = errors > goal.path_tolerance
            if np.any(over):
                j = int(np.argmax(errors - goal.path_tolerance))
                return GoalOutcome(PATH_TOLERANCE_VIOLATED, (
                    f'{goal.effectors[j]} {1e3 * errors[j]:.2f} mm from its path at '
                    f'{elapsed:.2f} s (path tolerance {1e3 * goal.path_tolerance[j]:.2f} mm)'),
                    errors, angles)
            over = angles > goal.path_angle_tolerance
            if np.any(over):
                j = int(np.argmax(angles - goal.path_angle_tolerance))
                return GoalOutcome(PATH_TOLERANCE_VIOLATED, (
                    f'{goal.effectors[j]} turned {math.degrees(angles[j]):.2f}° from its path '
                    f'at {elapsed:.2f} s (path angle tolerance '
                    f'{math.degrees(goal.path_angle_tolerance[j]):.2f}°)'), errors, angles)
        if elapsed < end:
            return None
        if np.all(errors <= goal.goal_tolerance) and np.all(angles <= goal.goal_angle_tolerance):
            return GoalOutcome(SUCCESSFUL, 'reached: ' + _errors_text(goal, errors, angles),
                               errors, angles)
        if elapsed > end + goal.goal_time_tolerance:
            if np.any(errors > goal.goal_tolerance):
                j = int(np.argmax(errors - goal.goal_tolerance))
                text = (f'{goal.effectors[j]} still {1e3 * errors[j]:.2f} mm from its goal '
                        f'{goal.goal_time_tolerance:.2f} s after the last waypoint (goal '
                        f'tolerance {1e3 * goal.goal_tolerance[j]:.2f} mm)')
            else:
                j = int(np.argmax(angles - goal.goal_angle_tolerance))
                text = (f'{goal.effectors[j]} still turned {math.degrees(angles[j]):.2f}° from '
                        f'its goal {goal.goal_time_tolerance:.2f} s after the last waypoint '
                        f'(goal angle tolerance '
                        f'{math.degrees(goal.goal_angle_tolerance[j]):.2f}°)')
            return GoalOutcome(GOAL_TOLERANCE_VIOLATED, text, errors, angles)
        return None


def _errors_text(goal, errors, angles):
    return ', '.join(f'{name} {1e3 * e:.2f} mm' + (f' {math.degrees(a):.2f}°' if oriented else '')
                     for name, e, a, oriented in zip(goal.effectors, errors, angles,
                                                     goal.oriented))
