"""
Test hosts in network namespaces, without root: the multi-host harness of test/system.

``unshare -Urn`` makes a user + network namespace (the "switch", which holds a bridge); each host
is a network namespace of that user namespace, joined to the bridge by a veth pair, its end
``eth0`` at a documentation-range address (``192.0.2.0/24``) with no route out (only the
subnet and multicast on ``eth0``). Processes run in a host through ``nsenter``, each in its own
process group; leaving the :class:`NetworkLab` ends every group (SIGINT, then SIGKILL), then the
namespaces' holder processes, so that no node outlives its test.
"""

import os
import shutil
import signal
import subprocess
import sys
import threading
import time

import pytest
from ros_helpers import child_env, REPO_ROOT

SUBNET = '192.0.2.'
"""Documentation range (RFC 5737): never routed anywhere."""


def namespaces_refused():
    """Return why user + network namespaces cannot be made here (one line), or None."""
    for tool in ('unshare', 'nsenter', 'ip'):
        if shutil.which(tool) is None:
            return f'{tool} is not installed'
    probe = subprocess.run(['unshare', '-Urn', 'ip', 'link', 'add', 'name', 'a', 'type',
                            'veth', 'peer', 'name', 'b'], capture_output=True, text=True)
    if probe.returncode != 0:
        lines = (probe.stderr or probe.stdout).strip().splitlines() or ['(no message)']
        return f'unprivileged user + network namespaces refused: {lines[-1]}'
    return None


def skip_without_namespaces():
    """Skip the calling test, with the one-line reason, where namespaces are refused."""
    reason = namespaces_refused()
    if reason:
        pytest.skip(reason)


def _holder(argv):
    """Start a namespace holder that prints its pid; return (process, pid)."""
    process = subprocess.Popen([*argv, 'sh', '-c', 'echo $$; exec sleep infinity'],
                               stdout=subprocess.PIPE, text=True, start_new_session=True)
    return process, int(process.stdout.readline())


class NetworkLab:
    """
    Hosts on one switch, each in its own network namespace (a context manager).

    Parameters
    ----------
    hosts : sequence of str
        Host names, e.g. ``('robot', 'control', 'cameras')``; host ``i`` gets the address
        ``192.0.2.<i + 1>``.
    multicast : bool
        Whether the hosts route multicast to ``eth0`` (SUBNET discovery needs it; without it
        only unicast works, as for static peers across routers).

    """

    def __init__(self, hosts, multicast=True):
        self.hosts = list(hosts)
        self.multicast = multicast
        self.addresses = {h: f'{SUBNET}{i + 1}' for i, h in enumerate(self.hosts)}
        self._holders = {}
        self._processes = []

    # namespaces -------------------------------------------------------------------------------
    def __enter__(self):
        try:
            switch, pid = _holder(['unshare', '-Urn'])
            self._holders['switch'] = (switch, pid)
            self.ip('switch', 'link', 'add', 'name', 'br0', 'type', 'bridge')
            self.ip('switch', 'link', 'set', 'br0', 'type', 'bridge', 'mcast_snooping', '0')
            self.ip('switch', 'link', 'set', 'br0', 'up')
            for host in self.hosts:
                self._holders[host] = _holder(self._enter(pid) + ['unshare', '-n'])
                port = self.port(host)
                self.ip('switch', 'link', 'add', 'name', port, 'type', 'veth', 'peer', 'name',
                        'eth0', 'netns', str(self._holders[host][1]))
                self.ip('switch', 'link', 'set', port, 'master', 'br0')
                self.ip('switch', 'link', 'set', port, 'up')
                self.ip(host, 'link', 'set', 'lo', 'up')
                self.ip(host, 'addr', 'add', f'{self.addresses[host]}/24', 'dev', 'eth0')
                self.ip(host, 'link', 'set', 'eth0', 'up', 'multicast', 'on')
                if self.multicast:
                    self.ip(host, 'route', 'add', '224.0.0.0/4', 'dev', 'eth0')
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc):
        # every node stops at once (SIGINT to all, then the waits), then the namespaces' holders
        _end_groups(self._processes)
        _end_groups([process for process, _ in self._holders.values()])
        self._holders.clear()

    @staticmethod
    def port(host):
        """Return the switch's interface toward ``host``."""
        return f'p-{host}'[:15]

    def _enter(self, pid):
        return ['nsenter', '-t', str(pid), '-U', '-n', '--preserve-credentials', '--']

    def enter(self, host):
        """Return the command prefix that runs a command in ``host`` (or ``'switch'``)."""
        return self._enter(self._holders[host][1])

    def ip(self, host, *args):
        """Run ``ip <args>`` in ``host``; raise with its message if it fails."""
        result = subprocess.run(self.enter(host) + ['ip', *args], capture_output=True,
                                text=True, timeout=10)
        if result.returncode != 0:
            raise RuntimeError(f'ip {" ".join(args)} in {host}: {result.stderr.strip()}')
        return result.stdout

    def set_link(self, host, up):
        """Plug (``up``) or pull the cable of ``host`` at the switch."""
        self.ip('switch', 'link', 'set', self.port(host), 'up' if up else 'down')

    def traffic(self, host):
        """Return the bytes ``(received, sent)`` so far on ``host``'s ``eth0``."""
        result = subprocess.run(self.enter(host) + ['cat', '/proc/net/dev'], capture_output=True,
                                text=True, timeout=10, check=True)
        for line in result.stdout.splitlines():
            name, _, counters = line.partition(':')
            if name.strip() == 'eth0':
                values = counters.split()
                return int(values[0]), int(values[8])
        raise RuntimeError(f'no eth0 in {host}')

    # processes --------------------------------------------------------------------------------
    def ros_env(self, static_peers=False, **extra):
        """
        Return the environment of a ROS process in a host.

        Discovery by SUBNET (multicast on the switch), or ``static_peers``: LOCALHOST plus
        ``ROS_STATIC_PEERS`` = every host's address (unicast only).
        """
        env = child_env()
        # untraced: coverage's tracing of child processes (``make test``) slows the nodes'
        # callbacks several times, and the loop's accuracy is what these hosts measure
        for name in ('COVERAGE_PROCESS_CONFIG', 'COVERAGE_PROCESS_START'):
            env.pop(name, None)
        if static_peers:
            env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
            env['ROS_STATIC_PEERS'] = ';'.join(self.addresses.values())
        else:
            env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'SUBNET'
            env.pop('ROS_STATIC_PEERS', None)
        env.update(extra)
        return env

    def run(self, host, argv, env):
        """
        Start ``argv`` in ``host`` in its own process group (ended on leaving the lab).

        Returns
        -------
        subprocess.Popen
            Text stdout, stderr merged; its attribute ``lines`` fills with ``(time.time(),
            line)`` as the process writes them.

        """
        process = subprocess.Popen(self.enter(host) + list(argv), cwd=REPO_ROOT, env=env,
                                   stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                   start_new_session=True)
        self._processes.append(process)
        process.lines = []

        def read():
            for line in process.stdout:
                process.lines.append((time.time(), line.rstrip('\n')))

        process.reader = threading.Thread(target=read, daemon=True)
        process.reader.start()
        return process

    def node(self, host, name, *ros_args, env):
        """Start ``python -m cbha_inverse.ros.nodes.<name> --ros-args <ros_args>`` in ``host``."""
        return self.run(host, [sys.executable, '-m', f'cbha_inverse.ros.nodes.{name}',
                               '--ros-args', *ros_args], env)


def _end_groups(processes, grace=5.0):
    """
    End the process groups of ``processes``: SIGINT to all, then SIGKILL after ``grace`` s.

    Each group gets SIGINT first, so they all stop at the same time; a group not ended
    ``grace`` s after its SIGINT gets SIGKILL (as what is left of an ended group does).
    """
    for process in processes:
        if process.poll() is None:
            try:
                os.killpg(process.pid, signal.SIGINT)
            except ProcessLookupError:
                pass
    deadline = time.monotonic() + grace
    for process in processes:
        try:
            process.wait(max(deadline - time.monotonic(), 0.0))
        except subprocess.TimeoutExpired:
            pass
        try:
            os.killpg(process.pid, signal.SIGKILL)     # what is left of the group
        except (ProcessLookupError, PermissionError):
            pass
        process.wait()
        reader = getattr(process, 'reader', None)
        if reader is not None:
            reader.join(2.0)


def wait_for(predicate, timeout, poll=0.05):
    """Wait until ``predicate()`` is true or ``timeout`` s passed; return whether it is."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(poll)
    return bool(predicate())
