"""
``cbha_status``: what the loop is doing, as one refreshing block read from ``/diagnostics``.

For users without the ``ros2`` CLI: subscribes ``/diagnostics`` (diagnostic_msgs/DiagnosticArray,
what every node of the package publishes about once a second) and shows, refreshed every
``--period`` seconds, the controller's decision, tracking error, actuators at their upper bound,
feedback age, tick and latency percentiles, whether a driver (``robotino_bridge``, or ``cbha_sim``)
is there, and every status line with its level and age. On a terminal the block is redrawn in
place; into a pipe each refresh is printed below the last. ``--once`` prints one block after
``--wait`` seconds and exits (status 1 if no diagnostics arrived). SIGINT or SIGTERM ends it at any
moment, status 0, no traceback (a stop while it loads: one line,
:mod:`cbha_inverse.ros.common.loading`).
"""

import argparse
import sys
import time

from cbha_inverse.ros.common.loading import split_ros_arguments

LEVELS = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}
PROGRAM = 'cbha_status'


def _number(values, key, scale=1.0, digits=2):
    """Return ``values[key]`` as a formatted number, or '-'."""
    try:
        value = float(values[key]) * scale
    except (KeyError, ValueError):
        return '-'
    return '-' if value != value else f'{value:.{digits}f}'


def status_lines(statuses, now):
    """
    Return the lines of the status block.

    Parameters
    ----------
    statuses : dict
        ``status name -> (level, message, values, received)``: the last DiagnosticStatus of
        each name (level 0-3, values a ``{key: text}`` dict, ``received`` a steady time [s]).
    now : float  [s]
        Steady time of the refresh.

    Returns
    -------
    list of str
        The block.

    """
    lines = []
    # by task: a status is named '<node name>: <task>', and a node can be renamed
    control = next((status for name, status in statuses.items()
                    if name.endswith(': control') and 'decision' in status[2]), None)
    if control is None:
        lines.append('controller  no inverse_solver on /diagnostics')
    else:
        values = control[2]
        lines.append(f"controller  {values.get('decision', '-')} ({values.get('mode', '-')} "
                     f'loop): {control[1]}')
        lines.append(f"            error {_number(values, 'measured_error_mm')} mm, predicted "
                     f"{_number(values, 'predicted_error_mm')} mm, at upper bound "
                     f"{values.get('at_upper_bound') or 'none'}")
        lines.append(f"            feedback age {_number(values, 'feedback_age_s')} s, target age "
                     f"{_number(values, 'target_age_s')} s")
        lines.append(f"            tick median {_number(values, 'tick_median_ms', digits=3)} ms, "
                     f"p99 {_number(values, 'tick_p99_ms', digits=3)} ms; latency median "
                     f"{_number(values, 'latency_median_ms', digits=3)} ms, p99 "
                     f"{_number(values, 'latency_p99_ms', digits=3)} ms")
    drivers = [(name, s) for name, s in statuses.items()
               if name.endswith((': driver', ': plant'))]
    if not drivers:
        lines.append('driver      none on /diagnostics (no robotino_bridge, no cbha_sim)')
    for name, (level, message, values, _) in drivers:
        reading = values.get('reading_age_s')
        extra = f", readings {_number(values, 'reading_age_s')} s old" if reading else ''
        lines.append(f'driver      {name}: {LEVELS.get(level, level)} {message}{extra}')
    lines.append('')
    for name in sorted(statuses):
        level, message, _, received = statuses[name]
        lines.append(f'{LEVELS.get(level, str(level)):5s} {name}: {message} '
                     f'({now - received:.1f} s ago)')
    return lines


def _parser():
    parser = argparse.ArgumentParser(prog=PROGRAM, description=__doc__.strip().splitlines()[0])
    parser.add_argument('--period', type=float, default=1.0, help='refresh period [s]')
    parser.add_argument('--once', action='store_true',
                        help='print one block after --wait seconds and exit')
    parser.add_argument('--wait', type=float, default=3.0,
                        help='with --once: how long to gather diagnostics [s]')
    return parser


def main(argv=None):
    """
    Run ``cbha_status``.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``); ROS arguments after ``--ros-args``.

    Returns
    -------
    int
        0 (SIGINT or SIGTERM at any moment, or ``--once`` with diagnostics), 1 (``--once``
        without any).

    """
    own, ros_args = split_ros_arguments(sys.argv[1:] if argv is None else argv)
    args = _parser().parse_args(own)
    # rclpy loads under the quiet stop while loading (:mod:`cbha_inverse.ros.common.loading`);
    # once loaded, a stop is a flag the loops poll
    from cbha_inverse.ros.common.runner import run_until_stopped
    return run_until_stopped(lambda stop: _show(args, ros_args, stop))


def _show(args, ros_args, stop):
    """Subscribe ``/diagnostics`` and print the blocks until ``stop`` (or once); see main."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    statuses = {}

    def on_diagnostics(message):
        received = time.monotonic()
        for status in message.status:
            level = status.level if isinstance(status.level, int) else ord(status.level)
            statuses[status.name] = (level, status.message,
                                     {kv.key: kv.value for kv in status.values}, received)

    def spin(seconds):
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline and not stop.requested:
            executor.spin_once(timeout_sec=min(0.05, max(deadline - time.monotonic(), 0.0)))

    context = rclpy.Context()
    rclpy.init(args=['cbha_status', *ros_args], context=context,
               signal_handler_options=SignalHandlerOptions.NO)
    node = executor = None
    terminal = sys.stdout.isatty()
    try:
        node = rclpy.create_node('cbha_status', context=context)
        node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        if args.once:
            spin(args.wait)
            if stop.requested:
                return 0
            print('\n'.join(status_lines(statuses, time.monotonic())), flush=True)
            return 0 if statuses else 1
        while not stop.requested:
            spin(args.period)
            if stop.requested:
                break
            clock = time.strftime('%H:%M:%S')
            block = '\n'.join([f'{PROGRAM}: {len(statuses)} statuses on /diagnostics, {clock}',
                               *status_lines(statuses, time.monotonic())])
            print(('\x1b[H\x1b[J' if terminal else '\n') + block, flush=True)
        return 0
    finally:
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


if __name__ == '__main__':
    sys.exit(main())
