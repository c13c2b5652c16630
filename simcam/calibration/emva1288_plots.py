"""Figures of an EMVA 1288 R4.0 characterisation (needs the optional ``plot`` extra: matplotlib).

One function per figure of EMVA Standard 1288 Release 4.0 Linear: photon transfer, SNR,
sensitivity and linearity, dark current, the DSNU / PRNU spectrograms and the logarithmic
defect-pixel histograms.  Figures are built with :class:`matplotlib.figure.Figure` (no pyplot
state) and sized to fit a report page (6.5 in wide).  :func:`save_figures` writes them all.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from simcam.calibration.emva1288 import ChannelResult, Emva1288Error

__all__ = ["photon_transfer_figure", "snr_figure", "linearity_figure", "dark_current_figure",
           "spectrogram_figure", "histogram_figure", "save_figures", "PAGE_WIDTH_IN"]

PAGE_WIDTH_IN = 6.5
"""Width of every figure in inches (a report page's text width)."""


def _figure(rows: int = 1, cols: int = 1, height: float = 3.4):
    try:
        from matplotlib.figure import Figure
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise Emva1288Error("matplotlib=missing; expected the 'plot' extra (pip install simcam[plot]) "
                            "for the EMVA 1288 figures") from exc
    fig = Figure(figsize=(PAGE_WIDTH_IN, height), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False)
    return fig, axes


def _empty(ax, why: str) -> None:
    ax.text(0.5, 0.5, "not applicable:\n" + (why or ""), ha="center", va="center",
            transform=ax.transAxes, fontsize=8, wrap=True)
    ax.set_xticks([])
    ax.set_yticks([])


def _title(r: ChannelResult, what: str) -> str:
    return what if r.channel == "Y" else f"{what} ({r.channel})"


def photon_transfer_figure(r: ChannelResult):
    """sigma_y^2 - sigma_y.dark^2 against mu_y - mu_y.dark with the fit of K (R4.0 Linear)."""
    fig, ax = _figure()
    ax = ax[0, 0]
    p = r.photon_transfer
    x = p.mean_dn - p.dark_mean_dn
    y = p.var_dn2 - p.dark_var_dn2
    if x.size == 0:
        _empty(ax, r.system_gain.reason)
        return fig
    ax.plot(x, y, "o", ms=3, label="data")
    if r.system_gain.applicable and p.fit_indices is not None:
        lo, hi = p.fit_indices
        xs = np.array([0.0, x[p.saturation_index]])
        ax.plot(xs, r.system_gain.value * xs, "-", lw=1,
                label=f"fit K = {r.system_gain.value:.4g} DN/e$^-$")
        ax.plot(x[lo:hi + 1], y[lo:hi + 1], "o", ms=3, mfc="none", mec="k", label="fit range (0-70 % sat.)")
    if p.saturation_index is not None:
        ax.axvline(x[p.saturation_index], ls=":", c="r", lw=1, label="saturation")
    ax.set_xlabel(r"$\mu_y - \mu_{y.dark}$ (DN)")
    ax.set_ylabel(r"$\sigma_y^2 - \sigma_{y.dark}^2$ (DN$^2$)")
    ax.set_title(_title(r, "Photon transfer"))
    ax.legend(fontsize=7)
    return fig


def snr_figure(r: ChannelResult):
    """Measured SNR, the linear-model SNR and the ideal sqrt(mu_p) limit (R4.0 Linear)."""
    fig, ax = _figure()
    ax = ax[0, 0]
    p = r.photon_transfer
    if p.mean_dn.size == 0 or not r.system_gain.applicable:
        _empty(ax, r.system_gain.reason)
        return fig
    K = r.system_gain.value
    sig = p.mean_dn - p.dark_mean_dn
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = sig / np.sqrt(p.var_dn2)
    eta = r.quantum_efficiency.value / 100 if r.quantum_efficiency.applicable else None
    if eta is not None:
        x, xlabel = p.photons, r"$\mu_p$ (photons/pixel)"
    else:
        x, xlabel = sig / K, r"$\mu_e$ (e$^-$/pixel)"
    ok = (x > 0) & (snr > 0) & np.isfinite(snr)
    if p.saturation_index is not None:  # beyond saturation the clipped variance is meaningless
        ok &= np.arange(x.size) <= p.saturation_index
    ax.loglog(x[ok], snr[ok], "o", ms=3, label="data")
    if r.dark_noise_dn.applicable and ok.any():
        xs = np.geomspace(x[ok].min(), x[ok].max() * 1.2, 200)
        mu_e = xs * (eta if eta is not None else 1.0)
        s2d = r.dark_noise_dn.value ** 2 / K ** 2
        ax.loglog(xs, mu_e / np.sqrt(s2d + mu_e), "-", lw=1, label="linear model")
        ax.loglog(xs, np.sqrt(xs), "--", lw=1, label=r"ideal $\sqrt{\mu_p}$" if eta else r"$\sqrt{\mu_e}$")
    if r.snr_max.applicable:
        ax.axhline(r.snr_max.value, ls=":", c="r", lw=1, label=f"SNR$_{{max}}$ = {r.snr_max.value:.4g}")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("SNR")
    ax.set_title(_title(r, "Signal-to-noise ratio"))
    ax.legend(fontsize=7)
    return fig


def linearity_figure(r: ChannelResult):
    """Sensitivity (mu_y - mu_y.dark against mu_p) and the relative deviation from the fit."""
    fig, axes = _figure(1, 2)
    a, b = axes[0]
    p = r.photon_transfer
    if p.linearity_deviation_percent is None:
        _empty(a, r.linearity_error.reason)
        _empty(b, r.linearity_error.reason)
        return fig
    sig = p.mean_dn - p.dark_mean_dn
    slope, off = p.linearity_fit
    lo, hi = p.linearity_indices
    a.plot(p.photons, sig, "o", ms=3, label="data")
    xs = np.array([0.0, np.nanmax(p.photons)])
    a.plot(xs, slope * xs + off, "-", lw=1, label="fit (5-95 % sat.)")
    a.set_xlabel(r"$\mu_p$ (photons/pixel)")
    a.set_ylabel(r"$\mu_y - \mu_{y.dark}$ (DN)")
    a.set_title(_title(r, "Sensitivity"))
    a.legend(fontsize=7)
    b.plot(sig[lo:hi + 1], p.linearity_deviation_percent[lo:hi + 1], "o-", ms=3, lw=0.8)
    b.axhline(0, c="k", lw=0.5)
    b.set_xlabel(r"$\mu_y - \mu_{y.dark}$ (DN)")
    b.set_ylabel("deviation (%)")
    b.set_title(f"Linearity error LE = {r.linearity_error.value:.3g} %")
    return fig


def dark_current_figure(r: ChannelResult):
    """mu_y.dark and sigma_y.dark^2 against the exposure time with the fitted lines."""
    fig, axes = _figure(1, 2)
    a, b = axes[0]
    p = r.photon_transfer
    t = p.dark_exposure_s
    if t.size < 2:
        _empty(a, r.dark_current_mean_e_s.reason)
        _empty(b, r.dark_current_var_e_s.reason)
        return fig
    a.plot(t * 1e3, p.dark_series_mean_dn, "o", ms=3)
    m, c = np.polyfit(t, p.dark_series_mean_dn, 1)
    a.plot(t * 1e3, m * t + c, "-", lw=1,
           label=(f"{r.dark_current_mean_e_s.value:.4g} e$^-$/s" if r.dark_current_mean_e_s.applicable
                  else f"{m:.4g} DN/s"))
    a.set_xlabel("exposure time (ms)")
    a.set_ylabel(r"$\mu_{y.dark}$ (DN)")
    a.set_title(_title(r, "Dark current (mean)"))
    a.legend(fontsize=7)
    ok = np.isfinite(p.dark_series_var_dn2)
    b.plot(t[ok] * 1e3, p.dark_series_var_dn2[ok], "o", ms=3)
    if ok.sum() >= 2:
        m, c = np.polyfit(t[ok], p.dark_series_var_dn2[ok], 1)
        lab = (f"{r.dark_current_var_e_s.value:.4g} e$^-$/s" if r.dark_current_var_e_s.applicable
               else "n/a: " + (r.dark_current_var_e_s.reason or "")[:40])
        b.plot(t * 1e3, m * t + c, "-", lw=1, label=lab)
        b.legend(fontsize=7)
    b.set_xlabel("exposure time (ms)")
    b.set_ylabel(r"$\sigma^2_{y.dark}$ (DN$^2$)")
    b.set_title("Dark current (variance)")
    return fig


def spectrogram_figure(r: ChannelResult):
    """Horizontal and vertical spectrograms of DSNU (top) and PRNU (bottom), log scale."""
    fig, axes = _figure(2, 2, height=5.2)
    for i, kind in enumerate(("dsnu", "prnu")):
        for j, direction in enumerate(("horizontal", "vertical")):
            ax = axes[i, j]
            s = r.spectrograms.get(f"{kind}_{direction}")
            if s is None:
                q = r.dsnu_e.total if kind == "dsnu" else r.prnu_percent.total
                _empty(ax, q.reason)
                continue
            f, amp = s.frequency[1:], s.amplitude[1:]
            ax.semilogy(f, np.where(amp > 0, amp, np.nan), lw=0.7)
            lines = [(s.nonuniformity, "r", f"{kind.upper()}$_{{1288}}$"),
                     (s.temporal_floor, "g", r"$\sigma_{y.stack}/\sqrt{L}$"),
                     (s.stack_noise, "m", r"$\sigma_{y.stack}$"),
                     (s.measured, "k", r"$s_{y.measured}$")]
            for v, c, lab in lines:
                if v is not None and math.isfinite(v) and v > 0:
                    ax.axhline(v, c=c, ls=":", lw=1, label=lab)
            ax.set_xlim(0, 0.5)
            ax.set_xlabel("cycles/pixel")
            ax.set_ylabel(f"{kind.upper()} ({s.unit})")
            ax.set_title(_title(r, f"{kind.upper()} spectrogram, {direction}"), fontsize=9)
            if i == 0 and j == 0 and ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=6)
    return fig


def histogram_figure(r: ChannelResult):
    """Logarithmic histograms (left) and accumulated histograms (right) of DSNU and PRNU."""
    fig, axes = _figure(2, 2, height=5.2)
    for i, kind in enumerate(("dsnu", "prnu")):
        h = r.histograms.get(kind)
        a, b = axes[i]
        if h is None:
            q = r.dsnu_e.total if kind == "dsnu" else r.prnu_percent.total
            _empty(a, q.reason)
            _empty(b, q.reason)
            continue
        centres = 0.5 * (h.bin_edges[1:] + h.bin_edges[:-1])
        a.stairs(h.counts, h.bin_edges, fill=True, alpha=0.7, label="data")
        if h.std > 0:
            w = h.bin_edges[1] - h.bin_edges[0]
            mu = float(np.sum(centres * h.counts) / max(h.counts.sum(), 1))
            model = h.n_pixels * w / (math.sqrt(2 * math.pi) * h.std) * np.exp(-0.5 * ((centres - mu) / h.std) ** 2)
            a.plot(centres, model, "r-", lw=0.8, label="normal")
        a.set_yscale("log")
        a.set_ylim(0.5, None)
        a.set_xlabel(f"deviation ({h.unit})")
        a.set_ylabel("pixels/bin")
        a.set_title(_title(r, f"{kind.upper()} histogram"), fontsize=9)
        a.legend(fontsize=6)
        ok = h.accumulated_percent > 0
        b.semilogy(h.abs_edges[ok], h.accumulated_percent[ok], lw=0.8)
        for thr in h.beyond:
            b.axvline(thr, c="gray", ls=":", lw=0.6)
        b.set_xlabel(f"|deviation| ({h.unit})")
        b.set_ylabel("pixels beyond (%)")
        b.set_title(f"{kind.upper()} accumulated", fontsize=9)
    return fig


_FIGURES = {"photon_transfer": photon_transfer_figure, "snr": snr_figure,
            "linearity": linearity_figure, "dark_current": dark_current_figure,
            "spectrograms": spectrogram_figure, "histograms": histogram_figure}


def save_figures(r: ChannelResult, outdir: str | Path, *, dpi: int = 150, prefix: str = "") -> list[Path]:
    """Write every figure of ``r`` as PNG into ``outdir``; returns the paths.

    Parameters
    ----------
    r : ChannelResult
    outdir : path
        Created if missing.
    dpi : int
        Resolution; at 150 dpi a figure is 975 pixels wide.
    prefix : str
        Prepended to the file names (e.g. the channel name).
    """
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, fn in _FIGURES.items():
        fig = fn(r)
        p = out / f"{prefix}{name}.png"
        fig.savefig(p, dpi=dpi)
        paths.append(p)
    return paths
