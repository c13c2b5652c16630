"""Dataset tools: capture sets, photon transfer, the calibration loop, ground truth from bursts
(seed 5.3); denoiser benchmark, noise estimation and on-the-fly training data."""
