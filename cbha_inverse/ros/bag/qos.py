"""Convert QoS profiles between rclpy and the bag records of :mod:`cbha_inverse.bag.qos`."""

import importlib

from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy)
from rosbags.interfaces import (
    Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime)


def _time(duration):
    seconds, nanoseconds = divmod(int(duration.nanoseconds), 1_000_000_000)
    return QosTime(seconds, nanoseconds)


def _policy(rclpy_enum, member):
    """Map a rosbags policy to rclpy's enum of the same name (UNKNOWN -> SYSTEM_DEFAULT)."""
    return rclpy_enum.__members__.get(member.name, rclpy_enum.SYSTEM_DEFAULT)


def qos_from_rclpy(profile):
    """
    Return an rclpy profile as a bag record.

    Parameters
    ----------
    profile : rclpy.qos.QoSProfile
        E.g. a publisher's offered profile from ``get_publishers_info_by_topic``.

    Returns
    -------
    rosbags.interfaces.Qos
        The same policies; durations as seconds and nanoseconds (infinite stays
        9223372036 s 854775807 ns, as rosbag2 writes it).

    """
    return Qos(QosHistory[profile.history.name], int(profile.depth),
               QosReliability[profile.reliability.name], QosDurability[profile.durability.name],
               _time(profile.deadline), _time(profile.lifespan),
               QosLiveliness[profile.liveliness.name],
               _time(profile.liveliness_lease_duration),
               bool(profile.avoid_ros_namespace_conventions))


def qos_to_rclpy(qos):
    """
    Return a bag record as an rclpy profile.

    Parameters
    ----------
    qos : rosbags.interfaces.Qos
        A recorded or adapted profile.

    Returns
    -------
    rclpy.qos.QoSProfile
        The same policies (unknown ones as the system default).

    """
    return QoSProfile(
        history=_policy(HistoryPolicy, qos.history), depth=max(int(qos.depth), 1),
        reliability=_policy(ReliabilityPolicy, qos.reliability),
        durability=_policy(DurabilityPolicy, qos.durability),
        deadline=Duration(seconds=qos.deadline.sec, nanoseconds=qos.deadline.nsec),
        lifespan=Duration(seconds=qos.lifespan.sec, nanoseconds=qos.lifespan.nsec),
        liveliness=_policy(LivelinessPolicy, qos.liveliness),
        liveliness_lease_duration=Duration(seconds=qos.liveliness_lease_duration.sec,
                                           nanoseconds=qos.liveliness_lease_duration.nsec),
        avoid_ros_namespace_conventions=bool(qos.avoid_ros_namespace_conventions))


def message_class(msgtype):
    """
    Import the rclpy message class of a type name.

    Parameters
    ----------
    msgtype : str
        E.g. ``geometry_msgs/msg/PointStamped``.

    Returns
    -------
    type
        The generated message class.

    Raises
    ------
    ValueError
        If the type name is malformed or its package is not installed.

    """
    parts = msgtype.split('/')
    if len(parts) != 3 or not all(parts):
        raise ValueError(f'malformed message type {msgtype!r}')
    try:
        return getattr(importlib.import_module(f'{parts[0]}.{parts[1]}'), parts[2])
    except (ImportError, AttributeError):
        raise ValueError(f'message type {msgtype} is not installed') from None
