"""Console views of the running nodes, for users without the ``ros2`` CLI: ``cbha_status``."""
