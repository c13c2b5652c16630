"""Noise Flow arm of ``table63_cpu.py``: a flow trained (briefly, on CPU) on the real training pairs.

Uses :mod:`simcam.noise.flow` (the project's own Noise Flow; never the published
weights). Returns a noise sampler for :class:`simcam.training.patches.NoisyPatchDataset`.
"""

from __future__ import annotations

import numpy as np


def noise_flow_sampler(train_pairs, *, log=print, out=None, epochs: int = 2, patches: int = 1000, seed: int = 0):

    from simcam.cfa import pack
    from simcam.noise.flow.model import NoiseFlow
    from simcam.noise.flow.train import train

    rng = np.random.default_rng(seed)
    clean, noise = [], []
    for _ in range(patches):
        frames, gt = train_pairs[int(rng.integers(len(train_pairs)))]
        f = int(rng.integers(frames.shape[0]))
        t, l = 2 * int(rng.integers((gt.shape[0] - 64) // 2)), 2 * int(rng.integers((gt.shape[1] - 64) // 2))
        c = pack(gt[t:t + 64, l:l + 64])
        clean.append(c)
        noise.append(pack(frames[f, t:t + 64, l:l + 64]) - c)
    ps = {"clean": np.stack(clean), "noise": np.stack(noise), "iso": np.full(patches, 800.0),
          "camera": np.array(["HE"] * patches)}
    d = (out / "noiseflow") if out is not None else None
    metrics = train(ps, d, arch="paper", sdn_per_iso=True, epochs=epochs, batch_size=64, seed=seed, progress=False)
    log(f"  [noiseflow] trained {epochs} epochs: {metrics}")
    flow, _ = NoiseFlow.load(d / "best.pt")
    flow.eval()
    return TorchFlowNoise(flow)


class TorchFlowNoise:
    """Sampler ``(clean_packed, rng, info) -> (noisy, params)`` drawing from a torch NoiseFlow."""

    needs_spawn = False

    def __init__(self, flow):
        self.flow = flow

    def __call__(self, clean, rng, info=None):
        import torch

        g = torch.Generator().manual_seed(int(rng.integers(2**62)))
        with torch.no_grad():
            c = torch.from_numpy(np.ascontiguousarray(clean))[None]
            n = self.flow.draw(c, iso=800.0, camera="HE", generator=g)[0].numpy()
        return (clean + n).astype(np.float32), {"iso": 800.0}
