"""Parametric raw noise models, physical effects, likelihoods and metrics.

Models (registry by ``type``): ``gaussian``, ``nlf``, ``poisson_gaussian``,
``poisson_mixture``, ``clipped`` (censored wrapper), ``composite`` (base model +
effects). See :mod:`simcam.noise.base` for the contract; this package registers
the built-in models (a base module never imports its implementations).
"""

from .base import BLOCK_ROWS, NoiseCondition, NoiseModel, model_from_entry, model_types, register_model

# The registry: importing each implementation registers it under its ``type``.
from . import clipped, composite, gaussian, nlf, onnx_sampler, poisson_gaussian, poisson_mixture  # noqa: E402,F401

__all__ = ["BLOCK_ROWS", "NoiseCondition", "NoiseModel", "model_from_entry", "model_types", "register_model"]
