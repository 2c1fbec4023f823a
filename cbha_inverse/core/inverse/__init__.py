"""The inverse model and controller (paper Sec. IV): solver tick, QP, closed-loop correction."""
