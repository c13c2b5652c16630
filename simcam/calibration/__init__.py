"""Calibration from measured frames: capture sets (directories of DNG/raw sequences, EMVA 1288
descriptors), photon transfer, residual diagnostics, the calibration loop (base fit, parametric
bootstrap, effect attribution, refit, held-out before/after) and its report.

Module dependencies run one way: ``capture`` -> ``photon_transfer``; ``diagnostics`` ->
``effects`` (the effect cards and their registry) -> ``model`` -> ``profile`` -> ``simulate`` ->
``fit`` -> ``loop`` -> ``report``; ``heldout`` depends on none of them. ``emva1288`` (EMVA
Standard 1288 Release 4.0 characterisation from streamed frames) and ``emva1288_plots`` (its
figures) depend on none of them either.
"""
