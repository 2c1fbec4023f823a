"""
The rendered stereo cameras of ``cbha_sim`` on ROS topics (``tip_output: stereo | both``).

At ``camera_rate_hz`` the current plant state is rendered by
:class:`cbha_inverse.sim.cameras.SimulatedStereo` and published as
``stereo/{left,right}/image_raw`` (bgr8, RELIABLE) with ``stereo/{left,right}/camera_info``,
both images stamped with the time of the plant state they show, in the optical frames that
``stereo_tracker`` latches on ``/tf_static`` (:func:`cbha_inverse.ros.common.tf.camera_frame`); a
state already sent is not sent again.
This module imports OpenCV; ``cbha_sim`` imports it only when stereo output is on.
"""

from cbha_inverse.ros.common.images import camera_info_message, image_message
from cbha_inverse.ros.common.qos import reliable
from cbha_inverse.ros.common.tf import camera_frame
from cbha_inverse.sim.cameras import SimulatedStereo
from sensor_msgs.msg import CameraInfo, Image

IMAGE_QOS = reliable(2)
"""Images: RELIABLE, keep-last 2 (large messages lose fragments over best effort)."""


class SimulatedCameras:
    """
    Publish rendered image pairs of the simulated tip.

    Parameters
    ----------
    node : rclpy.node.Node
        The owning node (publishers, timer, clock).
    rig : StereoRig
        Cameras and their pose.
    rate_hz : float  [Hz]
        Frame rate.
    marker_radius : float  [m]
        Radius of the rendered tip sphere.
    seed : int
        Seed of the texture and the image noise.
    shape : callable
        ``shape() -> (tip (3,), backbone (n + 1, 3), stamp) or None``: the plant's current state
        in ``cbha_base`` [m] and its time (``builtin_interfaces/Time``); None: nothing yet.

    """

    def __init__(self, node, rig, rate_hz, marker_radius, seed, shape):
        self.node = node
        self.rig = rig
        self.shape = shape
        self.stereo = SimulatedStereo(rig, marker_radius, seed)
        self.images = {side: node.create_publisher(Image, f'stereo/{side}/image_raw', IMAGE_QOS)
                       for side in ('left', 'right')}
        self.infos = {side: node.create_publisher(CameraInfo, f'stereo/{side}/camera_info',
                                                  reliable(10)) for side in ('left', 'right')}
        self.frames = 0
        self.timer = node.create_timer(1.0 / rate_hz, self.publish)

    def publish(self):
        """Render the current tip into both cameras and publish the pair with its camera_info."""
        state = self.shape()
        pair = None if state is None else self.stereo.render(*state)
        if pair is None:
            return
        stamp = state[2]
        for side, camera, pixels in zip(('left', 'right'), (self.rig.left, self.rig.right), pair):
            frame_id = camera_frame(side)
            self.infos[side].publish(camera_info_message(camera, stamp, frame_id))
            self.images[side].publish(image_message(pixels, 'bgr8', stamp, frame_id))
        self.frames += 1
