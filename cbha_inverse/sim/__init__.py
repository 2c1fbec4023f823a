"""
The simulated arm, no ROS: what ``cbha_sim`` runs on the node clock.

:mod:`~cbha_inverse.sim.plant` (the static solve under load), :mod:`~cbha_inverse.sim.valves`
(transport latency and first-order valves), :mod:`~cbha_inverse.sim.plant_errors` (the plant's
deliberate model errors as a scene calibration), :mod:`~cbha_inverse.sim.arm` (valves, plant and
noisy sensors together) and :mod:`~cbha_inverse.sim.cameras` (rendered stereo images).
"""
