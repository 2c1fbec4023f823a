"""
``cbha_static_transform``: publish one static transform on ``/tf_static``, as tf2_ros does.

The venv has no ``tf2_ros``; this is its ``static_transform_publisher`` for the frames a user
adds to the cell (a table, a camera mount), with the same options::

    cbha_static_transform --x 0.3 --z -0.1 --yaw 1.5708 --frame-id cbha_base --child-frame-id table

The child's origin in the parent (``--x --y --z``, m) and its orientation, by roll, pitch and
yaw about the parent's fixed x, y, z axes (rad) or by a quaternion (``--qx --qy --qz --qw``). The
message is latched (transient local): nodes that start later receive it, and ``inverse_solver``
then takes targets in the child frame. It runs until SIGINT or SIGTERM (status 0, no
traceback; :mod:`cbha_inverse.ros.common.loading` while it loads).
"""

import argparse
import math
import sys

from cbha_inverse.ros.common.loading import split_ros_arguments

PROGRAM = 'cbha_static_transform'


def _parser():
    """Return the command line parser."""
    parser = argparse.ArgumentParser(prog=PROGRAM, description=__doc__.strip().splitlines()[0])
    for axis in ('x', 'y', 'z'):
        parser.add_argument(f'--{axis}', type=float, default=0.0, help=f'{axis} [m]')
    for angle in ('roll', 'pitch', 'yaw'):
        parser.add_argument(f'--{angle}', type=float, default=None, help=f'{angle} [rad]')
    for part in ('qx', 'qy', 'qz', 'qw'):
        parser.add_argument(f'--{part}', type=float, default=None, help='quaternion part')
    parser.add_argument('--frame-id', required=True, help='parent frame')
    parser.add_argument('--child-frame-id', required=True, help='child frame')
    return parser


def transform_pose(args):
    """
    Return the child frame in the parent as ``[x, y, z, qx, qy, qz, qw]``.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed options.

    Returns
    -------
    list of 7 float

    Raises
    ------
    ValueError
        If angles and a quaternion are both given, a value is not finite, or the quaternion is
        zero.

    """
    from cbha_inverse.core.so3 import quat_from_matrix, so3_from_rpy
    import numpy as np
    angles = [args.roll, args.pitch, args.yaw]
    parts = [args.qx, args.qy, args.qz, args.qw]
    if any(a is not None for a in angles) and any(q is not None for q in parts):
        raise ValueError('give roll/pitch/yaw or a quaternion, not both')
    if any(q is not None for q in parts):
        quaternion = np.array([0.0 if q is None else q for q in parts])
    else:
        quaternion = quat_from_matrix(so3_from_rpy([0.0 if a is None else a for a in angles]))
    position = [args.x, args.y, args.z]
    norm = float(np.linalg.norm(quaternion))
    if not (all(map(math.isfinite, position)) and math.isfinite(norm) and norm > 1e-9):
        raise ValueError('the translation and the rotation must be finite, the quaternion '
                         'non-zero')
    return position + (quaternion / norm).tolist()


def main(argv=None):
    """
    Run ``cbha_static_transform``.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``); ROS arguments after ``--ros-args``.

    Returns
    -------
    int
        0 (stopped by SIGINT or SIGTERM), 1 (tf2_msgs not usable), 2 (bad arguments).

    """
    own, ros_args = split_ros_arguments(sys.argv[1:] if argv is None else argv)
    parser = _parser()
    args = parser.parse_args(own)
    try:
        pose = transform_pose(args)
    except ValueError as exc:
        parser.error(str(exc))
    from cbha_inverse.ros.common.runner import run_until_stopped
    return run_until_stopped(lambda stop: _publish(args, pose, ros_args, stop))


def _publish(args, pose, ros_args, stop):
    """Latch the transform on ``/tf_static`` and spin until ``stop``; see main."""
    import importlib

    from builtin_interfaces.msg import Time
    from cbha_inverse.ros.common.conversions import transform_stamped
    from cbha_inverse.ros.common.qos import TF_STATIC_QOS
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    try:
        message_type = importlib.import_module('tf2_msgs.msg').TFMessage
    except (ImportError, AttributeError, RuntimeError) as exc:
        print(f'{PROGRAM}: tf2_msgs is not usable ({str(exc).splitlines()[0]})', file=sys.stderr)
        return 1
    context = rclpy.Context()
    rclpy.init(args=[PROGRAM, *ros_args], context=context,
               signal_handler_options=SignalHandlerOptions.NO)
    node = executor = None
    try:
        node = rclpy.create_node('static_transform', context=context)
        publisher = node.create_publisher(message_type, '/tf_static', TF_STATIC_QOS)
        seconds, nanoseconds = divmod(node.get_clock().now().nanoseconds, 10 ** 9)
        message = message_type()
        message.transforms = [transform_stamped(args.frame_id, args.child_frame_id, pose,
                                                Time(sec=seconds, nanosec=nanoseconds))]
        publisher.publish(message)
        print(f'{PROGRAM}: {args.child_frame_id} in {args.frame_id}: '
              f'{[round(v, 6) for v in pose]}', flush=True)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        while not stop.requested:
            executor.spin_once(timeout_sec=0.1)
        return 0
    finally:
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


if __name__ == '__main__':
    sys.exit(main())
