"""
``cbha_bag eval``: tracking error, command statistics, saturation and latency from a bag alone.

Reads ``<ns>/target`` and ``<ns>/tip/true`` (or ``tip/measured``) as geometry_msgs/PointStamped
and ``<ns>/pressure_command`` as std_msgs/Float64MultiArray, decoded without rclpy. The tracking
error is :func:`cbha_inverse.metrics.tracking_errors` on the header stamps (the same
function and window as ``cbha_demo``), or on the receive times when the stamps of the targets
and of the tips are not on one clock (:func:`pairing_times`: a bag replayed through the nodes and
recorded again, its targets with their original stamps, its tips with new ones). The
target-to-command latency pairs each target with the
first command the recorder received after it (and before the next target), on the bag's receive
times: it includes the delivery of both messages to the recorder. With ``start=None`` the
start-up transient is left out of the score (:func:`cbha_inverse.metrics.transient_end`).
"""

from dataclasses import dataclass

from cbha_inverse.bag.storage import BagError, deserialize, open_bag
from cbha_inverse.metrics import plot_runs, tracking_errors, transient_end
import numpy as np

POINT_TYPE = 'geometry_msgs/msg/PointStamped'
COMMAND_TYPE = 'std_msgs/msg/Float64MultiArray'
JOINT_STATE_TYPE = 'sensor_msgs/msg/JointState'
ONE_CLOCK = 0.5
"""Largest gap of two topics' stamp offsets (:func:`stamp_offset`) on one clock [s].

Well above a delivery delay or a camera's exposure-to-publish delay (tens of ms), well below the
time between a run and its replay."""


@dataclass(frozen=True)
class CommandStatistics:
    """
    The commands of a bag.

    Attributes
    ----------
    count : int
        Commands recorded.
    minimum, mean, maximum : (m,) ndarray  [Pa]
        Per valve, in command order.
    saturated_fraction : (m,) ndarray  [-]
        Per valve, share of commands at 0 or at ``max_pressure`` (within 1 Pa).
    any_saturated_fraction : float  [-]
        Share of commands with at least one valve saturated.

    """

    count: int
    minimum: np.ndarray
    mean: np.ndarray
    maximum: np.ndarray
    saturated_fraction: np.ndarray
    any_saturated_fraction: float


@dataclass(frozen=True)
class BagEvaluation:
    """
    What ``cbha_bag eval`` reports.

    Attributes
    ----------
    tip_topic : str
        The tip topic compared with the targets.
    window : (2,) ndarray  [s]
        Scored stamps ``[start, end]``.
    tracking : cbha_inverse.metrics.TrackingErrors or None
        Tip-to-target errors (None without tips or targets in the window).
    targets, tips : (T, 3), (N, 3) ndarray  [m]
        Target and tip positions whose stamps lie in the window (for the plot).
    commands : CommandStatistics or None
        None when the bag has no commands.
    latencies : (L,) ndarray  [s]
        Target-to-command delays (receive times).
    skipped : float or None  [s]
        With ``start=None``: the start-up transient left out, after the first target.
    units : tuple of str or None
        Unit of each command value (``'Pa'`` or ``'N'``); None: Pa.
    stamp_gap : float or None  [s]
        When the targets and tips were paired on receive times: how far apart the clocks of
        their header stamps are (:func:`pairing_times`); None: paired on header stamps.

    """

    tip_topic: str
    window: np.ndarray
    tracking: object
    targets: np.ndarray
    tips: np.ndarray
    commands: object
    latencies: np.ndarray
    skipped: float = None
    units: tuple = None
    stamp_gap: float = None


def point_series(bag, topic):
    """
    Return the messages of a PointStamped topic of an open bag.

    Parameters
    ----------
    bag : cbha_inverse.bag.storage.BagReader
        An open bag (:func:`cbha_inverse.bag.storage.open_bag`).
    topic : str
        A geometry_msgs/PointStamped topic.

    Returns
    -------
    received : (N,) int64 ndarray  [ns]
        Receive (log) times.
    stamps : (N,) ndarray  [s]
        Header stamps.
    points : (N, 3) ndarray  [m]
        The points.

    """
    received, stamps, points = [], [], []
    for _, timestamp, data in bag.messages([topic]):
        message = deserialize(data, POINT_TYPE)
        received.append(timestamp)
        stamps.append(message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec)
        points.append((message.point.x, message.point.y, message.point.z))
    return (np.array(received, dtype=np.int64), np.array(stamps, dtype=float),
            np.array(points, dtype=float).reshape(-1, 3))


def command_series(bag, topic):
    """
    Return the messages of a Float64MultiArray command topic of an open bag.

    Parameters
    ----------
    bag : cbha_inverse.bag.storage.BagReader
        An open bag.
    topic : str
        A std_msgs/Float64MultiArray topic (e.g. ``/cbha/pressure_command``).

    Returns
    -------
    received : (K,) int64 ndarray  [ns]
        Receive (log) times.
    commands : list of (m,) ndarray  [Pa]
        The commands as recorded (their lengths are not checked here).

    """
    received, commands = [], []
    for _, timestamp, data in bag.messages([topic]):
        received.append(timestamp)
        commands.append(np.asarray(deserialize(data, COMMAND_TYPE).data, dtype=float))
    return np.array(received, dtype=np.int64), commands


def joint_state_series(bag, topic):
    """
    Return the messages of a sensor_msgs/JointState topic of an open bag (named raw readings).

    Parameters
    ----------
    bag : cbha_inverse.bag.storage.BagReader
        An open bag.
    topic : str
        A JointState topic (e.g. ``/cbha/string_pots``).

    Returns
    -------
    received : (K,) int64 ndarray  [ns]
        Receive (log) times.
    names : list of tuple of str
        The names of each message.
    positions : list of (c,) ndarray
        The positions of each message (their lengths are not checked here).

    """
    received, names, positions = [], [], []
    for _, timestamp, data in bag.messages([topic]):
        message = deserialize(data, JOINT_STATE_TYPE)
        received.append(timestamp)
        names.append(tuple(message.name))
        positions.append(np.asarray(message.position, dtype=float))
    return np.array(received, dtype=np.int64), names, positions


def command_statistics(commands, max_pressure, lower=0.0):
    """
    Summarise commands.

    Parameters
    ----------
    commands : (K, m) ndarray  [Pa or N]
        The commands in order.
    max_pressure : float or (m,) array_like  [Pa or N]
        The upper bound (per valve) used to count saturation.
    lower : float or (m,) array_like  [Pa or N]
        The lower bound (0: vented cavity, slack tendon).

    Returns
    -------
    CommandStatistics
        Per-valve minimum, mean, maximum and saturation.

    """
    upper = np.asarray(max_pressure, dtype=float)
    tolerance = 1e-5 * np.abs(upper)      # 1.5 Pa of 150 kPa, 0.1 mN of 10 N
    saturated = (commands <= lower + tolerance) | (commands >= upper - tolerance)
    return CommandStatistics(len(commands), commands.min(axis=0), commands.mean(axis=0),
                             commands.max(axis=0), saturated.mean(axis=0),
                             float(np.mean(np.any(saturated, axis=1))))


def target_command_latencies(target_times, command_times):
    """
    Pair each target with the first command after it, before the next target.

    Parameters
    ----------
    target_times : (T,) ndarray of int  [ns]
        Receive times of the targets (increasing).
    command_times : (K,) ndarray of int  [ns]
        Receive times of the commands (increasing).

    Returns
    -------
    (L,) ndarray  [s]
        Delays of the paired targets.

    """
    if target_times.size == 0 or command_times.size == 0:
        return np.zeros(0)
    following = np.searchsorted(command_times, target_times, side='left')
    valid = following < command_times.size
    next_target = np.append(target_times[1:], np.iinfo(np.int64).max)
    paired = valid.copy()
    paired[valid] = command_times[following[valid]] < next_target[valid]
    return (command_times[following[paired]] - target_times[paired]) * 1e-9


def stamp_offset(received, stamps):
    """
    Return the median of a topic's header stamps minus its receive times.

    Parameters
    ----------
    received : (N,) int64 ndarray  [ns]
        Receive (log) times.
    stamps : (N,) ndarray  [s]
        Header stamps.

    Returns
    -------
    float  [s]
        About minus the delivery delay when stamps and receive times share one clock; the shift
        between the clocks otherwise (a replayed message keeps its original stamp).

    """
    return float(np.median(stamps - 1e-9 * received))


def pairing_times(target_received, target_stamps, tip_received, tip_stamps):
    """
    Choose the times on which tips are compared with targets: header stamps, or receive times.

    A bag recorded from a live run has the targets' and the tips' header stamps on one clock: each
    topic's :func:`stamp_offset` is minus a delivery delay. A bag replayed through the nodes and
    recorded again has targets that keep their original stamps while the nodes stamp their tips
    anew (or the other way round): the two offsets then differ by the time between the run and
    its replay. The recorder's receive times are one clock for every topic, so such a bag is
    compared on them (both carry one delivery delay, ~1 ms on one host).

    Parameters
    ----------
    target_received, tip_received : (T,), (N,) int64 ndarray  [ns]
        Receive times.
    target_stamps, tip_stamps : (T,), (N,) ndarray  [s]
        Header stamps.

    Returns
    -------
    target_times, tip_times : (T,), (N,) ndarray  [s]
        The times to compare on.
    gap : float or None  [s]
        The gap of the two offsets when receive times were chosen (above :data:`ONE_CLOCK`),
        None when the header stamps were.

    """
    if tip_stamps.size == 0 or target_stamps.size == 0:
        return target_stamps, tip_stamps, None
    gap = (stamp_offset(tip_received, tip_stamps)
           - stamp_offset(target_received, target_stamps))
    if abs(gap) <= ONE_CLOCK:
        return target_stamps, tip_stamps, None
    return 1e-9 * target_received, 1e-9 * tip_received, gap


def evaluate_bag(path, namespace='/cbha', tip='auto', start=0.0, end=None,
                 max_pressure=150000.0, units=None):
    """
    Evaluate one recorded run.

    Parameters
    ----------
    path : str or os.PathLike
        The bag folder.
    namespace : str
        Namespace of the topics.
    tip : {'auto', 'true', 'measured'}
        Tip topic: ``tip/true`` (the plant's truth), ``tip/measured``, or ``auto`` (true if
        recorded, else measured).
    start : float or None  [s]
        Scoring starts this long after the first target's stamp; None: after the start-up
        transient (:func:`cbha_inverse.metrics.transient_end`).
    end : float, optional  [s]
        Scoring ends this long after the first target's stamp (default: the last target).
    max_pressure : float or (m,) array_like  [Pa or N]
        Upper command bound (per valve), for the saturation count.
    units : sequence of str, optional
        Unit of each command value (``'Pa'``, ``'N'``), e.g. from the scene's actuators.

    Returns
    -------
    BagEvaluation
        The numbers.

    Raises
    ------
    BagError
        If the bag cannot be read, has no targets, or has tips that overlap the targets neither
        in header stamps nor in receive times (the message says why and what to record).

    """
    namespace = '/' + namespace.strip('/') if namespace.strip('/') else ''
    with open_bag(path) as bag:
        names = {t.name: t.msgtype for t in bag.summary.topics}
        target_topic = f'{namespace}/target'
        if names.get(target_topic) != POINT_TYPE:
            raise BagError(f'{path}: no {target_topic} ({POINT_TYPE}) in the bag')
        if tip == 'auto':
            tip = 'true' if f'{namespace}/tip/true' in names else 'measured'
        tip_topic = f'{namespace}/tip/{tip}'
        target_received, target_stamps, targets = point_series(bag, target_topic)
        if target_stamps.size == 0:
            raise BagError(f'{path}: {target_topic} has no messages')
        tip_received, tip_stamps = np.zeros(0, dtype=np.int64), np.zeros(0)
        tips = np.zeros((0, 3))
        if names.get(tip_topic) == POINT_TYPE:
            tip_received, tip_stamps, tips = point_series(bag, tip_topic)
        command_topic = f'{namespace}/pressure_command'
        command_times, commands = np.zeros(0, dtype=np.int64), []
        if names.get(command_topic) == COMMAND_TYPE:
            command_times, commands = command_series(bag, command_topic)
    target_stamps, tip_stamps, stamp_gap = pairing_times(target_received, target_stamps,
                                                         tip_received, tip_stamps)
    if tip_stamps.size and (tip_stamps[-1] < target_stamps[0]
                            or tip_stamps[0] > target_stamps[-1]):
        raise BagError(f'{path}: {tip_topic} and {target_topic} do not overlap in time (tips '
                       f'{tip_stamps[0]:.3f}..{tip_stamps[-1]:.3f} s, targets '
                       f'{target_stamps[0]:.3f}..{target_stamps[-1]:.3f} s, on '
                       f'{"receive times" if stamp_gap is not None else "header stamps"}): '
                       'record the tips and the targets together, in one cbha_bag record')
    first = target_stamps[0]
    window = np.array([first + (start or 0.0),
                       first + end if end is not None else target_stamps[-1]])
    try:
        tracking = tracking_errors(target_stamps, targets, tip_stamps, tips, *window)
    except ValueError:
        tracking = None
    skipped = None
    if start is None and tracking is not None:
        window[0] = transient_end(tracking.times, tracking.errors)
        skipped = float(window[0] - first)
        tracking = tracking_errors(target_stamps, targets, tip_stamps, tips, *window)
    statistics = None
    if commands and len({c.size for c in commands}) == 1:
        if units is not None and len(units) != commands[0].size:
            raise BagError(f'{path}: the commands have {commands[0].size} values, the scene '
                           f'{len(units)} actuators (give its scene)')
        statistics = command_statistics(np.stack(commands), max_pressure)
    in_window = (target_stamps >= window[0]) & (target_stamps <= window[1])
    tip_in_window = (tip_stamps >= window[0]) & (tip_stamps <= window[1])
    return BagEvaluation(tip_topic, window, tracking, targets[in_window], tips[tip_in_window],
                         statistics, target_command_latencies(target_received, command_times),
                         skipped, None if units is None else tuple(units), stamp_gap)


def format_evaluation(evaluation):
    """
    Return the report of :func:`evaluate_bag` as text lines (mm; kPa or N; ms).

    Parameters
    ----------
    evaluation : BagEvaluation
        The numbers.

    Returns
    -------
    str
        Several lines.

    """
    lines = []
    tracking = evaluation.tracking
    if tracking is None:
        lines.append(f'tracking: no {evaluation.tip_topic} samples in the target window')
    else:
        lines.append(f'tracking ({evaluation.tip_topic}): RMS {tracking.rms * 1e3:.6f} mm, max '
                     f'{tracking.maximum * 1e3:.6f} mm over {tracking.errors.size} samples')
        if evaluation.stamp_gap is not None:
            lines.append(f'  paired on receive times: the header stamps of the tips are '
                         f'{evaluation.stamp_gap:+.3f} s off those of the targets (a replayed '
                         'bag: its messages keep their original stamps, the nodes stamp anew)')
        if evaluation.skipped is not None:
            lines.append(f'  scored from {evaluation.skipped:.2f} s after the first target: the '
                         'start-up transient (errors above 3x the settled median) left out; '
                         '--start 0 scores it')
    commands = evaluation.commands
    if commands is None:
        lines.append('commands: none recorded')
    else:
        units = evaluation.units or ('Pa',) * len(commands.minimum)
        scale = np.array([1e-3 if unit == 'Pa' else 1.0 for unit in units])
        shown = '|'.join(sorted({'kPa' if unit == 'Pa' else unit for unit in units}))

        def in_units(values):
            return ' '.join(f'{v:.1f}' if unit == 'Pa' else f'{v:.3f}'
                            for v, unit in zip(values * scale, units))
        lines += [f'commands: {commands.count}, per valve [{shown}] min '
                  f'{in_units(commands.minimum)} | mean {in_units(commands.mean)} | max '
                  f'{in_units(commands.maximum)}',
                  f'saturation: {100 * commands.any_saturated_fraction:.1f} % of commands, per '
                  'valve ' + ' '.join(f'{100 * v:.1f}' for v in commands.saturated_fraction)
                  + ' %']
    if evaluation.latencies.size:
        latency = evaluation.latencies * 1e3
        lines.append(f'target->command latency (receive times): median '
                     f'{np.median(latency):.3f} ms, p99 {np.percentile(latency, 99):.3f} ms '
                     f'over {latency.size} targets')
    else:
        lines.append('target->command latency: no target followed by a command')
    return '\n'.join(lines)


def plot_evaluation(evaluation, path, title):
    """
    Write the PNG of target vs tip in the y-z plane.

    Parameters
    ----------
    evaluation : BagEvaluation
        The numbers (needs tracking).
    path : str or os.PathLike
        Output PNG.
    title : str
        Panel title.

    """
    rms = evaluation.tracking.rms if evaluation.tracking is not None else float('nan')
    plot_runs([{'title': title, 'targets': evaluation.targets, 'tips': evaluation.tips,
                'rms': rms, 'tip_label': evaluation.tip_topic}], path)
