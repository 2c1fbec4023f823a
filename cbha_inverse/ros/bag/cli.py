"""
``cbha_bag``: rosbag2 bags without rosbag2, with the shape and flags of ``ros2 bag``.

Subcommands: ``record`` (:mod:`cbha_inverse.ros.bag.record`), ``play``
(:mod:`cbha_inverse.ros.bag.play`), ``info`` (:mod:`cbha_inverse.bag.info`) and ``eval``
(:mod:`cbha_inverse.bag.evaluate`). A missing or damaged bag or a bad option file prints one line
naming it and exits with code 2.
"""

import argparse
import signal
import sys

from cbha_inverse.bag.storage import BagError
from cbha_inverse.errors import ConfigError, report_config_error
from cbha_inverse.ros.common.loading import loaded
import numpy as np


def _size(text):
    return int(float(text))


def parse_args(argv):
    """Parse the command line."""
    parser = argparse.ArgumentParser(prog='cbha_bag', description=__doc__.split('\n\n')[0])
    commands = parser.add_subparsers(dest='command', required=True)

    record = commands.add_parser('record', help='record topics into a bag (v9 + MCAP)')
    record.add_argument('topics', nargs='*', help='topics to record')
    record.add_argument('--topics', dest='more_topics', nargs='+', default=[],
                        help='topics to record (as the positional list)')
    record.add_argument('-a', '--all', action='store_true', help='record every topic')
    record.add_argument('--allow-empty', action='store_true',
                        help='exit 0 even if no message was recorded (default: exit 1)')
    record.add_argument('-o', '--output', help='bag folder (default rosbag2_<date>-<time>)')
    record.add_argument('-s', '--storage', default='mcap', choices=('mcap',),
                        help='storage plugin (mcap, the Jazzy default)')
    record.add_argument('--duration', type=float, default=0.0,
                        help='stop after this many seconds (0: until SIGINT/SIGTERM)')
    record.add_argument('-b', '--max-bag-size', type=_size, default=0,
                        help='split the bag at this size [bytes] (0: never)')
    record.add_argument('-d', '--max-bag-duration', type=float, default=0.0,
                        help='split the bag after this many seconds (0: never)')
    record.add_argument('--use-sim-time', action='store_true',
                        help='time stamps from /clock')

    play = commands.add_parser('play', help='publish a bag with its recorded timing')
    play.add_argument('bag', help='bag folder')
    play.add_argument('-r', '--rate', type=float, default=1.0, help='playback speed factor')
    play.add_argument('-l', '--loop', action='store_true', help='play again at the end')
    play.add_argument('--topics', nargs='+', default=[], help='only these topics')
    play.add_argument('-m', '--remap', nargs='+', default=[], metavar='OLD:=NEW',
                      help='publish topic OLD as NEW')
    play.add_argument('--clock', type=float, nargs='?', const=40.0, default=0.0, metavar='HZ',
                      help='publish /clock at HZ (default 40) for use_sim_time nodes')
    play.add_argument('--start-offset', type=float, default=0.0,
                      help='start this many seconds into the bag')
    play.add_argument('-d', '--delay', type=float, default=0.0,
                      help='wait this many seconds before playing')
    play.add_argument('--qos-profile-overrides-path',
                      help='YAML of per-topic QoS profiles (rosbag2 format)')
    play.add_argument('--wait-for-subscribers', type=float, default=0.0, metavar='SECONDS',
                      help='before playing, wait up to SECONDS until every topic (and /clock) '
                      'has a subscriber')

    info = commands.add_parser('info', help="print a bag's metadata as ros2 bag info")
    info.add_argument('bag', help='bag folder')

    evaluate = commands.add_parser('eval', help='tracking error, command statistics, '
                                   'saturation and latency of a recorded run')
    evaluate.add_argument('bag', help='bag folder')
    evaluate.add_argument('--namespace', default='/cbha', help='namespace of the topics')
    evaluate.add_argument('--tip', default='auto', choices=('auto', 'true', 'measured'),
                          help='tip topic compared with the targets (auto: true if recorded)')
    evaluate.add_argument('--start', type=_start, default=None, metavar='SECONDS|auto',
                          help='score from this many seconds after the first target stamp '
                          '(default auto: after the start-up transient, the last error of the '
                          "run's first half above 3x the median error of its second half)")
    evaluate.add_argument('--end', type=float, default=None,
                          help='score until this many seconds after the first target stamp')
    evaluate.add_argument('--scene', default='cbha.yaml',
                          help="the run's scene: the unit (N for cables, Pa for cavities) and "
                          'bounds of each command value, in scene order')
    evaluate.add_argument('--max-pressure', type=float, default=None,
                          help='cap of the upper bounds for the saturation count [N or Pa] '
                          "(default: the scene's bounds)")
    evaluate.add_argument('--plot', help='write target vs tip to this PNG')
    args = parser.parse_args(argv)
    if args.command == 'record':
        args.topics = list(args.topics) + list(args.more_topics)
    return args


def _start(text):
    """Parse ``eval --start``: seconds, or ``auto`` (None)."""
    return None if text.strip().lower() == 'auto' else float(text)


def _info(args):
    from cbha_inverse.bag.info import format_info
    from cbha_inverse.bag.storage import open_bag
    with open_bag(args.bag) as bag:
        print(format_info(bag.summary))
    return 0


def _eval(args):
    from cbha_inverse.bag.evaluate import evaluate_bag, format_evaluation, plot_evaluation
    from cbha_inverse.scene import load_scene
    from cbha_inverse.scene.cli import actuator_units
    scene = load_scene(args.scene)
    upper = scene.upper_bounds if args.max_pressure is None else np.minimum(
        scene.upper_bounds, args.max_pressure)
    evaluation = evaluate_bag(args.bag, namespace=args.namespace, tip=args.tip,
                              start=args.start, end=args.end, max_pressure=upper,
                              units=actuator_units(scene))
    print(format_evaluation(evaluation))
    if args.plot:
        if evaluation.tracking is None:
            raise BagError(f'{args.bag}: nothing to plot (no tip samples in the window)')
        try:
            plot_evaluation(evaluation, args.plot, str(args.bag))
        except OSError as exc:
            raise BagError(f'{args.plot}: cannot write the plot: {exc.strerror or exc}') from None
        print(f'wrote {args.plot}')
    return 0


def main(argv=None):
    """
    Run ``cbha_bag``.

    Parameters
    ----------
    argv : list of str, optional
        Command line without the program name (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success (and after SIGINT/SIGTERM during record or play), 2 for a missing or
        damaged bag or bad options, 130 after SIGINT in ``info`` or ``eval``; a stop while
        the command loads exits 0 with one line.

    """
    args = parse_args(sys.argv[1:] if argv is None else argv)
    # what the subcommand runs loads under the quiet stop while loading (exit 0, one line:
    # :mod:`cbha_inverse.ros.common.loading`); then record and play turn a stop into the end of
    # the recording or the playback, and a stop anywhere else is exit 130 without a traceback
    run = None
    if args.command == 'record':
        from cbha_inverse.ros.bag.record import record as run
    elif args.command == 'play':
        from cbha_inverse.ros.bag.play import play as run
    loaded()
    try:
        if run is not None:
            return run(args)
        # a reader that closes the pipe early (``| head``) ends the output, not in a traceback
        signal.signal(signal.SIGPIPE, signal.SIG_DFL)
        if args.command == 'info':
            return _info(args)
        return _eval(args)
    except (BagError, ConfigError, FileNotFoundError) as exc:
        return report_config_error(f'cbha_bag {args.command}', exc)
    except KeyboardInterrupt:
        print(f'cbha_bag {args.command}: stopped', file=sys.stderr)
        return 128 + signal.SIGINT


if __name__ == '__main__':
    sys.exit(main())
