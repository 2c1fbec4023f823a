"""
Replay regression: the input bags under ``test/data/replay``, the replay pipeline, the goldens.

Inputs (50 Hz, sim time from 1000 s; regenerate with ``python test/regen_goldens.py --inputs``):

- ``circle_targets``: ``/cbha/target`` along the paper's circle (r 60 mm, 2.5 cm/s, y-z plane,
  CBHA workspace centre: ``config/trajectory.yaml``) for 3 s, the first 0.5 s at the start point;
- ``closed_loop_session``: the same targets and ``/cbha/tip/measured`` from a closed-loop session
  run offline on the core as the shipped params files set it up (the model's solver with the
  integral correction of ``config/inverse_solver.yaml`` against the plant of
  ``config/cbha_sim.yaml``: 10 % softer, 0.2 mm of measurement noise, seeded); each measurement is
  stamped 10 ms after its target, and one measurement of the rest shape comes first.

A replay starts the installed ``inverse_solver`` (``use_sim_time``; ``rate_hz`` 1 so its timer
never ticks between the 50 Hz targets: every command answers exactly one target, in order) and
``cbha_bag record --use-sim-time /cbha/pressure_command``, then ``cbha_bag play --clock 100``.
Where the OS allows, the player and, once its warm-up is done, every thread of the solver (its
executor and its DDS receive threads) run with SCHED_RR priority 10: both sleep between messages,
and other test suites on the shared cores must not delay a target past the next measurement (a
reordering the closed loop would see). The recorder's threads do too, once it subscribed: the
solver's command writer keeps 10 samples, and a recorder starved by the other processes for as
long loses one. Several replays of one bag run at once
(:func:`replays`), each in a DDS domain of its own: their solvers and recorders start together
(the start-up is most of a replay's CPU time), then their players play together (a replay is
real time: 3.5 s mostly asleep).
The recorded commands, without the leading vent commands and consecutive repeats (the watchdog's
holds before the first and after the last target), are compared with the goldens.

Tolerance: 1 Pa per valve. A replay computes the same floating-point operations in the same order
(bit-identical on one machine); 1 Pa leaves room for another BLAS/CPU's rounding (relative 1e-15
on ~1e5 Pa gives ~1e-10 Pa per operation) while staying 100x below the ~100 Pa resolution of the
proportional valves, so any change of the maths or of the inputs' handling fails.

One exception, closed loop only: a stall of the solver's process longer than the 10 ms between a
measurement and the next target (a garbage collection, the shared 2-core machine) leaves both
waiting, and the executor takes the target first. That measurement's integral increment then
reaches one command late: the sum is the same from the next measurement on, so at most a few
commands differ, by about one step of the command sequence (median step of the golden closed
loop: 290 Pa). Seen twice in about 25 replays under load 10-12 (102 Pa and 370 Pa, 3 commands).
:func:`compare` allows one such transient: at most ``TRANSIENT_COMMANDS`` consecutive commands
within ``TRANSIENT_PA``; every other command within 1 Pa.
"""

import contextlib
import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time

from cbha_inverse.bag.storage import BagWriter, deserialize, open_bag
from cbha_inverse.core.inverse.correction import TargetCorrector
from cbha_inverse.paths import config_path
from cbha_inverse.report.bench_bag import set_priority
from cbha_inverse.robot.trajectory import make_trajectory
from cbha_inverse.scene import load_scene
from cbha_inverse.sim.plant import StaticPlant
import numpy as np
from ros_helpers import keep_wheels_bootstrap
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.interfaces import QosTime
from rosbags.typesys import get_typestore, Stores
import yaml

DATA = Path(__file__).resolve().parent / 'data' / 'replay'
INPUTS = {'open': DATA / 'circle_targets', 'closed': DATA / 'closed_loop_session'}
GOLDENS = DATA / 'goldens.npz'
TOLERANCE_PA = 1.0
TRANSIENT_COMMANDS = 5
TRANSIENT_PA = 1000.0
EPOCH_NS = 1000 * 10**9
RATE = 50.0
HOLD = 0.5
DURATION = 3.0
MEASUREMENT_DELAY_NS = 10_000_000
REAL_TIME_PRIORITY = 10
"""SCHED_RR priority of the player and the solver: above the time-shared tests, low in 1-99."""
BIN = Path(sys.executable).parent
_NO_TIME = QosTime(0, 0)
TARGET_QOS = Qos(QosHistory.KEEP_LAST, 10, QosReliability.RELIABLE, QosDurability.VOLATILE,
                 _NO_TIME, _NO_TIME, QosLiveliness.AUTOMATIC, _NO_TIME, False)
SENSOR_QOS = TARGET_QOS._replace(depth=5, reliability=QosReliability.BEST_EFFORT)


def _point_bytes(typestore, stamp_ns, point):
    types = typestore.types
    sec, nanosec = divmod(stamp_ns, 10**9)
    message = types['geometry_msgs/msg/PointStamped'](
        header=types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec),
            frame_id='cbha_base'),
        point=types['geometry_msgs/msg/Point'](x=float(point[0]), y=float(point[1]),
                                               z=float(point[2])))
    return bytes(typestore.serialize_cdr(message, 'geometry_msgs/msg/PointStamped'))


def shipped_parameters(node):
    """Return the parameters of a node's shipped params file ``config/<node>.yaml``."""
    with open(config_path(f'{node}.yaml'), encoding='utf-8') as stream:
        return yaml.safe_load(stream)['/**']['ros__parameters']


def circle_targets():
    """Return the stamps [ns] and targets (N, 3) [m] of the input bags."""
    scene = load_scene('cbha')
    path = shipped_parameters('trajectory')
    trajectory = make_trajectory(path['shape'], center=scene.workspace_center[-1],
                                 radius=path['radius'], plane=path['plane'], speed=path['speed'],
                                 laps=1, start_hold=HOLD)
    times = np.arange(int(DURATION * RATE)) / RATE
    stamps = EPOCH_NS + np.round(times * 1e9).astype(np.int64)
    return stamps, trajectory.sample(times).reshape(-1, 3)


def write_inputs():
    """Write both input bags (replacing them)."""
    import shutil
    typestore = get_typestore(Stores.ROS2_JAZZY)
    stamps, targets = circle_targets()
    for path in INPUTS.values():
        if path.exists():
            shutil.rmtree(path)
    writer = BagWriter(INPUTS['open'])
    writer.add_topic('/cbha/target', 'geometry_msgs/msg/PointStamped', [TARGET_QOS])
    for stamp, target in zip(stamps, targets):
        writer.write('/cbha/target', int(stamp), _point_bytes(typestore, int(stamp), target))
    writer.close()
    scene = load_scene('cbha')
    solver = scene.make_inverse_solver()
    solver.warm_up()
    sim, control = shipped_parameters('cbha_sim'), shipped_parameters('inverse_solver')
    plant = StaticPlant(load_scene('cbha', stiffness_scale=sim['stiffness_scale'],
                                   gravity=tuple(sim['gravity'])))
    corrector = TargetCorrector(1, gain=control['loop_gain'],
                                max_correction=control['max_correction'])
    rng = np.random.default_rng(0)
    writer = BagWriter(INPUTS['closed'])
    writer.add_topic('/cbha/target', 'geometry_msgs/msg/PointStamped', [TARGET_QOS])
    writer.add_topic('/cbha/tip/measured', 'geometry_msgs/msg/PointStamped', [SENSOR_QOS])
    rest = plant.update(np.zeros(len(scene.actuator_names))).effector_positions[-1]
    first = int(stamps[0]) - MEASUREMENT_DELAY_NS
    writer.write('/cbha/tip/measured', first, _point_bytes(typestore, first, rest))
    for stamp, target in zip(stamps, targets):
        stamp = int(stamp)
        writer.write('/cbha/target', stamp, _point_bytes(typestore, stamp, target))
        result = solver.step(corrector.update(target[None], None))
        solver.prepare()
        tip = plant.update(result.actuation).effector_positions[-1]
        measured = tip + rng.normal(0.0, sim['noise_std'], 3)
        corrector.update(target[None], measured[None], saturated=result.status == 'saturated')
        when = stamp + MEASUREMENT_DELAY_NS
        writer.write('/cbha/tip/measured', when, _point_bytes(typestore, when, measured))
    writer.close()


def _real_time_priority():
    """Run a sleeping child (the player) with SCHED_RR priority where the OS allows it."""
    set_priority(REAL_TIME_PRIORITY)


def _real_time_threads(pid):
    """Give every thread of a process (executor, DDS receive threads) SCHED_RR priority."""
    for task in Path(f'/proc/{pid}/task').iterdir():
        with contextlib.suppress(OSError, ValueError):
            os.sched_setscheduler(int(task.name), os.SCHED_RR,
                                  os.sched_param(REAL_TIME_PRIORITY))


def _environment(domain=None):
    env = keep_wheels_bootstrap(dict(os.environ))
    # untraced: coverage's tracing of the solver and player processes (``make test`` measures
    # child processes) makes their callbacks several times slower, and a stall past the 10 ms
    # between a measurement and the next target is the reordering described above
    env.pop('COVERAGE_PROCESS_CONFIG', None)
    env.pop('COVERAGE_PROCESS_START', None)
    env['PYTHONUNBUFFERED'] = '1'
    if domain is not None:
        env['ROS_DOMAIN_ID'] = str(domain)
    return env


class _Lines:
    """Collect a child's output lines in a thread."""

    def __init__(self, process):
        self.lines = []
        self.thread = threading.Thread(target=self._read, args=(process,), daemon=True)
        self.thread.start()

    def _read(self, process):
        for line in process.stdout:
            self.lines.append(line.rstrip('\n'))

    def wait_for(self, predicate, timeout):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if any(predicate(line) for line in list(self.lines)):
                return True
            time.sleep(0.05)
        return any(predicate(line) for line in list(self.lines))


def _start(command, env):
    process = subprocess.Popen([str(c) for c in command], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    return process, _Lines(process)


def _wait(process):
    """Wait for a process (SIGINT sent) to end; kill it after 20 s; return its exit code."""
    try:
        return process.wait(timeout=20)
    except subprocess.TimeoutExpired:
        process.kill()
        return process.wait()


def _commands(bag):
    with open_bag(bag) as reader:
        return [np.asarray(deserialize(data, 'std_msgs/msg/Float64MultiArray').data, dtype=float)
                for _, _, data in reader.messages()]


def answers(commands):
    """
    Return the commands that answer targets: leading vent commands and repeats dropped.

    Parameters
    ----------
    commands : list of (m,) ndarray  [Pa]
        Recorded commands in order.

    Returns
    -------
    (K, m) ndarray  [Pa]
        The distinct consecutive commands after the first non-vent one.

    """
    kept = []
    for command in commands:
        if not kept and not np.any(command):
            continue
        if kept and np.array_equal(command, kept[-1]):
            continue
        kept.append(command)
    return np.array(kept)


def compare(commands, golden, mode):
    """
    Return why ``commands`` do not match ``golden`` ('' if they do), as the module docstring says.

    Parameters
    ----------
    commands, golden : (K, m) ndarray  [Pa]
        Replayed and golden commands.
    mode : {'open', 'closed'}
        Only the closed loop may show one reordering transient.

    Returns
    -------
    str
        Empty when they match, else what differs.

    """
    if commands.shape != golden.shape:
        return f'{commands.shape[0]} commands, the goldens have {golden.shape[0]}'
    deviation = np.abs(commands - golden).max(axis=1)
    off = np.flatnonzero(deviation > TOLERANCE_PA)
    if off.size == 0:
        return ''
    transient = (mode == 'closed' and off[-1] - off[0] < TRANSIENT_COMMANDS
                 and deviation[off].max() <= TRANSIENT_PA)
    return '' if transient else (f'commands {off.tolist()} differ by up to '
                                 f'{deviation.max():.1f} Pa')


def replay(mode, workdir):
    """
    Replay one input bag into the installed ``inverse_solver``; return the answered commands.

    Parameters
    ----------
    mode : {'open', 'closed'}
        Solver mode, and which input bag.
    workdir : pathlib.Path
        Fresh folder for the params override, the recorded bag and the logs.

    Returns
    -------
    (K, m) ndarray  [Pa]
        See :func:`answers`.

    """
    (commands,) = replays([(mode, workdir)])
    return commands


class _Replay:
    """One replay's solver and recorder (started at construction) in its own DDS domain."""

    def __init__(self, mode, workdir, domain):
        workdir.mkdir(parents=True, exist_ok=True)
        self.workdir = workdir
        self.env = _environment(domain)
        override = workdir / 'override.yaml'
        override.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
            'use_sim_time': True, 'mode': mode, 'rate_hz': 1.0}}}))
        self.qos = workdir / 'qos.yaml'
        self.qos.write_text(yaml.safe_dump({'/cbha/tip/measured': {'reliability': 'reliable'}}))
        self.solver, self.solver_log = _start([
            BIN / 'inverse_solver', '--ros-args', '-r', '__ns:=/cbha', '--params-file',
            config_path('inverse_solver.yaml'), '--params-file', override], self.env)
        self.recorder, self.recorder_log = _start([
            BIN / 'cbha_bag', 'record', '--use-sim-time', '-o', workdir / 'commands',
            '/cbha/pressure_command'], self.env)
        self.player = None

    def logs(self):
        return '\n'.join(self.solver_log.lines + self.recorder_log.lines)

    def wait_ready(self):
        """Wait for the solver's warm-up and the recorder's subscription; raise their priority."""
        assert self.solver_log.wait_for(lambda line: 'warm-up' in line, 120.0), \
            '\n'.join(self.solver_log.lines)
        _real_time_threads(self.solver.pid)
        assert self.recorder_log.wait_for(lambda line: 'Subscribed to topic' in line, 120.0), \
            self.logs()
        _real_time_threads(self.recorder.pid)

    def play(self, bag):
        """Start ``cbha_bag play --clock`` of ``bag`` (real-time priority where allowed)."""
        self.player = subprocess.Popen(
            [str(c) for c in (BIN / 'cbha_bag', 'play', bag, '--clock', 100,
                              '--wait-for-subscribers', 60, '--delay', 0.5,
                              '--qos-profile-overrides-path', self.qos)],
            env=self.env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
            preexec_fn=_real_time_priority)

    def wait_recorded(self, targets):
        """Wait for the player's end (exit 0) and for ``targets`` recorded commands."""
        try:
            _, errors = self.player.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            self.player.kill()
            _, errors = self.player.communicate()
        assert self.player.returncode == 0, errors
        assert self.recorder_log.wait_for(lambda line: line.startswith('recording ') and int(
            line.split()[1]) >= targets, 30.0), '\n'.join(self.recorder_log.lines)

    def stop_player(self):
        """Kill the player if it still runs (a failed replay)."""
        if self.player is not None and self.player.poll() is None:
            self.player.kill()
            self.player.wait()


def _stop_all(processes):
    """SIGINT every process once, then wait for each (:func:`_wait`); return the exit codes."""
    for process in processes:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
    return [_wait(process) for process in processes]


def replays(jobs):
    """
    Replay input bags, several at once, each replay in a DDS domain of its own.

    Every replay has its own solver, recorder and player (and ``/clock``) in a domain reserved
    from ``domain_coordinator`` (so nothing crosses between them or other tests); the solvers
    and recorders start together, then the players play together. The solvers' and players'
    real-time priority keeps the other replays' processes from delaying a target.

    Parameters
    ----------
    jobs : sequence of (str, pathlib.Path)
        Per replay: the solver mode and input bag (``'open'`` or ``'closed'``) and a fresh
        folder (see :func:`replay`).

    Returns
    -------
    list of (K, m) ndarray  [Pa]
        The answered commands of each replay, in the order of ``jobs`` (see :func:`answers`).

    """
    from domain_coordinator import domain_id
    targets = {}
    for mode in {mode for mode, _ in jobs}:
        with open_bag(INPUTS[mode]) as bag:
            targets[mode] = next(
                t.count for t in bag.summary.topics if t.name == '/cbha/target')
    with contextlib.ExitStack() as domains:
        runs = []
        try:
            for mode, workdir in jobs:
                runs.append(_Replay(mode, workdir, domains.enter_context(domain_id())))
            for run in runs:
                run.wait_ready()
            for run, (mode, _) in zip(runs, jobs):
                run.play(INPUTS[mode])
            for run, (mode, _) in zip(runs, jobs):
                run.wait_recorded(targets[mode])
        finally:
            for run in runs:
                run.stop_player()
            # the recorders first: a solver's last commands as it stops are not recorded
            codes = list(zip(_stop_all([run.recorder for run in runs]),
                             _stop_all([run.solver for run in runs])))
    for run, code in zip(runs, codes):
        (run.workdir / 'inverse_solver.log').write_text('\n'.join(run.solver_log.lines))
        assert code == (0, 0), f'exit codes (recorder, solver) {code}\n{run.logs()}'
    return [answers(_commands(run.workdir / 'commands')) for run in runs]
