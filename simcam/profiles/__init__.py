"""Noise calibration profiles: the YAML schema (:mod:`.schema`) and importers from darktable presets and
DNG NoiseProfile tags (:mod:`.importers`)."""
