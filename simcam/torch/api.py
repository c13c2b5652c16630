"""``add_noise`` and :class:`AddNoise`: simcam noise models applied to raw batches on any torch device."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import nn

from ..errors import NoiseModelError
from .context import Ctx
from .dispatch import sample_group
from .group import group_models, per_sample, resolve_models
from .layout import PACKED, layout_of, to_mosaic, to_packed


def _is_flow(obj: Any) -> bool:
    return isinstance(obj, nn.Module) and hasattr(obj, "sample") and hasattr(obj, "config") and hasattr(obj, "iso_knots")


def _check_generator(generator, device: torch.device, where: str = "generator") -> None:
    if generator is None:
        return
    if not isinstance(generator, torch.Generator):
        raise NoiseModelError(f"{where}: expected a torch.Generator, got {type(generator).__name__}")
    if torch.device(generator.device).type != device.type:
        raise NoiseModelError(f"{where}: the generator is on {generator.device} but the batch is on {device}; "
                              f"expected torch.Generator(device={device.type!r})")


def _exposure(clean: torch.Tensor, exposure: Any) -> torch.Tensor:
    if exposure is None:
        return clean
    vals = np.asarray([float(v) for v in per_sample(exposure, clean.shape[0], name="exposure")], np.float64)
    if not (np.isfinite(vals).all() and (vals > 0).all()):
        raise NoiseModelError(f"exposure: expected positive finite relative exposures, got {vals.tolist()}")
    if (vals == 1).all():
        return clean
    return clean * torch.as_tensor(vals, dtype=clean.dtype).to(clean.device).reshape(-1, 1, 1, 1)


def _offsets(offsets: Any, frame_shape: Any, clean: torch.Tensor, layout: str):
    if frame_shape is None and offsets is None:
        return None
    if frame_shape is None or offsets is None:
        raise NoiseModelError("offsets: frame_shape and offsets go together (the full frame and each patch's place in it)")
    fh, fw = (int(v) for v in frame_shape)
    o = np.asarray(offsets, dtype=np.int64).reshape(-1, 2)
    if o.shape[0] == 1:
        o = np.repeat(o, clean.shape[0], axis=0)
    if o.shape[0] != clean.shape[0]:
        raise NoiseModelError(f"offsets: expected one (row, column) per sample ({clean.shape[0]}), got {o.shape[0]}")
    h, w = clean.shape[-2:]
    if layout == PACKED:
        h, w = 2 * h, 2 * w
    if (o % 2).any() or (o < 0).any() or (o[:, 0] + h > fh).any() or (o[:, 1] + w > fw).any():
        raise NoiseModelError(f"offsets: expected even offsets with the {h}x{w} patch inside the {fh}x{fw} frame, "
                              f"got {o.tolist()}")
    return o


def _exposure_s(value: Any, batch: int):
    if value is None:
        return None
    t = np.asarray([float(v) for v in per_sample(value, batch, name="exposure_s")], np.float64)
    if not (np.isfinite(t).all() and (t >= 0).all()):
        raise NoiseModelError(f"exposure_s: expected exposure times >= 0 in seconds, got {t.tolist()}")
    return t


def add_noise(clean: torch.Tensor, profile_or_model: Any, *, iso: Any = None, exposure: Any = None,
              camera: Any = None, generator: torch.Generator | None = None, extrapolate: bool = False,
              validate: bool = True, temperature: float | None = None, frame_shape: Any = None,
              offsets: Any = None, exposure_s: Any = None, _cache: dict | None = None) -> torch.Tensor:
    """Noisy raw batch for a clean one, drawn on the batch's device.

    Parameters
    ----------
    clean : Tensor
        Clean normalised raw (0 = black, 1 = white), packed ``[B, 4, h, w]`` (channels = CFA sites
        (0,0), (0,1), (1,0), (1,1), as :func:`simcam.cfa.pack`) or mosaic ``[B, 1, H, W]`` whose
        pixel (0, 0) is CFA site (0, 0); any float dtype (half types are computed in float32 where
        ``torch.poisson`` needs it), any device.
    profile_or_model : NoiseModel, dict, CalibrationProfile, str, Path, list or NoiseFlow
        A simcam noise model (all samples), its profile entry, a list of one model (or entry) per
        sample, a calibration profile (or the path of its YAML) resolved per sample at ``iso``
        (log-ISO interpolation, as ``model_for``), or a
        trained :class:`simcam.noise.flow.NoiseFlow` (Noise Flow, Abdelhamed, Brubaker, Brown, ICCV 2019).
    iso : float or sequence of B, optional
        ISO of each sample (needed by profiles and Noise Flow).
    exposure : float or sequence of B, optional
        Relative exposure of each sample: the clean signal is multiplied by it before the noise is
        drawn (e.g. 1/100 for a frame 100x shorter than the reference); default 1.
    camera : str or sequence of B, optional
        Camera id in the profile / flow (default: the only one).
    generator : torch.Generator, optional
        Source of every random draw, on the batch's device type (Philox on CUDA). The same
        generator state gives the same tensor on the same device; CPU and CUDA streams differ
        from each other and from numpy's, so only the law is shared with the numpy models.
    extrapolate : bool
        Allow ISOs outside the profile's calibrated range (``model_for(extrapolate=True)``).
    validate : bool
        Check that ``clean`` is finite and >= 0 and the Poisson means are in range (one device
        synchronisation per call); turn off in a tight training loop once the data is known good.
    temperature : float, optional
        Noise Flow latent temperature (default: the flow's own).
    frame_shape : (int, int), optional
        Mosaic (H, W) of the full sensor frame the patches were cropped from. With ``offsets``, the
        composite's fixed patterns (DSNU, PRNU, column FPN, hot pixels) are drawn once for the full frame
        and each sample gets its crop, and fixed-phase periodic patterns are evaluated at the sample's
        place in the frame; without it a patch is a frame of its own size.
    offsets : sequence of B (row, column), optional
        Mosaic position of each patch's pixel (0, 0) in the full frame (even values: the CFA phase).
    exposure_s : float or sequence of B, optional
        Exposure time of each sample in seconds, for the exposure-dependent effects (``dark_current``,
        ``amp_glow``, ``empirical_field``; the numpy models' ``NoiseCondition.exposure_s``).

    Returns
    -------
    Tensor
        Noisy normalised raw, same shape, dtype and device as ``clean``.

    Examples
    --------
    >>> import torch
    >>> clean = torch.full((2, 1, 4, 4), 0.25)  # two 4x4 mosaics
    >>> noisy = add_noise(clean, {"type": "nlf", "beta1": 1e-3, "beta2": 1e-5}, generator=torch.Generator().manual_seed(0))
    >>> noisy.shape, noisy.dtype
    (torch.Size([2, 1, 4, 4]), torch.float32)
    """
    layout = layout_of(clean)
    _check_generator(generator, clean.device)
    b = clean.shape[0]
    if validate and clean.numel():
        lo, hi = torch.aminmax(clean.detach())
        lo, hi = float(lo), float(hi)
        if not (np.isfinite(lo) and np.isfinite(hi)):
            raise NoiseModelError("clean: expected finite clean values, got NaN/inf pixel(s)")
        if lo < 0:
            raise NoiseModelError(f"clean: expected clean normalised raw >= 0 (an expected signal cannot be negative), "
                                  f"got min {lo:.6g}")
    x = _exposure(clean, exposure)
    if _is_flow(profile_or_model):
        return x + flow_noise(profile_or_model, x, iso=iso, camera=camera, generator=generator, temperature=temperature)
    work = x if x.dtype in (torch.float32, torch.float64) else x.float()
    models = resolve_models(profile_or_model, b, iso=iso, camera=camera, extrapolate=extrapolate, cache=_cache)
    ctx = Ctx(device=clean.device, dtype=work.dtype, layout=layout, shape=tuple(work.shape[-2:]),
              generator=generator, validate=validate, frame_shape=None if frame_shape is None else tuple(frame_shape),
              offsets=_offsets(offsets, frame_shape, clean, layout), exposure_s=_exposure_s(exposure_s, b))
    groups = group_models(models)
    if len(groups) == 1:
        out = sample_group(groups[0], work, ctx)
    else:
        out = torch.empty_like(work)
        for g in groups:
            idx = torch.as_tensor(g.index, device=work.device)
            out = out.index_copy(0, idx, sample_group(g, work.index_select(0, idx), ctx))
    return out.to(clean.dtype)


def flow_noise(flow, clean: torch.Tensor, *, iso, camera=None, generator=None, temperature=None) -> torch.Tensor:
    """Noise Flow noise for ``clean`` (packed or mosaic): ``flow.sample(T * randn)`` with the latent on the batch's device.

    Parameters
    ----------
    flow : NoiseFlow
        A Noise Flow (Abdelhamed, Brubaker, Brown, ICCV 2019).
    clean : Tensor
        Packed ``[B, 4, h, w]`` or mosaic ``[B, 1, H, W]`` clean normalised raw.
    iso : float or sequence of B
        ISO of each sample.
    camera : str, optional
        A camera of the flow (default: its only one).
    generator : torch.Generator, optional
        Source of the latent draw.
    temperature : float, optional
        Latent temperature T (default: the flow's own).

    Returns
    -------
    Tensor
        The noise (not the noisy image), in the layout of ``clean``.

    Examples
    --------
    >>> import torch
    >>> from simcam.noise.flow import FlowConfig, NoiseFlow
    >>> flow = NoiseFlow(FlowConfig(cameras=["GP"], iso_knots=[100.0, 1600.0]))
    >>> flow_noise(flow, torch.full((1, 1, 8, 8), 0.3), iso=400.0).shape
    torch.Size([1, 1, 8, 8])
    """
    if iso is None:
        raise NoiseModelError("iso: Noise Flow needs each sample's ISO, got none")
    packed = clean if layout_of(clean) == PACKED else to_packed(clean)
    cams = flow.config.cameras
    if camera is None:
        if len(cams) != 1:
            raise NoiseModelError(f"camera: the flow holds cameras {cams}; name one")
        camera = cams[0]
    t = flow.config.default_temperature if temperature is None else float(temperature)
    z = t * torch.randn(packed.shape, generator=generator, device=packed.device, dtype=packed.dtype)
    iso_t = torch.as_tensor(np.asarray(per_sample(iso, packed.shape[0], name="iso"), np.float64))
    n = flow.sample(z, clean=packed, iso=iso_t, camera=camera)
    return n if layout_of(clean) == PACKED else to_mosaic(n)


class AddNoise(nn.Module):
    """:func:`add_noise` as a module: ``AddNoise(profile)(clean, iso=..., generator=...)``.

    Holds the profile (or model / Noise Flow) and a memo of the per-ISO models it resolved, so
    a training loop pays the host-side lookup once per distinct ISO. A Noise Flow is registered as
    a submodule (``.to(device)`` moves it). Has no parameters of its own.

    Parameters
    ----------
    profile_or_model : NoiseModel, dict, CalibrationProfile, str, Path, list or NoiseFlow
        As :func:`add_noise` (a path is loaded once here).
    camera, extrapolate, validate, temperature
        As :func:`add_noise`, fixed for every call.

    Attributes
    ----------
    source
        The profile, model or flow.

    Examples
    --------
    >>> import torch
    >>> noise = AddNoise({"type": "poisson_gaussian", "beta1": 1e-3, "beta2": 1e-5})
    >>> noise(torch.full((1, 4, 2, 2), 0.5), generator=torch.Generator().manual_seed(1)).shape
    torch.Size([1, 4, 2, 2])
    """

    def __init__(self, profile_or_model: Any, *, camera: Any = None, extrapolate: bool = False,
                 validate: bool = True, temperature: float | None = None):
        super().__init__()
        from ..profiles.schema import load_profile
        from pathlib import Path

        if isinstance(profile_or_model, (str, Path)):
            profile_or_model = load_profile(profile_or_model)
        self.source = profile_or_model
        self.camera, self.extrapolate, self.validate, self.temperature = camera, extrapolate, validate, temperature
        self._memo: dict = {}

    def forward(self, clean: torch.Tensor, *, iso: Any = None, exposure: Any = None,
                generator: torch.Generator | None = None, frame_shape: Any = None, offsets: Any = None,
                exposure_s: Any = None) -> torch.Tensor:
        return add_noise(clean, self.source, iso=iso, exposure=exposure, camera=self.camera, generator=generator,
                         extrapolate=self.extrapolate, validate=self.validate, temperature=self.temperature,
                         frame_shape=frame_shape, offsets=offsets, exposure_s=exposure_s, _cache=self._memo)
