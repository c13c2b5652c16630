"""Baseline denoisers behind one calling convention.

A denoiser is any callable ``f(noisy, info) -> denoised`` where ``noisy`` is
an H x W normalised-raw mosaic (or an H x W x 3 sRGB image in [0, 1]) and
``info`` a :class:`BlockInfo` (CFA pattern, noise level function, ...).
Built-ins, by spec string (see :func:`get_denoiser`):

``none``
    identity (the noisy input's score).
``bm3d[:vst|:mean]``
    BM3D (Dabov et al. 2007, doi:10.1109/TIP.2007.901238; the ``bm3d``
    package of Makinen et al.). Raw: each packed CFA plane separately, with the
    NLF (DNG NoiseProfile or :func:`~simcam.denoise.noise_estimation.estimate_nlf`)
    either variance-stabilised by the generalised Anscombe transform (``vst``,
    default; Makitalo and Foi 2013, doi:10.1109/TIP.2012.2202675, asymptotically
    unbiased inverse) or turned into one sigma at the plane's mean (``mean``).
    sRGB: CBM3D with Chen's sigma.
``nlm``
    non-local means (Buades et al. 2005; scikit-image ``denoise_nl_means``,
    fast mode, 5x5 patches, 13x13 search, ``h = 0.8 sigma``) on the four
    packed planes as channels after the same VST (raw), or per colour (sRGB).
``dncnn:CKPT``
    DnCNN (Zhang et al. 2017, doi:10.1109/TIP.2017.2662206) on 4-channel packed
    raw; see :mod:`simcam.denoise.dncnn` (needs ``simcam[torch]``).
``cmd:TEMPLATE``
    an external program: ``TEMPLATE`` names ``{input}`` and ``{output}``
    (``.npy`` float32 files), e.g. ``cmd:python my_denoise.py {input} {output}``.
``python:MODULE:FUNCTION``
    any importable callable with the signature above.
"""

from __future__ import annotations

import importlib
import shlex
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Literal

import numpy as np

from ..cfa import pack, unpack
from ..errors import DatasetError, require_extra
from .noise_estimation import estimate_nlf, estimate_sigma


@dataclass
class BlockInfo:
    """What a denoiser may know about one block.

    ``nlf`` is ``(beta1, beta2)`` of ``var = beta1 y + beta2`` on normalised
    raw (or None: estimated from the block when needed).
    """

    cfa: str | None = "RGGB"
    nlf: tuple[float, float] | None = None
    iso: float | None = None
    image: int = 0
    block: int = 0
    meta: Any = None
    extra: dict = field(default_factory=dict)


Denoiser = Callable[[np.ndarray, BlockInfo], np.ndarray]


# ------------------------------------------------------------------------------- helpers
def block_nlf(noisy: np.ndarray, info: BlockInfo) -> tuple[float, float]:
    """The NLF of a raw block: ``info.nlf``, else estimated from the block (clipped fit,
    :func:`~simcam.denoise.noise_estimation.estimate_nlf`), else -- for blocks too small
    for level sets -- Chen's Gaussian sigma of the packed planes as ``(0, sigma^2)``."""
    if info.nlf is not None:
        return float(info.nlf[0]), float(info.nlf[1])
    try:
        est = estimate_nlf(noisy)
        return max(est.beta1, 0.0), est.beta2
    except DatasetError:
        planes = pack(np.asarray(noisy, np.float64))
        return 0.0, float(np.mean([estimate_sigma(p, patch=min(8, min(p.shape)), stride=1) ** 2 for p in planes]))


def _gaussian_only(beta1: float, beta2: float) -> bool:
    # signal-dependent part negligible (below 1e-4 of the variance at full scale): plain scaling
    return beta1 <= 1e-4 * max(beta1 + beta2, 1e-30)


def gat_forward(x: np.ndarray, beta1: float, beta2: float) -> np.ndarray:
    """Generalised Anscombe transform: noise of variance ``beta1 y + beta2`` -> unit variance.

    ``(2 / beta1) sqrt(beta1 x + 3/8 beta1^2 + beta2)`` (Makitalo and Foi 2013);
    ``x / sqrt(beta2)`` when the signal-dependent part is negligible.
    """
    if _gaussian_only(beta1, beta2):
        return x / np.sqrt(max(beta2, 1e-30))
    return (2.0 / beta1) * np.sqrt(np.maximum(beta1 * x + 0.375 * beta1 * beta1 + beta2, 0.0))


def gat_inverse(d: np.ndarray, beta1: float, beta2: float) -> np.ndarray:
    """Asymptotically unbiased inverse of :func:`gat_forward`: ``beta1 ((d/2)^2 - 1/8) - beta2/beta1``."""
    if _gaussian_only(beta1, beta2):
        return d * np.sqrt(max(beta2, 1e-30))
    return beta1 * ((d / 2.0) ** 2 - 0.125) - beta2 / beta1


def _check_input(noisy: np.ndarray, name: str) -> np.ndarray:
    x = np.asarray(noisy)
    if not (x.ndim == 2 or (x.ndim == 3 and x.shape[2] == 3)):
        raise DatasetError(f"denoiser {name}: expected an H x W mosaic or H x W x 3 image, got shape {x.shape}")
    return x.astype(np.float64)


# ------------------------------------------------------------------------------- built-ins
def identity(noisy: np.ndarray, info: BlockInfo) -> np.ndarray:
    """The ``none`` denoiser."""
    return np.asarray(noisy, dtype=np.float32).copy()


@dataclass
class BM3D:
    """BM3D per packed CFA plane (raw) or CBM3D (sRGB); see module docstring."""

    mode: Literal["vst", "mean"] = "vst"
    name: str = "bm3d"

    def __call__(self, noisy: np.ndarray, info: BlockInfo) -> np.ndarray:
        bm3d = require_extra("bm3d", "bench")
        x = _check_input(noisy, self.name)
        if x.ndim == 3:
            sigma = estimate_sigma(x)
            return np.asarray(bm3d.bm3d_rgb(x, sigma), dtype=np.float32)
        b1, b2 = block_nlf(x, info)
        planes = pack(x)
        out = np.empty_like(planes)
        for k, p in enumerate(planes):
            if self.mode == "vst":
                d = bm3d.bm3d(gat_forward(p, b1, b2), 1.0)
                out[k] = gat_inverse(np.asarray(d, np.float64), b1, b2)
            else:
                sigma = float(np.sqrt(max(b1 * max(p.mean(), 0.0) + b2, 1e-12)))
                out[k] = bm3d.bm3d(p, sigma)
        return unpack(out).astype(np.float32)


@dataclass
class NLM:
    """Non-local means (scikit-image) on VST-stabilised packed planes (raw) or per colour (sRGB)."""

    patch_size: int = 5
    patch_distance: int = 6
    h_factor: float = 0.8
    name: str = "nlm"

    def __call__(self, noisy: np.ndarray, info: BlockInfo) -> np.ndarray:
        restoration = require_extra("skimage.restoration", "bench")
        x = _check_input(noisy, self.name)
        kw = dict(patch_size=self.patch_size, patch_distance=self.patch_distance, fast_mode=True)
        if x.ndim == 3:
            sigma = estimate_sigma(x)
            return restoration.denoise_nl_means(x, h=self.h_factor * sigma, sigma=sigma, channel_axis=-1,
                                                **kw).astype(np.float32)
        b1, b2 = block_nlf(x, info)
        planes = gat_forward(pack(x), b1, b2)  # unit noise variance
        d = restoration.denoise_nl_means(np.moveaxis(planes, 0, -1), h=self.h_factor, sigma=1.0,
                                         channel_axis=-1, **kw)
        return unpack(gat_inverse(np.moveaxis(d, -1, 0), b1, b2)).astype(np.float32)


@dataclass
class ExternalCommand:
    """Run an external program on files: ``{input}`` and ``{output}`` are ``.npy`` float32 paths."""

    template: str
    timeout_s: float = 3600.0
    name: str = "cmd"

    def __post_init__(self):
        if "{input}" not in self.template or "{output}" not in self.template:
            raise DatasetError(f"denoiser cmd:{self.template!r}: expected a command naming {{input}} and {{output}}")

    def __call__(self, noisy: np.ndarray, info: BlockInfo) -> np.ndarray:
        with tempfile.TemporaryDirectory(prefix="simcam-denoise-") as tmp:
            src, dst = Path(tmp) / "noisy.npy", Path(tmp) / "denoised.npy"
            np.save(src, np.asarray(noisy, dtype=np.float32))
            argv = [a.format(input=str(src), output=str(dst)) for a in shlex.split(self.template)]
            try:
                proc = subprocess.run(argv, capture_output=True, text=True, timeout=self.timeout_s)
            except (OSError, subprocess.TimeoutExpired) as exc:
                raise DatasetError(f"denoiser cmd:{self.template!r}: cannot run ({exc})") from None
            if proc.returncode != 0:
                tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or [""]
                raise DatasetError(f"denoiser cmd:{self.template!r}: exit code {proc.returncode} on image "
                                   f"{info.image} block {info.block}: {tail[0]}")
            if not dst.exists():
                raise DatasetError(f"denoiser cmd:{self.template!r}: wrote no {{output}} file")
            out = np.load(dst, allow_pickle=False)
        if out.shape != np.shape(noisy):
            raise DatasetError(f"denoiser cmd:{self.template!r}: output shape {out.shape}, expected {np.shape(noisy)}")
        return out.astype(np.float32)


def get_denoiser(spec: str | Callable) -> tuple[str, Denoiser]:
    """``(name, callable)`` for a spec string (see module docstring) or a callable."""
    if callable(spec):
        return getattr(spec, "name", getattr(spec, "__name__", "callable")), spec
    kind, _, arg = str(spec).partition(":")
    if kind == "none":
        return "none", identity
    if kind == "bm3d":
        mode = arg or "vst"
        if mode not in ("vst", "mean"):
            raise DatasetError(f"--denoiser {spec}: expected bm3d, bm3d:vst or bm3d:mean")
        return f"bm3d:{mode}", BM3D(mode=mode)
    if kind == "nlm":
        return "nlm", NLM()
    if kind == "dncnn":
        if not arg:
            raise DatasetError(f"--denoiser {spec}: expected dncnn:CHECKPOINT")
        from .dncnn import DnCNNDenoiser

        return f"dncnn:{Path(arg).name}", DnCNNDenoiser.from_checkpoint(arg)
    if kind == "cmd":
        return "cmd", ExternalCommand(arg)
    if kind == "python":
        mod, _, fn = arg.partition(":")
        try:
            f = getattr(importlib.import_module(mod), fn)
        except (ImportError, AttributeError, ValueError) as exc:
            raise DatasetError(f"--denoiser {spec}: cannot import {fn!r} from {mod!r} ({exc})") from None
        return fn, f
    raise DatasetError(f"--denoiser {spec!r}: expected none, bm3d[:vst|:mean], nlm, dncnn:CKPT, cmd:TEMPLATE "
                       f"or python:MODULE:FUNCTION")
