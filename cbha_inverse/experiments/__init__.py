"""End-to-end experiments on the simulated arm: ``cbha_demo`` and ``cbha_identify_check``."""
