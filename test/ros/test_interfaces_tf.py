"""
``cbha_launch sim`` broadcasts the backbone on ``/tf`` with the tf2_msgs that make install put in.

The composition starts as a user starts it, from the venv with nothing sourced; a plain rclpy
subscriber in this process receives ``/tf`` over real DDS: every frame of the CBHA model's
backbone (``cbha_frame_0`` … ``cbha_frame_16``) and ``cbha_tip``, children of ``cbha_base``, the
tip at the last frame's origin; no node says ``no TF``.
"""

import signal
import subprocess
import sys

from cbha_inverse.ros.common.qos import TF_QOS
from cbha_inverse.ros.common.tf import backbone_frame, TIP_FRAME
import numpy as np
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from ros_helpers import child_env, REPO_ROOT, spin_until

FRAMES = [backbone_frame(i) for i in range(17)] + [TIP_FRAME]
"""The CBHA scene's 16 vertebrae and its base, then the tip."""


def test_cbha_launch_sim_broadcasts_the_backbone_frames_on_tf(rclpy_context):
    from tf2_msgs.msg import TFMessage
    launch = subprocess.Popen(
        [sys.executable, '-m', 'cbha_inverse.ros.launch.launcher', 'sim'], cwd=REPO_ROOT,
        env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    listener = Node('tf_listener', context=rclpy_context)
    received = []
    listener.create_subscription(TFMessage, '/tf', received.append, TF_QOS)
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(listener)
    try:
        # the solver publishes /tf from its first tick on (the trajectory's first target)
        assert spin_until(executor, lambda: len(received) >= 3, 90.0), 'no /tf received'
    finally:
        executor.shutdown()
        listener.destroy_node()
        launch.send_signal(signal.SIGINT)
        try:
            output = launch.communicate(timeout=40)[0]
        finally:
            if launch.poll() is None:
                launch.kill()
                launch.communicate()
    assert launch.returncode == 0, output
    assert 'no TF' not in output and 'Traceback' not in output, output
    transforms = {t.child_frame_id: t for t in received[-1].transforms}
    assert list(transforms) == FRAMES
    assert {t.header.frame_id for t in transforms.values()} == {'cbha_base'}

    def origin(frame):
        t = transforms[frame].transform.translation
        return np.array([t.x, t.y, t.z])

    np.testing.assert_allclose(origin(TIP_FRAME), origin(FRAMES[-2]), atol=1e-12)
    # the backbone reaches out along +x of the base (the CBHA's rest length ~0.23 m)
    assert 0.1 < origin(TIP_FRAME)[0] < 0.4, origin(TIP_FRAME)
