"""
Aligned quasi-static samples (valve pressures, measured tip) from a recorded session.

The bag holds ``pressure_command`` (std_msgs/Float64MultiArray, gauge Pa in ``valve_names``
order) and ``tip/measured`` (geometry_msgs/PointStamped), both on the recorder's receive clock.
The pressure that acts on the arm at a tip sample is the command history delayed by the link
``latency`` and passed through the valves' first-order lag ``valve_time_constant`` (the
``cbha_sim`` valve model; exact for piecewise-constant commands). A sample is quasi-static when
that pressure has changed by at most ``settle_tolerance`` over the preceding ``settle_time``:
the arm then sits at the equilibrium the forward model predicts.
"""

from dataclasses import dataclass
import math

from cbha_inverse.bag.evaluate import command_series, point_series
from cbha_inverse.bag.storage import open_bag
import numpy as np


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

    """

    times: np.ndarray
    pressures: np.ndarray
    tips: np.ndarray
    recorded: int
    quasi_static: int


def read_session(path, namespace='/cbha'):
    """
    Read the commands and the measured tips of a bag.

    Parameters
    ----------
    path : str or os.PathLike
        The bag folder.
    namespace : str
        Namespace of the topics.

    Returns
    -------
    command_times : (K,) ndarray  [s]
        Receive times of the commands.
    commands : (K, m) ndarray  [Pa]
        The commands, in command order.
    tip_times : (N,) ndarray  [s]
        Receive times of the measured tips (same clock).
    tips : (N, 3) ndarray  [m]
        The measured tips.

    Raises
    ------
    IdentificationError
        Without commands or without tip measurements.
    cbha_inverse.bag.storage.BagError
        If the bag cannot be read.

    """
    prefix = namespace.rstrip('/')
    command_topic, tip_topic = f'{prefix}/pressure_command', f'{prefix}/tip/measured'
    with open_bag(path) as bag:
        command_received, commands = command_series(bag, command_topic)
        tip_received, _, tips = point_series(bag, tip_topic)
    if not commands:
        raise IdentificationError(f'{path}: no {command_topic} messages: record the valve '
                                  'commands (cbha_bag record ... pressure_command)')
    if tips.size == 0:
        raise IdentificationError(f'{path}: no {tip_topic} messages: the tip must be measured '
                                  '(a tracker or the simulated plant) while recording')
    if len({len(c) for c in commands}) != 1:
        raise IdentificationError(f'{path}: {command_topic} messages of different lengths')
    return command_received * 1e-9, np.array(commands, dtype=float), tip_received * 1e-9, tips


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
            previous = _relax(previous, commands[k - 1], arrive[k] - arrive[k - 1],
                              valve_time_constant)
        state[k] = previous
    times = np.asarray(times, dtype=float)
    index = np.searchsorted(arrive, times, side='right') - 1
    out = np.zeros((len(times), commands.shape[1]))
    after = index >= 0
    k = index[after]
    out[after] = _relax(state[k], commands[k], (times[after] - arrive[k])[:, None],
                        valve_time_constant)
    return out


def _relax(pressure, setpoint, elapsed, time_constant):
    """First-order step: the pressure after ``elapsed`` seconds toward ``setpoint``."""
    if time_constant == 0.0:
        return np.broadcast_to(setpoint, np.broadcast(pressure, setpoint).shape).copy()
    return setpoint + (pressure - setpoint) * np.exp(-np.asarray(elapsed) / time_constant)


def quasi_static_samples(session, *, latency=0.003, valve_time_constant=0.01, settle_time=0.05,
                         settle_tolerance=2000.0, max_samples=60):
    """
    Align a session in time and keep evenly spread quasi-static samples.

    Parameters
    ----------
    session : tuple
        What :func:`read_session` returns.
    latency : float  [s]
        Command -> valve delay (link latency; the recorder sees commands and tips with similar
        delivery delays).
    valve_time_constant : float  [s]
        First-order valve response.
    settle_time : float  [s]
        A sample is quasi-static if its pressures moved at most ``settle_tolerance`` in this
        time before it.
    settle_tolerance : float  [Pa]
        See ``settle_time``.
    max_samples : int
        At most this many samples, evenly spread in time (they bound the fit's run time).

    Returns
    -------
    Samples

    Raises
    ------
    IdentificationError
        If no tip sample is quasi-static.

    """
    command_times, commands, tip_times, tips = session
    if not all(math.isfinite(v) and v >= 0.0 for v in (latency, valve_time_constant,
                                                       settle_time, settle_tolerance)):
        raise ValueError('latency, valve_time_constant, settle_time and settle_tolerance must '
                         'be finite and >= 0')
    keep = np.all(np.isfinite(tips), axis=1) & (tip_times > command_times[0] + latency)
    now = valve_pressures(command_times, commands, tip_times, latency, valve_time_constant)
    checks = [valve_pressures(command_times, commands, tip_times - settle_time * f, latency,
                              valve_time_constant) for f in (0.25, 0.5, 0.75, 1.0)]
    moved = np.max([np.abs(now - c).max(axis=1) for c in checks], axis=0)
    keep &= moved <= settle_tolerance
    chosen = np.flatnonzero(keep)
    if chosen.size == 0:
        raise IdentificationError('no quasi-static tip sample (the pressures never settle '
                                  f'within {settle_tolerance:g} Pa over {settle_time:g} s): '
                                  'move slower or hold poses while recording')
    if chosen.size > max_samples:
        chosen = chosen[np.round(np.linspace(0, chosen.size - 1, max_samples)).astype(int)]
    return Samples(tip_times[chosen] - command_times[0], now[chosen], tips[chosen],
                   len(tip_times), int(keep.sum()))
