"""
``cbha_bag info``: a bag's metadata laid out as Jazzy's ``ros2 bag info`` prints it.

The layout (labels padded to 19 columns, sizes in KiB/MiB, times as local date with nanoseconds
and the epoch seconds in parentheses, one ``Topic: ... | Type: ... | Count: ... | Serialization
Format: ...`` line per topic, recorded service events as services) follows rosbag2_py's
``format_bag_meta_data``; each topic line ends with the QoS its publishers offered while recording.
"""

import time

from cbha_inverse.bag.qos import describe_qos

_LABEL = 19
SERVICE_EVENT_SUFFIX = '/_service_event'
"""Topics of recorded service events (rosbag2 >= Jazzy) are listed as services."""


def format_size(size_bytes):
    """
    Return a size as rosbag2 prints it: ``512 B``, ``14.7 KiB``, ``1.2 MiB``.

    Parameters
    ----------
    size_bytes : int  [bytes]
        The size.

    Returns
    -------
    str
        One decimal above 1 KiB, binary prefixes.

    """
    value = float(size_bytes)
    for unit in ('B', 'KiB', 'MiB', 'GiB'):
        if value < 1024.0 or unit == 'GiB':
            return f'{int(value)} {unit}' if unit == 'B' else f'{value:.1f} {unit}'
        value /= 1024.0
    raise AssertionError('unreachable')


def format_time(stamp_ns):
    """
    Return a time stamp as rosbag2 prints it.

    E.g. ``Mar  4 2024 14:25:28.592173508 (1709558728.592173508)``.

    Parameters
    ----------
    stamp_ns : int  [ns]
        Nanoseconds since the epoch.

    Returns
    -------
    str
        Local date and time with nanoseconds, then the epoch seconds.

    """
    seconds, nanoseconds = divmod(int(stamp_ns), 1_000_000_000)
    local = time.strftime('%b %e %Y %H:%M:%S', time.localtime(seconds))
    return f'{local}.{nanoseconds:09d} ({seconds}.{nanoseconds:09d})'


def _prefix(label):
    return f'{label + ":":<{_LABEL - 1}} '


def _row(label, value):
    return _prefix(label) + str(value)


def topic_line(topic):
    """
    Return the info line of one topic.

    Parameters
    ----------
    topic : cbha_inverse.bag.storage.TopicRecord
        The topic.

    Returns
    -------
    str
        ``Topic: <name> | Type: <type> | Count: <n> | Serialization Format: cdr | QoS: ...``.

    """
    offered = '; '.join(describe_qos(q) for q in topic.offered_qos) or 'not recorded'
    return (f'Topic: {topic.name} | Type: {topic.msgtype} | Count: {topic.count} | '
            f'Serialization Format: {topic.serialization_format} | QoS: {offered}')


def format_info(summary):
    """
    Lay out a bag's metadata as ``ros2 bag info``.

    Parameters
    ----------
    summary : cbha_inverse.bag.storage.BagSummary
        The bag.

    Returns
    -------
    str
        The report, several lines, no trailing newline.

    """
    files = [f.name for f in summary.files] or ['']
    lines = [_row('Files', files[0])]
    lines += [' ' * _LABEL + name for name in files[1:]]
    lines += [_row('Bag size', format_size(summary.size_bytes)),
              _row('Storage id', summary.storage_identifier),
              _row('ROS Distro', summary.ros_distro or 'unknown'),
              _row('Duration', f'{summary.duration_ns / 1e9:.9f}s'),
              _row('Start', format_time(summary.start_ns)),
              _row('End', format_time(summary.end_ns)),
              _row('Messages', summary.message_count)]
    services = [t for t in summary.topics if t.name.endswith(SERVICE_EVENT_SUFFIX)]
    topics = [topic_line(t) for t in summary.topics if t not in services] or ['']
    lines.append(_row('Topic information', topics[0]))
    lines += [' ' * _LABEL + line for line in topics[1:]]
    lines.append(_row('Service', len(services)))
    events = [f'Service: {t.name[:-len(SERVICE_EVENT_SUFFIX)]} | Type: '
              f'{t.msgtype.removesuffix("_Event")} | Event Count: {t.count} | '
              f'Serialization Format: {t.serialization_format}' for t in services] or ['']
    lines.append(_row('Service information', events[0]))
    lines += [' ' * len(_prefix('Service information')) + line for line in events[1:]]
    return '\n'.join(lines)
