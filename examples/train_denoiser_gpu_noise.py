"""Train a small DnCNN with noise drawn on the device, inside the training step, from a `simcam loop` profile.

The profile (``examples/data/loop_profile.yaml``, written by ``simcam loop`` from a
synthetic capture set) holds a ``composite`` model per ISO: Poisson-Gaussian base
plus the fixed patterns (PRNU, DSNU, column FPN) and black-level offsets the loop
attributed. Each sample of a batch gets its own ISO; :class:`simcam.torch.AddNoise`
resolves each ISO's model on the host once, then draws the noise on the batch's
device (CUDA when available) with an explicit ``torch.Generator``.

Clean patches are smooth random raw images made on the device (no dataset
needed); swap in your own packed ``[B, 4, h, w]`` normalised raw crops.

Usage::

    python examples/train_denoiser_gpu_noise.py                 # 200 steps, batch 32 x 4x64x64
    python examples/train_denoiser_gpu_noise.py --tiny          # a few steps at tiny size (tests)
    python examples/train_denoiser_gpu_noise.py --profile my/profile.yaml --device cuda
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from simcam.profiles import load_profile
from simcam.torch import AddNoise

HERE = Path(__file__).resolve().parent


class DnCNN(nn.Module):
    """DnCNN (Zhang et al., IEEE TIP 2017) on packed raw: predicts the noise, returns the denoised patch."""

    def __init__(self, depth: int = 8, width: int = 48):
        super().__init__()
        layers = [nn.Conv2d(4, width, 3, padding=1), nn.ReLU(inplace=True)]
        for _ in range(depth - 2):
            layers += [nn.Conv2d(width, width, 3, padding=1), nn.ReLU(inplace=True)]
        layers += [nn.Conv2d(width, 4, 3, padding=1)]
        self.net = nn.Sequential(*layers)

    def forward(self, noisy):
        return noisy - self.net(noisy)


def clean_batch(b: int, size: int, generator: torch.Generator, device) -> torch.Tensor:
    """Smooth random packed raw patches in [0.01, 0.8] (bilinear upsampling of coarse random grids)."""
    coarse = torch.rand((b, 1, 5, 5), generator=generator, device=device)
    colour = 0.5 + torch.rand((b, 4, 1, 1), generator=generator, device=device)
    img = F.interpolate(coarse, size=(size, size), mode="bilinear", align_corners=True) * colour
    return (0.01 + 0.79 * img / img.amax(dim=(1, 2, 3), keepdim=True)).contiguous()


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", default=str(HERE / "data" / "loop_profile.yaml"))
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--patch", type=int, default=64, help="packed patch size h = w (mosaic 2h x 2w)")
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--tiny", action="store_true", help="3 steps, batch 4, 16x16 patches, small net (tests)")
    a = ap.parse_args(argv)
    if a.tiny:
        a.steps, a.batch, a.patch = 3, 4, 16
    device = torch.device(a.device)
    torch.manual_seed(a.seed)
    profile = load_profile(a.profile)
    isos = [e.iso for e in profile.camera().entries]  # the loop's entries (their effect lists differ: no interpolation)
    add_noise = AddNoise(profile, validate=False)
    net = DnCNN(depth=4 if a.tiny else 8, width=16 if a.tiny else 48).to(device)
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    gen = torch.Generator(device=device.type).manual_seed(a.seed)
    host = torch.Generator().manual_seed(a.seed + 1)
    t0, psnr = time.perf_counter(), float("nan")
    for step in range(1, a.steps + 1):
        clean = clean_batch(a.batch, a.patch, gen, device)
        iso = [isos[int(i)] for i in torch.randint(len(isos), (a.batch,), generator=host)]
        with torch.no_grad():
            noisy = add_noise(clean, iso=iso, generator=gen)
        out = net(noisy)
        loss = F.l1_loss(out, clean)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        mse = F.mse_loss(out.detach(), clean).item()
        psnr = 10 * math.log10(1.0 / max(mse, 1e-12))
        if step == 1 or step == a.steps or step % 20 == 0:
            print(f"step {step:4d}  loss {loss.item():.5f}  psnr {psnr:6.2f} dB  isos {sorted(set(iso))}")
    dt = time.perf_counter() - t0
    print(f"done: {a.steps} steps of {a.batch} x 4x{a.patch}x{a.patch} on {device} in {dt:.2f} s "
          f"({a.steps * a.batch / dt:.1f} patches/s incl. the step)")
    return {"steps": a.steps, "psnr": psnr}


if __name__ == "__main__":
    main()
