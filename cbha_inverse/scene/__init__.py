"""
Scenes: a YAML file that names the chain, actuators and effectors of a run.

:func:`load_scene` (:mod:`cbha_inverse.scene.loader`, where the YAML schema is described) builds
a :class:`Scene` (:mod:`cbha_inverse.scene.scene`) with only what the file names: a
beam-and-tendon scene imports neither gmsh nor meshio nor OpenCV. The ``calibration`` block is
read by :mod:`cbha_inverse.scene.calibration`, the condensed segments of a ``segments`` chain by
:mod:`cbha_inverse.scene.segments`, the ``obstacles`` and ``collision`` blocks by
:mod:`cbha_inverse.scene.obstacles`.
"""

from cbha_inverse.scene.loader import load_scene, resolve_scene_path
from cbha_inverse.scene.scene import Scene

__all__ = ['Scene', 'load_scene', 'resolve_scene_path']
