"""Helpers for the node tests over real DDS (bounded spinning, child processes)."""

import contextlib
import os
from pathlib import Path
import subprocess
import sys
import time

REPO_ROOT = Path(__file__).resolve().parents[1]


def spin_until(executor, predicate, timeout):
    """
    Spin ``executor`` until ``predicate()`` is true or ``timeout`` seconds passed.

    Returns
    -------
    bool
        Whether the predicate became true.

    """
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        executor.spin_once(timeout_sec=0.02)
    return bool(predicate())


@contextlib.contextmanager
def spinning(context, *nodes):
    """Yield one executor over ``nodes``; shut it down and destroy the nodes afterwards."""
    from rclpy.executors import SingleThreadedExecutor
    executor = SingleThreadedExecutor(context=context)
    for node in nodes:
        executor.add_node(node)
    try:
        yield executor
    finally:
        executor.shutdown()
        for node in nodes:
            node.destroy_node()


def spin_for(executor, duration):
    """Spin ``executor`` for ``duration`` seconds."""
    deadline = time.monotonic() + duration
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)


def child_env():
    """
    Return an environment for a Python child process that imports rclpy.

    The rclpy wheels re-exec Python once with their LD_LIBRARY_PATH; a child that inherits the
    bootstrap flag without that path cannot import rclpy, so the flag is dropped (the child
    bootstraps itself). The DDS isolation variables of test/conftest.py are inherited.
    """
    env = dict(os.environ)
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    env['PYTHONPATH'] = os.pathsep.join(p for p in [str(REPO_ROOT), env.get('PYTHONPATH')] if p)
    env['PYTHONUNBUFFERED'] = '1'
    return env


def start_node(module, *ros_args):
    """
    Start ``python -m <module> --ros-args <ros_args>`` as a child process.

    Returns
    -------
    subprocess.Popen
        The process (text stdout with stderr merged).

    """
    return subprocess.Popen(
        [sys.executable, '-m', module, '--ros-args', *ros_args], cwd=REPO_ROOT, env=child_env(),
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
