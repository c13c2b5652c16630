"""The calibration loop: capture sets, photon transfer, fit, diagnostics and report (moving to
``simcam.calibration``). Ground truth, the denoiser benchmark and training data live in
:mod:`simcam.groundtruth`, :mod:`simcam.denoise` and :mod:`simcam.training`."""
