"""Node helpers without mechanics: simulated plant, safety checks, trajectories, Robotino I/O."""
