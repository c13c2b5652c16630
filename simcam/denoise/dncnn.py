"""DnCNN on 4-channel packed raw (Zhang et al. 2017, doi:10.1109/TIP.2017.2662206).

Residual learning: the network predicts the noise and returns ``x - f(x)``.
Input and output are packed Bayer planes (channel order (0,0), (0,1), (1,0),
(1,1)) of normalised raw. Needs ``simcam[torch]``; torch is imported inside.

Checkpoint format (``torch.save``): ``{"format": "simcam-dncnn", "version": 1,
"arch": {"channels", "depth", "width", "batch_norm"}, "state_dict": ...,
"train": {...}}``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Iterator

import numpy as np

from ..cfa import pack, unpack
from ..errors import DatasetError, require_extra

CKPT_FORMAT = "simcam-dncnn"


def build_dncnn(channels: int = 4, depth: int = 17, width: int = 64, batch_norm: bool = True,
                zero_init_last: bool = True):
    """The DnCNN network: conv+ReLU, (depth-2) x conv(+BN)+ReLU, conv; residual output.

    ``zero_init_last`` (simcam choice) starts the last convolution at zero, so an
    untrained model is the identity and short CPU trainings start from the noisy
    input's error instead of a random residual.
    """
    torch = require_extra("torch", "torch")
    nn = torch.nn

    class DnCNN(nn.Module):
        def __init__(self):
            super().__init__()
            layers: list[Any] = [nn.Conv2d(channels, width, 3, padding=1), nn.ReLU(inplace=True)]
            for _ in range(depth - 2):
                layers += [nn.Conv2d(width, width, 3, padding=1, bias=not batch_norm)]
                if batch_norm:
                    layers += [nn.BatchNorm2d(width)]
                layers += [nn.ReLU(inplace=True)]
            layers += [nn.Conv2d(width, channels, 3, padding=1)]
            if zero_init_last:
                nn.init.zeros_(layers[-1].weight)
                nn.init.zeros_(layers[-1].bias)
            self.body = nn.Sequential(*layers)
            self.arch = dict(channels=channels, depth=depth, width=width, batch_norm=batch_norm)

        def forward(self, x):
            return x - self.body(x)

    return DnCNN()


def save_checkpoint(model, path: str | Path, **train_info: Any) -> Path:
    torch = require_extra("torch", "torch")
    path = Path(path)
    torch.save({"format": CKPT_FORMAT, "version": 1, "arch": model.arch,
                "state_dict": model.state_dict(), "train": train_info}, path)
    return path


def load_checkpoint(path: str | Path):
    """Model (eval mode, CPU) from a checkpoint written by :func:`save_checkpoint`."""
    torch = require_extra("torch", "torch")
    path = Path(path)
    if not path.exists():
        raise DatasetError(f"{path}: no such DnCNN checkpoint")
    try:
        ck = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:
        raise DatasetError(f"{path}: not a readable torch checkpoint ({type(exc).__name__})") from None
    if not isinstance(ck, dict) or ck.get("format") != CKPT_FORMAT:
        raise DatasetError(f"{path}: format: expected a {CKPT_FORMAT!r} checkpoint")
    model = build_dncnn(**ck["arch"])
    model.load_state_dict(ck["state_dict"])
    model.eval()
    return model


@dataclass
class DnCNNDenoiser:
    """A denoiser (see :mod:`simcam.denoise.denoisers`) running a DnCNN on packed raw."""

    model: Any
    name: str = "dncnn"

    @classmethod
    def from_checkpoint(cls, path: str | Path) -> "DnCNNDenoiser":
        return cls(load_checkpoint(path), name=f"dncnn:{Path(path).name}")

    def __call__(self, noisy: np.ndarray, info=None) -> np.ndarray:
        torch = require_extra("torch", "torch")
        x = np.asarray(noisy, dtype=np.float32)
        if x.ndim != 2 or self.model.arch["channels"] != 4:
            raise DatasetError(f"denoiser {self.name}: expected an H x W raw mosaic for a 4-channel model, "
                               f"got shape {x.shape}")
        with torch.no_grad():
            out = self.model(torch.from_numpy(pack(x))[None])[0].numpy()
        return unpack(out)


def train_dncnn(model, batches: Iterable[dict], *, steps: int, lr: float = 1e-3, lr_end: float | None = 1e-4,
                log_every: int = 50, max_seconds: float | None = None, log=print) -> list[float]:
    """Train ``model`` on ``{"noisy", "clean"}`` batches (packed raw, B x 4 x h x w) with MSE and Adam.

    The learning rate decays geometrically from ``lr`` to ``lr_end``. Stops
    after ``steps`` batches or ``max_seconds``. Returns the per-step losses.
    """
    torch = require_extra("torch", "torch")
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    gamma = (lr_end / lr) ** (1.0 / max(steps, 1)) if lr_end else 1.0
    sched = torch.optim.lr_scheduler.ExponentialLR(opt, gamma)
    model.train()
    losses: list[float] = []
    t0 = time.perf_counter()
    it: Iterator[dict] = iter(batches)
    for step in range(steps):
        try:
            batch = next(it)
        except StopIteration:
            it = iter(batches)
            batch = next(it)
        noisy, clean = batch["noisy"].float(), batch["clean"].float()
        loss = torch.nn.functional.mse_loss(model(noisy), clean)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        losses.append(float(loss.detach()))
        if log and log_every and (step + 1) % log_every == 0:
            log(f"step {step + 1}/{steps} loss {np.mean(losses[-log_every:]):.3e} "
                f"({time.perf_counter() - t0:.0f} s)")
        if max_seconds is not None and time.perf_counter() - t0 > max_seconds:
            break
    model.eval()
    return losses
