"""
Real-time scheduling of a node's control thread (``docs/nodes.md``, "Latency").

On a machine whose cores the controller shares with the plant, the recorder, the tracker and
their DDS threads, a callback that becomes runnable may wait for a core for a scheduler slice
(milliseconds) behind them: that wait, not the solver's arithmetic, is the tail of the
target -> command latency. Under ``SCHED_FIFO`` the control thread runs as soon as it is
runnable and is not preempted by ordinary threads while it solves and publishes. This is the
``thread_priority`` of ros2_control's controller manager (which also defaults to 50) for a
Python node: only the calling thread changes (threads it creates afterwards inherit it); the
DDS threads created before stay under the normal scheduler. The kernel's real-time throttling
(``/proc/sys/kernel/sched_rt_runtime_us``, 95 % by default) bounds what a runaway thread takes.
"""

import os

MAX_REALTIME_PRIORITY = 98
"""Highest priority a node may ask for (99 is left to the kernel's own watchdog threads)."""


def set_realtime_priority(priority):
    """
    Run the calling thread under ``SCHED_FIFO`` at a priority.

    Parameters
    ----------
    priority : int
        1 to :data:`MAX_REALTIME_PRIORITY`; 0 leaves the thread under the normal scheduler.

    Returns
    -------
    str or None
        Why the priority could not be set (the thread stays as it was), or None when it was
        set or ``priority`` is 0. Setting it needs root, ``CAP_SYS_NICE`` or an ``rtprio``
        limit of at least ``priority`` (``/etc/security/limits.conf``, ``ulimit -r``).

    Raises
    ------
    ValueError
        If ``priority`` is not an integer in ``[0, MAX_REALTIME_PRIORITY]``.

    """
    if isinstance(priority, bool) or not isinstance(priority, int) \
            or not 0 <= priority <= MAX_REALTIME_PRIORITY:
        raise ValueError(f'realtime priority must be an integer in [0, '
                         f'{MAX_REALTIME_PRIORITY}], not {priority!r}')
    if priority == 0:
        return None
    if not hasattr(os, 'sched_setscheduler'):
        return 'this platform has no SCHED_FIFO (os.sched_setscheduler)'
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        limit = _rtprio_limit()
        return (f'SCHED_FIFO priority {priority} refused ({exc.strerror}; rtprio limit '
                f'{limit}): needs root, CAP_SYS_NICE or "ulimit -r {priority}"')
    return None


def _rtprio_limit():
    """Return the soft ``RLIMIT_RTPRIO`` as text (``'unknown'`` where it cannot be read)."""
    try:
        import resource
        soft, _ = resource.getrlimit(resource.RLIMIT_RTPRIO)
    except (ImportError, AttributeError, OSError):
        return 'unknown'
    return 'unlimited' if soft == resource.RLIM_INFINITY else str(soft)
