"""Noise Flow training: maximum likelihood with Adam (Abdelhamed 2020, ch. 6.4).

Adam, lr 1e-3, betas (0.9, 0.999) as in Abdelhamed 2020; 32x32 packed patches; a
train/test split with every (camera, ISO) in both; per-epoch test NLL per
dimension (nats) and marginal KL (:func:`simcam.noise.metrics.marginal_kl`) written to
``metrics.csv`` and ``metrics.png``; checkpoints ``last.pt`` (with optimizer state,
for ``resume``) and ``best.pt`` (lowest test NLL). Batch order of epoch e comes from
``SeedSequence([seed, e])``.

simcam addition: with ``data_init`` (default) the signal-dependent layer starts from a
least-squares NLF fit of the training pairs (``E[n^2] = beta1 clean + beta2`` per
camera and ISO) and the gain layer at 1, instead of the paper's generic start
(beta1 = e^-5, beta2 = 1, u = 1/200), which Adam at lr 1e-3 needs ~10^4 steps to leave;
the couplings start as the identity either way.
"""

from __future__ import annotations

import csv
import math
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ...errors import DatasetError, NoiseModelError, require_extra
from .data import split_by_condition
from ..metrics import KL_BINNING, marginal_kl
from .model import FlowConfig, NoiseFlow

torch = require_extra("torch", "torch")

CSV_FIELDS = ["epoch", "train_nll_per_dim", "test_nll_per_dim", "test_marginal_kl", "seconds"]


def fit_nlf(ps: dict) -> dict:
    """Least-squares NLF per (camera, ISO): ``noise^2 ~ beta1 * clean + beta2`` (floored at 1e-9)."""
    out = {}
    for cam, iso in sorted(set(zip(ps["camera"].tolist(), ps["iso"].tolist()))):
        m = (ps["camera"] == cam) & (ps["iso"] == iso)
        c = ps["clean"][m].astype(np.float64).ravel()
        n2 = ps["noise"][m].astype(np.float64).ravel() ** 2
        a = np.stack([np.clip(c, 0, None), np.ones_like(c)], 1)
        b1, b2 = np.linalg.lstsq(a, n2, rcond=None)[0]
        out[(cam, float(iso))] = (max(b1, 1e-9), max(b2, 1e-9))
    return out


def init_from_data(flow: NoiseFlow, ps: dict) -> None:
    """Data-dependent start of the signal-dependent and gain layers (see module docstring)."""
    cfg = flow.config
    nlf = fit_nlf(ps)
    sdn, gain = flow.layers[0], flow.layers[1 + 2 * cfg.steps]
    with torch.no_grad():
        if cfg.arch == "published":
            # psi = 1 (cam_params 0), beta1 = 1: beta1/gamma_k = exp(-g_k)/ISO_k = fitted beta1 (mean over
            # cameras); one beta2 (geometric mean); unit gain layer
            sdn.cam_params.zero_()
            sdn.beta1.zero_()
            g = []
            for iso in cfg.iso_knots:
                b1s = [v[0] for (c, i), v in nlf.items() if i == iso]
                g.append(-math.log(float(np.exp(np.mean(np.log(b1s)))) * iso) if b1s else -math.log(iso))
            sdn.gain_params.copy_(torch.tensor(g))
            sdn.beta2.fill_(float(np.mean(np.log([v[1] for v in nlf.values()]))))
            gain.log_gain.zero_()
        elif cfg.sdn_per_iso:
            for m, cam in enumerate(cfg.cameras):
                for k, iso in enumerate(cfg.iso_knots):
                    if (cam, iso) in nlf:
                        sdn.b1[m, k] = math.log(nlf[(cam, iso)][0])
                        sdn.b2[m, k] = math.log(nlf[(cam, iso)][1])
            gain.v.copy_(-torch.log(torch.tensor(cfg.iso_knots)))
        else:
            # one (beta1, beta2) for all: geometric mean; the gain layer carries ISO
            b = np.array(list(nlf.values()))
            sdn.b1.fill_(float(np.mean(np.log(b[:, 0]))))
            sdn.b2.fill_(float(np.mean(np.log(b[:, 1]))))
            iso_scale = {}
            for (cam, iso), (b1, _) in nlf.items():
                iso_scale.setdefault(iso, []).append(0.5 * (math.log(b1) - float(sdn.b1)))
            v = [-math.log(k) + float(np.mean(iso_scale.get(k, [0.0]))) for k in cfg.iso_knots]
            gain.v.copy_(torch.tensor(v))
        if cfg.arch == "paper":
            gain.log_psi.zero_()


def _batches(n: int, batch: int, rng: np.random.Generator):
    order = rng.permutation(n)
    return [order[i : i + batch] for i in range(0, n, batch)]


def _tensors(ps, idx, cams):
    t = torch.from_numpy
    cam = torch.tensor([cams.index(c) for c in ps["camera"][idx]], dtype=torch.int64)
    return t(ps["noise"][idx]), t(ps["clean"][idx]), t(ps["iso"][idx].astype(np.float32)), cam


def evaluate(flow: NoiseFlow, ps: dict, *, batch: int = 256, seed: int = 0, temperature: float = 1.0):
    """Test NLL per dimension (nats) and marginal KL (mean over batches) of ``ps``."""
    flow.eval()
    nll, kls, n = 0.0, [], ps["clean"].shape[0]
    d = int(np.prod(ps["clean"].shape[1:]))
    g = torch.Generator().manual_seed(int(np.random.SeedSequence([seed, 104729]).generate_state(1)[0]))
    with torch.no_grad():
        for i in range(0, n, batch):
            idx = np.arange(i, min(i + batch, n))
            noise, clean, iso, cam = _tensors(ps, idx, flow.config.cameras)
            nll -= float(flow.log_prob(noise, clean=clean, iso=iso, camera=cam).sum())
            z = temperature * torch.randn(noise.shape, generator=g)
            fake = flow.sample(z, clean=clean, iso=iso, camera=cam)
            kls.append(marginal_kl(noise.numpy(), fake.numpy()).kl)
    return nll / (n * d), float(np.mean(kls))


def plot_metrics(csv_path: Path, png_path: Path, reference_nll: float | None = None) -> None:
    """NLL/dim (train, test) and marginal KL against epoch."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = list(csv.DictReader(open(csv_path)))
    if not rows:
        return
    ep = [int(r["epoch"]) for r in rows]
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].plot(ep, [float(r["train_nll_per_dim"]) for r in rows], "o-", label="train")
    ax[0].plot(ep, [float(r["test_nll_per_dim"]) for r in rows], "s-", label="test")
    if reference_nll is not None:
        ax[0].axhline(reference_nll, color="k", ls="--", label="reference (test)")
    ax[0].set(xlabel="epoch", ylabel="NLL per dimension (nats)", title="Noise Flow likelihood")
    ax[0].legend()
    ax[1].semilogy(ep, [float(r["test_marginal_kl"]) for r in rows], "o-")
    ax[1].axhline(0.01, color="k", ls="--", label="0.01")
    ax[1].set(xlabel="epoch", ylabel="marginal KL (nats)", title="test marginal KL, D(real || model)")
    fig.text(0.5, 0.01, "marginal KL bins: " + KL_BINNING, ha="center", fontsize=7)
    ax[1].legend()
    fig.subplots_adjust(left=0.09, right=0.98, bottom=0.17, top=0.9, wspace=0.3)
    fig.savefig(png_path, dpi=100)
    plt.close(fig)


def train(
    ps: dict,
    out_dir,
    *,
    arch: str = "paper",
    sdn_per_iso: bool = True,
    epochs: int = 10,
    batch_size: int = 64,
    lr: float = 1e-3,
    seed: int = 0,
    test_fraction: float = 0.2,
    resume: bool = False,
    threads: int | None = None,
    data_init: bool = True,
    progress: bool = True,
    reference_nll=None,
    plot_every: int = 1,
) -> dict:
    """Train a Noise Flow on a patch set; returns the last epoch's metrics.

    Parameters
    ----------
    ps : dict
        Patch set (:mod:`simcam.noise.flow.data`).
    out_dir : path-like
        Receives ``last.pt``, ``best.pt``, ``metrics.csv``, ``metrics.png``.
    reference_nll : callable, optional
        ``reference_nll(test_set) -> float``: a known model's test NLL/dim to draw.
    plot_every : int
        Redraw ``metrics.png`` every this many epochs (and after the last one).
    """
    from tqdm import tqdm

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if threads:
        torch.set_num_threads(int(threads))
    tr, te = split_by_condition(ps, test_fraction, seed)
    last = out / "last.pt"
    if resume:
        if not last.is_file():
            raise NoiseModelError(f"{last}: --resume given but no checkpoint to resume from")
        flow, ck = NoiseFlow.load(last)
        if ck.get("split") != [test_fraction, seed, int(ps["clean"].shape[0])]:
            raise NoiseModelError(f"{last}: split: checkpoint was trained on a different data set or split")
        start, best = ck["epoch"] + 1, ck["best_test_nll"]
    else:
        cfg = FlowConfig(arch=arch, cameras=sorted(set(tr["camera"].tolist())),
                         iso_knots=sorted(set(tr["iso"].tolist())), sdn_per_iso=sdn_per_iso)
        torch.manual_seed(seed)
        flow = NoiseFlow(cfg, seed=seed)
        if data_init:
            init_from_data(flow, tr)
        start, best, ck = 1, math.inf, None
        with open(out / "metrics.csv", "w", newline="") as f:
            csv.writer(f).writerow(CSV_FIELDS)
    unknown = set(te["camera"].tolist()) - set(flow.config.cameras)
    if unknown:
        raise DatasetError(f"test set: cameras {sorted(unknown)} not in the training set")
    opt = torch.optim.Adam(flow.parameters(), lr=lr, betas=(0.9, 0.999))
    if ck is not None:
        opt.load_state_dict(ck["optimizer"])
        flow.load_state_dict(ck["state_dict"])
    d = int(np.prod(tr["clean"].shape[1:]))
    ref = reference_nll(te) if reference_nll else None
    row = {}
    for epoch in range(start, epochs + 1):
        t0 = time.time()
        flow.train()
        rng = np.random.default_rng(np.random.SeedSequence([seed, epoch]))
        batches = _batches(tr["clean"].shape[0], batch_size, rng)
        total = 0.0
        bar = tqdm(batches, desc=f"epoch {epoch}/{epochs}", disable=not progress, leave=False)
        for idx in bar:
            noise, clean, iso, cam = _tensors(tr, np.sort(idx), flow.config.cameras)
            loss = -flow.log_prob(noise, clean=clean, iso=iso, camera=cam).mean() / d
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(idx)
            bar.set_postfix(nll=f"{float(loss.detach()):.4f}")
        test_nll, kl = evaluate(flow, te, seed=seed)
        row = {"epoch": epoch, "train_nll_per_dim": total / tr["clean"].shape[0], "test_nll_per_dim": test_nll,
               "test_marginal_kl": kl, "seconds": time.time() - t0}
        with open(out / "metrics.csv", "a", newline="") as f:
            csv.writer(f).writerow([f"{row[k]:.6f}" if isinstance(row[k], float) else row[k] for k in CSV_FIELDS])
        if test_nll < best:
            best = test_nll
            flow.save(out / "best.pt", epoch=epoch, test_nll_per_dim=test_nll)
        flow.save(last, optimizer=opt.state_dict(), epoch=epoch, best_test_nll=best,
                  split=[test_fraction, seed, int(ps["clean"].shape[0])], train_config=asdict(flow.config))
        if epoch % max(1, plot_every) == 0 or epoch == epochs:
            plot_metrics(out / "metrics.csv", out / "metrics.png", ref)
        if progress:
            tqdm.write(f"epoch {epoch}: train {row['train_nll_per_dim']:.4f} test {test_nll:.4f} nats/dim, "
                       f"marginal KL {kl:.4f}" + (f" (reference {ref:.4f})" if ref is not None else ""))
    return row
