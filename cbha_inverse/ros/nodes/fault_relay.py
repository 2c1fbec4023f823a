"""
``fault_relay``: topics relayed to other names through a faulty link (``docs/multi-host.md``).

For each ``inputs[i]`` (type ``types[i]``, QoS ``qos[i]``: ``reliable`` or ``sensor``) the node
subscribes the serialized messages (any type, not deserialized) and republishes them on
``outputs[i]`` after a :class:`cbha_inverse.sim.link.FaultyLink` (``drop``, ``delay`` +
``jitter``, ``duplicate``, ``reorder``; one seeded random stream per topic). Between two hosts
the sender is remapped to the input name, the receiver keeps the output name, so that every
message of the topic crosses the relay. ``/diagnostics`` (~1 Hz) counts what each link did.
"""

from dataclasses import dataclass
import sys
import time

from cbha_inverse.ros.bag.qos import message_class
from cbha_inverse.ros.common.diagnostics import DiagnosticsPublisher, make_status, OK
from cbha_inverse.ros.common.params import declare_parameters, param, ParameterError
from cbha_inverse.ros.common.qos import MEASURED_QOS, reliable
from cbha_inverse.ros.common.runner import run_node
from cbha_inverse.sim.link import FaultyLink, LinkFaults
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

NODE_NAME = 'fault_relay'
QOS_PROFILES = {'reliable': reliable(10), 'sensor': MEASURED_QOS}


@dataclass(frozen=True)
class FaultRelayParams:
    """Parameters of the ``fault_relay`` node."""

    inputs: tuple = param(None, 'topics relayed (relative names resolve in the namespace)',
                          unset_type='string_array')
    outputs: tuple = param(None, 'where each input is republished', unset_type='string_array')
    types: tuple = param(None, 'message type of each input, e.g. geometry_msgs/msg/PointStamped',
                         unset_type='string_array')
    qos: tuple = param(None, 'QoS of each topic: reliable (depth 10) or sensor (best effort, '
                       'depth 5); unset: reliable', unset_type='string_array')
    drop: float = param(0.0, 'probability that a message is lost', low=0.0, high=1.0)
    delay: float = param(0.0, 'fixed delay [s]', low=0.0, high=10.0)
    jitter: float = param(0.0, 'uniform jitter around the delay, +- [s] (keeps the order)',
                          low=0.0, high=10.0)
    duplicate: float = param(0.0, 'probability that a message is delivered twice',
                             low=0.0, high=1.0)
    reorder: float = param(0.0, 'probability that a message is held back reorder_delay, so '
                           'that the next ones overtake it', low=0.0, high=1.0)
    reorder_delay: float = param(0.02, 'extra delay of a reordered message [s]',
                                 low=0.0, high=10.0)
    seed: int = param(0, 'seed of the random faults (topic i uses seed + i)', low=0,
                      high=2 ** 31 - 1)
    tick: float = param(0.001, 'period of the delivery timer [s] (the delay resolution)',
                        low=0.0001, high=1.0)
    diagnostics_period: float = param(1.0, 'period of /diagnostics [s]', low=0.05, high=60.0)


def relay_table(params):
    """
    Return the relayed topics of ``params`` as ``(input, output, type, qos)`` rows.

    Raises
    ------
    ValueError
        If the lists are missing, differ in length or name an unknown QoS.

    """
    if not params.inputs:
        raise ValueError('inputs is empty: nothing to relay')
    qos = params.qos or ('reliable',) * len(params.inputs)
    lengths = {len(params.inputs), len(params.outputs or ()), len(params.types or ()), len(qos)}
    if len(lengths) != 1:
        raise ValueError('inputs, outputs, types and qos (when given) need the same length')
    unknown = sorted(set(qos) - set(QOS_PROFILES))
    if unknown:
        raise ValueError(f'qos {unknown} not one of {sorted(QOS_PROFILES)}')
    return list(zip(params.inputs, params.outputs, params.types, qos))


class FaultRelayNode(Node):
    """
    Topics in, the same serialized messages out on other names, through faulty links.

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node`` (``context``, ``namespace``, ``parameter_overrides``).

    Raises
    ------
    ParameterError
        On invalid parameters or a message type that is not installed.

    """

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        try:
            self.params = p = declare_parameters(self, FaultRelayParams)
            self.table = relay_table(p)
            classes = [message_class(msgtype) for _, _, msgtype, _ in self.table]
            faults = LinkFaults(p.drop, p.delay, p.jitter, p.duplicate, p.reorder,
                                p.reorder_delay)
        except ValueError as exc:
            self.destroy_node()
            raise ParameterError(str(exc)) from None
        self.links = []
        for i, ((source, target, _, qos), cls) in enumerate(zip(self.table, classes)):
            link = FaultyLink(faults, p.seed + i)
            publisher = self.create_publisher(cls, target, QOS_PROFILES[qos])
            self.create_subscription(cls, source, lambda raw, link=link: link.send(
                raw, time.monotonic()), QOS_PROFILES[qos], raw=True)
            self.links.append((link, publisher))
        self.create_timer(p.tick, self._deliver, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.diagnostics = DiagnosticsPublisher(self, self._statuses, p.diagnostics_period)
        self.get_logger().info(
            f'relaying {", ".join(f"{s} -> {t}" for s, t, _, _ in self.table)}: {faults}, '
            f'seed {p.seed}')

    def _deliver(self):
        now = time.monotonic()
        for link, publisher in self.links:
            for raw in link.receive(now):
                publisher.publish(raw)

    def _statuses(self):
        values = {f'{source}.{key}': count for (source, _, _, _), (link, _)
                  in zip(self.table, self.links) for key, count in link.counts.items()}
        return [make_status(self.get_name(), 'links', OK, f'{len(self.links)} topics relayed',
                            values)]


def main(argv=None):
    """
    Run ``fault_relay`` until SIGINT/SIGTERM (0; 2 on invalid parameters).

    E.g. ``fault_relay --ros-args -p 'inputs:=[tip/measured/wire]' -p 'outputs:=[tip/measured]'
    -p 'types:=[geometry_msgs/msg/PointStamped]' -p 'qos:=[sensor]' -p drop:=0.05``.
    """
    return run_node(FaultRelayNode, NODE_NAME, argv, params_class=FaultRelayParams)


if __name__ == '__main__':
    sys.exit(main())
