"""The Noise Flow composite: S-Ax4-G-Ax4 (Abdelhamed 2020, fig. 6.2, ch. 6.3).

Noise -> latent order: signal-dependent layer, four (1x1 conv, coupling) steps,
gain layer, four more steps. Tensors are NCHW with channels in
:data:`simcam.cfa.PACK_OFFSETS` order ((0,0), (0,1), (1,0), (1,1)).
"""

from __future__ import annotations

import math
import pickle
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ...errors import NoiseModelError, require_extra
from . import layers as L

torch = require_extra("torch", "torch")
nn = torch.nn

ARCHS = ("published", "paper")
LOG_2PI = math.log(2.0 * math.pi)


@dataclass
class FlowConfig:
    """Architecture and conditioning of a Noise Flow.

    Attributes
    ----------
    arch : {"published", "paper"}
        ``published``: the released code (ISO and camera in the signal-dependent
        layer, scalar gain layer). ``paper``: Abdelhamed 2020, eq. 6.10-6.14 (global beta1, beta2;
        per-ISO and per-camera gain in the gain layer).
    cameras : list of str
        Camera names; the ``camera`` input is an index into this list.
    iso_knots : list of float
        ISO values of the per-ISO parameters (sorted); the trained range is
        ``[iso_knots[0], iso_knots[-1]]``, interpolated in log-ISO between knots.
    sdn_per_iso : bool
        ``paper`` only: beta1, beta2 per camera and ISO knot (simcam extension; makes
        the signal-dependent layer contain any NLF exactly).
    steps : int
        Flow steps K on each side of the gain layer (4 in the paper).
    width : int
        Hidden channels of the coupling networks (4 in the released model).
    legacy_iso : bool
        Reproduce the released code's ISO lookup (exact match or factor exp(0) = 1).
        For golden-vector checks only; never for new work.
    default_temperature : float
        Latent scale used by samplers by default (1.0 = the model's own distribution).

    Parameters
    ----------
    arch, cameras, iso_knots, sdn_per_iso, steps, width, legacy_iso, default_temperature
        As the attributes.

    Examples
    --------
    >>> cfg = FlowConfig(cameras=["GP", "IP"], iso_knots=[100.0, 800.0])
    >>> cfg.arch, len(cfg.cameras), cfg.default_temperature
    ('paper', 2, 1.0)
    """

    arch: str = "paper"
    cameras: list = field(default_factory=lambda: ["IP", "GP", "S6", "N6", "G4"])
    iso_knots: list = field(default_factory=lambda: [100.0, 400.0, 800.0, 1600.0, 3200.0])
    sdn_per_iso: bool = False
    steps: int = 4
    width: int = 4
    legacy_iso: bool = False
    default_temperature: float = 1.0

    def __post_init__(self):
        if self.arch not in ARCHS:
            raise NoiseModelError(f"FlowConfig.arch: expected one of {ARCHS}, got {self.arch!r}")
        knots = [float(k) for k in self.iso_knots]
        if not knots or any(k <= 0 for k in knots) or knots != sorted(set(knots)):
            raise NoiseModelError(f"FlowConfig.iso_knots: expected increasing positive ISOs, got {self.iso_knots}")
        self.iso_knots = knots
        self.cameras = [str(c) for c in self.cameras]
        if not self.cameras or len(set(self.cameras)) != len(self.cameras):
            raise NoiseModelError(f"FlowConfig.cameras: expected distinct names, got {self.cameras}")

    @property
    def iso_range(self) -> tuple[float, float]:
        return self.iso_knots[0], self.iso_knots[-1]


class NoiseFlow(nn.Module):
    """Conditional normalising flow p(noise | clean, ISO, camera) on packed raw (Noise Flow,
    Abdelhamed, Brubaker, Brown, ICCV 2019).

    Parameters
    ----------
    config : FlowConfig, optional
        Architecture and conditioning (default ``FlowConfig()``).
    seed : int
        Seed of the initial weights.

    Attributes
    ----------
    config : FlowConfig
        As given.
    layers : torch.nn.ModuleList
        The flow's layers, data side first.

    Examples
    --------
    >>> import torch
    >>> flow = NoiseFlow(FlowConfig(cameras=["GP"], iso_knots=[100.0, 1600.0]))
    >>> clean = torch.full((1, 4, 8, 8), 0.3)
    >>> noise = flow.sample(torch.randn(1, 4, 8, 8), clean=clean, iso=400.0, camera="GP")
    >>> z, logdet = flow.to_latent(noise, clean=clean, iso=400.0, camera="GP")
    >>> z.shape, logdet.shape
    (torch.Size([1, 4, 8, 8]), torch.Size([1]))
    """

    def __init__(self, config: FlowConfig | None = None, seed: int = 0):
        super().__init__()
        with torch.random.fork_rng(devices=[]):  # the initial weights depend on ``seed`` only
            torch.manual_seed(seed)
            self._build(config or FlowConfig(), seed)

    def _build(self, cfg: FlowConfig, seed: int) -> None:
        self.config = cfg
        m, k = len(cfg.cameras), len(cfg.iso_knots)
        self.register_buffer("iso_knots", torch.tensor(cfg.iso_knots, dtype=torch.float32))
        if cfg.arch == "published":
            sdn, gain = L.SignalDependentPublished(m, k), L.GainScalar()
        else:
            sdn, gain = L.SignalDependentNLF(m, k, per_iso=cfg.sdn_per_iso), L.GainIsoCamera(m, k)
        steps = []
        for i in range(2 * cfg.steps):
            steps += [L.LUConv1x1(4, seed=seed * 1000 + i), L.AffineCoupling(cfg.width)]
        self.layers = nn.ModuleList([sdn] + steps[: 2 * cfg.steps] + [gain] + steps[2 * cfg.steps :])

    # ----------------------------------------------------------------- inputs
    def camera_index(self, camera, batch: int):
        """Camera name(s) or index(es) -> int64 tensor (B,); unknown -> NoiseModelError."""
        cams = self.config.cameras
        if isinstance(camera, (str, int, np.integer)):
            camera = [camera] * batch
        elif isinstance(camera, (torch.Tensor, np.ndarray)):
            camera = camera.reshape(-1).tolist()
        out = []
        for c in camera:
            if isinstance(c, str):
                if c not in cams:
                    raise NoiseModelError(f"camera: {c!r} is not one of the model's cameras {cams}")
                out.append(cams.index(c))
            else:
                if not 0 <= int(c) < len(cams):
                    raise NoiseModelError(f"camera: index {c} outside 0..{len(cams) - 1} ({cams})")
                out.append(int(c))
        if len(out) != batch:
            raise NoiseModelError(f"camera: expected {batch} values (one per patch), got {len(out)}")
        return torch.tensor(out, dtype=torch.int64, device=self.iso_knots.device)

    def iso_tensor(self, iso, batch: int, dtype):
        """ISO scalar or (B,) -> tensor; outside the trained range -> NoiseModelError."""
        iso = torch.as_tensor(iso, dtype=torch.float64).reshape(-1)
        if iso.numel() == 1:
            iso = iso.expand(batch)
        if iso.numel() != batch:
            raise NoiseModelError(f"iso: expected a scalar or {batch} values, got {iso.numel()}")
        lo, hi = self.config.iso_range
        if not self.config.legacy_iso:
            bad = iso[(iso < lo * (1 - 1e-6)) | (iso > hi * (1 + 1e-6)) | torch.isnan(iso)]
            if bad.numel():
                raise NoiseModelError(
                    f"iso: {bad[0].item():g} is outside the trained range {lo:g}..{hi:g}"
                )
        return iso.to(dtype)

    def _check(self, name, x):
        if not isinstance(x, torch.Tensor):
            raise NoiseModelError(f"{name}: expected a torch tensor, got {type(x).__name__}")
        if x.ndim != 4 or x.shape[1] != 4:
            raise NoiseModelError(f"{name}: expected shape (B, 4, H, W) packed raw, got {tuple(x.shape)}")
        if not x.is_floating_point():
            raise NoiseModelError(f"{name}: expected a float tensor, got {x.dtype}")

    def condition(self, x, clean, iso, camera) -> L.Cond:
        """Validate inputs and build the :class:`~simcam.noise.flow.layers.Cond` of a batch."""
        self._check("clean", clean)
        if clean.shape != x.shape:
            raise NoiseModelError(f"clean: shape {tuple(clean.shape)} differs from {tuple(x.shape)}")
        b = x.shape[0]
        iso_t = self.iso_tensor(iso, b, x.dtype).to(x.device)
        cam = self.camera_index(camera, b)
        knots = self.iso_knots.to(x.dtype)
        return L.Cond(clean.to(x.dtype), iso_t, L.iso_weights(iso_t, knots, legacy=self.config.legacy_iso), cam)

    # ------------------------------------------------------------- directions
    def to_latent(self, noise, *, clean, iso, camera):
        """Noise -> latent.

        Parameters
        ----------
        noise, clean : Tensor (B, 4, H, W)
            Packed noise (noisy - clean) and clean patch, normalised raw.
        iso : float or Tensor (B,)
            ISO inside the trained range.
        camera : str, int or sequence
            Camera name or index (one, or one per patch).

        Returns
        -------
        z : Tensor (B, 4, H, W)
        logdet : Tensor (B,)
            log |det dz/dnoise| per patch (nats).
        """
        self._check("noise", noise)
        cond = self.condition(noise, clean, iso, camera)
        return self._to_latent(noise, cond)

    def _to_latent(self, h, cond):
        logdet = torch.zeros(h.shape[0], dtype=h.dtype, device=h.device)
        for layer in self.layers:
            h, ld = layer.to_latent(h, cond)
            logdet = logdet + ld
        return h, logdet

    def sample(self, z, *, clean, iso, camera):
        """Latent -> noise (the generative direction); ``z = T * eps``, eps ~ N(0, I)."""
        self._check("z", z)
        cond = self.condition(z, clean, iso, camera)
        return self._from_latent(z, cond)

    def _from_latent(self, h, cond):
        for layer in reversed(self.layers):
            h = layer.from_latent(h, cond)
        return h

    def log_prob(self, noise, *, clean, iso, camera):
        """Per-patch log-likelihood (B,) in nats under the N(0, I) prior."""
        z, logdet = self.to_latent(noise, clean=clean, iso=iso, camera=camera)
        return logdet + log_normal(z)

    def draw(self, clean, *, iso, camera, generator=None, temperature: float | None = None):
        """Draw noise for ``clean`` with ``z = T * randn`` from ``generator``."""
        t = self.config.default_temperature if temperature is None else temperature
        z = t * torch.randn(clean.shape, generator=generator, dtype=clean.dtype)
        return self.sample(z, clean=clean, iso=iso, camera=camera)

    def freeze(self, on: bool = True):
        """Precompute the 1x1 convolutions' inverses (for export and fast sampling)."""
        for layer in self.layers:
            if isinstance(layer, L.LUConv1x1):
                layer.freeze(on)
        return self

    # ------------------------------------------------------------ persistence
    def save(self, path, **extra):
        """Write a checkpoint: config, state dict and ``extra`` (optimizer, epoch, ...)."""
        torch.save({"format": "simcam-noiseflow/1", "config": asdict(self.config),
                    "state_dict": self.state_dict(), **extra}, str(path))

    @classmethod
    def load(cls, path, *, map_location="cpu"):
        """Load a checkpoint written by :meth:`save`; returns ``(flow, checkpoint_dict)``."""
        path = Path(path)
        if not path.is_file():
            raise NoiseModelError(f"{path}: checkpoint not found")
        try:
            ck = torch.load(str(path), map_location=map_location, weights_only=True)
        except pickle.UnpicklingError:
            raise NoiseModelError(f"{path}: refused: the checkpoint holds Python objects other than tensors and plain "
                                  "data (checkpoints are read with torch.load(weights_only=True); a file is data, "
                                  "never code)") from None
        except Exception as exc:  # noqa: BLE001 - any unreadable file
            raise NoiseModelError(f"{path}: not a readable torch checkpoint ({type(exc).__name__})") from None
        if not isinstance(ck, dict) or ck.get("format") != "simcam-noiseflow/1":
            raise NoiseModelError(f"{path}: format: expected a simcam-noiseflow/1 checkpoint")
        flow = cls(FlowConfig(**ck["config"]))
        flow.load_state_dict(ck["state_dict"])
        return flow, ck


def log_normal(z):
    """Sum over C, H, W of the standard normal log-density (nats), shape (B,)."""
    return (-0.5 * (LOG_2PI + z * z)).flatten(1).sum(1)
