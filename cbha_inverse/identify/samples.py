"""
Aligned quasi-static samples (valve pressures, measured tip) from a recorded session.

The bag holds ``pressure_command`` (std_msgs/Float64MultiArray, gauge Pa in ``valve_names``
order) and ``tip/measured`` (geometry_msgs/PointStamped), both on the recorder's receive clock,
and, when the valves report them, ``pressure_measured`` (Float64MultiArray, Pa, the same order:
``robotino_bridge`` from the driver's readings, ``cbha_sim`` from its simulated valves).

The pressure that acts on the arm at a tip sample comes from one of two sources:

- ``measured``: the measured series, linearly interpolated in receive time at the tip's receive
  time plus ``measured_latency`` (how much later than the tip a measurement of the same instant
  reaches the recorder; 0 by default). A tip sample is used only if the series covers its whole
  settle window (below) with measurements at most ``settle_time`` apart (``settle_time`` 0: no
  gap limit): across a longer gap nothing says the pressure was steady;
- ``commanded``: the command history delayed by the link ``latency`` and passed through the
  valves' first-order lag ``valve_time_constant`` (the ``cbha_sim`` valve model,
  :mod:`cbha_inverse.sim.valves`; exact for piecewise-constant commands).

``auto`` (the default) takes the measured series when the bag has one. A sample is quasi-static
when the acting pressure (from the same source) has changed by at most ``settle_tolerance`` over
the preceding ``settle_time``: the arm then sits at the equilibrium the forward model predicts.

Measured messages that cannot be a reading of the valves (another length than the commands, a
non-finite entry) are dropped and counted (:attr:`Session.measured_dropped`, reported by
``cbha_identify``): one glitch of a sensor does not void a session, and a series with no valid
message at all is refused when it is to be used.

When the bag has ``string_pots`` (sensor_msgs/JointState, the raw pot readings by name, as
``robotino_bridge`` and ``cbha_sim`` publish them), each sample also carries the readings
interpolated at its tip's receive time (NaN where the series leaves a gap longer than
``settle_time``): what :mod:`cbha_inverse.identify.pots` calibrates the pots with. Messages with
other names than the first one's, another number of positions or a non-finite one are dropped and
counted (:attr:`Session.pots_dropped`).
"""

from dataclasses import dataclass
import math
from typing import NamedTuple

from cbha_inverse.bag.evaluate import command_series, joint_state_series, point_series
from cbha_inverse.bag.storage import open_bag
from cbha_inverse.sim.valves import first_order_step
import numpy as np

PRESSURE_SOURCES = ('auto', 'measured', 'commanded')


class IdentificationError(ValueError):
    """The data cannot give a valid identification (the message says why and what to record)."""


@dataclass(frozen=True)
class Samples:
    """
    Quasi-static samples of one session.

    Attributes
    ----------
    times : (N,) ndarray  [s]
        Receive time of each tip sample, from the first command.
    pressures : (N, m) ndarray  [Pa]
        Valve pressures acting at each sample, in the bag's command order.
    tips : (N, 3) ndarray  [m]
        Measured tip positions.
    recorded : int
        Tip samples in the bag (before selection).
    quasi_static : int
        Of which quasi-static (before subsampling).
    pressure_source : str
        Where ``pressures`` come from: ``'measured'`` (the measured valve pressures) or
        ``'commanded'`` (delayed commands through the valve lag).
    measured_dropped : int
        Measured-pressure messages dropped as invalid (wrong length, non-finite).
    receive_times : (N,) ndarray  [s]
        Receive time of each tip sample on the recorder's clock (for
        :func:`acting_pressures` at another delay).
    delay : float  [s]
        The delay the pressures were aligned with (``latency`` or ``measured_latency``).
    part : (N,) int ndarray
        Session of each sample (:func:`pooled_samples`; zeros for one session).
    pots : (N, c) ndarray or None  [reading]
        Raw string-pot readings at each sample (NaN rows where not recorded; None: no session
        has them).
    pot_names : tuple of str or None
        The pots' names, in the columns' order.

    """

    times: np.ndarray
    pressures: np.ndarray
    tips: np.ndarray
    recorded: int
    quasi_static: int
    pressure_source: str = 'commanded'
    measured_dropped: int = 0
    receive_times: np.ndarray = None
    delay: float = 0.0
    part: np.ndarray = None
    pots: np.ndarray = None
    pot_names: tuple = None


class Session(NamedTuple):
    """
    The time series of one recorded session, on the recorder's receive clock.

    A plain tuple of the first four fields is accepted wherever a session is (no measured
    pressures).

    Attributes
    ----------
    command_times : (K,) ndarray  [s]
        Receive times of the commands.
    commands : (K, m) ndarray  [Pa]
        The commands, in command order.
    tip_times : (N,) ndarray  [s]
        Receive times of the measured tips.
    tips : (N, 3) ndarray  [m]
        The measured tips.
    measured_times : (M,) ndarray or None  [s]
        Receive times of the valid measured pressures, increasing (None: none recorded).
    measured : (M, m) ndarray or None  [Pa]
        The valid measured pressures, in command order.
    measured_dropped : int
        Measured messages dropped (wrong length or non-finite entries).
    pot_times : (P,) ndarray or None  [s]
        Receive times of the valid string-pot readings, increasing (None: none recorded).
    pots : (P, c) ndarray or None  [reading]
        The valid raw readings, in the order of ``pot_names``.
    pot_names : tuple of str or None
        The pots' names (those of the first message).
    pots_dropped : int
        String-pot messages dropped (other names, wrong length or non-finite entries).

    """

    command_times: np.ndarray
    commands: np.ndarray
    tip_times: np.ndarray
    tips: np.ndarray
    measured_times: np.ndarray = None
    measured: np.ndarray = None
    measured_dropped: int = 0
    pot_times: np.ndarray = None
    pots: np.ndarray = None
    pot_names: tuple = None
    pots_dropped: int = 0


def read_session(path, namespace='/cbha', tip='tip/measured'):
    """
    Read the commands, the measured tips and, if recorded, the measured pressures of a bag.

    Parameters
    ----------
    path : str or os.PathLike
        The bag folder.
    namespace : str
        Namespace of the topics.
    tip : str
        The tip reference's topic in the namespace: ``tip/measured`` (a tracker), or
        ``tip/true`` of a simulated plant (a run without a tip measurement).

    Returns
    -------
    Session
        ``measured_times`` / ``measured`` are None when the bag has no
        ``<namespace>/pressure_measured`` messages; messages of another length than the
        commands or with non-finite entries are dropped and counted; the same for
        ``<namespace>/string_pots`` (``pot_times``, ``pots``, ``pot_names``).

    Raises
    ------
    IdentificationError
        Without commands or without tip measurements.
    cbha_inverse.bag.storage.BagError
        If the bag cannot be read.

    """
    prefix = namespace.rstrip('/')
    command_topic, tip_topic = f'{prefix}/pressure_command', f'{prefix}/{tip}'
    with open_bag(path) as bag:
        command_received, commands = command_series(bag, command_topic)
        tip_received, _, tips = point_series(bag, tip_topic)
        measured_received, measured = command_series(bag, f'{prefix}/pressure_measured')
        pot_received, pot_names, pot_readings = joint_state_series(bag, f'{prefix}/string_pots')
    if not commands:
        raise IdentificationError(f'{path}: no {command_topic} messages: record the valve '
                                  'commands (cbha_bag record ... pressure_command)')
    if tips.size == 0:
        raise IdentificationError(f'{path}: no {tip_topic} messages: the tip must be measured '
                                  '(a tracker or the simulated plant) while recording')
    if len({len(c) for c in commands}) != 1:
        raise IdentificationError(f'{path}: {command_topic} messages of different lengths')
    session = Session(command_received * 1e-9, np.array(commands, dtype=float),
                      tip_received * 1e-9, tips)
    if pot_readings:
        times, rows, dropped = _valid_series(pot_received, pot_readings, len(pot_names[0]),
                                             [n == pot_names[0] for n in pot_names])
        session = session._replace(pot_times=times, pots=rows, pot_names=pot_names[0],
                                   pots_dropped=dropped)
    if not measured:
        return session
    times, rows, dropped = _valid_series(measured_received, measured, len(commands[0]))
    return session._replace(measured_times=times, measured=rows, measured_dropped=dropped)


def _valid_series(received, values, size, named=None):
    """
    Return the valid messages of a series in time order, and how many were dropped.

    Parameters
    ----------
    received : (K,) int64 ndarray  [ns]
        Receive times.
    values : list of (m,) ndarray
        The messages' values.
    size : int
        The length a valid message has (its entries all finite).
    named : sequence of bool, optional
        Whether each message has the expected names.

    Returns
    -------
    times : (M,) ndarray  [s]
    rows : (M, size) ndarray
    dropped : int

    """
    valid = np.array([len(v) == size and bool(np.all(np.isfinite(v))) for v in values])
    if named is not None:
        valid &= np.asarray(named, dtype=bool)
    order = np.argsort(received[valid], kind='stable')
    rows = np.array([v for v, ok in zip(values, valid) if ok], dtype=float).reshape(-1, size)
    return received[valid][order] * 1e-9, rows[order], int(np.sum(~valid))


def interpolate_pressures(measured_times, measured, times, max_gap=math.inf):
    """
    Interpolate a measured series (valve pressures, pot readings) linearly in time.

    Parameters
    ----------
    measured_times : (M,) ndarray  [s]
        Times of the measurements, increasing (M >= 1).
    measured : (M, m) ndarray  [Pa]
        The measured pressures.
    times : (N,) ndarray  [s]
        Where to evaluate.
    max_gap : float  [s]
        A time between two measurements further apart than this is not covered.

    Returns
    -------
    values : (N, m) ndarray  [Pa]
        The interpolated pressures (the nearest end of the series where not covered).
    covered : (N,) bool ndarray
        Whether each time lies within the series (ends included) and either on a measurement
        or between two measurements at most ``max_gap`` apart.

    """
    measured_times = np.asarray(measured_times, dtype=float)
    measured = np.asarray(measured, dtype=float).reshape(len(measured_times), -1)
    times = np.asarray(times, dtype=float)
    if len(measured_times) == 1:
        covered = times == measured_times[0]
        return np.repeat(measured, len(times), axis=0), covered
    # interval [t_i, t_i+1] holding each time; its end for the last measurement
    i = np.clip(np.searchsorted(measured_times, times, side='right') - 1, 0,
                len(measured_times) - 2)
    start, gap = measured_times[i], measured_times[i + 1] - measured_times[i]
    weight = np.clip(np.divide(times - start, gap, out=np.ones_like(times), where=gap > 0.0),
                     0.0, 1.0)
    values = measured[i] + weight[:, None] * (measured[i + 1] - measured[i])
    on_sample = (times == start) | (times == measured_times[i + 1])
    covered = ((times >= measured_times[0]) & (times <= measured_times[-1])
               & ((gap <= max_gap) | on_sample))
    return values, covered


def valve_pressures(command_times, commands, times, latency, valve_time_constant):
    """
    Return the valve pressures at given times (delayed commands through a first-order lag).

    Parameters
    ----------
    command_times : (K,) ndarray  [s]
        When the commands were sent (increasing).
    commands : (K, m) ndarray  [Pa]
        The set-points; each holds until the next; zero before the first.
    times : (N,) ndarray  [s]
        Where to evaluate.
    latency : float  [s]
        Transport delay command -> valves.
    valve_time_constant : float  [s]
        First-order valve response (0: the valves follow at once).

    Returns
    -------
    (N, m) ndarray  [Pa]

    """
    arrive = np.asarray(command_times, dtype=float) + latency
    # valve state just after each command arrives (exact exponential steps between commands)
    state = np.zeros_like(commands)
    previous = np.zeros(commands.shape[1])
    for k in range(len(arrive)):
        if k:
            previous = first_order_step(previous, commands[k - 1], arrive[k] - arrive[k - 1],
                                        valve_time_constant)
        state[k] = previous
    times = np.asarray(times, dtype=float)
    index = np.searchsorted(arrive, times, side='right') - 1
    out = np.zeros((len(times), commands.shape[1]))
    after = index >= 0
    k = index[after]
    out[after] = first_order_step(state[k], commands[k], (times[after] - arrive[k])[:, None],
                                  valve_time_constant)
    return out


def acting_pressures(session, times, source, delay, valve_time_constant=0.01,
                     max_gap=math.inf):
    """
    Return the valve pressures acting on the arm at given (tip receive) times.

    Parameters
    ----------
    session : Session
        What :func:`read_session` returns.
    times : (N,) ndarray  [s]
        Receive times (the recorder's clock).
    source : {'measured', 'commanded'}
        ``measured``: the measured series interpolated at ``times + delay``; ``commanded``: the
        commands delayed by ``delay`` through the first-order valves.
    delay : float  [s]
        ``measured_latency`` or the command ``latency`` (module docstring); any sign (a fit
        may try either).
    valve_time_constant : float  [s]
        First-order valve response (commanded source).
    max_gap : float  [s]
        Measured source: a time between two measurements further apart is not covered.

    Returns
    -------
    pressures : (N, m) ndarray  [Pa]
    covered : (N,) bool ndarray
        Whether the source defines each pressure (always true for the commands).

    """
    times = np.asarray(times, dtype=float)
    if source == 'measured':
        return interpolate_pressures(session.measured_times, session.measured, times + delay,
                                     max_gap)
    return (valve_pressures(session.command_times, session.commands, times, delay,
                            valve_time_constant), np.ones(len(times), dtype=bool))


def quasi_static_samples(session, *, latency=0.003, valve_time_constant=0.01, settle_time=0.05,
                         settle_tolerance=2000.0, max_samples=60, pressure_source='auto',
                         measured_latency=0.0):
    """
    Align a session in time and keep evenly spread quasi-static samples.

    Parameters
    ----------
    session : Session or tuple
        What :func:`read_session` returns (or its first four fields).
    latency : float  [s]
        Command -> valve delay (link latency; the recorder sees commands and tips with similar
        delivery delays). Commanded source only.
    valve_time_constant : float  [s]
        First-order valve response. Commanded source only.
    settle_time : float  [s]
        A sample is quasi-static if its pressures moved at most ``settle_tolerance`` in this
        time before it.
    settle_tolerance : float  [Pa]
        See ``settle_time``.
    max_samples : int
        At most this many samples, evenly spread in time (they bound the fit's run time).
    pressure_source : {'auto', 'measured', 'commanded'}
        Where the acting pressures come from (module docstring); ``auto``: the measured series
        when the session has one.
    measured_latency : float  [s]
        How much later than a tip sample the measurement of the valve pressures at the same
        instant is received (sensor path); measured source only.

    Returns
    -------
    Samples

    Raises
    ------
    IdentificationError
        If no tip sample is quasi-static, or the measured source is asked for (or, with
        ``auto``, recorded) but no valid measured pressure is available.
    ValueError
        On a negative or non-finite time or tolerance, or an unknown ``pressure_source``.

    """
    session = Session(*session)
    command_times, commands, tip_times, tips = session[:4]
    if not all(math.isfinite(v) and v >= 0.0 for v in (latency, valve_time_constant,
                                                       settle_time, settle_tolerance,
                                                       measured_latency)):
        raise ValueError('latency, valve_time_constant, settle_time, settle_tolerance and '
                         'measured_latency must be finite and >= 0')
    if pressure_source not in PRESSURE_SOURCES:
        raise ValueError(f'pressure_source must be one of {PRESSURE_SOURCES}, got '
                         f'{pressure_source!r}')
    recorded = session.measured_times is not None
    source = ('measured' if pressure_source == 'measured' or (pressure_source == 'auto'
                                                              and recorded) else 'commanded')
    lookback = [settle_time * f for f in (0.0, 0.25, 0.5, 0.75, 1.0)]
    keep = np.all(np.isfinite(tips), axis=1)
    if source == 'measured':
        if not recorded or len(session.measured_times) == 0:
            why = ('not recorded' if not recorded else f'all {session.measured_dropped} messages '
                   f'dropped: not {commands.shape[1]} finite values')
            raise IdentificationError(f'no valid measured valve pressures (pressure_measured '
                                      f'{why}): record them, or use the commanded pressures '
                                      '(--pressure-source commanded)')
        delay = measured_latency
    else:
        keep &= tip_times > command_times[0] + latency
        delay = latency
    max_gap = settle_time if settle_time > 0.0 else math.inf
    series = [acting_pressures(session, tip_times - back, source, delay, valve_time_constant,
                               max_gap) for back in lookback]
    for _, covered in series:
        keep &= covered
    pressures = [values for values, _ in series]
    now = pressures[0]
    moved = np.max([np.abs(now - c).max(axis=1) for c in pressures[1:]], axis=0)
    keep &= moved <= settle_tolerance
    chosen = np.flatnonzero(keep)
    if chosen.size == 0:
        gaps = (f', or the measured pressures leave gaps over {settle_time:g} s around the tip '
                'samples' if source == 'measured' else '')
        raise IdentificationError(f'no quasi-static tip sample ({source} pressures): the '
                                  f'pressures never settle within {settle_tolerance:g} Pa over '
                                  f'{settle_time:g} s{gaps}: move slower or hold poses while '
                                  'recording')
    if chosen.size > max_samples:
        chosen = chosen[np.round(np.linspace(0, chosen.size - 1, max_samples)).astype(int)]
    pots = None
    if session.pot_times is not None and len(session.pot_times):
        pots, covered = interpolate_pressures(session.pot_times, session.pots,
                                              tip_times[chosen], max_gap)
        pots[~covered] = np.nan
    return Samples(tip_times[chosen] - command_times[0], now[chosen], tips[chosen],
                   len(tip_times), int(keep.sum()), source, session.measured_dropped,
                   tip_times[chosen], delay, np.zeros(chosen.size, dtype=int), pots,
                   None if pots is None else session.pot_names)


def pooled_samples(parts, max_samples):
    """
    Pool the samples of several sessions (a lap, an excitation program) into one set.

    Parameters
    ----------
    parts : sequence of Samples
        The samples of each session (:func:`quasi_static_samples`), in order.
    max_samples : int
        At most this many samples, evenly spread over the pooled set (in session order).

    Returns
    -------
    Samples
        ``part`` tells each sample's session; ``pressure_source`` and ``delay`` are the common
        ones (``'mixed'`` and NaN when the sessions differ); counts are summed; the pot readings
        of a session without them are NaN.

    Raises
    ------
    IdentificationError
        When sessions name different string pots.

    """
    if not parts:
        raise ValueError('no sessions to pool')
    pot_names = {p.pot_names for p in parts if p.pot_names is not None}
    if len(pot_names) > 1:
        raise IdentificationError(f'the sessions name different string pots: {sorted(pot_names)}')
    pot_names = pot_names.pop() if pot_names else None
    pots = None if pot_names is None else np.concatenate([
        p.pots if p.pots is not None else np.full((len(p.tips), len(pot_names)), np.nan)
        for p in parts])
    part = np.concatenate([np.full(len(p.tips), k) for k, p in enumerate(parts)])
    chosen = np.arange(part.size)
    if part.size > max_samples:
        chosen = np.round(np.linspace(0, part.size - 1, max_samples)).astype(int)
    sources = {p.pressure_source for p in parts}
    delays = {p.delay for p in parts}
    return Samples(np.concatenate([p.times for p in parts])[chosen],
                   np.concatenate([p.pressures for p in parts])[chosen],
                   np.concatenate([p.tips for p in parts])[chosen],
                   sum(p.recorded for p in parts), sum(p.quasi_static for p in parts),
                   sources.pop() if len(sources) == 1 else 'mixed',
                   sum(p.measured_dropped for p in parts),
                   np.concatenate([p.receive_times for p in parts])[chosen],
                   delays.pop() if len(delays) == 1 else math.nan, part[chosen],
                   None if pots is None else pots[chosen], pot_names)
