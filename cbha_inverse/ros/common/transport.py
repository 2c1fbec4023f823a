"""
The environment of node processes started together on one host: DDS discovery and transport.

:func:`node_environment` isolates a run (its ``ROS_DOMAIN_ID``, discovery on this host only,
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` unless the caller's environment sets a range).
Under that range the ROS 2 middleware gives every participant Fast DDS's shared-memory transport
beside UDP on 127.0.0.1, whatever ``FASTDDS_BUILTIN_TRANSPORTS`` or a profile file says.

:func:`loopback_udp_environment` moves one process (the controller) to UDP on the loopback
interface alone (``config/fastdds/udp_loopback.xml``). A shared-memory write takes a lock
that the reading process's listener thread also takes; on a host whose cores are busy that
thread, under the normal scheduler, can be preempted while it holds the lock, and the writer
waits for it even under ``SCHED_FIFO``. Measured on the demo's direct closed circle (2 cores,
load average 7-17): the target -> command latency's p99 was 0.67-1.07 ms against a CPU time of
0.36-0.53 ms over shared memory, and equal to the CPU time (0.41-0.57 ms) over UDP
(``docs/nodes.md``, "Latency").
"""

import os

from cbha_inverse.paths import config_path

LOOPBACK_UDP_PROFILE = 'fastdds/udp_loopback.xml'
"""The Fast DDS profile of :func:`loopback_udp_environment`, relative to ``config/``."""


def node_environment(domain=None, environment=None):
    """
    Return the environment of node processes started together: one domain, this host only.

    Parameters
    ----------
    domain : int or None
        ``ROS_DOMAIN_ID`` of the run; None keeps the environment's.
    environment : mapping of str to str, optional
        The environment to start from (default ``os.environ``).

    Returns
    -------
    dict of str to str
        A copy without the ROS wheels' bootstrap flag (each child bootstraps itself), with
        ``ROS_AUTOMATIC_DISCOVERY_RANGE`` ``LOCALHOST`` and ``FASTDDS_BUILTIN_TRANSPORTS``
        ``UDPv4`` unless set, unbuffered output, and ``PYTHONFAULTHANDLER`` (a node stopped by
        SIGABRT logs the stack of every thread).

    """
    env = dict(os.environ if environment is None else environment)
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    if domain is not None:
        env['ROS_DOMAIN_ID'] = str(domain)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    # no shared-memory segments left behind by killed processes: honoured outside LOCALHOST only
    env.setdefault('FASTDDS_BUILTIN_TRANSPORTS', 'UDPv4')
    env['PYTHONUNBUFFERED'] = '1'
    env['PYTHONFAULTHANDLER'] = '1'
    return env


def loopback_udp_variables():
    """
    Return the environment variables that put one process on UDP on 127.0.0.1 alone.

    ``FASTRTPS_DEFAULT_PROFILES_FILE`` names ``config/fastdds/udp_loopback.xml`` and
    ``ROS_AUTOMATIC_DISCOVERY_RANGE`` is ``SUBNET`` (see :func:`loopback_udp_environment`). The
    profile's transports win over ``FASTDDS_BUILTIN_TRANSPORTS`` (a process with both binds
    127.0.0.1 alone), so a launcher that can only add variables (``launch_ros``'s
    ``additional_env``) needs no more.

    Returns
    -------
    dict of str to str

    """
    return {'FASTRTPS_DEFAULT_PROFILES_FILE': str(config_path(LOOPBACK_UDP_PROFILE)),
            'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}


def loopback_udp_environment(environment):
    """
    Return a copy of a process environment whose DDS participant uses UDP on 127.0.0.1 alone.

    The process reads ``config/fastdds/udp_loopback.xml`` (UDPv4, interface whitelist
    127.0.0.1, no shared memory) with the discovery range ``SUBNET``: the ``LOCALHOST`` range
    would replace the profile's transports. The whitelist keeps all its traffic on the loopback
    interface. Its peers need no change: they reach it over UDP.

    Parameters
    ----------
    environment : mapping of str to str
        The environment, e.g. from :func:`node_environment`.

    Returns
    -------
    dict of str to str

    """
    env = dict(environment)
    env.update(loopback_udp_variables())
    env.pop('FASTDDS_BUILTIN_TRANSPORTS', None)
    return env
