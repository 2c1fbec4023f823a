"""
Rendered stereo cameras of the simulated arm (no ROS; imports OpenCV through the renderer).

:class:`SimulatedStereo` draws the plant's tip marker (and its backbone, as clutter) into both
cameras of a rig (:class:`cbha_inverse.vision.render.StereoRenderer`: lens distortion, blur,
noise), as a hardware-triggered pair exposed at the instant of the plant state it shows; a state
already rendered is not rendered again. ``cbha_sim`` publishes the pairs
(:mod:`cbha_inverse.ros.common.sim_cameras`).
"""

from cbha_inverse.vision.render import RenderSettings, StereoRenderer


class SimulatedStereo:
    """
    Image pairs of the simulated tip, one per new plant state.

    Parameters
    ----------
    rig : cbha_inverse.vision.rig.StereoRig
        Cameras and their pose.
    marker_radius : float  [m]
        Radius of the rendered tip sphere.
    seed : int
        Seed of the texture and the image noise.

    """

    def __init__(self, rig, marker_radius, seed):
        self.rig = rig
        self.renderer = StereoRenderer(rig, RenderSettings(marker_radius=marker_radius), seed)
        self._last_time = None

    def render(self, tip, backbone, time):
        """
        Return the image pair of a plant state, or None when that state was the last rendered.

        Parameters
        ----------
        tip : (3,) array_like  [m]
            The tip marker's centre in ``cbha_base``.
        backbone : (n + 1, 3) array_like  [m]
            The frame origins of the chain (drawn as clutter).
        time : object
            The state's time (any value that compares equal for the same state, e.g. a stamp).

        Returns
        -------
        (left, right) of (H, W, 3) uint8 ndarray, or None
            BGR images.

        """
        if time == self._last_time:
            return None
        self._last_time = time
        return self.renderer.render(tip, backbone=backbone)
