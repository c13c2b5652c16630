"""Dataset tools: capture sets, photon transfer, the calibration loop; denoiser benchmark,
noise estimation and on-the-fly training data."""
