"""Actuation of the frame chain: cables, pressure cavities, effector points (paper Sec. IV)."""
