"""What the nodes share: parameters, the runner, diagnostics, QoS, message conversions, images."""
