"""
One node of a composition as ``cbha_launch`` runs it: a quiet stop while the node still loads.

``python -m cbha_inverse.ros.launch.node_process MODULE [ARGS ...]`` imports the node module
``MODULE`` (e.g. ``cbha_inverse.ros.nodes.cbha_sim``) and returns its
``main([executable, *ARGS])``.
Loading a node (numpy, scipy, numba's cached kernels, the scene) takes a second or more; a SIGINT
or SIGTERM in that time (``cbha_launch`` stopping the others because one node failed at once, or a
Ctrl-C right after the start) ends the process with status 0 and one line, instead of a
``KeyboardInterrupt`` traceback from deep inside an import. Once the module is loaded, the node's
own handling applies (rclpy's: :func:`cbha_inverse.ros.common.runner.run_node`).

``cbha_launch`` starts the process with SIGINT and SIGTERM blocked, so that a signal during the
interpreter's own start (before this module runs, where it would end in a fatal error) waits;
they are unblocked here once the handler is set, and a signal that came meanwhile is handled as
one during the import.
"""

import importlib
import signal
import sys

from cbha_inverse.ros.common.loading import (
    install_quiet_stop, restore_handlers, STOP_SIGNALS)


def main(argv=None):
    """
    Load a node module and run its ``main``.

    Parameters
    ----------
    argv : list of str, optional
        ``[MODULE, ARGS ...]`` (default ``sys.argv[1:]``).

    Returns
    -------
    int
        The node's exit status; 2 without a module name. A stop signal while the module loads
        ends the process with status 0
        (:func:`cbha_inverse.ros.common.loading.install_quiet_stop`).

    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv:
        print('usage: python -m cbha_inverse.ros.launch.node_process MODULE [ARGS ...]',
              file=sys.stderr)
        return 2
    module_name, node_args = argv[0], argv[1:]
    executable = module_name.rsplit('.', 1)[-1]
    previous = install_quiet_stop(executable)
    try:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
        module = importlib.import_module(module_name)
    finally:
        restore_handlers(previous)
    return module.main([executable, *node_args])


if __name__ == '__main__':
    sys.exit(main())
