"""Noise samplers for on-the-fly training data (numpy; picklable; no torch).

A sampler is a callable ``noise(clean, rng, info) -> (noisy, params)`` on a
packed clean patch (4 x h x w float32, normalised raw, channels in
:data:`simcam.cfa.PACK_OFFSETS` order); ``params`` is a flat dict of floats
describing what was drawn (it ends up in the sample's ``meta``).
``needs_spawn`` tells data loaders that the sampler uses a library with its
own thread pool (onnxruntime) and needs ``spawn`` worker processes; a sampler
with ``writes_out = True`` also takes ``out=`` (a float32 array of the clean
patch's shape) and writes the noisy patch there, which lets a batch be made in
place (:meth:`simcam.training.patches.PatchMaker.make_batch`); one whose ``packs``
is true also has ``pack_noise(mosaic_crop, rng, info, clean_out, noisy_out) -> params``,
packing and adding noise in one pass (same bytes as ``pack`` then ``__call__``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..cfa import pack, unpack
from ..errors import NoiseModelError


NORMALS = ("kernel", "auto", "numpy", "torch")


def _check_normals(backend: str) -> None:
    if backend not in NORMALS:
        raise NoiseModelError(f"normals: expected one of {', '.join(map(repr, NORMALS))}, got {backend!r}")


def hetero_gaussian(clean: np.ndarray, beta1: float, beta2: float, rng: np.random.Generator,
                    clip: bool, backend: str, out: np.ndarray | None = None) -> np.ndarray:
    """``clean + sqrt(beta1 clean + beta2) z`` (float32), clipped to [0, 1] if ``clip``.

    ``backend="kernel"``: the fused numba kernel :func:`simcam.noise.kernels.nlf.nlf_noise`
    (one pass, about 3x faster than numpy's normal generator alone); otherwise the normals come
    from :func:`standard_normal` and the arithmetic from numpy. All are deterministic given
    ``rng`` but give different bytes. ``out``: float32 C-contiguous array to write into.
    """
    _check_normals(backend)
    if backend == "kernel":
        from ..noise.kernels.nlf import nlf_noise

        return nlf_noise(clean, beta1, beta2, rng, clip=(0.0, 1.0) if clip else None, out=out)
    std = np.sqrt(np.maximum(np.float32(beta1) * clean + np.float32(beta2), 0.0, dtype=np.float32))
    noisy = standard_normal(rng, clean.shape, backend)
    noisy *= std
    noisy += clean
    if clip:
        np.clip(noisy, 0.0, 1.0, out=noisy)
    if out is not None:
        out[...] = noisy
        return out
    return noisy


def _packed_kernel(mosaic, beta1, beta2, rng, clean_out, noisy_out, clip: bool) -> None:
    from ..noise.kernels.nlf import nlf_noise_packed

    nlf_noise_packed(np.asarray(mosaic, dtype=np.float32), beta1, beta2, rng, clean_out, noisy_out,
                     clip=(0.0, 1.0) if clip else None)


def standard_normal(rng: np.random.Generator, shape: tuple[int, ...], backend: str = "auto") -> np.ndarray:
    """float32 standard normals drawn from ``rng`` (numpy) or from a torch generator seeded by ``rng``."""
    if backend not in ("auto", "numpy", "torch"):
        raise NoiseModelError(f"normals: expected 'auto', 'numpy' or 'torch', got {backend!r}")
    if backend != "numpy":
        try:
            import torch
        except ImportError:
            if backend == "torch":
                raise NoiseModelError("normals='torch' needs torch: pip install simcam[torch]") from None
        else:
            g = torch.Generator().manual_seed(int(rng.integers(2**63)))
            return torch.randn(shape, generator=g).numpy()
    return rng.standard_normal(shape, dtype=np.float32)


class _FusedKernelNoise:
    """What the two kernel-backed samplers share: ``__call__`` takes ``out=``, and with
    ``normals="kernel"`` :meth:`pack_noise` packs and adds noise in one pass. Subclasses
    define ``draw(rng) -> (beta1, beta2)``, ``clip`` and ``normals``."""

    writes_out = True  # __call__ takes ``out=``

    @property
    def packs(self) -> bool:
        """Whether :meth:`pack_noise` is available (the fused kernel)."""
        return self.normals == "kernel"

    def pack_noise(self, mosaic, rng, info, clean_out, noisy_out) -> dict:
        """Pack a 2p x 2p crop into ``clean_out`` and write the noisy patch into ``noisy_out`` in one
        pass: the bytes of ``pack`` followed by ``self(clean, rng, info, out=noisy_out)``."""
        b1, b2 = self.draw(rng)
        _packed_kernel(mosaic, b1, b2, rng, clean_out, noisy_out, self.clip)
        return {"beta1": b1, "beta2": b2}


@dataclass
class GaussianNoise(_FusedKernelNoise):
    """Homoscedastic Gaussian noise, sigma ~ U(lo, hi) per sample (normalised raw units)."""

    sigma: tuple[float, float] = (0.24 / 255, 11.51 / 255)  # Abdelhamed 2020, section 6.5's range, 8-bit units / 255
    clip: bool = False
    normals: str = "kernel"
    needs_spawn: bool = False

    def __post_init__(self):
        _check_normals(self.normals)

    def __call__(self, clean: np.ndarray, rng: np.random.Generator, info: dict | None = None, out=None):
        s = float(rng.uniform(*self.sigma))
        if self.normals == "kernel":
            return hetero_gaussian(clean, 0.0, s * s, rng, self.clip, "kernel", out), {"beta1": 0.0, "beta2": s * s}
        noisy = clean + np.float32(s) * standard_normal(rng, clean.shape, self.normals)
        if self.clip:
            np.clip(noisy, 0.0, 1.0, out=noisy)
        if out is not None:
            out[...] = noisy
            noisy = out
        return noisy, {"beta1": 0.0, "beta2": s * s}

    def draw(self, rng: np.random.Generator) -> tuple[float, float]:
        """(beta1, beta2) = (0, sigma^2) of one sample (what ``__call__`` draws first)."""
        s = float(rng.uniform(*self.sigma))
        return 0.0, s * s


@dataclass
class NLFNoise(_FusedKernelNoise):
    """Heteroscedastic Gaussian noise ``var = beta1 y + beta2`` (Abdelhamed 2020, eq. 5.2), clipped to [0, 1] (eq. 5.3).

    Parameters
    ----------
    nlfs : sequence of (beta1, beta2), optional
        Camera NLFs to pick from uniformly (e.g. DNG NoiseProfiles of a set).
    beta1, beta2 : (lo, hi), optional
        Otherwise log-uniform ranges: beta1 drawn log-uniformly, then beta2
        log-uniformly in its range.
    clip : bool
        Clip the noisy patch to [0, 1].
    normals : {"kernel", "auto", "numpy", "torch"}
        "kernel" (default): one fused numba pass (:mod:`simcam.noise.kernels.nlf`,
        ziggurat normals). Otherwise the normals come from numpy's generator or a
        torch CPU generator seeded from it ("auto" uses torch when installed) and
        the arithmetic from numpy. All are deterministic given the sample's
        generator but give different bytes.
    """

    nlfs: Sequence[tuple[float, float]] | None = None
    beta1: tuple[float, float] | None = None
    beta2: tuple[float, float] | None = None
    clip: bool = True
    normals: str = "kernel"
    needs_spawn: bool = False

    def __post_init__(self):
        _check_normals(self.normals)
        if self.nlfs is None and (self.beta1 is None or self.beta2 is None):
            raise NoiseModelError("NLFNoise: expected nlfs=[(beta1, beta2), ...] or beta1=(lo, hi) and beta2=(lo, hi)")
        if self.nlfs is not None:
            self.nlfs = [(float(a), float(b)) for a, b in self.nlfs]

    def draw(self, rng: np.random.Generator) -> tuple[float, float]:
        if self.nlfs is not None:
            return self.nlfs[int(rng.integers(len(self.nlfs)))]
        b1 = float(np.exp(rng.uniform(np.log(self.beta1[0]), np.log(self.beta1[1]))))
        b2 = float(np.exp(rng.uniform(np.log(self.beta2[0]), np.log(self.beta2[1]))))
        return b1, b2

    def __call__(self, clean: np.ndarray, rng: np.random.Generator, info: dict | None = None, out=None):
        b1, b2 = self.draw(rng)
        return hetero_gaussian(clean, b1, b2, rng, self.clip, self.normals, out), {"beta1": b1, "beta2": b2}


@dataclass
class ModelNoise:
    """Any simcam noise model (:mod:`simcam.noise`): ``model.sample(clean, cond, rng) -> noisy`` on a mosaic.

    ``conds`` are the conditions to pick from uniformly (dicts of
    :class:`~simcam.noise.base.NoiseCondition` fields, e.g. ``{"iso": 800}``);
    the patch's CFA is filled in. Numeric condition values go into the sample's meta.
    """

    model: Any
    conds: Sequence[dict] = field(default_factory=lambda: [{}])
    needs_spawn: bool = False

    def __call__(self, clean: np.ndarray, rng: np.random.Generator, info: dict | None = None):
        from ..noise.base import NoiseCondition

        cond = dict(self.conds[int(rng.integers(len(self.conds)))])
        cond.setdefault("cfa", (info or {}).get("cfa", "RGGB"))
        noisy = self.model.sample(unpack(clean), NoiseCondition(**cond), rng)
        params = {k: float(v) for k, v in cond.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
        return pack(np.asarray(noisy, dtype=np.float32)), params


@dataclass
class ProfileNoise:
    """Noise from a calibration profile (``profiles/*.yaml``): per sample an ISO drawn
    uniformly from ``isos`` (or log-uniformly in ``iso_range``) and the profile's model at that ISO.

    Parameters
    ----------
    profile : str
        Profile YAML path.
    isos : sequence of float, optional
        ISOs to pick from.
    iso_range : (lo, hi), optional
        Otherwise a log-uniform ISO in this range (inside the calibrated range).
    camera : str, optional
        Camera id in the profile (default: its only camera).
    """

    profile: str
    isos: Sequence[float] | None = None
    iso_range: tuple[float, float] | None = None
    camera: str | None = None
    needs_spawn: bool = False

    def __post_init__(self):
        if (self.isos is None) == (self.iso_range is None):
            raise NoiseModelError(f"ProfileNoise({self.profile}): expected exactly one of isos=[...] or iso_range=(lo, hi)")
        self._models: dict[float, Any] = {}

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_models"] = {}
        return state

    def model_at(self, iso: float):
        model = self._models.get(iso)
        if model is None:  # (thread workers may race here: each gets a valid model)
            from ..profiles.schema import load_profile

            if len(self._models) > 256:
                self._models.clear()
            model = self._models[iso] = load_profile(self.profile).model_for(iso, self.camera)
        return model

    def __call__(self, clean: np.ndarray, rng: np.random.Generator, info: dict | None = None):
        from ..noise.base import NoiseCondition

        if self.isos is not None:
            iso = float(self.isos[int(rng.integers(len(self.isos)))])
        else:
            iso = float(np.exp(rng.uniform(np.log(self.iso_range[0]), np.log(self.iso_range[1]))))
        cond = NoiseCondition(iso=iso, camera=self.camera, cfa=(info or {}).get("cfa", "RGGB"))
        noisy = self.model_at(iso).sample(unpack(clean), cond, rng)
        return pack(np.asarray(noisy, dtype=np.float32)), {"iso": iso}


@dataclass
class PipelineNoise:
    """Noise from a :class:`~simcam.pipeline.Pipeline` of input kind ``raw`` (e.g. one ``noise`` stage).

    The pipeline's seed is drawn from the sample's generator, so the result
    depends only on (seed, epoch, index).
    """

    pipeline: Any
    needs_spawn: bool = False

    def __call__(self, clean: np.ndarray, rng: np.random.Generator, info: dict | None = None):
        from ..frame import CameraMeta, RawFrame

        meta = (info or {}).get("camera_meta") or CameraMeta(cfa=(info or {}).get("cfa", "RGGB"))
        frame = RawFrame(unpack(clean), meta, kind="raw")
        out = self.pipeline(frame, seed=int(rng.integers(2**62)), epoch=0, index=0)
        return pack(out.data), {}


@dataclass
class FlowNoise:
    """Noise Flow noise from an exported ONNX graph (``simcam flow export``), run with onnxruntime.

    The session is created lazily in each worker process with one intra-op
    thread (onnxruntime keeps its own thread pool: use ``spawn`` workers,
    which :func:`simcam.training.patches.make_loader` picks from
    ``needs_spawn``). ``conds`` are (iso, camera) pairs picked uniformly.
    """

    path: str
    conds: Sequence[tuple[float, Any]] = ((800.0, 0),)
    clip: bool = False
    temperature: float | None = None
    needs_spawn: bool = True

    def __getstate__(self):
        state = dict(self.__dict__)
        state.pop("_flow", None)
        return state

    def _model(self):
        if getattr(self, "_flow", None) is None:
            from ..noise.onnx_sampler import NoiseFlowRuntime  # type: ignore[import-not-found]

            self._flow = NoiseFlowRuntime(self.path, threads=1)
        return self._flow

    def __call__(self, clean: np.ndarray, rng: np.random.Generator, info: dict | None = None):
        iso, cam = self.conds[int(rng.integers(len(self.conds)))]
        noise = self._model().sample(clean[None], iso=iso, camera=cam, rng=rng, temperature=self.temperature)[0]
        noisy = (clean + noise).astype(np.float32)
        if self.clip:
            np.clip(noisy, 0.0, 1.0, out=noisy)
        params = {"iso": float(iso)}
        if isinstance(cam, (int, np.integer)):
            params["camera"] = float(cam)
        return noisy, params
