"""Datasets and evaluation: denoiser benchmark, noise estimation, on-the-fly training data."""
