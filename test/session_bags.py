"""Write recorded sessions (commands, measured pressures, tips, string pots) as rosbag2 bags."""

from cbha_inverse.bag.storage import BagWriter
import numpy as np
from rosbags.typesys import get_typestore, Stores


def write_session_bag(path, commands=(), measured=(), tips=(), pots=(), namespace='/cbha',
                      tip_topic='tip/measured'):
    """
    Write a session into a rosbag2 bag, each message at its receive time (= its stamp).

    Parameters
    ----------
    path : pathlib.Path
        The bag folder (created).
    commands, measured : sequence of (float, (m,) array_like)
        ``(t [s], pressures [Pa])`` of ``pressure_command`` and ``pressure_measured``.
    tips : sequence of (float, (3,) array_like)
        ``(t [s], point [m])`` of ``tip_topic``.
    pots : sequence of (float, sequence of str, (c,) array_like)
        ``(t [s], names, raw readings)`` of ``string_pots`` (sensor_msgs/JointState).
    namespace : str
        Namespace of the topics.
    tip_topic : str
        The tips' topic in the namespace (``tip/measured`` or ``tip/true``).

    """
    store = get_typestore(Stores.ROS2_JAZZY)
    types = store.types
    array, point = types['std_msgs/msg/Float64MultiArray'], types['geometry_msgs/msg/PointStamped']
    joints = types['sensor_msgs/msg/JointState']
    layout = types['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0)

    def header(t):
        ns = int(round(t * 1e9))
        return types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=ns // 10 ** 9, nanosec=ns % 10 ** 9),
            frame_id='cbha_base')

    def pressures(values):
        return store.serialize_cdr(array(layout=layout, data=np.asarray(values, dtype=float)),
                                   array.__msgtype__)

    messages = [(t, 'pressure_command', pressures(v)) for t, v in commands]
    messages += [(t, 'pressure_measured', pressures(v)) for t, v in measured]
    messages += [(t, tip_topic, store.serialize_cdr(point(
        header=header(t), point=types['geometry_msgs/msg/Point'](x=p[0], y=p[1], z=p[2])),
        point.__msgtype__)) for t, p in tips]
    empty = np.zeros(0)
    messages += [(t, 'string_pots', store.serialize_cdr(joints(
        header=header(t), name=list(names), position=np.asarray(readings, dtype=float),
        velocity=empty, effort=empty), joints.__msgtype__)) for t, names, readings in pots]
    writer = BagWriter(path)
    for topic, series, type_name in (('pressure_command', commands, array.__msgtype__),
                                     ('pressure_measured', measured, array.__msgtype__),
                                     (tip_topic, tips, point.__msgtype__),
                                     ('string_pots', pots, joints.__msgtype__)):
        if len(series):
            writer.add_topic(f'{namespace}/{topic}', type_name)
    for t, topic, data in sorted(messages, key=lambda m: m[0]):
        writer.write(f'{namespace}/{topic}', int(round(t * 1e9)), data)
    writer.close()
