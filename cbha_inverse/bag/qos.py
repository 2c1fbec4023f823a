"""
QoS profiles as rosbag2 stores them (``offered_qos_profiles``) and ``ros2 bag play`` adapts them.

Pure data (``rosbags.interfaces.Qos``); :mod:`cbha_inverse.ros.bag.qos` converts to and from
rclpy. The override file of ``--qos-profile-overrides-path`` has rosbag2's format: a map from
topic name to a profile whose keys are ``history``, ``depth``, ``reliability``, ``durability``,
``deadline``, ``lifespan``, ``liveliness``, ``liveliness_lease_duration`` (``{sec, nsec}``) and
``avoid_ros_namespace_conventions``; keys left out keep the adapted profile's value.
"""

from pathlib import Path

from cbha_inverse.errors import ConfigError
from rosbags.interfaces import (
    Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime)
from rosbags.rosbag2.metadata import dump_qos_v9
import yaml

INFINITE = QosTime(0, 0)
"""rosbag2 writes an unset duration (deadline, lifespan, lease) as 0 s 0 ns."""

DEFAULT_QOS = Qos(QosHistory.KEEP_LAST, 10, QosReliability.RELIABLE, QosDurability.VOLATILE,
                  INFINITE, INFINITE, QosLiveliness.AUTOMATIC, INFINITE, False)
"""rmw's default profile: reliable, volatile, keep last 10."""

_ENUMS = {'history': QosHistory, 'reliability': QosReliability, 'durability': QosDurability,
          'liveliness': QosLiveliness}
_TIMES = ('deadline', 'lifespan', 'liveliness_lease_duration')


def dump_qos(profiles):
    """
    Return profiles as metadata version 9 stores them (a list of maps, lower-case names).

    Parameters
    ----------
    profiles : sequence of rosbags.interfaces.Qos
        Offered profiles of one topic.

    Returns
    -------
    list of dict
        ``history``, ``depth``, ``reliability``, ``durability``, ``deadline``, ``lifespan``,
        ``liveliness``, ``liveliness_lease_duration``, ``avoid_ros_namespace_conventions``.

    """
    return dump_qos_v9(list(profiles))


def adapt_offered(offered):
    """
    Return the profile that reaches every recorded publisher, as rosbag2's player chooses it.

    Parameters
    ----------
    offered : sequence of rosbags.interfaces.Qos
        The offered profiles recorded for one topic (one per publisher; may be empty).

    Returns
    -------
    rosbags.interfaces.Qos
        RELIABLE only when every publisher was reliable, TRANSIENT_LOCAL only when every one
        was, KEEP_LAST with the largest recorded depth (at least 10); the rest as the defaults.

    """
    if not offered:
        return DEFAULT_QOS
    reliable = all(q.reliability == QosReliability.RELIABLE for q in offered)
    latched = all(q.durability == QosDurability.TRANSIENT_LOCAL for q in offered)
    return DEFAULT_QOS._replace(
        depth=max([10] + [int(q.depth) for q in offered]),
        reliability=QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
        durability=QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE)


def describe_qos(qos):
    """
    Return a one-line description of a profile, e.g. ``reliable, volatile, keep_last(10)``.

    Parameters
    ----------
    qos : rosbags.interfaces.Qos
        The profile.

    Returns
    -------
    str
        Reliability, durability and history (with depth for keep_last).

    """
    history = qos.history.name.lower()
    if qos.history == QosHistory.KEEP_LAST:
        history += f'({qos.depth})'
    return f'{qos.reliability.name.lower()}, {qos.durability.name.lower()}, {history}'


def _profile(path, topic, entry, base):
    """Parse one topic's override entry on top of ``base``."""
    if not isinstance(entry, dict):
        raise ConfigError(path, topic, f'expected a map of QoS policies, got {entry!r}')
    values = base._asdict()
    for key, value in entry.items():
        where = f'{topic}.{key}'
        if key in _ENUMS:
            names = [m.name.lower() for m in _ENUMS[key] if m.name != 'UNKNOWN']
            if str(value).lower() not in names:
                raise ConfigError(path, where, f'must be one of {names}, got {value!r}')
            values[key] = _ENUMS[key][str(value).upper()]
        elif key in _TIMES:
            if (not isinstance(value, dict) or set(value) - {'sec', 'nsec'}
                    or not all(isinstance(v, int) and v >= 0 for v in value.values())):
                raise ConfigError(path, where, f'expected {{sec: int, nsec: int}}, got {value!r}')
            values[key] = QosTime(value.get('sec', 0), value.get('nsec', 0))
        elif key == 'depth':
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise ConfigError(path, where, f'must be an integer >= 0, got {value!r}')
            values[key] = value
        elif key == 'avoid_ros_namespace_conventions':
            if not isinstance(value, bool):
                raise ConfigError(path, where, f'must be true or false, got {value!r}')
            values[key] = value
        else:
            raise ConfigError(path, where, 'unknown QoS policy')
    return Qos(**values)


def load_qos_overrides(path, defaults):
    """
    Read a ``--qos-profile-overrides-path`` file (rosbag2's format).

    Parameters
    ----------
    path : str or os.PathLike
        The YAML file.
    defaults : mapping of str to rosbags.interfaces.Qos
        The adapted profile of each topic; an override changes the keys it names.

    Returns
    -------
    dict of str to rosbags.interfaces.Qos
        The profile of each overridden topic (topics not in the bag are kept: a remapped or
        filtered bag may still name them).

    Raises
    ------
    ConfigError
        If the file is missing, is not YAML, or a policy is unknown or has a bad value.

    """
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise ConfigError(path, 'file', exc.strerror or str(exc)) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f'line {mark.line + 1}' if mark is not None else 'file'
        raise ConfigError(path, where, f'not valid YAML ({getattr(exc, "problem", exc)})') \
            from None
    if not isinstance(document, dict):
        raise ConfigError(path, 'file', 'expected a map from topic names to QoS profiles')
    return {str(topic): _profile(path, topic, entry, defaults.get(str(topic), DEFAULT_QOS))
            for topic, entry in document.items()}
