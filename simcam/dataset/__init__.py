"""Dataset tools: capture sets, photon transfer, the calibration loop."""
