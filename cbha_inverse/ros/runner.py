"""The Jazzy ``main()`` of every node: init, spin until SIGINT/SIGTERM, clean shutdown."""

from cbha_inverse.ros.params import ParameterError
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation


def run_node(node_class, node_name, argv=None):
    """
    Create one node, spin it until SIGINT/SIGTERM and shut down cleanly.

    Parameters
    ----------
    node_class : callable
        ``node_class() -> rclpy.node.Node``; raises ``ParameterError`` on invalid parameters.
    node_name : str
        Logger name for start-up errors.
    argv : list of str, optional
        Command line (default ``sys.argv``), with ``--ros-args ...``.

    Returns
    -------
    int
        0 after SIGINT/SIGTERM, 2 on invalid parameters, an unusable scene or a message package
        that a node imports at start and cannot find (``ModuleNotFoundError``).

    """
    rclpy.init(args=argv)
    node = None
    try:
        node = node_class()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except rclpy_implementation.RCLError:
        # A signal that shuts the context down while a callback runs makes the next wait-set
        # construction fail instead of raising ExternalShutdownException: still a clean stop.
        if rclpy.ok():
            raise
    except (ParameterError, FileNotFoundError, ModuleNotFoundError) as exc:
        rclpy.logging.get_logger(node_name).fatal(str(exc))
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
