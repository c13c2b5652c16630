"""simcam's noise models as torch operations on any device (the ``torch`` extra).

Noise for denoiser training drawn inside the training step, on the batch's
device, from the same laws as the numpy models of :mod:`simcam.noise` and
from calibration profiles (``simcam loop``'s ``profile.yaml`` included, with
its fixed patterns):

>>> import torch
>>> from simcam.torch import add_noise
>>> from simcam.noise import model_from_entry
>>> g = torch.Generator().manual_seed(0)
>>> clean = torch.full((2, 4, 8, 8), 0.25)
>>> noisy = add_noise(clean, model_from_entry({"type": "nlf", "beta1": 1e-3, "beta2": 1e-5}), generator=g)

See ``docs/torch.md`` for layouts, randomness and the support table.
"""

from .api import AddNoise, add_noise, flow_noise
from .dispatch import NOT_SUPPORTED, SAMPLERS
from .effects import EFFECTS, EFFECTS_NOT_SUPPORTED
from .layout import to_mosaic, to_packed
from .logprob import log_prob

__all__ = ["AddNoise", "EFFECTS", "EFFECTS_NOT_SUPPORTED", "NOT_SUPPORTED", "SAMPLERS", "add_noise", "flow_noise", "log_prob", "to_mosaic",
           "to_packed"]
