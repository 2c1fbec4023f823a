"""
Model identification from one recorded session (``cbha_identify``).

:mod:`~cbha_inverse.identify.samples` turns a bag's valve commands and measured tips into aligned
quasi-static samples; :mod:`~cbha_inverse.identify.fit` fits a scene's ``calibration`` block
(:mod:`cbha_inverse.scene.calibration`) to them by robust nonlinear least squares through the
scene's forward model; :mod:`~cbha_inverse.identify.cli` is the command (its progress:
:mod:`~cbha_inverse.identify.progress`);
:mod:`~cbha_inverse.identify.excitation` holds the excitation programs ``cbha_excite`` runs to
record such a session. No ROS.
"""
