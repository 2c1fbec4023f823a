"""Pure numerics without ROS: mechanics, block-tridiagonal solver, actuation and inverse model."""
