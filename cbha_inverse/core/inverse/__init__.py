"""The inverse model and controller of DESIGN §6: solver tick, QP, closed-loop correction."""
