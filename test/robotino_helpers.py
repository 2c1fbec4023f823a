"""
The Robotino driver's messages in tests: build them once, load them, and a driver stand-in.

:func:`build_and_load` builds the shipped ``robotino_msgs`` with colcon
(:func:`cbha_inverse.interfaces.robotino_msgs_build.build_robotino_msgs`) and makes it usable in
this already running test process. A process reads ``LD_LIBRARY_PATH`` once at start, and the
ROS type support opens ``librobotino_msgs__rosidl_typesupport_*.so`` by that name; so the built
libraries are loaded here by their full paths first (the dynamic loader then resolves the name
to the loaded library), and the Python package's folder goes on ``sys.path``. Child processes get
the environment of ``install/setup.sh`` instead (:func:`robotino_child_env`).

:class:`DriverStandIn` speaks the driver's messages as ``robotino_node`` does: it takes
``set_bha_pressures`` (anything but exactly 8 values ignored), records it, optionally forwards
the arm channels in Pa to a plant (``cbha_sim``) and publishes ``bha_readings``.
"""

import ctypes
import os
import sys
import time

from cbha_inverse.interfaces.robotino_msgs_build import (
    build_robotino_msgs, interface_environment)
from cbha_inverse.robot.robotino import ARM_VALVES, N_CHANNELS, PASCAL_PER_BAR
from cbha_inverse.ros.common.conversions import command_message
from cbha_inverse.ros.common.qos import COMMAND_QOS, DRIVER_SET_POINTS_QOS, MEASURED_QOS
import numpy as np
from rclpy.node import Node
from ros_helpers import child_env
from std_msgs.msg import Float64MultiArray


def build_and_load(workspace):
    """
    Build ``robotino_msgs`` into ``workspace`` and make it importable in this process.

    Returns
    -------
    pathlib.Path
        The install prefix of the package.

    """
    started = time.perf_counter()
    prefix = build_robotino_msgs(workspace)
    print(f'robotino_msgs built with colcon in {time.perf_counter() - started:.1f} s')
    return load(prefix)


def load(prefix):
    """
    Make the ``robotino_msgs`` built under the install prefix ``prefix`` importable here.

    Returns
    -------
    pathlib.Path
        ``prefix``.

    """
    for library in sorted((prefix / 'lib').glob('*.so')):
        ctypes.CDLL(str(library), mode=os.RTLD_GLOBAL)
    version = f'python{sys.version_info.major}.{sys.version_info.minor}'
    site = str(prefix / 'lib' / version / 'site-packages')
    if site not in sys.path:
        sys.path.insert(0, site)
    return prefix


def robotino_child_env(prefix):
    """Return the environment of a child process that uses the built messages."""
    return interface_environment(prefix, child_env())


def messages():
    """Return ``(SetBHAPressures, BHAReadings)`` (after :func:`build_and_load`)."""
    from robotino_msgs.msg import BHAReadings, SetBHAPressures
    return SetBHAPressures, BHAReadings


class DriverStandIn(Node):
    """
    A stand-in for ``robotino_node``'s CBHA interface (root namespace, the driver's topics).

    Parameters
    ----------
    context : rclpy.Context
        Test context.
    plant_topic : str, optional
        If given, every accepted set-point is forwarded there as a Float64MultiArray of the arm
        channels 0-5 in Pa (vendor order), e.g. to ``cbha_sim``.
    read_bar : callable, optional
        ``read_bar() -> (8,) bar`` measured pressures to publish on ``bha_readings`` at
        ``reading_rate`` (default: the last accepted set-points).
    reading_rate : float  [Hz]
        Rate of ``bha_readings`` (0: none).

    """

    def __init__(self, context, plant_topic=None, read_bar=None, reading_rate=0.0):
        super().__init__('robotino_node', context=context)
        set_pressures, readings = messages()
        self.readings_type = readings
        self.received = []
        self.ignored = 0
        self.set_points = np.zeros(N_CHANNELS)
        self.create_subscription(set_pressures, '/set_bha_pressures', self._on_set_points,
                                 DRIVER_SET_POINTS_QOS)
        self.readings_publisher = self.create_publisher(readings, '/bha_readings', MEASURED_QOS)
        self.plant_publisher = (None if plant_topic is None else self.create_publisher(
            Float64MultiArray, plant_topic, COMMAND_QOS))
        self.read_bar = read_bar if read_bar is not None else (lambda: self.set_points)
        if reading_rate > 0.0:
            self.create_timer(1.0 / reading_rate, self.publish_readings)

    def _on_set_points(self, message):
        values = np.array(message.pressures, dtype=float)
        if values.size != N_CHANNELS:
            self.ignored += 1
            return
        self.received.append((time.monotonic(), values))
        self.set_points = values
        if self.plant_publisher is not None:
            self.plant_publisher.publish(command_message(
                values[:len(ARM_VALVES)] * PASCAL_PER_BAR, ARM_VALVES))

    def publish_readings(self, pressures_bar=None, cablepull=None):
        """Publish one ``BHAReadings`` (default: :attr:`read_bar`, cable pulls 0.1 m)."""
        message = self.readings_type()
        message.stamp = self.get_clock().now().to_msg()
        bar = self.read_bar() if pressures_bar is None else pressures_bar
        message.pressures = [float(v) for v in bar]
        message.cablepull = [float(v) for v in (np.full(6, 0.1) if cablepull is None
                                                else cablepull)]
        self.readings_publisher.publish(message)
        return message
