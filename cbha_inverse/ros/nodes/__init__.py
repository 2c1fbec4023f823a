"""
ROS 2 nodes: one node per module (module name = node name = executable name).

Importing the package in a node executable makes a stop signal during the node's loading a quiet
exit (:func:`cbha_inverse.ros.common.loading.quiet_while_loading`).
"""

from pathlib import Path

from cbha_inverse.ros.common.loading import quiet_while_loading

quiet_while_loading({path.stem for path in Path(__file__).parent.glob('*.py')} - {'__init__'})
