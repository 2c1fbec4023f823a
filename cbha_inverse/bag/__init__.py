"""
rosbag2 bags without rosbag2 (no ROS import): storage, metadata, QoS records, info, evaluation.

Built on ``rosbags``: bags are written as rosbag2 metadata v9 + MCAP (the Jazzy default) and
read in every layout rosbag2 wrote (MCAP or sqlite3, metadata versions 5 to 9). The rclpy
recorder and player live in :mod:`cbha_inverse.ros.bag.record` and
:mod:`cbha_inverse.ros.bag.play`; the ``cbha_bag`` command in :mod:`cbha_inverse.ros.bag.cli`.
"""
