"""
ROS 2 interface packages that cbha_inverse ships as data, and the tools that build them (no ROS).

``robotino_msgs/`` holds the two CBHA messages of the Robotino ROS 2 driver (``SetBHAPressures``,
``BHAReadings``) as an ament_cmake package; :mod:`.robotino_msgs_build` builds it into a colcon
workspace (``cbha_build_robotino_msgs``) and :mod:`.rosidl_exports` repairs the CMake export files
of the PyPI interface wheels that such a build needs.
"""
