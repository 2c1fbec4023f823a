"""
``cbha_demo`` (``make demo``): the paper's circle and square, open and closed loop, on real DDS.

Each run is ``cbha_launch sim`` with the run's parameters: the nodes of the composition ``sim``
(:mod:`cbha_inverse.ros.launch.compositions`; ``feedback`` ``sim``, ``stereo`` or ``proprio`` by
the run, ``solver_transport`` from ``--solver-transport``, by default ``udp-loopback``: the solver
over UDP on 127.0.0.1 alone), started and stopped by the launcher's
:class:`cbha_inverse.ros.launch.processes.NodeProcesses`. Every node gets its installed params
file, then the composition's overrides with the run's over them (``<output>/<run>/<node>.yaml``:
the plant's errors, the lap, ``--realtime-priority``), and writes its output into
``<output>/<run>/<node>.log``. The demo first starts ``cbha_bag record`` (into
``<output>/<run>/bag``: target, tip/true, tip/measured, tip/estimated, payload/estimated,
sections/estimated, pressure_command, pressure_measured, string_pots, /diagnostics), then every
node but ``trajectory``, which starts once the others publish diagnostics. After one lap it stops
the nodes, then the recorder, as ``cbha_launch`` does (SIGINT; SIGTERM 15 s later, SIGKILL 5 s
after that: a process that needed either fails the demo), and prints one line: tracking RMS and
max (plant tip vs target, moving part: ``cbha_bag eval``), the solver's tick and target-to-command
latency (callback entry to publish; its CPU time: the rest is waiting for a core), median / p99.
It writes ``demo.png``, ``summary.json`` and per run params, logs, bag.

Defaults (paper, section V): circle r = 60 mm at 2.5 cm/s, square 80 mm at 3.1 cm/s, y-z plane,
centred on the scene's suggested workspace centre; the plant is 10 % softer than the model.

``--feedback stereo`` adds the closed loop through the cameras: ``cbha_sim`` renders its tip
marker into the rig ``--stereo-rig`` (default ``config/cameras/demo_rig.yaml``: the default rig at
640x512, f = 700 px, so that ``make demo`` stays under two minutes) at ``--camera-rate`` frames/s,
``stereo_tracker`` measures the tip from the images, and ``inverse_solver`` closes the loop on it
with ``--stereo-loop-gain`` (0.2 per frame at 30 frames/s = 6 /s, below the 10 /s of direct
feedback (0.1 x 100 Hz): a frame interval, the image transport and the tracking add ~50-70 ms of
delay, and 10 /s rang after the start jump on the loaded 2-core machine). Its line is printed
beside the direct-feedback runs.

``--feedback proprio`` (in the default) closes the loop without any tip measurement:
``cbha_sim`` publishes ``string_pots`` and no tip (``tip_output: none``), ``shape_estimator``
estimates the tip from the pots and the measured pressures (``docs/proprioception.md``) and
``inverse_solver`` closes the loop on ``tip/estimated``; the run is scored against ``tip/true``
as the others, and its second line gives the estimate's own RMS against ``tip/true``.
``--plant-payload`` hangs a payload at the plant's tip that no model knows; ``--stuck-pot``
freezes one plant pot halfway through the lap (the estimator drops it: ``degraded``).

``--feedback obstacles`` (in the default) adds the closed-loop squares of ``--obstacles``
(``rows,free``) on ``--obstacle-scene`` (``cbha_post``: the CBHA over a table, a short post
29 mm beyond the square's plane below its centre, in the way of the tip's sphere along the lower
edge; ``docs/obstacles.md``). The plant touches the obstacles in both; the inverse keeps its
collision spheres ``obstacle_margin`` clear of them with its rows in ``rows`` and is told of
none in ``free`` (it loads ``--obstacle-free-scene``, ``cbha``: the same model without
obstacles). Their lines give the plant's lowest clearance over the whole run (its collision
spheres against its obstacles, the ``lowest_clearance_m`` of the ``cbha_sim`` diagnostics;
negative: a penetration), the model's (its equilibria at the run's recorded commands), the
clearance the tip's sphere would have on the lap's targets, the tracking of the *unblocked part*
of the lap
(:func:`cbha_inverse.metrics.unblocked_errors`: the samples whose target is at least
``--blocked-distance`` from every obstacle, by default the collision radius + the margin + 5 mm
= 31.5 mm, and more than ``--settle-time`` (0.5 s) after the last sample that was not; on the
CBHA's square the post blocks the lower edge's middle 59 mm, and the settling takes 16 mm more)
and the solver's tick and latency as above. ``--feedback obstacles`` runs these two alone.

``--excite PROGRAM`` (a ``cbha_excite`` program: ``bends``, ``all``, ... or a YAML file of
holds) adds an identification run: ``cbha_sim`` and ``cbha_excite`` alone, recorded
(pressure_command, pressure_measured, tip/measured, tip/true) into
``<output>/excite_<program>/bag``, listed in ``summary.json`` under ``excitation``.
"""

import argparse
from dataclasses import dataclass, replace
import json
import os
from pathlib import Path
import shutil
import sys
import time

from cbha_inverse.bag.evaluate import command_series, evaluate_bag
from cbha_inverse.bag.storage import open_bag
from cbha_inverse.config_files import read_yaml
from cbha_inverse.core.obstacles import sphere_gaps
from cbha_inverse.errors import ConfigError, report_config_error
from cbha_inverse.experiments.proprio import (add_estimator_arguments, add_plant_pot_arguments,
                                              bag_points, estimate_error, plant_pot_parameters,
                                              proprio_node_parameters, proprio_sim_parameters)
from cbha_inverse.identify.excitation import make_program
from cbha_inverse.metrics import plot_runs, unblocked_errors
from cbha_inverse.paths import config_path
from cbha_inverse.robot.safety import command_bounds, valve_order
from cbha_inverse.robot.trajectory import make_trajectory
from cbha_inverse.ros.common.transport import node_environment
from cbha_inverse.ros.launch.compositions import (ArgumentError, COMPOSITIONS, NodeProcess,
                                                  resolve)
from cbha_inverse.ros.launch.processes import NodeProcesses
from cbha_inverse.scene import load_scene
from cbha_inverse.sim.plant import StaticPlant
import numpy as np
import yaml

PROGRAM = 'cbha_demo'
FEEDBACK = {'direct': 'sim', 'stereo': 'stereo', 'proprio': 'proprio'}
"""The ``feedback`` argument of the ``sim`` composition for each kind of run."""
NAMESPACE = '/cbha'
RECORDED = ('target', 'tip/true', 'tip/measured', 'tip/estimated', 'payload/estimated',
            'sections/estimated', 'pressure_command', 'pressure_measured', 'string_pots',
            '/diagnostics')
EXCITE_RECORDED = ('pressure_command', 'pressure_measured', 'tip/measured', 'tip/true')
BLOCKED_EXTRA = 0.005
"""Default blocked distance beyond the collision radius and the margin [m]: the neighbouring
spheres of the tip's and the rim of a post reach a few millimetres farther."""


def parse_args(argv):
    """Parse the command line."""
    parser = argparse.ArgumentParser(prog='cbha_demo', description=__doc__.split('\n\n')[0])
    parser.add_argument('--output', default='output/demo', help='output folder')
    parser.add_argument('--scene', default='cbha.yaml', help='scene of model and plant')
    parser.add_argument('--shapes', default='circle,square', help='comma-separated shapes')
    parser.add_argument('--modes', default='open,closed', help='comma-separated modes')
    parser.add_argument('--radius', type=float, default=0.06, help='circle radius [m]')
    parser.add_argument('--side', type=float, default=0.08, help='square side [m]')
    parser.add_argument('--circle-speed', type=float, default=0.025, help='[m/s]')
    parser.add_argument('--square-speed', type=float, default=0.031, help='[m/s]')
    parser.add_argument('--start-hold', type=float, default=1.5,
                        help='time at the start point before moving [s] (not scored)')
    parser.add_argument('--stiffness-scale', type=float, default=0.9,
                        help='plant stiffness / model stiffness')
    parser.add_argument('--plant-section-scale', default='1.0',
                        help='comma-separated plant stiffness error per scene section, on top '
                        'of --stiffness-scale (cbha_sim section_stiffness_scale)')
    parser.add_argument('--plant-gain-scale', default='1.0',
                        help='comma-separated plant effective-area error per valve (cbha_sim '
                        'cavity_gain_scale)')
    parser.add_argument('--plant-base-offset', default='0,0,0',
                        help='comma-separated plant base position in cbha_base [m] (a tracker '
                        'registration error; cbha_sim base_offset)')
    parser.add_argument('--plant-seed', type=int, default=0,
                        help='seed of the plant measurement noise (cbha_sim seed)')
    parser.add_argument('--model-scene', default=None, help="inverse_solver's and "
                        "shape_estimator's scene (default --scene), e.g. cbha_identify's")
    parser.add_argument('--feedback', default='direct,stereo,proprio,obstacles',
                        help='comma-separated: direct (tip/measured from the plant: every shape '
                        'and mode) and/or stereo (closed loop through rendered cameras and '
                        'stereo_tracker, for --stereo-shapes) and/or proprio (closed loop on '
                        'the string-pot estimate of shape_estimator, no tip measurement, for '
                        '--proprio-shapes) and/or obstacles (direct closed-loop squares on '
                        '--obstacle-scene, the runs of --obstacles)')
    parser.add_argument('--proprio-shapes', default='circle', help='shapes of the proprio runs')
    parser.add_argument('--plant-payload', type=float, default=0.0,
                        help='plant tip payload unknown to the controller [kg]')
    add_plant_pot_arguments(parser)
    add_estimator_arguments(parser)
    parser.add_argument('--stereo-shapes', default='circle', help='shapes of the stereo runs')
    parser.add_argument('--stereo-rig', default='cameras/demo_rig.yaml',
                        help='rig of the stereo runs (path, or relative to config/)')
    parser.add_argument('--camera-rate', type=float, default=30.0, help='stereo frames/s')
    parser.add_argument('--stereo-loop-gain', type=float, default=0.2,
                        help='inverse_solver loop_gain of the stereo runs (per measurement)')
    parser.add_argument('--excite', default=None, metavar='PROGRAM',
                        help='after the trajectory runs, record an excitation run for '
                        'cbha_identify: cbha_sim + cbha_excite with this program (bends, '
                        'outer_bends, extension, all, ... or a YAML file of holds) into '
                        '<output>/excite_<program>/bag')
    parser.add_argument('--excite-hold-time', type=float, default=3.0,
                        help='cbha_excite hold_time [s]')
    parser.add_argument('--excite-ramp-time', type=float, default=1.0,
                        help='cbha_excite ramp_time [s]')
    parser.add_argument('--obstacles', default='rows,free',
                        help='comma-separated obstacle runs (with --feedback obstacles): rows '
                        "(the inverse keeps clear of the scene's obstacles) and/or free (the "
                        'inverse on --obstacle-free-scene, told of no obstacles; the plant '
                        'still touches them)')
    parser.add_argument('--obstacle-scene', default='cbha_post.yaml',
                        help='scene of plant and inverse of the obstacle runs')
    parser.add_argument('--obstacle-free-scene', default='cbha.yaml',
                        help="the inverse's scene of the free obstacle run: --obstacle-scene "
                        'without obstacles')
    parser.add_argument('--blocked-distance', type=float, default=None,
                        help='obstacle runs: a target closer than this to an obstacle is '
                        "blocked [m] (default: the largest collision radius + the inverse's "
                        'obstacle_margin + 5 mm)')
    parser.add_argument('--settle-time', type=float, default=0.5,
                        help='obstacle runs: samples this long after a blocked one are '
                        'settling, not scored as unblocked [s]')
    parser.add_argument('--realtime-priority', type=int, default=50,
                        help="inverse_solver's SCHED_FIFO priority (0: normal scheduler)")
    parser.add_argument('--solver-transport', choices=('udp-loopback', 'default'),
                        default='udp-loopback', help="inverse_solver's DDS transport: UDP on "
                        '127.0.0.1 alone (config/fastdds/udp_loopback.xml), or the default '
                        '(shared memory and UDP)')
    parser.add_argument('--domain', type=int, default=None,
                        help='ROS_DOMAIN_ID for the run (default: the environment, else a free '
                        'one from domain_coordinator)')
    return parser.parse_args(argv)


def run_nodes(args, parameters, mode='closed', feedback='direct', scene=None):
    """
    Return ``{node: NodeProcess}`` of one run: the ``sim`` composition, the run's parameters last.

    ``parameters`` maps a node to its run's overrides; ``feedback`` is a key of :data:`FEEDBACK`;
    ``scene`` the composition's scene (default ``args.scene``); a mode the composition does not
    know raises its ``ArgumentError``.
    """
    nodes = resolve(COMPOSITIONS['sim'], {
        'namespace': NAMESPACE, 'scene': scene or args.scene, 'mode': mode,
        'feedback': FEEDBACK[feedback], 'solver_transport': args.solver_transport})
    return {node.executable: replace(node, parameters={
        **node.parameters, **parameters.get(node.executable, {})}) for node in nodes}


def _start_recorder(recording, run_dir, recorded=RECORDED):
    """Start ``cbha_bag record`` of the run's topics into ``run_dir/bag`` (replacing it)."""
    bag = run_dir / 'bag'
    if bag.exists():
        shutil.rmtree(bag)
    topics = [t if t.startswith('/') else f'{NAMESPACE}/{t}' for t in recorded]
    return recording.start(
        'cbha_bag_record',
        [sys.executable, '-m', 'cbha_inverse.ros.bag.cli', 'record', '-o', str(bag), *topics],
        log=run_dir / 'cbha_bag_record.log', node=False)


def _start_node(processes, node, run_dir):
    """Start a node with its params files, its overrides in ``run_dir``, its log there."""
    return processes.start_node(node, run_dir, log=run_dir / f'{node.executable}.log')


def _stop(processes, recording):
    """Stop a run's nodes, then its recorder; return exit statuses and escalations by name."""
    try:
        codes = dict(processes.stop())
    finally:
        recorded = dict(recording.stop())
    return {**codes, **recorded}, {**processes.escalated, **recording.escalated}


class Recorder:
    """Subscribe to target, tip/true, tip/measured and /diagnostics (one node in this process)."""

    def __init__(self, context):
        from cbha_inverse.ros.common.qos import DIAGNOSTICS_QOS, MEASURED_QOS, TARGET_QOS
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PointStamped
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        self.node = Node('cbha_demo_recorder', context=context, namespace=NAMESPACE)
        self.targets, self.tips, self.measured, self.diagnostics = [], [], [], {}
        self.node.create_subscription(PointStamped, 'target', self._point(self.targets),
                                      TARGET_QOS)
        self.node.create_subscription(PointStamped, 'tip/true', self._point(self.tips),
                                      MEASURED_QOS)
        self.node.create_subscription(PointStamped, 'tip/measured', self._point(self.measured),
                                      MEASURED_QOS)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics,
                                      DIAGNOSTICS_QOS)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)

    @staticmethod
    def _point(store):
        def callback(message):
            stamp = message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec
            store.append((stamp, message.point.x, message.point.y, message.point.z))
        return callback

    def _on_diagnostics(self, message):
        for status in message.status:
            self.diagnostics[status.name] = ({v.key: v.value for v in status.values},
                                             time.monotonic())

    def spin_until(self, predicate, timeout):
        """Spin until ``predicate()`` or ``timeout`` seconds; return the predicate."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and not predicate():
            self.executor.spin_once(timeout_sec=0.05)
        return predicate()

    def clear(self):
        """Forget what was recorded."""
        self.targets.clear()
        self.tips.clear()
        self.measured.clear()
        self.diagnostics.clear()

    def close(self):
        """Destroy the node."""
        self.executor.shutdown()
        self.node.destroy_node()


def _stereo_overrides(args):
    """Return the cbha_sim and stereo_tracker overrides of a run through the cameras."""
    from cbha_inverse.vision.rig import load_rig
    rig_path = config_path(args.stereo_rig)
    rig_path = rig_path if rig_path.is_file() else Path(args.stereo_rig)
    rig = load_rig(rig_path)
    with open(rig_path) as stream:
        names = yaml.safe_load(stream)
    sim = {'tip_output': 'stereo', 'camera_rig': str(rig_path),
           'camera_rate_hz': args.camera_rate}
    tracker = {'left_camera_info_file': str(rig_path.parent / names['left_camera_info']),
               'right_camera_info_file': str(rig_path.parent / names['right_camera_info']),
               'base_from_left': [float(v) for v in rig.base_from_left],
               'diagnostics_period': 0.5}
    return sim, tracker


def _floats(text):
    """Parse comma-separated floats."""
    return [float(v) for v in text.split(',')]


def _sim_overrides(args, valve_names, scene=None):
    """Return the ``cbha_sim`` parameters of the demo's plant (on ``scene``, default its own)."""
    return {'scene': scene or args.scene, 'valve_names': list(valve_names),
            'stiffness_scale': args.stiffness_scale,
            'section_stiffness_scale': _floats(args.plant_section_scale),
            'cavity_gain_scale': _floats(args.plant_gain_scale),
            'base_offset': _floats(args.plant_base_offset), 'seed': args.plant_seed,
            'payload_mass': args.plant_payload, **plant_pot_parameters(args)}


def excite_run_name(program):
    """Return the folder name of the excitation run of ``program`` (a YAML file: its stem)."""
    return f'excite_{Path(program).stem}'


def run_excitation(recorder, run_dir, args, program, valve_names, env):
    """
    Run ``cbha_excite`` on the simulated plant, recorded; return its summary dict.

    Parameters
    ----------
    recorder : Recorder
        The demo's in-process subscriber (it tells when the plant is up).
    run_dir : pathlib.Path
        The run's folder (params, logs, ``bag``).
    args : argparse.Namespace
        The demo's options (plant, ``--excite``, hold and ramp times).
    program : cbha_inverse.identify.excitation.ExcitationProgram
        The program ``cbha_excite`` will run (its duration bounds the wait).
    valve_names : sequence of str
        Command order.
    env : dict
        The children's environment.

    Returns
    -------
    dict
        Program, holds, duration, exit codes, the bag and its message count per topic.

    """
    run_dir.mkdir(parents=True, exist_ok=True)
    recorder.clear()
    plant = run_nodes(args, {'cbha_sim': _sim_overrides(args, valve_names)})['cbha_sim']
    excite = NodeProcess('cbha_excite', NAMESPACE, (str(config_path('cbha_excite.yaml')),), {
        'scene': args.scene, 'valve_names': list(valve_names), 'program': args.excite,
        'hold_time': args.excite_hold_time, 'ramp_time': args.excite_ramp_time,
        'wait_for_subscribers': 2})
    recording, processes = NodeProcesses(PROGRAM, env, sys.stderr), NodeProcesses(
        PROGRAM, env, sys.stderr)
    try:
        _start_recorder(recording, run_dir, EXCITE_RECORDED)
        _start_node(processes, plant, run_dir)
        if not recorder.spin_until(lambda: any(
                name.startswith('cbha_sim:') for name in recorder.diagnostics), 120.0):
            raise RuntimeError(f'cbha_sim did not start, see the logs in {run_dir}')
        # the program starts once the plant and the bag recorder subscribe to its commands
        excited = _start_node(processes, excite, run_dir)
        if not recorder.spin_until(lambda: excited.poll() is not None,
                                   program.duration + 120.0):
            raise RuntimeError(f'cbha_excite did not finish, see the logs in {run_dir}')
        time.sleep(0.3)     # the plant's response to the last command reaches the bag
    finally:
        codes, escalated = _stop(processes, recording)
    with open_bag(run_dir / 'bag') as bag:
        counts = {topic.name: topic.count for topic in bag.summary.topics}
    return {'program': args.excite, 'holds': program.n_holds,
            'hold_time_s': program.hold_time, 'ramp_time_s': program.ramp_time,
            'duration_s': program.duration, 'exit_codes': codes, 'escalated': escalated,
            'bag': str(run_dir / 'bag'), 'messages': counts}


@dataclass(frozen=True)
class ObstacleRun:
    """
    One obstacle run of the demo: the closed-loop square on the obstacle scene.

    Attributes
    ----------
    name : str
        ``'rows'`` (the inverse keeps clear of the obstacles) or ``'free'`` (the inverse is told
        of none).
    plant_scene, model_scene : str
        The scenes of ``cbha_sim`` and of ``inverse_solver``.
    obstacles : tuple of cbha_inverse.core.obstacles.Obstacle
        The plant's obstacles.
    model : cbha_inverse.scene.Scene
        The obstacle scene (the inverse's model: no stiffness error).
    margin : float  [m]
        The ``obstacle_margin`` of the obstacle scene's inverse.
    radius : float  [m]
        The largest collision sphere's radius (the tip's on the CBHA).
    blocked_distance : float  [m]
        Targets closer than this to an obstacle are blocked.
    settle_time : float  [s]
        Samples this long after a blocked one are settling.

    """

    name: str
    plant_scene: str
    model_scene: str
    obstacles: tuple
    model: object
    margin: float
    radius: float
    blocked_distance: float
    settle_time: float

    def numbers(self, tracking, plant, bag, valve_names):
        """
        Return the summary entries of the run: the plant's lowest clearance, unblocked tracking.

        Parameters
        ----------
        tracking : cbha_inverse.metrics.TrackingErrors
            The lap's errors (plant tip vs target).
        plant : dict
            The key/values of the last ``cbha_sim: plant`` diagnostics.
        bag : pathlib.Path
            The run's bag (its ``pressure_command``).
        valve_names : sequence of str
            The commands' order.

        Returns
        -------
        dict
            ``lowest_clearance_mm`` (over the whole run, the plant's spheres against its
            obstacles), ``target_clearance_mm`` (the smallest clearance a sphere of
            :attr:`radius` centred on a target of the lap would have: what reaching every
            target would ask), ``model_clearance_mm`` (the lowest clearance of the model's
            equilibria at the run's commands: where the inverse meant the spheres to be),
            ``unblocked_rms_mm``, ``unblocked_max_mm``, ``unblocked_samples`` and the
            selection's parameters.

        """
        unblocked, kept = unblocked_errors(tracking, self.obstacles, self.blocked_distance,
                                           self.settle_time)
        on_targets = sphere_gaps(self.obstacles, tracking.goals,
                                 np.full(len(tracking.goals), self.radius))
        try:
            lowest = float(plant['lowest_clearance_m'])
        except (KeyError, ValueError):
            lowest = float('nan')
        return {'obstacles': self.name, 'obstacle_scene': self.plant_scene,
                'inverse_scene': self.model_scene, 'lowest_clearance_mm': lowest * 1e3,
                'target_clearance_mm': float(on_targets.min()) * 1e3,
                'model_clearance_mm': self.model_clearance(bag, valve_names) * 1e3,
                'obstacle_margin_mm': self.margin * 1e3,
                'unblocked_rms_mm': unblocked.rms * 1e3,
                'unblocked_max_mm': unblocked.maximum * 1e3,
                'unblocked_samples': int(kept.sum()),
                'blocked_distance_mm': self.blocked_distance * 1e3,
                'settle_time_s': self.settle_time}

    def model_clearance(self, bag, valve_names):
        """
        Return the lowest clearance of the model's equilibria at a run's commands [m].

        Each recorded ``pressure_command`` is solved as the model's equilibrium (the obstacle
        scene without its obstacles, warm-started from the previous command's), and its
        collision spheres are measured against the plant's obstacles
        (:meth:`cbha_inverse.core.contact.CollisionSpheres.clearances`).
        """
        with open_bag(bag) as recorded:
            _, commands = command_series(recorded, f'{NAMESPACE}/pressure_command')
        _, order = valve_order(self.model.actuator_names, valve_names)
        model = StaticPlant(self.model)
        model.set_obstacles(())
        lowest = np.inf
        for command in commands:
            actuation = np.zeros(len(order))
            actuation[order] = command
            state = model.update(actuation)
            lowest = min(lowest, float(self.model.collision.clearances(
                state.positions, self.obstacles).min()))
        return lowest


def obstacle_runs(args):
    """
    Return the obstacle runs of ``--obstacles`` (none without ``--feedback obstacles``).

    Parameters
    ----------
    args : argparse.Namespace
        The demo's options.

    Returns
    -------
    runs : list of ObstacleRun
        In the order given.
    center : (3,) ndarray or None  [m]
        The obstacle scene's workspace centre (None without runs).

    Raises
    ------
    ValueError
        On an unknown run name, or an obstacle scene without obstacles or collision spheres.

    """
    names = [name for name in args.obstacles.split(',') if name]
    if 'obstacles' not in args.feedback.split(',') or not names:
        return [], None
    unknown = sorted(set(names) - {'rows', 'free'})
    if unknown:
        raise ValueError(f'--obstacles: unknown run {unknown[0]!r} (rows, free)')
    scene = load_scene(args.obstacle_scene)
    if not scene.obstacles or scene.collision is None:
        raise ValueError(f'--obstacle-scene {args.obstacle_scene}: no obstacles or no collision '
                         'spheres')
    margin = scene.make_inverse_solver().options.obstacle_margin
    radius = float(scene.collision.radii.max())
    distance = (args.blocked_distance if args.blocked_distance is not None
                else radius + margin + BLOCKED_EXTRA)
    return [ObstacleRun(name, args.obstacle_scene,
                        args.obstacle_scene if name == 'rows' else args.obstacle_free_scene,
                        tuple(scene.obstacles), scene, margin, radius, distance,
                        args.settle_time)
            for name in names], scene.workspace_center[-1]


def run_once(recorder, run_dir, shape, mode, args, center, valve_names, env, feedback='direct',
             obstacles=None):
    """
    Run one shape in one mode for one lap and return its summary dict.

    ``obstacles`` makes it an obstacle run: an :class:`ObstacleRun`, whose scenes the plant and
    the inverse load and whose numbers the summary adds (the plant's lowest clearance, the
    tracking of the unblocked part).
    """
    speed = args.circle_speed if shape == 'circle' else args.square_speed
    trajectory = make_trajectory(shape, center=center, radius=args.radius, side=args.side,
                                 plane='yz', speed=speed, laps=1, start_hold=args.start_hold)
    run_dir.mkdir(parents=True, exist_ok=True)
    recorder.clear()
    plant_scene = args.scene if obstacles is None else obstacles.plant_scene
    model_scene = str(args.model_scene or args.scene) if obstacles is None else \
        obstacles.model_scene
    common = {'scene': plant_scene, 'valve_names': list(valve_names)}
    model = {**common, 'scene': model_scene, 'diagnostics_period': 0.5}
    sim_extra, solver_extra, tracker_params, estimator_extra = {}, {}, {}, {}
    if obstacles is not None:   # the lowest clearance read after the lap is at most 0.5 s old
        sim_extra = {'diagnostics_period': 0.5}
    if feedback == 'stereo':
        sim_extra, tracker_params = _stereo_overrides(args)
        solver_extra = {'loop_gain': args.stereo_loop_gain}
    if feedback == 'proprio':
        sim_extra = proprio_sim_parameters(args, trajectory)
        estimator_extra, solver_extra = proprio_node_parameters(args)
    nodes = run_nodes(args, {
        'cbha_sim': {**_sim_overrides(args, valve_names, plant_scene), **sim_extra},
        'stereo_tracker': tracker_params,
        'shape_estimator': {**model, **estimator_extra},
        'inverse_solver': {**model, 'mode': mode, 'realtime_priority': args.realtime_priority,
                           **solver_extra},
        'trajectory': {'shape': shape, 'center': [float(v) for v in center],
                       'radius': args.radius, 'side': args.side, 'plane': 'yz', 'speed': speed,
                       'laps': 1, 'start_hold': args.start_hold, 'wait_for_subscribers': 3}},
        mode, feedback, plant_scene)
    waited = [name for name in nodes if name != 'trajectory']
    recording, processes = NodeProcesses(PROGRAM, env, sys.stderr), NodeProcesses(
        PROGRAM, env, sys.stderr)
    try:
        _start_recorder(recording, run_dir)
        for name in waited:
            _start_node(processes, nodes[name], run_dir)
        # the trajectory starts once the nodes publish diagnostics (they spin), and keeps its
        # clock at 0 until the solver, this recorder and the bag recorder subscribe to it
        if not recorder.spin_until(lambda: all(
                any(name.startswith(f'{node}:') for name in recorder.diagnostics)
                for node in waited), 120.0):
            raise RuntimeError(f'nodes did not start, see the logs in {run_dir}')
        launched = time.time()  # targets stamped earlier are late messages of a previous run
        _start_node(processes, nodes['trajectory'], run_dir)
        if not recorder.spin_until(lambda: any(t[0] >= launched for t in recorder.targets),
                                   60.0):
            raise RuntimeError(f'no target received, see the logs in {run_dir}')
        started = time.monotonic()
        recorder.spin_until(lambda: time.monotonic() - started > trajectory.duration + 0.3,
                            trajectory.duration + 10.0)
        fresh = time.monotonic()
        awaited = ['inverse_solver: control'] + (['cbha_sim: plant'] if obstacles else [])
        recorder.spin_until(lambda: all(recorder.diagnostics.get(name, ({}, 0.0))[1] > fresh
                                        for name in awaited), 2.0)
    finally:
        codes, escalated = _stop(processes, recording)
    evaluation = evaluate_bag(run_dir / 'bag', namespace=NAMESPACE, tip='true',
                              start=args.start_hold, end=trajectory.duration)
    if evaluation.tracking is None:
        raise RuntimeError(f'no tip samples in the lap, see the logs in {run_dir}')
    errors = evaluation.tracking
    control = recorder.diagnostics.get('inverse_solver: control', ({}, 0.0))[0]
    plant = recorder.diagnostics.get('cbha_sim: plant', ({}, 0.0))[0]
    tracking = recorder.diagnostics.get('stereo_tracker: tracking', ({}, 0.0))[0]
    estimating = recorder.diagnostics.get('shape_estimator: estimate', ({}, 0.0))[0]

    def number(values, key):
        try:
            return float(values[key])
        except (KeyError, ValueError):
            return float('nan')

    stereo = {} if feedback != 'stereo' else {
        'stereo_detection_rate': number(tracking, 'detection_rate'),
        'stereo_processing_median_ms': number(tracking, 'processing_median_ms'),
        'stereo_processing_p99_ms': number(tracking, 'processing_p99_ms'),
        'stereo_input_rate_hz': number(tracking, 'input_rate_hz'),
        'stereo_rejected': number(tracking, 'rejected_total')}
    proprio = {} if feedback != 'proprio' else {
        'estimate_median_ms': number(estimating, 'estimate_median_ms'),
        'estimate_p99_ms': number(estimating, 'estimate_p99_ms'),
        'estimate_degraded': number(estimating, 'degraded_updates'),
        'estimate_rejected': number(estimating, 'rejected_total'),
        'estimate_payload_kg': number(estimating, 'payload_kg'),
        'estimate_sections': {k: number(estimating, k) for k in estimating
                              if k.startswith('section_stiffness.')},
        'solver_sections': {k: number(control, k) for k in control
                            if k.startswith('section_stiffness.')},
        'estimate_tip_rms_mm': estimate_error(bag_points(run_dir / 'bag', NAMESPACE),
                                              args.start_hold, trajectory.duration) * 1e3}
    blocked = {} if obstacles is None else obstacles.numbers(errors, plant, run_dir / 'bag',
                                                             valve_names)
    return {'shape': shape, 'mode': mode, 'feedback': feedback, **stereo, **proprio, **blocked,
            'speed_m_s': speed, 'lap_s': trajectory.lap_time,
            'rms_mm': errors.rms * 1e3, 'max_mm': errors.maximum * 1e3,
            'samples': int(errors.errors.size),
            'tick_median_ms': number(control, 'tick_median_ms'),
            'tick_p99_ms': number(control, 'tick_p99_ms'),
            'latency_median_ms': number(control, 'latency_median_ms'),
            'latency_p99_ms': number(control, 'latency_p99_ms'),
            'latency_cpu_p99_ms': number(control, 'latency_cpu_p99_ms'),
            'solver_ticks': number(control, 'ticks'),
            'solver_status': {k[len('status.'):]: v for k, v in control.items()
                              if k.startswith('status.')},
            'plant_tick_median_ms': number(plant, 'tick_median_ms'),
            'exit_codes': codes, 'escalated': escalated, 'bag': str(run_dir / 'bag'),
            'eval_window_s': [args.start_hold, trajectory.duration],
            'bag_latency_p99_ms': float(np.percentile(evaluation.latencies, 99) * 1e3)
            if evaluation.latencies.size else float('nan'),
            '_targets': evaluation.targets, '_tips': evaluation.tips}


def main(argv=None):
    """
    Run the demo; return 0 when every run completed and every node exited cleanly.

    Parameters
    ----------
    argv : list of str, optional
        Command line without the program name (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit code.

    """
    args = parse_args(sys.argv[1:] if argv is None else argv)
    wall = time.monotonic()
    output = Path(args.output)
    output.mkdir(parents=True, exist_ok=True)
    try:
        scene = load_scene(args.scene)
        configured = read_yaml(config_path('inverse_solver.yaml'))
    except (ConfigError, FileNotFoundError) as exc:
        return report_config_error('cbha_demo', exc)
    center = scene.workspace_center[-1]
    valve_names = configured.get('/**', {}).get('ros__parameters', {}).get('valve_names')
    if valve_names is None or sorted(valve_names) != sorted(scene.actuator_names):
        valve_names = list(scene.actuator_names)
    feedbacks = args.feedback.split(',')
    runs = [(shape, mode, 'direct') for shape in args.shapes.split(',')
            for mode in args.modes.split(',') if 'direct' in feedbacks]
    runs += [(shape, 'closed', 'stereo') for shape in args.stereo_shapes.split(',')
             if 'stereo' in feedbacks]
    runs += [(shape, 'closed', 'proprio') for shape in args.proprio_shapes.split(',')
             if 'proprio' in feedbacks]
    try:       # the composition's arguments of every run, checked before any node starts
        for _, mode, feedback in runs:
            run_nodes(args, {}, mode, feedback)
        blocked_runs, obstacle_center = obstacle_runs(args)
    except (ArgumentError, ConfigError, ValueError, FileNotFoundError) as exc:
        return report_config_error('cbha_demo', exc)
    excitation = None
    if args.excite is not None:
        try:       # the program cbha_excite will run, checked before any node starts
            max_pressure = read_yaml(config_path(
                'cbha_excite.yaml'))['/**']['ros__parameters']['max_pressure']
            excitation = make_program(
                scene, args.excite, hold_time=args.excite_hold_time,
                ramp_time=args.excite_ramp_time,
                bounds=command_bounds(scene.lower_bounds, scene.upper_bounds, max_pressure))
        except ValueError as exc:      # ConfigError included
            return report_config_error('cbha_demo', exc)
    domain = args.domain
    reservation = None
    if domain is None and 'ROS_DOMAIN_ID' not in os.environ:
        try:
            from domain_coordinator import domain_id
            reservation = domain_id()
            domain = reservation.__enter__()
        except ImportError:
            domain = None
    env = node_environment(domain)
    os.environ.update({k: env[k] for k in ('ROS_AUTOMATIC_DISCOVERY_RANGE',
                                           'FASTDDS_BUILTIN_TRANSPORTS')})
    if domain is not None:
        os.environ['ROS_DOMAIN_ID'] = str(domain)
    used_domain = env.get('ROS_DOMAIN_ID') or '0 (unset: the default)'
    print(f'cbha_demo: scene {scene.name}, centre {[round(float(v), 4) for v in center]} m, '
          f'plant stiffness x{args.stiffness_scale:g}, ROS_DOMAIN_ID {used_domain}, '
          f'output {output}', flush=True)
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    recorder = Recorder(context)
    results = []
    try:
        for shape, mode, feedback in runs:
            name = f'{shape}_{mode}' + ('' if feedback == 'direct' else f'_{feedback}')
            result = run_once(recorder, output / name, shape, mode, args, center, valve_names,
                              env, feedback)
            results.append(result)
            label = mode if feedback == 'direct' else feedback
            print(f"{shape:6s} {label:6s}: RMS {result['rms_mm']:6.3f} mm, max "
                  f"{result['max_mm']:6.3f} mm | tick median {result['tick_median_ms']:.3f}"
                  f" ms, p99 {result['tick_p99_ms']:.3f} ms | target->command latency "
                  f"median {result['latency_median_ms']:.3f} ms, p99 "
                  f"{result['latency_p99_ms']:.3f} ms (CPU p99 {result['latency_cpu_p99_ms']:.3f}"
                  ' ms)', flush=True)
            if feedback == 'stereo':
                print(f"{'':6s} {'':6s}  closed loop through the cameras ({args.camera_rate:g}"
                      f' frames/s, {args.stereo_rig}): detection rate '
                      f"{result['stereo_detection_rate']:.3f}, tracker median "
                      f"{result['stereo_processing_median_ms']:.2f} ms, p99 "
                      f"{result['stereo_processing_p99_ms']:.2f} ms per pair", flush=True)
            if feedback == 'proprio':
                print(f"{'':6s} {'':6s}  closed loop on the string-pot estimate (no tip "
                      'measurement): estimated tip vs true RMS '
                      f"{result['estimate_tip_rms_mm']:.3f} mm, estimate median "
                      f"{result['estimate_median_ms']:.3f} ms, p99 "
                      f"{result['estimate_p99_ms']:.3f} ms, "
                      f"{result['estimate_degraded']:.0f} degraded updates", flush=True)
        for run in blocked_runs:
            result = run_once(recorder, output / f'square_closed_obstacles_{run.name}', 'square',
                              'closed', args, obstacle_center, valve_names, env,
                              obstacles=run)
            results.append(result)
            print(f"square {run.name:6s}: lowest clearance {result['lowest_clearance_mm']:6.3f} mm"
                  f" (margin {result['obstacle_margin_mm']:g} mm; the model's at the "
                  f"commands {result['model_clearance_mm']:.3f} mm, the tip's sphere on the "
                  f"targets {result['target_clearance_mm']:.3f} mm) | unblocked RMS "
                  f"{result['unblocked_rms_mm']:6.3f} mm, max {result['unblocked_max_mm']:6.3f}"
                  f" mm ({result['unblocked_samples']} of {result['samples']} samples) | "
                  f"tick median {result['tick_median_ms']:.3f} ms, p99 "
                  f"{result['tick_p99_ms']:.3f} ms | target->command latency median "
                  f"{result['latency_median_ms']:.3f} ms, p99 {result['latency_p99_ms']:.3f} ms "
                  f"(CPU p99 {result['latency_cpu_p99_ms']:.3f} ms)", flush=True)
            print(f"{'':6s} {'':6s}  {run.plant_scene}, inverse on {run.model_scene} "
                  f"({'obstacle rows' if run.name == 'rows' else 'told of no obstacles'}); "
                  f"whole lap RMS {result['rms_mm']:.3f} mm, max {result['max_mm']:.3f} mm",
                  flush=True)
        if excitation is not None:
            excited = run_excitation(recorder, output / excite_run_name(args.excite), args,
                                     excitation, valve_names, env)
            print(f"excite {args.excite}: {excited['holds']} holds, "
                  f"{excited['duration_s']:.1f} s, "
                  f"{excited['messages'].get(f'{NAMESPACE}/tip/measured', 0)} tip samples, "
                  f"exit codes {excited['exit_codes']}; bag {excited['bag']}", flush=True)
    finally:
        recorder.close()
        rclpy.try_shutdown(context=context)
        if reservation is not None:
            reservation.__exit__(None, None, None)
    plot_runs([{'title': f"{r['shape']} {r['mode']} loop"
                + {'stereo': ' (stereo cameras)', 'proprio': ' (string pots)'}.get(
                    r['feedback'], '')
                + {'rows': ', post: rows', 'free': ', post: no rows'}.get(
                    r.get('obstacles'), ''),
                'targets': r['_targets'],
                'tips': r['_tips'], 'rms': r['rms_mm'] * 1e-3} for r in results],
              output / 'demo.png')
    summary = {'scene': scene.name, 'center_m': [float(v) for v in center],
               'stiffness_scale': args.stiffness_scale, 'wall_time_s': time.monotonic() - wall,
               'runs': [{k: v for k, v in r.items() if not k.startswith('_')} for r in results]}
    if excitation is not None:
        summary['excitation'] = excited
    (output / 'summary.json').write_text(json.dumps(summary, indent=2))
    print(f"wrote {output / 'demo.png'} and {output / 'summary.json'} "
          f"({summary['wall_time_s']:.0f} s)")
    done = results + ([excited] if excitation is not None else [])
    clean = all(code == 0 for r in done for code in r['exit_codes'].values()) and not any(
        r['escalated'] for r in done)
    return 0 if clean else 1


if __name__ == '__main__':
    sys.exit(main())
