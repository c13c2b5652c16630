"""The spectrum of temporal row offsets: a white floor against a power law, and the measured table.

Row noise as the loop's vocabulary has it (:mod:`simcam.calibration.effects.row_noise`) is an offset
drawn independently for every row of every frame: the row means of a frame's temporal residual then
form a white sequence along the row index, whose periodogram is flat at ``sigma^2 + pixel variance /
W``. Readout electronics also make offsets that wander slowly from row to row (flicker, 1/f noise of
the row reference; J. R. Janesick, *Photon Transfer*, SPIE 2007, ch. 9), whose periodogram falls as
``a f^-alpha``. Both are additive, temporal and shared along the row, and the row means' variance cannot
tell them apart; their spectra can.

:func:`fit_row_spectrum` fits the frame-averaged periodogram ``P(f)`` of the row means (per frame,
the frame's mean removed; bins ``f = 1/H ... < 1/2``) by Whittle's likelihood (P. Whittle, "Estimation
and information in stationary time series", Ark. Mat. 2, 1953: each bin of one frame's periodogram
is exponential about the spectrum, an average of M frames Gamma(M, S/M)) with three nested models:

* ``white``: ``S(f) = c``;
* ``coloured``: ``S(f) = floor + w + a g(f)`` (``w, a >= 0``), ``g`` the better of two shapes: a power
  law ``f^-alpha`` (``alpha`` in [0.2, 3]: flicker noise) or a first-order low-pass
  ``1 / (1 - 2 rho cos 2 pi f + rho^2)`` (``rho`` in [0.3, 0.99]: an RC-filtered reference sampled row
  by row, an autoregression of order 1, whose spectrum flattens below its corner where a power law
  does not);
* ``no white``: the same with ``w = 0``,

``floor`` being the pixel noise's share, the residual's variance over W. Bins far above the fitted
spectrum (a periodic pattern's line: beyond the Gamma law's 1 - 1e-4 / bins quantile) are left out
and the fit repeated. The likelihood-ratio statistic ``2 (L_no-white - L_coloured)``, computed inside
each shape, says whether a white part (``row_noise``) sits beside the coloured one; it is kept only when
every shape needs it (the smaller statistic over :data:`WHITE_LR`), so that a coloured spectrum no single
shape describes is not split into a white part and a coloured one. Without it the parameters are those of
the best fit without a white part.

:func:`coloured_table` is the measured spectrum itself, less the floor and that white part, averaged
in bands of frequency spaced evenly in log f: what ``empirical_spectrum`` simulates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: likelihood-ratio statistic above which the row offsets are called coloured (two extra parameters;
#: 25 is beyond what a white sequence gives in 10^5 tries, and leaves room for a spectrum that is
#: only roughly a power law)
COLOURED_LR = 25.0
#: likelihood-ratio statistic above which a white part is kept beside a coloured one (one parameter on
#: its boundary: 9 is z = 3)
WHITE_LR = 9.0


@dataclass(frozen=True)
class RowSpectrum:
    """The fit of :func:`fit_row_spectrum` (variances in DN^2; ``lr_*`` are likelihood-ratio statistics)."""

    floor: float  # the pixel noise's share of the row means' variance
    white: float  # the white model's excess over the floor (the row-noise variance if the offsets are white)
    w: float  # the white part beside the coloured one
    a: float  # amplitude of the coloured part a g(f) (f in cycles per row)
    shape: str  # "power": g = f^-param; "ar1": g = 1 / (1 - 2 param cos 2 pi f + param^2)
    param: float
    lr_coloured: float
    lr_white: float
    bins: int
    excluded: int

    @property
    def coloured(self) -> bool:
        return self.lr_coloured > COLOURED_LR

    def model(self, f: np.ndarray) -> np.ndarray:
        """The fitted spectrum ``floor + w + a g(f)`` of the row means at frequencies ``f``."""
        return self.floor + self.w + self.a * _shape(self.shape, self.param, f)

    @property
    def white_part(self) -> bool:
        return self.lr_white > WHITE_LR


def row_mean_periodogram(res: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Frame-averaged periodogram of the row means of temporal residuals ``(frames, H, W)``.

    Returns (frequencies, mean periodogram, pixel floor, frames averaged); bins 1 .. ceil(H/2) - 1
    (no DC, no Nyquist bin). The periodogram is ``|rfft|^2 / H``: a white sequence of variance v
    has E[P] = v in every bin.
    """
    h = res[0].shape[1]
    ps, floors, counts = [], [], []
    for r in res:
        rm = r.mean(axis=2)
        rm = rm - rm.mean(axis=1, keepdims=True)
        ps.append((np.abs(np.fft.rfft(rm, axis=1)) ** 2 / h)[:, 1:(h + 1) // 2])
        floors.append(float(np.var(r)) / r.shape[2])
        counts.append(r.shape[0])
    n = np.asarray(counts, np.float64)
    f = np.fft.rfftfreq(h)[1:(h + 1) // 2]
    return f, np.concatenate(ps).mean(0), float(np.sum(n * floors) / n.sum()), int(n.sum())


def _nll(s: np.ndarray, p: np.ndarray, m: float) -> float:
    return float(m * np.sum(np.log(s) + p / s))


#: the coloured shapes' parameter grids: the power law's exponent, the low-pass's lag-1 coefficient
SHAPES = (("power", tuple(np.round(np.arange(0.2, 3.0001, 0.1), 1))),
          ("ar1", (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95, 0.98, 0.99)))


def _shape(shape: str, param: float, f: np.ndarray) -> np.ndarray:
    if shape == "power":
        return f ** -param
    return 1.0 / (1.0 - 2.0 * param * np.cos(2 * np.pi * f) + param * param)


def _coloured(f, p, floor, m, with_white: bool, only: str | None = None) -> tuple[float, float, float, str, float]:
    """Best (nll, w, a, shape, param) of floor + w + a g(f) over :data:`SHAPES`' grids (``only``: that
    shape's), (w, a) >= 0 by L-BFGS-B at each grid point (``with_white=False``: w = 0)."""
    from scipy.optimize import minimize

    best = (np.inf, 0.0, 0.0, "power", 0.0)
    span = max(float(np.mean(p)), 1e-300)
    for shape, param in ((sh, x) for sh, grid in SHAPES if only in (None, sh) for x in grid):
        g = _shape(shape, param, f)
        a0 = max(float(np.mean(p) - floor), span * 1e-6) / float(np.mean(g))

        def obj(x, g=g):
            w = x[0] if with_white else 0.0
            s = floor + w + x[-1] * g
            return _nll(np.maximum(s, 1e-300), p, m)

        x0 = [0.5 * a0 * float(np.min(g)), 0.5 * a0] if with_white else [a0]
        bounds = [(0.0, None)] * len(x0)
        r = minimize(obj, x0, method="L-BFGS-B", bounds=bounds)
        if r.fun < best[0]:
            best = (float(r.fun), float(r.x[0]) if with_white else 0.0, float(r.x[-1]), shape, float(param))
    return best


def fit_row_spectrum(res: list[np.ndarray]) -> RowSpectrum | None:
    """White-or-coloured fit of the row means of temporal residuals (module docstring); None with
    fewer than 8 usable bins."""
    from scipy.stats import gamma

    if not res or res[0].shape[1] < 18:
        return None
    f, p, floor, m = row_mean_periodogram(res)
    keep = np.ones(p.size, bool)
    cut = gamma.ppf(1 - 1e-4 / p.size, m) / m
    for _ in range(3):
        fc, pc = f[keep], p[keep]
        full = _coloured(fc, pc, floor, m, True)
        new = p <= cut * (floor + full[1] + full[2] * _shape(full[3], full[4], f))
        if new.sum() < 8 or np.array_equal(new, keep):
            break
        keep = new
    fc, pc = f[keep], p[keep]
    if fc.size < 8:
        return None
    c = max(float(np.mean(pc)), 1e-300)
    l_white = _nll(np.full(pc.size, c), pc, m)
    # the white part is tested inside each shape and kept only if every shape needs it: across shapes, a
    # low-pass plus a white floor can mimic a power law over two decades (1/f^1.1 rows: likelihood ratio 13
    # against the power law alone, 1.4 inside the power law)
    per = [(_coloured(fc, pc, floor, m, False, only=sh), _coloured(fc, pc, floor, m, True, only=sh))
           for sh, _grid in SHAPES]  # (without, with) a white part, each shape
    lr_white = min(2 * (no[0] - yes[0]) for no, yes in per)
    nowhite = min((no for no, _yes in per), key=lambda x: x[0])
    full = min((yes for _no, yes in per), key=lambda x: x[0]) if lr_white > WHITE_LR else nowhite
    return RowSpectrum(floor=floor, white=max(c - floor, 0.0), w=full[1], a=full[2], shape=full[3], param=full[4],
                       lr_coloured=max(2 * (l_white - full[0]), 0.0), lr_white=max(lr_white, 0.0),
                       bins=int(fc.size), excluded=int(p.size - fc.size))


#: bands per decade of frequency of :func:`coloured_table` (a band holds at least one bin)
BANDS_PER_DECADE = 8


def row_mean_residuals(d) -> list[np.ndarray]:
    """The dark temporal residuals ``(frames, H, W)`` whose row means the spectrum is measured on: the
    darks only (in a flat, a per-frame gain times the flat's shading is a smooth row profile too)."""
    return [r for r in d.temporal_residuals("dark") if r.shape[0] >= 2]


def row_spectrum_of(d) -> RowSpectrum | None:
    """:func:`fit_row_spectrum` of :func:`row_mean_residuals` of the capture ``d``, kept in ``d.cache``."""
    if "row_spectrum" not in d.cache:
        res = row_mean_residuals(d)
        d.cache["row_spectrum"] = fit_row_spectrum(res) if res else None
    return d.cache["row_spectrum"]


def coloured_table(res: list[np.ndarray], spec: RowSpectrum | None = None
                   ) -> tuple[list[float], list[float], float] | None:
    """The measured spectrum of the row offsets less its white part: (band frequencies in cycles per row,
    band powers in DN^2, the power at f = 0 in DN^2), or None when the residuals are too short for
    :func:`fit_row_spectrum`.

    The frame-averaged periodogram less the pixel floor and, where the fit keeps a white part beside the
    coloured one (:attr:`RowSpectrum.white_part`), less that part (``row_noise``'s); bins a periodic
    line holds (left out of the fit) are left out here too. The bins are averaged in bands evenly spaced
    in log f (:data:`BANDS_PER_DECADE`), each band's frequency the geometric mean of its bins', its power
    clipped at 0. The power is a periodogram level: a white sequence of variance ``v`` has ``v``.

    The power at f = 0 (the frame's mean offset, which each frame's row means cannot show once their mean
    is removed) comes from the frames' means instead: ``H`` times their variance over the frames, less the
    same floor and white part, clipped at 0 (a 1/f offset moves the frame's mean; one synthesised without
    it does not).
    """
    spec = spec or fit_row_spectrum(res)
    if spec is None:
        return None
    from scipy.stats import gamma

    f, p, floor, m = row_mean_periodogram(res)
    keep = p <= gamma.ppf(1 - 1e-4 / p.size, m) / m * spec.model(f)
    white = spec.w if spec.white_part else 0.0
    excess = p - floor - white
    lo, hi = np.log10(f[0]), np.log10(f[-1])
    nb = max(int(np.ceil((hi - lo) * BANDS_PER_DECADE)), 1)
    band = np.minimum(((np.log10(f) - lo) / max(hi - lo, 1e-12) * nb).astype(int), nb - 1)
    freqs, powers = [], []
    for b in range(nb):
        sel = keep & (band == b)
        if sel.any():
            freqs.append(float(np.exp(np.mean(np.log(f[sel])))))
            powers.append(float(max(np.mean(excess[sel]), 0.0)))
    if not freqs:
        return None
    h = res[0].shape[1]
    v = np.concatenate([r.mean(axis=(1, 2)) for r in res])
    dc = max(h * float(np.mean(v * v)) - floor - white, 0.0)
    return freqs, powers, dc
