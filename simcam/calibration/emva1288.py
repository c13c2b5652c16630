"""EMVA 1288 Release 4.0 (Linear) characterisation from streamed frames.

Implements the evaluation of EMVA Standard 1288 Release 4.0 "Linear" (the direct successor
of Release 3.1 for cameras with a linear characteristic): the photon transfer method (system
gain K, temporal dark noise, quantum efficiency, saturation, SNR, dynamic range, absolute
sensitivity threshold, linearity), the dark current (mean and variance methods), the spatial
non-uniformities DSNU and PRNU split into row / column / pixel components with the correction
for the residual temporal noise of the averaged frames, their horizontal and vertical
spectrograms, and the logarithmic defect-pixel histograms.

Frames are consumed in a single pass per operating point: each point keeps a per-pixel
running mean and sum of squared deviations (Welford, float64) and the per-frame means; after
the point only scalars remain, except the average image of the one dark and one bright point
chosen for the spatial evaluation.  While streaming, a point holds four float64 maps (running
mean, sum of squared deviations, two work buffers) besides the kept average images, whatever
the number of frames; a 12 MP evaluation of 16-frame points peaks at about 7.5 float64 maps.

Differences to the reference implementation ``emva1288`` (PyPI 1.0.2, which follows Release
3.x for the temporal quantities) are listed in :data:`R4_DIFFERENCES` and in the notes of
each result.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass
from typing import Iterable, Iterator, Literal

import numpy as np

from simcam.errors import DatasetError

from .streaming import kernel_input, welford_add

__all__ = [
    "Emva1288Error", "OperatingPoint", "PointAccumulator", "PointStats", "Quantity",
    "Spectrogram", "DefectHistogram", "NonUniformity", "PhotonTransferData", "ChannelResult",
    "Emva1288Report", "characterise", "characterise_stats", "cfa_channels", "R4_DIFFERENCES",
    "QUANTISATION_VARIANCE_DN2", "DARK_VARIANCE_FLOOR_DN2",
]

QUANTISATION_VARIANCE_DN2 = 1.0 / 12.0
"""Variance of the uniform quantisation noise, sigma_q^2 = 1/12 DN^2 (EMVA 1288 R4.0 Sec. 2)."""

DARK_VARIANCE_FLOOR_DN2 = 0.24
"""Lower limit of the temporal dark variance, 0.24 DN^2 (EMVA 1288 R4.0 Linear, temporal dark
noise): below it the dark noise is not measurable, the variance is set to 0.24 DN^2 and the dark
noise is reported as an upper limit sigma_d < sqrt(0.24 - 1/12) / K = 0.40 / K."""

PTC_FIT_FRACTION = 0.70
"""Upper end of the photon-transfer and sensitivity fits: 70 % of the saturation signal."""

LINEARITY_RANGE = (0.05, 0.95)
"""Range of the linearity fit in fractions of the saturation signal."""

R4_DIFFERENCES = {
    "absolute_sensitivity_threshold": (
        "R4.0 solves SNR = 1 exactly: mu_e.min = sqrt(sigma_y.dark^2/K^2 + 1/4) + 1/2; emva1288 "
        "1.0.2 uses the Release 3 approximation sigma_y.dark/K + 1/2 (larger by < 0.5/(sigma_d)^2 "
        "relative)."),
    "dynamic_range": "follows the threshold: DR = mu_p.sat / mu_p.min with the exact threshold.",
    "temporal_variance": (
        "computed for any number L >= 2 of frames as the mean per-pixel stack variance minus the "
        "variance of the frame means; for L = 2 this is exactly the two-frame difference formula "
        "sigma_y^2 = mean((y_A - y_B)^2)/2 - (mu_A - mu_B)^2/2 used by emva1288."),
    "dark_current": (
        "computed from two distinct exposure times on; emva1288 requires more than two."),
    "temporal_dark_noise": (
        "R4.0 takes sigma_y.dark^2 from the dark measurement at the shortest exposure time; "
        "emva1288 1.0.2 extrapolates a line over all dark exposure times to 0 s (three or more "
        "exposure times).  dark_noise='intercept' reproduces emva1288."),
    "illumination_correction": (
        "R4.0 Sec. 8.1 high-pass (7x7 box, 11x11 box, 3x3 binomial) is available as an option; "
        "emva1288 1.0.2 computes the spatial variances unfiltered and high-passes (5x5 box) "
        "only the PRNU histogram."),
    "defect_histograms": (
        "fixed number of equal bins over the deviation range; emva1288 and R4.0 use an integer "
        "bin width of the summed image with at most 256 bins."),
}


class Emva1288Error(DatasetError):
    """Inputs to the EMVA 1288 evaluation are invalid (shape, kind, exposure, CFA)."""


# ----------------------------------------------------------------------------- results types


@dataclass(frozen=True)
class Quantity:
    """One result with its unit; ``value`` is None when not applicable, with ``reason``.

    ``upper_limit`` marks a value that is only an upper bound (dark noise below the
    quantisation limit, EMVA 1288 R4.0 Linear).
    """

    value: float | None
    unit: str
    reason: str | None = None
    upper_limit: bool = False

    @property
    def applicable(self) -> bool:
        return self.value is not None

    @classmethod
    def of(cls, value: float, unit: str, *, upper_limit: bool = False,
           what: str = "value") -> "Quantity":
        v = float(value)
        if not math.isfinite(v):
            return cls(None, unit, f"{what} is not finite ({v})")
        return cls(v, unit, None, upper_limit)

    @classmethod
    def na(cls, unit: str, reason: str) -> "Quantity":
        return cls(None, unit, reason)

    def __float__(self) -> float:
        if self.value is None:
            raise TypeError(f"quantity not applicable: {self.reason}")
        return self.value

    def to_dict(self) -> dict:
        d = {"value": self.value, "unit": self.unit}
        if self.reason is not None:
            d["reason"] = self.reason
        if self.upper_limit:
            d["upper_limit"] = True
        return d


@dataclass(frozen=True)
class OperatingPoint:
    """One EMVA 1288 operating point: a sequence of frames at one exposure and irradiation.

    Parameters
    ----------
    kind : {"dark", "bright"}
    exposure_s : float
        Exposure time in seconds (> 0).
    frames : iterable of 2-D arrays
        Frames in DN, consumed once (a generator is fine).  Monochrome, or a Bayer mosaic
        when a CFA pattern is given to :func:`characterise`.
    photons : float or None
        Mean number of photons per pixel during the exposure (bright points); None when
        unknown, in which case the quantum efficiency and the photon-referred quantities are
        not applicable.
    role : {"auto", "temporal", "spatial"}
        ``temporal``: used for the photon transfer / dark current only; ``spatial``: used only
        for the non-uniformity evaluation; ``auto``: used for the photon transfer and a
        candidate for the spatial evaluation (the point with most frames of its kind is kept).
    """

    kind: Literal["dark", "bright"]
    exposure_s: float
    frames: Iterable[np.ndarray]
    photons: float | None = None
    role: Literal["auto", "temporal", "spatial"] = "auto"


@dataclass
class PointStats:
    """Sufficient statistics of one operating point in one channel (after streaming)."""

    kind: str
    exposure_s: float
    photons: float | None
    role: str
    n_frames: int
    mean: float                      # mu_y, DN
    var_temporal: float | None       # sigma_y^2 (drift-corrected), DN^2; None for one frame
    var_stack: float | None          # mean per-pixel variance of the stack, DN^2
    mean_map: np.ndarray | None = None  # <y>, kept for spatial candidates only
    shape: tuple[int, int] = (0, 0)


@dataclass(frozen=True)
class Spectrogram:
    """Horizontal or vertical spectrogram of a non-uniformity image (EMVA 1288 R4.0 Linear).

    ``frequency`` in cycles/pixel (0 ... 0.5); ``amplitude`` is the square root of the power
    spectrum averaged over the lines, in the unit of the non-uniformity (e- for DSNU, % for
    PRNU); ``temporal_floor`` is the level of the residual temporal noise of the averaged
    frames (sqrt(sigma_stack^2 / L) in the same unit), a white floor in the spectrogram;
    ``nonuniformity`` the DSNU1288 / PRNU1288 value, ``stack_noise`` the temporal noise of one
    frame sigma_y.stack and ``measured`` the uncorrected spatial standard deviation s_y.measured,
    the reference lines R4.0 draws in the spectrogram plots.
    """

    direction: str
    frequency: np.ndarray
    amplitude: np.ndarray
    unit: str
    temporal_floor: float
    nonuniformity: float | None
    stack_noise: float = math.nan
    measured: float = math.nan


@dataclass(frozen=True)
class DefectHistogram:
    """Logarithmic histogram of the deviations of the averaged image (EMVA 1288 R4.0 Linear).

    ``bin_edges`` in ``unit`` (deviation from the mean: e- for DSNU, % of the mean signal for
    PRNU); ``counts`` per bin (plotted on a log axis); ``accumulated_percent[i]`` is the
    percentage of pixels whose absolute deviation is >= ``abs_edges[i]``; ``beyond`` maps a
    threshold (in ``unit``) to the count of pixels with absolute deviation above it.
    """

    name: str
    unit: str
    bin_edges: np.ndarray
    counts: np.ndarray
    abs_edges: np.ndarray
    accumulated_percent: np.ndarray
    beyond: dict
    std: float
    n_pixels: int


@dataclass(frozen=True)
class NonUniformity:
    """Total / row / column / pixel split of a spatial non-uniformity."""

    total: Quantity
    row: Quantity
    column: Quantity
    pixel: Quantity
    variances_dn2: dict


@dataclass(frozen=True)
class PhotonTransferData:
    """The points of the photon transfer, sensitivity and linearity curves (sorted by signal)."""

    exposure_s: np.ndarray
    photons: np.ndarray            # NaN where unknown
    mean_dn: np.ndarray            # mu_y
    var_dn2: np.ndarray            # sigma_y^2
    dark_mean_dn: np.ndarray       # mu_y.dark matched to each bright point
    dark_var_dn2: np.ndarray       # sigma_y.dark^2 matched to each bright point
    saturation_index: int | None
    fit_indices: tuple[int, int] | None        # K / R fit: inclusive index range
    linearity_indices: tuple[int, int] | None  # linearity fit: inclusive index range
    linearity_deviation_percent: np.ndarray | None
    linearity_fit: tuple[float, float] | None  # slope (DN/photon), offset (DN)
    dark_exposure_s: np.ndarray
    dark_series_mean_dn: np.ndarray
    dark_series_var_dn2: np.ndarray


@dataclass(frozen=True)
class ChannelResult:
    """EMVA 1288 R4.0 Linear results for one channel (monochrome, or one CFA colour plane)."""

    channel: str
    system_gain: Quantity              # K, DN/e-
    inverse_system_gain: Quantity      # 1/K, e-/DN
    gain_fit_range_dn: Quantity        # upper end of the fit in (mu_y - mu_y.dark), DN
    dark_noise_dn: Quantity            # sigma_y.dark
    dark_noise_e: Quantity             # sigma_d
    responsivity: Quantity             # R, DN/photon
    quantum_efficiency: Quantity       # eta, %
    saturation_signal_dn: Quantity     # mu_y.sat - mu_y.dark
    saturation_photons: Quantity       # mu_p.sat
    saturation_capacity_e: Quantity    # mu_e.sat
    snr_max: Quantity
    snr_max_db: Quantity
    snr_max_bits: Quantity
    sensitivity_threshold_photons: Quantity  # mu_p.min
    sensitivity_threshold_e: Quantity        # mu_e.min
    dynamic_range: Quantity
    dynamic_range_db: Quantity
    dynamic_range_bits: Quantity
    linearity_error_min: Quantity
    linearity_error_max: Quantity
    linearity_error: Quantity          # (max - min) / 2
    dark_current_mean_e_s: Quantity
    dark_current_mean_dn_s: Quantity
    dark_current_var_e_s: Quantity
    dark_current_var_dn_s: Quantity
    dsnu_e: NonUniformity
    dsnu_dn: NonUniformity
    prnu_percent: NonUniformity
    spectrograms: dict
    histograms: dict
    photon_transfer: PhotonTransferData
    spatial_frames: dict
    notes: tuple

    def to_dict(self) -> dict:
        """JSON-ready dict (arrays as lists, not-applicable values as null with a reason)."""
        return _jsonable(self)


@dataclass(frozen=True)
class Emva1288Report:
    """Results per channel (``"Y"`` for monochrome, the CFA colour names otherwise)."""

    channels: dict
    cfa: str | None = None

    @property
    def mono(self) -> ChannelResult:
        if len(self.channels) != 1:
            raise Emva1288Error(f"report: channels={list(self.channels)}; expected one channel "
                                "for .mono (index by channel name instead)")
        return next(iter(self.channels.values()))

    def __getitem__(self, name: str) -> ChannelResult:
        return self.channels[name]

    def to_dict(self) -> dict:
        return {"standard": "EMVA 1288 Release 4.0 Linear", "cfa": self.cfa,
                "channels": {k: v.to_dict() for k, v in self.channels.items()}}


def _jsonable(obj):
    if isinstance(obj, Quantity):
        return obj.to_dict()
    if dataclasses.is_dataclass(obj):
        return {f.name: _jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [None if (isinstance(v, float) and not math.isfinite(v)) else v
                for v in obj.tolist()]
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


# ----------------------------------------------------------------------------- streaming


def cfa_channels(cfa: str | None) -> list[tuple[str, int, int]]:
    """Channel names and (row, col) offsets of a 2x2 CFA pattern such as ``"RGGB"``.

    Repeated colours get a 1-based index in raster order (``"RGGB"`` -> R, G1, G2, B).
    None gives the single monochrome channel ``"Y"``.
    """
    if cfa is None:
        return [("Y", 0, 0)]
    pat = str(cfa).upper()
    if len(pat) != 4 or any(c not in "RGBCMYW" for c in pat):
        raise Emva1288Error(f"cfa={cfa!r}; expected a 2x2 pattern of four letters such as 'RGGB'")
    names = []
    for i, c in enumerate(pat):
        names.append(f"{c}{pat[:i + 1].count(c)}" if pat.count(c) > 1 else c)
    return [(names[i], i // 2, i % 2) for i in range(4)]


class PointAccumulator:
    """Single-pass statistics of one operating point, per channel (Welford, float64).

    Call :meth:`add` with each frame, then :meth:`finish`.  Holds per channel a running
    mean map and a running sum of squared deviations; nothing else per pixel.
    """

    def __init__(self, point: OperatingPoint, cfa: str | None = None, *, index: int = 0):
        if point.kind not in ("dark", "bright"):
            raise Emva1288Error(f"operating point {index}: kind={point.kind!r}; expected 'dark' or 'bright'")
        if not (isinstance(point.exposure_s, numbers.Real) and math.isfinite(point.exposure_s)
                and point.exposure_s > 0):
            raise Emva1288Error(f"operating point {index}: exposure_s={point.exposure_s!r}; "
                                "expected a finite time in seconds > 0")
        if point.photons is not None and not (isinstance(point.photons, numbers.Real)
                                              and math.isfinite(point.photons) and point.photons >= 0):
            raise Emva1288Error(f"operating point {index}: photons={point.photons!r}; expected "
                                "a finite mean photon count >= 0 or None")
        if point.role not in ("auto", "temporal", "spatial"):
            raise Emva1288Error(f"operating point {index}: role={point.role!r}; expected "
                                "'auto', 'temporal' or 'spatial'")
        self.point, self.index = point, index
        self.channels = cfa_channels(cfa)
        self.n = 0
        self.shape: tuple[int, int] | None = None
        self._mean: list[np.ndarray] = []
        self._m2: list[np.ndarray] = []
        self._frame_means: list[list[float]] = [[] for _ in self.channels]

    def add(self, frame: np.ndarray) -> None:
        a = np.asarray(frame)
        if a.ndim != 2 or a.size == 0:
            raise Emva1288Error(f"operating point {self.index} frame {self.n}: shape={a.shape}; "
                                "expected a non-empty 2-D array (monochrome or Bayer mosaic)")
        if self.shape is None:
            step = 1 if len(self.channels) == 1 else 2
            if step == 2 and (a.shape[0] % 2 or a.shape[1] % 2 or min(a.shape) < 4):
                raise Emva1288Error(f"operating point {self.index}: frame shape={a.shape}; expected "
                                    "even height and width >= 4 for a 2x2 CFA")
            self.shape = a.shape
            self._step = step
        elif a.shape != self.shape:
            raise Emva1288Error(f"operating point {self.index} frame {self.n}: shape={a.shape}; "
                                f"expected {self.shape} like the first frame")
        self.n += 1
        s = self._step
        for c, (_name, dy, dx) in enumerate(self.channels):
            x = a[dy::s, dx::s]
            if self.n == 1:
                self._mean.append(x.astype(np.float64))
                self._m2.append(np.zeros(x.shape, np.float64))
                self._frame_means[c].append(float(self._mean[c].mean()))
                continue
            # Welford's update in one pass over the plane (simcam.calibration.streaming)
            tot = welford_add(kernel_input(x), self._mean[c], self._m2[c], float(self.n))
            self._frame_means[c].append(tot / x.size)

    def finish(self, keep_map: bool = True) -> list[PointStats]:
        if self.n == 0:
            raise Emva1288Error(f"operating point {self.index}: frames is empty; expected at least "
                                "one frame (two for a temporal variance)")
        out = []
        for c, _ch in enumerate(self.channels):
            mean_map, m2 = self._mean[c], self._m2[c]
            if self.n >= 2:
                var_stack = float(m2.mean()) / (self.n - 1)
                var_t = var_stack - float(np.var(self._frame_means[c], ddof=1))
            else:
                var_stack = var_t = None
            out.append(PointStats(self.point.kind, float(self.point.exposure_s),
                                  None if self.point.photons is None else float(self.point.photons),
                                  self.point.role, self.n, float(mean_map.mean()), var_t, var_stack,
                                  mean_map if keep_map else None, mean_map.shape))
        self._mean, self._m2 = [], []
        return out


def _stream(points: Iterable[OperatingPoint], cfa: str | None) -> tuple[dict, list[str]]:
    """One pass over every point; keeps the mean maps of the chosen spatial points only."""
    names = [n for n, _, _ in cfa_channels(cfa)]
    stats = {n: [] for n in names}
    best: dict[str, tuple[int, int] | None] = {"dark": None, "bright": None}  # (priority, n)
    best_idx: dict[str, int | None] = {"dark": None, "bright": None}
    for i, p in enumerate(points):
        if not isinstance(p, OperatingPoint):
            raise Emva1288Error(f"operating point {i}: type={type(p).__name__}; expected OperatingPoint")
        acc = PointAccumulator(p, cfa, index=i)
        for f in p.frames:
            acc.add(f)
        per_ch = acc.finish(keep_map=True)
        keep = False
        if p.role != "temporal" and acc.n >= 2:
            prio = (1 if p.role == "spatial" else 0, acc.n)
            cur = best[p.kind]
            if cur is None or prio > cur:
                keep = True
                if best_idx[p.kind] is not None:  # drop the previous candidate's maps
                    for n in names:
                        stats[n][best_idx[p.kind]].mean_map = None
                best[p.kind], best_idx[p.kind] = prio, len(stats[names[0]])
        for n, st in zip(names, per_ch):
            if not keep:
                st.mean_map = None
            stats[n].append(st)
    if not stats[names[0]]:
        raise Emva1288Error("points: no operating point given; expected dark and bright points")
    return stats, names


# ----------------------------------------------------------------------------- evaluation


def characterise(points: Iterable[OperatingPoint], *, cfa: str | None = None,
                 histogram_bins: int = 256, threshold_multiples: tuple = (3.0, 5.0, 10.0),
                 dark_noise: Literal["shortest", "intercept"] = "shortest",
                 illumination_correction: bool = False) -> Emva1288Report:
    """EMVA 1288 R4.0 Linear evaluation of streamed operating points.

    Parameters
    ----------
    points : iterable of OperatingPoint
        Dark and bright points; each point's frames are read once, in order.
    cfa : str or None
        2x2 Bayer pattern (e.g. ``"RGGB"``) to evaluate each colour plane separately, as
        EMVA 1288 R4.0 prescribes for colour cameras with raw data; None for monochrome.
    histogram_bins : int
        Number of bins of the defect-pixel histograms.
    threshold_multiples : tuple of float
        The histograms count pixels deviating by more than these multiples of the spatial
        standard deviation (DSNU in e-, PRNU in %).
    dark_noise : {"shortest", "intercept"}
        Where the temporal dark variance sigma_y.dark^2 is taken when dark points exist at
        several exposure times: ``shortest`` (R4.0 Linear: the measurement at the shortest
        exposure time) or ``intercept`` (the linear fit of sigma_y.dark^2 over the exposure
        time extrapolated to 0 s, as emva1288 1.0.2 does with three or more exposure times).
    illumination_correction : bool
        Apply the R4.0 Sec. 8.1 high-pass filter (7x7 box, 11x11 box and 3x3 binomial
        smoothing subtracted, border of 9 pixels dropped) to the averaged images before the
        spatial variances, spectrograms and histograms; the residual temporal variance is
        scaled by the filter's noise gains.  Off by default (uniform illumination).

    Returns
    -------
    Emva1288Report
    """
    stats, names = _stream(points, cfa)
    return Emva1288Report({n: characterise_stats(stats[n], channel=n, histogram_bins=histogram_bins,
                                                 threshold_multiples=threshold_multiples,
                                                 dark_noise=dark_noise,
                                                 illumination_correction=illumination_correction)
                           for n in names}, None if cfa is None else str(cfa).upper())


def _fit_origin(x: np.ndarray, y: np.ndarray) -> float:
    """Least-squares slope of y = m x (regression through the origin)."""
    sxx = float(np.dot(x, x))
    return float(np.dot(x, y)) / sxx if sxx > 0 else math.nan


def _fit_line(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares (slope, intercept) of y = m x + b."""
    xm, ym = float(np.mean(x)), float(np.mean(y))
    sxx = float(np.sum((x - xm) ** 2))
    if sxx <= 0:
        return math.nan, math.nan
    m = float(np.sum((x - xm) * (y - ym))) / sxx
    return m, ym - m * xm


def _dark_series(darks: list[PointStats]):
    """Per distinct exposure: mean of mu_y.dark and sigma_y.dark^2 over the dark points."""
    groups: dict[float, list[PointStats]] = {}
    for d in darks:
        key = next((k for k in groups if math.isclose(k, d.exposure_s, rel_tol=1e-9)), d.exposure_s)
        groups.setdefault(key, []).append(d)
    t = np.array(sorted(groups))
    mu = np.array([np.mean([d.mean for d in groups[k]]) for k in t])
    var = np.array([np.mean([d.var_temporal for d in groups[k] if d.var_temporal is not None])
                    if any(d.var_temporal is not None for d in groups[k]) else np.nan for k in t])
    return t, mu, var


def _match_dark(t: float, dt: np.ndarray, dmu: np.ndarray, dvar: np.ndarray):
    """mu_y.dark and sigma_y.dark^2 at exposure t: the dark point at t, else a line in t."""
    hit = np.flatnonzero(np.isclose(dt, t, rtol=1e-9, atol=0))
    if hit.size:
        return float(dmu[hit[0]]), float(dvar[hit[0]]), None
    if dt.size == 1:
        return float(dmu[0]), float(dvar[0]), "no dark point at its exposure: the single dark exposure is used"
    m, b = _fit_line(dt, dmu)
    ok = np.isfinite(dvar)
    mv, bv = _fit_line(dt[ok], dvar[ok]) if ok.sum() >= 2 else (0.0, float(np.nanmean(dvar)))
    return m * t + b, mv * t + bv, "no dark point at its exposure: dark values interpolated linearly in time"


def _spatial_variances(avg: np.ndarray, var_stack: float, L: int,
                       gains: tuple[float, float] = (1.0, 1.0)) -> dict:
    """Spatial variance and its row / column / pixel split (EMVA 1288 R4.0 Linear, Sec. 8).

    ``avg`` is the average of L frames; the residual temporal variance var_stack / L of each
    pixel, var_stack / (L M) of a column mean and var_stack / (L N) of a row mean is removed
    (R4.0 eqs. for s_y^2, s_y.cav^2, s_y.rav^2), then the three equations
    s_cav^2 = s_col^2 + s_pix^2/M, s_rav^2 = s_row^2 + s_pix^2/N, s_y^2 = s_col^2 + s_row^2 + s_pix^2
    are solved for the column, row and pixel variances.  ``gains`` = (g2, g1) scale the
    residual temporal variances after a high-pass filter: g2 for a pixel, g1 for a row or
    column mean (white noise through the 2-D and the 1-D filter).
    """
    g2, g1 = gains
    M, N = avg.shape
    mu = float(avg.mean())
    col_means = avg.mean(axis=0)   # mu_y[n], N values
    row_means = avg.mean(axis=1)   # mu_y[m], M values
    s2_measured = float(np.var(avg, ddof=1))
    s2 = s2_measured - g2 * var_stack / L
    s2_cav = float(np.mean((col_means - mu) ** 2)) - g1 * var_stack / (L * M)
    s2_rav = float(np.mean((row_means - mu) ** 2)) - g1 * var_stack / (L * N)
    den = M * N - M - N
    if den <= 0:
        col = row = pix = math.nan
    else:
        col = (M * N - M) / den * s2_cav - N / den * (s2 - s2_rav)
        row = (M * N - N) / den * s2_rav - M / den * (s2 - s2_cav)
        pix = M * N / den * (s2 - s2_cav - s2_rav)
    return {"measured": s2_measured, "total": s2, "column_average": s2_cav, "row_average": s2_rav,
            "column": col, "row": row, "pixel": pix, "mean": mu, "stack": var_stack, "L": L,
            "residual_gain": g2}


def _sqrt_q(v: float, scale: float, unit: str, what: str) -> Quantity:
    if not math.isfinite(v):
        return Quantity.na(unit, f"{what}: variance not available")
    if v < 0:
        return Quantity.na(unit, f"{what}: corrected spatial variance is negative ({v:.4g} DN^2): "
                                 "the residual temporal noise exceeds the measured non-uniformity")
    return Quantity.of(math.sqrt(v) * scale, unit, what=what)


def _na_split(unit: str, reason: str) -> NonUniformity:
    q = Quantity.na(unit, reason)
    return NonUniformity(q, q, q, q, {})


def _spectrogram(img: np.ndarray, direction: str, scale: float, unit: str, floor_var: float,
                 nonuni: float | None, stack_noise: float, measured: float) -> Spectrogram:
    """Power spectrum per line, averaged over lines (EMVA 1288 R4.0 Linear, spectrograms).

    ``horizontal``: FFT along each row; ``vertical``: along each column.  Rows are processed
    in blocks so the complex spectrum never exceeds a few MB.
    """
    a = img if direction == "horizontal" else img.T
    mu = float(img.mean())
    n_lines, n = a.shape
    acc = np.zeros(n // 2 + 1)
    block = max(1, (1 << 22) // max(n, 1))
    for s in range(0, n_lines, block):
        f = np.fft.rfft(a[s:s + block] - mu, axis=1)
        acc += np.sum(f.real ** 2 + f.imag ** 2, axis=0)
    power = acc / (n_lines * n)   # DN^2 per frequency; white noise of variance s2 gives s2
    return Spectrogram(direction, np.arange(n // 2 + 1) / n, np.sqrt(power) * scale, unit,
                       math.sqrt(max(floor_var, 0.0)) * scale, nonuni, stack_noise, measured)


def _illumination_kernel() -> np.ndarray:
    """1-D smoothing kernel of the uneven-illumination correction (EMVA 1288 R4.0 Linear, Sec. 8.1):
    a 7x7 box, an 11x11 box and a 3x3 binomial filter in cascade (separable, 19 taps)."""
    k = np.convolve(np.ones(7) / 7, np.ones(11) / 11)
    return np.convolve(k, np.array([1.0, 2.0, 1.0]) / 4)


def _highpass(img: np.ndarray) -> np.ndarray:
    """img minus its R4.0 Sec. 8.1 smoothing, on the region the 19x19 kernel fully covers."""
    from scipy.ndimage import correlate1d

    k = _illumination_kernel()
    h = k.size // 2
    if min(img.shape) <= 2 * h + 2:
        raise Emva1288Error(f"spatial image shape={img.shape}; expected both sides > {2 * h + 2} "
                            "pixels for the uneven-illumination correction")
    smooth = correlate1d(correlate1d(img, k, axis=0, mode="nearest"), k, axis=1, mode="nearest")
    return (img - smooth)[h:-h, h:-h]


def _highpass_noise_gains() -> tuple[float, float]:
    """Variance gains (g2, g1) of the high-pass for white temporal noise: g2 = sum((delta - h)^2)
    for one pixel (2-D kernel h = k k^T), g1 = sum((delta - k)^2) for a row or column mean (the
    smoothing along the averaged direction drops out of the mean)."""
    k = _illumination_kernel()
    c = k.size // 2
    h2 = np.outer(k, k)
    g2 = float(1.0 - 2.0 * h2[c, c] + np.sum(h2 ** 2))
    g1 = float(1.0 - 2.0 * k[c] + np.sum(k ** 2))
    return g2, g1


def _grid_step(avg: np.ndarray, L: int) -> float | None:
    """1/L when ``avg`` is the mean of L integer-valued frames (values on a 1/L DN grid)."""
    y = avg * L
    return 1.0 / L if np.allclose(y, np.round(y), rtol=0, atol=1e-6 * max(1.0, L)) else None


def _histogram(name: str, dev: np.ndarray, unit: str, bins: int, multiples,
               scale: float = 1.0, grid: float | None = None) -> DefectHistogram:
    """Histogram of the deviations ``dev`` (DN), reported in ``unit`` (``dev * scale``).

    When the averaged image lives on a grid of 1/L DN (integer frames), the bin width is a whole
    number of grid steps with edges between grid values, as EMVA 1288 prescribes (at most
    ``bins`` bins), so no bin is systematically empty; otherwise ``bins`` equal bins.
    """
    dev = dev.ravel()
    lo, hi = float(dev.min()), float(dev.max())
    if grid is not None and hi > lo:
        steps = int(round((hi - lo) / grid))
        w = steps // bins + 1
        nb = steps // w + 1
        edges = lo - grid / 2 + grid * w * np.arange(nb + 1)
    else:
        if hi <= lo:
            hi = lo + 1e-12
        edges = np.linspace(lo, hi, bins + 1)
    counts, edges = np.histogram(dev, bins=edges)
    ad = np.abs(dev)
    amax = float(ad.max()) if ad.size else 0.0
    abs_edges = np.linspace(0.0, amax if amax > 0 else 1e-12, bins + 1)
    hist_abs, _ = np.histogram(ad, bins=abs_edges)
    acc = 100.0 * np.cumsum(hist_abs[::-1])[::-1] / ad.size
    sc = abs(scale)
    std = float(dev.std()) * sc
    beyond = ({float(k * std): int(np.count_nonzero(ad * sc > k * std)) for k in multiples}
              if std > 0 else {})
    return DefectHistogram(name, unit, edges * scale, counts, abs_edges[:-1] * sc, acc, beyond,
                           std, int(ad.size))


def characterise_stats(stats: list[PointStats], *, channel: str = "Y", histogram_bins: int = 256,
                       threshold_multiples: tuple = (3.0, 5.0, 10.0),
                       dark_noise: str = "shortest",
                       illumination_correction: bool = False) -> ChannelResult:
    """Evaluate the streamed statistics of one channel (see :func:`characterise`)."""
    if dark_noise not in ("shortest", "intercept"):
        raise Emva1288Error(f"dark_noise={dark_noise!r}; expected 'shortest' or 'intercept'")
    notes: list[str] = []
    darks_t = [s for s in stats if s.kind == "dark" and s.role != "spatial"]
    brights = [s for s in stats if s.kind == "bright" and s.role != "spatial"
               and s.var_temporal is not None]
    n_single = sum(1 for s in stats if s.var_temporal is None)
    if n_single:
        notes.append(f"{n_single} operating point(s) with one frame: no temporal variance, "
                     "used for the means only")

    na = Quantity.na
    # ---------------------------------------------------------------- dark series
    if darks_t:
        dt, dmu, dvar = _dark_series(darks_t)
    else:
        dt = dmu = dvar = np.zeros(0)
    n_dark_t = int(dt.size)

    # ---------------------------------------------------------------- photon transfer points
    if brights and n_dark_t:
        rows = []
        for b in brights:
            m, v, why = _match_dark(b.exposure_s, dt, dmu, dvar)
            if why and why not in notes:
                notes.append(why)
            rows.append((b.mean - m, b, m, v))
        rows.sort(key=lambda r: r[0])
        sig = np.array([r[0] for r in rows])
        var = np.array([r[1].var_temporal for r in rows])
        dm = np.array([r[2] for r in rows])
        dv = np.array([r[3] for r in rows])
        texp = np.array([r[1].exposure_s for r in rows])
        phot = np.array([np.nan if r[1].photons is None else r[1].photons for r in rows])
        mu_b = np.array([r[1].mean for r in rows])
        var_sig = var - dv
    else:
        sig = var = dm = dv = texp = phot = mu_b = var_sig = np.zeros(0)
    have_ptc = sig.size > 0 and np.all(np.isfinite(dv))

    K = sat_i = fit_hi = None
    why_K = None
    if not brights:
        why_K = "no bright operating point with two or more frames"
    elif not n_dark_t:
        why_K = "no dark operating point for the temporal evaluation"
    elif not have_ptc:
        why_K = "dark temporal variance unavailable (dark points with one frame)"
    else:
        # Saturation: the maximum of the photon transfer curve (R4.0 Linear, saturation).
        sat_i = int(np.argmax(var_sig))
        s_sat = float(sig[sat_i])
        if sat_i == sig.size - 1:
            notes.append("the photon-transfer maximum is the brightest point: saturation may not "
                         "have been reached, the brightest point is taken as saturation")
        if s_sat <= 0:
            why_K = f"saturation signal mu_y.sat - mu_y.dark = {s_sat:.4g} DN is not positive"
        else:
            sel = np.flatnonzero((sig <= PTC_FIT_FRACTION * s_sat) & (np.arange(sig.size) <= sat_i))
            if sel.size == 0:
                why_K = "no photon-transfer point below 70 % of the saturation signal"
            else:
                fit_hi = int(sel.max())
                k = _fit_origin(sig[: fit_hi + 1], var_sig[: fit_hi + 1])
                if not (math.isfinite(k) and k > 0):
                    why_K = f"photon-transfer slope {k:.4g} is not a positive gain"
                else:
                    K = k
    if K is None:
        q_K = na("DN/e-", why_K)
    else:
        q_K = Quantity.of(K, "DN/e-")
    q_iK = na("e-/DN", why_K) if K is None else Quantity.of(1.0 / K, "e-/DN")
    q_fit = (na("DN", why_K) if fit_hi is None
             else Quantity.of(sig[fit_hi], "DN"))

    # ---------------------------------------------------------------- temporal dark noise
    upper = False
    s2_dark = None
    why_d = None
    if not n_dark_t:
        why_d = "no dark operating point"
    else:
        ok = np.isfinite(dvar)
        if not ok.any():
            why_d = "dark points have one frame each: no temporal variance"
        elif dark_noise == "intercept" and np.unique(dt[ok]).size >= 3:
            s2_dark = _fit_line(dt[ok], dvar[ok])[1]   # extrapolated to t_exp = 0 (emva1288)
        else:
            s2_dark = float(dvar[ok][0])                 # shortest exposure (R4.0)
    if s2_dark is not None and s2_dark < DARK_VARIANCE_FLOOR_DN2:
        notes.append(f"temporal dark variance {s2_dark:.4g} DN^2 < {DARK_VARIANCE_FLOOR_DN2} DN^2 "
                     "(quantisation limited): set to 0.24 DN^2, dark noise is an upper limit")
        s2_dark, upper = DARK_VARIANCE_FLOOR_DN2, True
    if s2_dark is None:
        q_sd_dn = na("DN", why_d)
        q_sd_e = na("e-", why_d)
    else:
        q_sd_dn = Quantity.of(math.sqrt(s2_dark), "DN", upper_limit=upper)
        q_sd_e = (na("e-", why_K) if K is None else
                  Quantity.of(math.sqrt(s2_dark - QUANTISATION_VARIANCE_DN2) / K, "e-", upper_limit=upper))

    # ---------------------------------------------------------------- sensitivity, QE
    R = None
    if K is None:
        why_R = why_K
    elif np.any(~np.isfinite(phot[: fit_hi + 1])):
        why_R = "photon counts not given for every point of the sensitivity fit"
    else:
        r = _fit_origin(phot[: fit_hi + 1], sig[: fit_hi + 1])
        if math.isfinite(r) and r > 0:
            R, why_R = r, None
        else:
            why_R = f"sensitivity slope {r:.4g} DN/photon is not positive"
    eta = None if R is None else R / K
    q_R = na("DN/photon", why_R) if R is None else Quantity.of(R, "DN/photon")
    q_eta = na("%", why_R) if eta is None else Quantity.of(100.0 * eta, "%")

    # ---------------------------------------------------------------- saturation, SNR, DR
    if sat_i is None or K is None:
        q_ssat = na("DN", why_K) if sat_i is None else Quantity.of(sig[sat_i], "DN")
        q_psat = na("photons", why_K)
        q_esat = na("e-", why_K)
        mu_e_sat = None
    else:
        q_ssat = Quantity.of(sig[sat_i], "DN")
        if math.isfinite(phot[sat_i]) and eta is not None:
            q_psat = Quantity.of(phot[sat_i], "photons")
            mu_e_sat = eta * phot[sat_i]
        else:
            q_psat = na("photons", why_R or "photon count of the saturation point not given")
            mu_e_sat = sig[sat_i] / K
            notes.append("saturation capacity from (mu_y.sat - mu_y.dark)/K (no photon counts)")
        q_esat = Quantity.of(mu_e_sat, "e-")
    if mu_e_sat is None or mu_e_sat <= 0:
        why = why_K if mu_e_sat is None else f"saturation capacity {mu_e_sat:.4g} e- is not positive"
        q_snr, q_snr_db, q_snr_b = na("1", why), na("dB", why), na("bit", why)
    else:
        snr = math.sqrt(mu_e_sat)
        q_snr, q_snr_db, q_snr_b = (Quantity.of(snr, "1"), Quantity.of(20 * math.log10(snr), "dB"),
                                    Quantity.of(math.log2(snr), "bit"))
    if K is None or s2_dark is None:
        why = why_K if K is None else why_d
        q_emin, q_pmin = na("e-", why), na("photons", why)
        mu_e_min = None
    else:
        # SNR = 1 solved exactly (EMVA 1288 R4.0 Linear, absolute sensitivity threshold)
        mu_e_min = math.sqrt(s2_dark / K ** 2 + 0.25) + 0.5
        q_emin = Quantity.of(mu_e_min, "e-", upper_limit=upper)
        q_pmin = (na("photons", why_R) if eta is None
                  else Quantity.of(mu_e_min / eta, "photons", upper_limit=upper))
    if mu_e_min is None or mu_e_sat is None or mu_e_sat <= 0:
        why = ("needs the saturation capacity and the sensitivity threshold: "
               + (why_K or why_d or "saturation capacity not positive"))
        q_dr, q_dr_db, q_dr_b = na("1", why), na("dB", why), na("bit", why)
    else:
        dr = mu_e_sat / mu_e_min
        q_dr, q_dr_db, q_dr_b = (Quantity.of(dr, "1"), Quantity.of(20 * math.log10(dr), "dB"),
                                 Quantity.of(math.log2(dr), "bit"))

    # ---------------------------------------------------------------- linearity
    lin_dev = lin_fit = lin_idx = None
    if sat_i is None:
        why_L = why_K or "no saturation point"
    elif np.any(~np.isfinite(phot)):
        why_L = "photon counts not given: the linearity is evaluated against the irradiation"
    else:
        s_sat = sig[sat_i]
        idx = np.flatnonzero((sig >= LINEARITY_RANGE[0] * s_sat) & (sig <= LINEARITY_RANGE[1] * s_sat))
        if idx.size < 2 or np.any(sig[idx] <= 0):
            why_L = "fewer than two points between 5 % and 95 % of the saturation signal"
        else:
            x, y = phot[idx], sig[idx]
            # Fit minimising the relative deviations (weights 1/y^2), EMVA 1288 R4.0 Linear, linearity
            w = 1.0 / y ** 2
            A = np.array([[np.sum(w * x * x), np.sum(w * x)], [np.sum(w * x), np.sum(w)]])
            bvec = np.array([np.sum(w * x * y), np.sum(w * y)])
            if abs(np.linalg.det(A)) <= 1e-300 * max(1.0, float(np.abs(A).max()) ** 2):
                why_L = "linearity fit is singular (all points at one irradiation)"
            else:
                a, b0 = np.linalg.solve(A, bvec)
                fitv = a * phot + b0
                with np.errstate(divide="ignore", invalid="ignore"):
                    lin_dev = 100.0 * (sig - fitv) / fitv
                lin_fit, lin_idx = (float(a), float(b0)), (int(idx.min()), int(idx.max()))
                why_L = None
    if lin_dev is None:
        q_lmin, q_lmax, q_le = na("%", why_L), na("%", why_L), na("%", why_L)
    else:
        d = lin_dev[lin_idx[0]: lin_idx[1] + 1]
        q_lmin, q_lmax = Quantity.of(d.min(), "%"), Quantity.of(d.max(), "%")
        q_le = Quantity.of((d.max() - d.min()) / 2.0, "%")

    # ---------------------------------------------------------------- dark current
    if n_dark_t < 2:
        why = ("one dark exposure time: the dark current needs dark points at two or more "
               "exposure times" if n_dark_t == 1 else "no dark operating point")
        q_im_e, q_im_dn, q_iv_e, q_iv_dn = na("e-/s", why), na("DN/s", why), na("e-/s", why), na("DN/s", why)
    else:
        slope, _ = _fit_line(dt, dmu)
        q_im_dn = Quantity.of(slope, "DN/s")
        q_im_e = na("e-/s", why_K) if K is None else Quantity.of(slope / K, "e-/s")
        ok = np.isfinite(dvar)
        if ok.sum() < 2 or np.unique(dt[ok]).size < 2:
            why = "dark temporal variance known at fewer than two exposure times"
            q_iv_e, q_iv_dn = na("e-/s", why), na("DN/s", why)
        else:
            vs, _ = _fit_line(dt[ok], dvar[ok])
            if vs < 0:
                why = f"dark variance decreases with exposure time (slope {vs:.4g} DN^2/s)"
                q_iv_e, q_iv_dn = na("e-/s", why), na("DN/s", why)
            elif K is None:
                q_iv_e, q_iv_dn = na("e-/s", why_K), na("DN/s", why_K)
            else:
                q_iv_e, q_iv_dn = Quantity.of(vs / K ** 2, "e-/s"), Quantity.of(vs / K, "DN/s")

    # ---------------------------------------------------------------- spatial
    sp_dark = next((s for s in stats if s.kind == "dark" and s.mean_map is not None), None)
    sp_bright = next((s for s in stats if s.kind == "bright" and s.mean_map is not None), None)
    spectrograms: dict = {}
    histograms: dict = {}
    spatial_frames = {k: None if p is None else {"frames": p.n_frames, "exposure_s": p.exposure_s,
                                                 "shape": list(p.mean_map.shape)}
                      for k, p in (("dark", sp_dark), ("bright", sp_bright))}
    gains = _highpass_noise_gains() if illumination_correction else (1.0, 1.0)
    prep = _highpass if illumination_correction else (lambda im: im)
    if illumination_correction:
        notes.append("spatial evaluation on high-pass filtered averages (R4.0 Sec. 8.1 uneven-illumination "
                     f"correction; residual temporal variances scaled by the filter gains {gains[0]:.4f} per "
                     f"pixel, {gains[1]:.4f} per row/column mean)")
    kk = 1.0 / K if K is not None else math.nan
    comps = ("total", "row", "column", "pixel")
    if sp_dark is None:
        why = "no dark operating point with two or more frames for the spatial evaluation"
        dsnu_e, dsnu_dn = _na_split("e-", why), _na_split("DN", why)
        vd = None
    else:
        dimg = prep(sp_dark.mean_map)
        vd = _spatial_variances(dimg, sp_dark.var_stack, sp_dark.n_frames, gains)
        vd["mean"] = sp_dark.mean
        dsnu_dn = NonUniformity(*(_sqrt_q(vd[c], 1.0, "DN", f"DSNU {c}") for c in comps), vd)
        if K is None:
            dsnu_e = _na_split("e-", why_K)
        else:
            dsnu_e = NonUniformity(*(_sqrt_q(vd[c], kk, "e-", f"DSNU {c}") for c in comps), vd)
        unit, scale = ("e-", kk) if K is not None else ("DN", 1.0)
        total = (dsnu_e if K is not None else dsnu_dn).total.value
        for direction in ("horizontal", "vertical"):
            spectrograms[f"dsnu_{direction}"] = _spectrogram(
                dimg, direction, scale, unit, vd["residual_gain"] * vd["stack"] / vd["L"], total,
                math.sqrt(sp_dark.var_stack) * scale, math.sqrt(vd["measured"]) * scale)
        grid = None if illumination_correction else _grid_step(sp_dark.mean_map, sp_dark.n_frames)
        histograms["dsnu"] = _histogram("dsnu", dimg - dimg.mean(), unit, histogram_bins,
                                        threshold_multiples, scale, grid)
    if sp_bright is None or sp_dark is None:
        why = ("no bright operating point with two or more frames for the spatial evaluation"
               if sp_bright is None else "no dark spatial point to subtract")
        prnu = _na_split("%", why)
    elif sp_bright.mean_map.shape != sp_dark.mean_map.shape:
        prnu = _na_split("%", "bright and dark spatial points have different frame shapes")
    else:
        if not math.isclose(sp_bright.exposure_s, sp_dark.exposure_s, rel_tol=1e-6):
            notes.append(f"spatial dark point exposure {sp_dark.exposure_s:g} s differs from the "
                         f"bright one {sp_bright.exposure_s:g} s")
        bimg = prep(sp_bright.mean_map)
        vb = _spatial_variances(bimg, sp_bright.var_stack, sp_bright.n_frames, gains)
        denom = sp_bright.mean - sp_dark.mean
        if denom <= 0:
            prnu = _na_split("%", f"bright spatial mean minus dark mean = {denom:.4g} DN is not positive")
        else:
            diff = {c: vb[c] - vd[c] for c in comps}
            prnu = NonUniformity(*(_sqrt_q(diff[c], 100.0 / denom, "%", f"PRNU {c}") for c in comps),
                                 {"bright": vb, "dark": vd})
            img = bimg - dimg
            floor = vb["residual_gain"] * (vb["stack"] / vb["L"] + vd["stack"] / vd["L"])
            for direction in ("horizontal", "vertical"):
                spectrograms[f"prnu_{direction}"] = _spectrogram(
                    img, direction, 100.0 / denom, "%", floor, prnu.total.value,
                    math.sqrt(sp_bright.var_stack) * 100.0 / denom,
                    math.sqrt(max(vb["measured"] - vd["measured"], 0.0)) * 100.0 / denom)
            grid = None
            if not illumination_correction and sp_bright.n_frames == sp_dark.n_frames:
                grid = _grid_step(img, sp_bright.n_frames)
            histograms["prnu"] = _histogram("prnu", img - img.mean(), "%", histogram_bins,
                                            threshold_multiples, 100.0 / denom, grid)

    ptc = PhotonTransferData(texp, phot, mu_b, var, dm, dv, sat_i, None if fit_hi is None else (0, fit_hi),
                             lin_idx, lin_dev, lin_fit, dt, dmu, dvar)
    return ChannelResult(
        channel, q_K, q_iK, q_fit, q_sd_dn, q_sd_e, q_R, q_eta, q_ssat, q_psat, q_esat,
        q_snr, q_snr_db, q_snr_b, q_pmin, q_emin, q_dr, q_dr_db, q_dr_b, q_lmin, q_lmax, q_le,
        q_im_e, q_im_dn, q_iv_e, q_iv_dn, dsnu_e, dsnu_dn, prnu, spectrograms, histograms, ptc,
        spatial_frames, tuple(notes))


def frames_of(stack: np.ndarray) -> Iterator[np.ndarray]:
    """Yield the frames of an (n, H, W) array one by one (a convenience for in-memory data)."""
    for i in range(stack.shape[0]):
        yield stack[i]
