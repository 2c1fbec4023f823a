"""
ROS 2 interface packages that cbha_inverse ships as data, and the tools that build them (no ROS).

``robotino_msgs/`` holds the two CBHA messages of the Robotino ROS 2 driver (``SetBHAPressures``,
``BHAReadings``) and ``tf2_msgs/`` the ``TFMessage`` of ``/tf`` and ``/tf_static``, as ament_cmake
packages; :mod:`.colcon_build` builds one into a colcon workspace (``cbha_build_robotino_msgs``:
:mod:`.robotino_msgs_build`, ``cbha_build_tf2_msgs``: :mod:`.tf2_msgs_build`) and
:mod:`.rosidl_exports` repairs the CMake export files of the PyPI interface wheels that such a
build needs.
"""
