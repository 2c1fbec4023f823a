"""
Stereo tracking of the tip marker, no ROS: the only OpenCV importer of the package.

Camera models and their YAML (:mod:`~cbha_inverse.vision.camera`), the stereo rig
(:mod:`~cbha_inverse.vision.rig`), marker detection (:mod:`~cbha_inverse.vision.marker`),
triangulation (:mod:`~cbha_inverse.vision.stereo`), the tracker
(:mod:`~cbha_inverse.vision.tracking`), image pairing (:mod:`~cbha_inverse.vision.pairing`), the
renderer of simulated cameras (:mod:`~cbha_inverse.vision.render`) and checkerboard calibration
(:mod:`~cbha_inverse.vision.calibration`, ``stereo_calibrate``). See ``docs/cameras.md``.
"""
