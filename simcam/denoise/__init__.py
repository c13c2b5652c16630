"""Denoiser benchmark: denoisers (classical, DnCNN, external commands), noise estimation from a single
image, image metrics (PSNR, SSIM) and the benchmark runner over SIDD-format blocks."""
