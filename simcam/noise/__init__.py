"""Parametric raw noise models, physical effects, likelihoods and metrics.

Models (registry by ``type``): ``gaussian``, ``nlf``, ``poisson_gaussian``,
``poisson_mixture``, ``clipped`` (censored wrapper), ``composite`` (base model +
effects). See :mod:`simcam.noise.base` for the contract.
"""

from .base import BLOCK_ROWS, NoiseCondition, NoiseModel, model_from_entry, model_types, register_model

__all__ = ["BLOCK_ROWS", "NoiseCondition", "NoiseModel", "model_from_entry", "model_types", "register_model"]
