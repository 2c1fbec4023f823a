"""The launch compositions (one table) and ``cbha_launch``, which starts them as processes."""
