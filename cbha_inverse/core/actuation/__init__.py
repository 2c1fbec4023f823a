"""Actuation of the frame chain: cables, pressure cavities, effector points (DESIGN §5)."""
