"""The launch compositions (one table), how their nodes run as processes, and ``cbha_launch``."""
