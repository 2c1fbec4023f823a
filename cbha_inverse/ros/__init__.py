"""
The ROS 2 layer (rclpy).

``nodes/`` (one node per module), ``common/`` (what the nodes share), ``bag/`` (the rclpy side of
``cbha_bag``), ``launch/`` (the compositions and ``cbha_launch``) and ``console/``
(``cbha_status``, a console view of ``/diagnostics``). Below this layer nothing
imports rclpy; above it only :mod:`cbha_inverse.experiments` and the bag benchmark
:mod:`cbha_inverse.report.bench_bag` do (see ``docs/design.md``).

Importing it in a node executable or in a command (``cbha_launch``, ``cbha_ctl``, ``cbha_status``,
``cbha_bag``, ``cbha_static_transform``) makes a stop signal while the program still loads a quiet
exit (:func:`cbha_inverse.ros.common.loading.quiet_while_loading`): every node module and these
commands are below this package, so no program of it loads before that.
"""

from pathlib import Path

from cbha_inverse.ros.common.loading import quiet_while_loading

PROGRAMS = {
    **{f'{__name__}.nodes.{path.stem}': path.stem
       for path in (Path(__file__).parent / 'nodes').glob('*.py') if path.stem != '__init__'},
    f'{__name__}.launch.launcher': 'cbha_launch',
    f'{__name__}.console.status': 'cbha_status',
    f'{__name__}.console.ctl': 'cbha_ctl',
    f'{__name__}.console.static_transform': 'cbha_static_transform',
    f'{__name__}.bag.cli': 'cbha_bag'}
"""The programs that stop quietly while they load: ``module -> program`` (console script)."""

quiet_while_loading(PROGRAMS)
