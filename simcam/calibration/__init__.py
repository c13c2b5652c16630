"""Calibration from measured frames: capture sets (directories of DNG/raw sequences, EMVA 1288
descriptors), photon transfer, residual diagnostics, the calibration loop (base fit, parametric
bootstrap, effect attribution, refit, held-out before/after) and its report.

Module dependencies run one way: ``capture`` -> ``photon_transfer``; ``model`` -> ``profile`` ->
``simulate`` -> ``effects`` -> ``loop`` -> ``report``; ``diagnostics`` and ``heldout`` depend on
none of them.  ``emva1288`` (EMVA Standard 1288 Release 4.0 characterisation from streamed
frames) and ``emva1288_plots`` (its figures) depend on none of them either.
"""
