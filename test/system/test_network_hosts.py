"""
The closed loop across hosts: nodes in network namespaces on one switch, over real Fast DDS.

Hosts ``robot`` (``cbha_sim``), ``control`` (``inverse_solver`` + ``trajectory``) and
``cameras`` (a probe that records what crosses the switch) each have their own network namespace
and address (``test/netns.py``; ``docs/multi-host.md``). Discovery by SUBNET (multicast), or by
static peers with multicast unrouted. The CBHA scene at 100 Hz, closed loop, the paper's circle;
the tip error is reported both against the target of the tip's stamp (which includes the loop
lag, :func:`ros_helpers.loop_lag_error`: 0.83 mm at 100 Hz, plus the network's delay) and
across the path (cross-track, timing ignored). The cross-track RMS is held to 1 mm; the
time-matched RMS, which grows with the effective lag of loaded processes (0.2-0.4 mm on a
quiet machine, 0.8-1.1 mm at a load average of 14-18 on 2 cores), to twice the lag bound.
"""

import math
import re
import sys
import time

from cbha_inverse.interfaces.robotino_msgs_build import interface_environment
from cbha_inverse.metrics import cross_track_errors, tracking_errors
from cbha_inverse.paths import config_path
from cbha_inverse.ros.nodes.trajectory import TrajectoryParams
from netns import NetworkLab, skip_without_namespaces, wait_for
import numpy as np
import pytest
from ros_helpers import loop_lag_error

HOLD, SETTLE, SCORED = 0.5, 1.0, 2.0
"""Trajectory start hold, settling after it, then the scored time [s] (2 s: ~200 tips at 100 Hz,
5 cm of the circle; the RMS of 3 s windows was 0.1 mm cross-track, 0.15-0.3 mm time-matched)."""
MAX_PRESSURE = 150000.0
"""The CBHA's command ceiling [Pa] (config/inverse_solver.yaml, config/cbha_sim.yaml)."""
N_VALVES = 6
RATE = 100.0
"""Rate of trajectory, solver and plant (their config files) [Hz]."""
LAG_BOUND = loop_lag_error(RATE)
"""The tracking error that the loop lag alone gives on the circle [m]."""


def params_file(node):
    return str(config_path(f'{node}.yaml'))


def start_arm(lab, env, namespace='/cbha', robot=('robot', ()), control=('control', ()),
              trajectory=(), plant=True):
    """
    Start ``cbha_sim`` in the robot host, ``inverse_solver`` and ``trajectory`` in the control.

    ``robot`` and ``control`` are ``(host, extra ros args)`` of the plant and the solver;
    ``trajectory`` extra ros args of the trajectory; ``plant=False``: no ``cbha_sim``. Returns
    the processes by node name.
    """
    ns = ('-r', f'__ns:={namespace}')
    nodes = {'cbha_sim': lab.node(robot[0], 'cbha_sim', '--params-file',
                                  params_file('cbha_sim'), *ns, *robot[1], env=env)
             } if plant else {}
    return {
        **nodes,
        'inverse_solver': lab.node(control[0], 'inverse_solver', '--params-file',
                                   params_file('inverse_solver'), *ns, '-p', 'mode:=closed',
                                   *control[1], env=env),
        'trajectory': lab.node(control[0], 'trajectory', '--params-file',
                               params_file('trajectory'), *ns, '-p', f'start_hold:={HOLD}',
                               '-p', 'wait_for_subscribers:=2', *trajectory, env=env)}


def start_probe(lab, host, env, namespace='/cbha'):
    """
    Start test/netns_probe.py in ``host``; return the process (:func:`probes_ready` waits).

    The arm may start before the probe is ready: its trajectory publishes nothing until the
    solver and the probe subscribe (``wait_for_subscribers`` 2), so the probe sees every target.
    """
    return lab.run(host, [sys.executable, 'test/netns_probe.py', namespace], env)


def probes_ready(*probes):
    """Wait until every probe subscribed (it prints ``probe ready``)."""
    for probe in probes:
        assert wait_for(lambda: any(line == 'probe ready' for _, line in probe.lines), 30.0), (
            '\n'.join(line for _, line in probe.lines))


def recorded(probe):
    """Return what the probe printed: targets, tips (stamp, xyz), commands (time, values)."""
    out = {'T': [], 'P': [], 'C': []}
    for _, line in list(probe.lines):
        kind, _, rest = line.partition(' ')
        if kind in out:
            values = [float(v) for v in rest.split()]
            out[kind].append((values[0] if kind == 'C' else values[1], values[2:]))
    return out['T'], out['P'], out['C']


def first_target_time(probe, timeout=40.0):
    assert wait_for(lambda: recorded(probe)[0], timeout), 'no target reached the probe'
    return recorded(probe)[0][0][0]


RUNNING = r'^(waiting|hold) -> run'
"""The solver's log line when it starts running."""


def running_since(probe, solver, timeout=40.0):
    """
    Wait until the loop runs; return since when [s] (wall clock, as the stamps).

    Running: the solver runs (``waiting -> run`` or ``hold -> run``: a target and feedback
    arrived; on a loaded machine discovery across the hosts can take seconds) and the probe
    receives tips.
    """
    assert wait_for(lambda: log_events(solver, RUNNING) and recorded(probe)[1],
                    timeout), 'the loop did not start'
    return log_events(solver, RUNNING)[0]


def scored_start(probe, solver):
    """Return the start [s] of the scored window: settled after the start hold and the loop."""
    return max(first_target_time(probe) + HOLD, running_since(probe, solver)) + SETTLE


def score(probe, start):
    """Return (time-matched RMS, cross-track RMS, cross-track max) [m] from ``start`` [s]."""
    targets, tips, _ = recorded(probe)
    t_times = np.array([t for t, _ in targets])
    t_points = np.array([p for _, p in targets])
    tip_times = np.array([t for t, _ in tips])
    tip_points = np.array([p for _, p in tips])
    timed = tracking_errors(t_times, t_points, tip_times, tip_points, start, t_times[-1])
    window = (tip_times >= start) & (tip_times <= t_times[-1])
    path = t_points[t_times >= start - 0.5]
    cross = cross_track_errors(path, tip_points[window])
    assert window.sum() > 0.3 * RATE * SCORED, f'too few tip samples ({window.sum()})'
    return timed.rms, float(np.sqrt(np.mean(cross ** 2))), float(cross.max())


def invalid_commands(commands):
    """Return the commands that a valve driver would reject (length, non-finite, range)."""
    return [c for _, c in commands if len(c) != N_VALVES or not all(
        math.isfinite(v) and 0.0 <= v <= MAX_PRESSURE for v in c)]


def log_messages(process, pattern):
    """Return ``(ROS log time [s], message)`` of ``process``'s lines that match ``pattern``."""
    found = []
    for _, line in list(process.lines):
        match = re.match(r'\[\w+\] \[(\d+\.\d+)\] \[[^]]+\]: (.*)', line)
        if match and re.search(pattern, match.group(2)):
            found.append((float(match.group(1)), match.group(2)))
    return found


def log_events(process, pattern):
    """Return the ROS log times [s] of ``process``'s lines that match ``pattern``."""
    return [t for t, _ in log_messages(process, pattern)]


def run_scored(probe, solver):
    """Wait until the loop runs and settles, run the scored time; return the score."""
    start = scored_start(probe, solver)
    time.sleep(max(start + SCORED - time.time(), 0.0))
    return score(probe, start)


@pytest.mark.parametrize('discovery', ['subnet', 'static_peers'])
def test_closed_loop_circle_across_three_hosts(discovery, capsys):
    skip_without_namespaces()
    static = discovery == 'static_peers'
    with NetworkLab(['robot', 'control', 'cameras'], multicast=not static) as lab:
        env = lab.ros_env(static_peers=static)
        probe = start_probe(lab, 'cameras', env)
        nodes = start_arm(lab, env)
        probes_ready(probe)
        running_since(probe, nodes['inverse_solver'])
        before, started = lab.traffic('robot'), time.monotonic()
        timed, cross, cross_max = run_scored(probe, nodes['inverse_solver'])
        after, elapsed = lab.traffic('robot'), time.monotonic() - started
        _, _, commands = recorded(probe)
        alive = {name: p.poll() is None for name, p in nodes.items()}
    with capsys.disabled():
        print(f'\n{discovery}: circle across hosts, RMS {timed * 1e3:.3f} mm at the tip stamp, '
              f'cross-track RMS {cross * 1e3:.3f} mm (max {cross_max * 1e3:.3f}); robot host '
              f'{(after[0] - before[0]) / elapsed / 1e3:.1f} kB/s in, '
              f'{(after[1] - before[1]) / elapsed / 1e3:.1f} kB/s out')
    assert all(alive.values()), alive
    assert commands and not invalid_commands(commands)
    assert cross <= 1e-3 and timed <= 2 * LAG_BOUND


RELAYED = ('-p', 'inputs:=[tip/measured/wire,pressure_command/wire]',
           '-p', 'outputs:=[tip/measured,pressure_command]',
           '-p', 'types:=[geometry_msgs/msg/PointStamped,std_msgs/msg/Float64MultiArray]',
           '-p', 'qos:=[sensor,reliable]')
"""The relay's table: the plant publishes ``tip/measured/wire``, the solver
``pressure_command/wire``; the relay (in the control host) passes both on."""


def test_loss_and_jitter_on_feedback_and_commands(capsys):
    """5 % loss and 10 +- 5 ms on ``tip/measured`` and ``pressure_command``: RMS <= 1 mm."""
    skip_without_namespaces()
    with NetworkLab(['robot', 'control']) as lab:
        env = lab.ros_env()
        probe = start_probe(lab, 'robot', env)
        relay = lab.node('control', 'fault_relay', '-r', '__ns:=/cbha', *RELAYED,
                         '-p', 'drop:=0.05', '-p', 'delay:=0.01', '-p', 'jitter:=0.005',
                         '-p', 'seed:=3', env=env)
        nodes = start_arm(lab, env, robot=('robot', ('-r', 'tip/measured:=tip/measured/wire')),
                          control=('control', ('-r', 'pressure_command:=pressure_command/wire')))
        probes_ready(probe)
        timed, cross, cross_max = run_scored(probe, nodes['inverse_solver'])
        _, _, commands = recorded(probe)
        alive = {name: p.poll() is None for name, p in {**nodes, 'relay': relay}.items()}
    with capsys.disabled():
        print(f'\n5 % loss, 10 +- 5 ms: RMS {timed * 1e3:.3f} mm at the tip stamp, cross-track '
              f'RMS {cross * 1e3:.3f} mm (max {cross_max * 1e3:.3f}), {len(commands)} commands')
    assert all(alive.values()), alive
    assert commands and not invalid_commands(commands)
    # the tip lags the target by the loop lag and the network delay, there and back
    assert cross <= 1e-3 and timed <= 2 * (LAG_BOUND + TrajectoryParams.speed * 2 * 0.01)


def test_link_cut_holds_then_the_loop_resumes(capsys):
    """
    The robot's cable is pulled for 2 s: hold at ``feedback_timeout``, resume after, no burst.

    The solver (``stale_action: hold``, ``feedback_timeout`` 0.5 s) must log the hold once and
    the resumption once, within 2 s of the cable's return, with the same process (no restart);
    the commands that reach the robot after the return must not come in a burst: within 25 ms
    of the first one at most 5 (a 100 Hz stream gives 3; the held commands that a writer of
    depth 10 keeps came as 10 or more within a few ms).
    """
    skip_without_namespaces()
    cut_for, timeout = 2.0, 0.5
    with NetworkLab(['robot', 'control']) as lab:
        env = lab.ros_env()
        probe = start_probe(lab, 'robot', env)
        nodes = start_arm(lab, env, control=('control', ('-p', f'feedback_timeout:={timeout}')))
        probes_ready(probe)
        settled = scored_start(probe, nodes['inverse_solver'])
        time.sleep(max(settled + 0.5 - time.time(), 0.0))
        cut = time.time()
        lab.set_link('robot', up=False)
        time.sleep(cut_for)
        back = time.time()
        lab.set_link('robot', up=True)
        solver = nodes['inverse_solver']
        # until the loop resumed (3 s at most), then 1 s of commands and tips after it, in which
        # a second hold or a burst would show
        wait_for(lambda: [t for t in log_events(solver, r'^hold -> run') if t > back], 3.0)
        time.sleep(1.0)
        alive = {name: p.poll() is None for name, p in nodes.items()}
        holds = log_messages(solver, r'^run -> hold')
        runs = log_events(solver, r'^hold -> run')
        _, tips, commands = recorded(probe)
    after = [t for t, _ in commands if t > back]
    tips_after = [t for t, _ in tips if t > back]
    burst = sum(1 for t in after if t - after[0] <= 0.025) if after else 0
    with capsys.disabled():
        hold_at = holds[0][0] - cut if holds else math.nan
        run_at = runs[-1] - back if runs else math.nan
        print(f'\nlink cut {cut_for:g} s: hold {hold_at:.2f} s after the cut '
              f'({holds[0][1] if holds else ""}), run again {run_at:.2f} s after the return; '
              f'{burst} commands within 25 ms of the first one after the return')
    assert all(alive.values()), alive
    # one hold, after the cut, once the feedback was feedback_timeout old (the last tip came
    # before the cut, earlier when the plant stalls on a loaded machine)
    assert len(holds) == 1 and 0.0 < holds[0][0] - cut <= timeout + 1.0, holds
    age = float(re.search(r'no tip/measured for (\d+\.\d+) s', holds[0][1]).group(1))
    assert timeout <= age <= timeout + 0.25, holds
    resumed = [t for t in runs if t > back]
    assert len(resumed) == 1 and resumed[0] - back <= 2.0, runs
    assert tips_after and after and not invalid_commands(commands)
    assert burst <= 5


def test_link_cut_vents_the_bridge_at_its_timeout_and_it_resumes(robotino_msgs):
    """
    The robot PC's cable pulled for 2 s with ``robotino_bridge`` there: it vents once, resumes.

    ``robotino_bridge`` (robot host, ``command_timeout`` 0.5 s, ``stale_action: vent``) gets
    ``pressure_command`` from an open-loop ``inverse_solver`` on the control host: it must log
    ``run -> vent`` once, at most ``command_timeout`` + 1 s after the cut, and ``vent -> run``
    once, within 2 s of the return, with the same process.
    """
    skip_without_namespaces()
    cut_for, timeout = 2.0, 0.5
    with NetworkLab(['robot', 'control']) as lab:
        env = lab.ros_env()
        bridge = lab.node('robot', 'robotino_bridge', '--params-file',
                          params_file('robotino_bridge'), '-r', '__ns:=/cbha',
                          '-p', f'command_timeout:={timeout}', '-p', 'stale_action:=vent',
                          env=interface_environment(robotino_msgs, env))
        start_arm(lab, env, control=('control', ('-p', 'mode:=open')), plant=False,
                  trajectory=('-p', 'wait_for_subscribers:=1'))
        assert wait_for(lambda: log_events(bridge, r'^waiting -> run'), 40.0), 'no command'
        time.sleep(1.0)
        cut = time.time()
        lab.set_link('robot', up=False)
        time.sleep(cut_for)
        back = time.time()
        lab.set_link('robot', up=True)
        assert wait_for(lambda: log_events(bridge, r'^vent -> run'), 3.0)
        time.sleep(0.5)
        alive = bridge.poll() is None
        vents = log_events(bridge, r'^run -> vent')
        runs = [t for t in log_events(bridge, r'^vent -> run') if t > back]
    print(f'bridge: vent {vents[0] - cut if vents else math.nan:.2f} s after the cut, run '
          f'{runs[0] - back if runs else math.nan:.2f} s after the return')
    assert alive
    # the last command may have come before the cut, earlier on a loaded machine
    assert len(vents) == 1 and 0.0 < vents[0] - cut <= timeout + 1.0, vents
    assert len(runs) == 1 and runs[0] - back <= 2.0, runs


def test_two_arms_on_one_domain_do_not_cross_talk(capsys):
    """
    ``/cbha_a`` and ``/cbha_b``, both across the hosts on one domain: each tracks its own path.

    The two trajectories are circles of different radii about one centre: each arm's targets
    must all lie on its own circle, its tip must follow its own path (cross-track RMS <= 1 mm)
    and stay far from the other's.
    """
    skip_without_namespaces()
    center = np.array(TrajectoryParams.center)
    radii = {'/cbha_a': TrajectoryParams.radius, '/cbha_b': 0.5 * TrajectoryParams.radius}
    with NetworkLab(['robot', 'control']) as lab:
        env = lab.ros_env()
        probes = {ns: start_probe(lab, 'robot', env, ns) for ns in radii}
        nodes = {ns: start_arm(lab, env, ns, trajectory=('-p', f'radius:={r}'))
                 for ns, r in radii.items()}
        probes_ready(*probes.values())
        starts = {ns: scored_start(p, nodes[ns]['inverse_solver']) for ns, p in probes.items()}
        time.sleep(max(max(starts.values()) + SCORED - time.time(), 0.0))
        runs = {ns: recorded(p) for ns, p in probes.items()}
        alive = {f'{ns}{name}': p.poll() is None for ns, arm in nodes.items()
                 for name, p in arm.items()}
    lines = []
    for ns, (targets, tips, commands) in runs.items():
        other = next(n for n in radii if n != ns)
        points = np.array([p for _, p in targets])
        radius = np.linalg.norm(points[:, 1:] - center[1:], axis=1)     # the yz plane
        moving = radius > 0.5 * radii[ns]       # not the start point (at the centre's side)
        start = starts[ns]
        tip_points = np.array([p for t, p in tips if start <= t <= targets[-1][0]])
        own = cross_track_errors(points[[t >= start - 0.5 for t, _ in targets]], tip_points)
        lines.append(f'{ns}: cross-track RMS {np.sqrt(np.mean(own ** 2)) * 1e3:.3f} mm')
        np.testing.assert_allclose(radius[moving], radii[ns], atol=1e-9)
        assert np.sqrt(np.mean(own ** 2)) <= 1e-3, lines
        assert commands and not invalid_commands(commands)
        # the other arm's circle is 30 mm away: no tip of this arm comes near it
        away = np.abs(np.linalg.norm(tip_points[:, 1:] - center[1:], axis=1) - radii[other])
        assert away.min() > 0.01
    with capsys.disabled():
        print('\ntwo arms: ' + ', '.join(lines))
    assert all(alive.values()), alive
