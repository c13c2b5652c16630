"""Residual diagnostics of the calibration loop.

Each diagnostic maps a capture (dark / flat / scene frame stacks in DN) to one
number. The loop computes it on the measured frames and on frames simulated
from the current model (same shapes and frame counts) and standardises the
difference (:func:`discrepancy`). Names, the effect each one points to (as the
effects' cards in :mod:`simcam.calibration.effects` declare it), and the
statistic (EMVA 1288 R4.0 sec. 8 for the spatial split, ELD/Wei et al. 2020
for row noise and Tukey-lambda PPCC):

======================  ==================  =====================================================
diagnostic              effect              statistic
======================  ==================  =====================================================
ptc_curvature           nonlinearity        quadratic / linear coefficient of variance vs mean
plane_gain_spread       channel_gain        std / mean of the per-CFA-plane photon-transfer slopes
row_mean_excess         row_noise           var(row means of temporal residual) / (pixel var / W)
row_spectrum_peak       periodic_pattern    max / median of the periodogram of row means
                                            (per frame / its median; mean over frames / its
                                            9-bin running median)
col_spectrum_peak       periodic_pattern    same along columns
col_temporal_excess     empirical_offset    var(column means of temporal residual) / (pixel var / H)
row_mean_lag1           empirical_spectrum  lag-1 autocorrelation of the row means of the dark temporal
                                            residual along the rows (frame mean removed), pooled over
                                            frames: 0 for white row noise, > 0 for offsets that wander
                                            from row to row (1/f)
dark_checker_jitter     (none)              log of: var over dark frames of the checkerboard contrast
                                            of the temporal residual (sites 00 + 11 - 01 - 10) /
                                            (pixel var / pixels)
col_fpn_excess          column_fpn          cov(column means of even- and odd-frame dark mean maps) /
                                            (map var / H)
col_fpn_spectrum_peak   empirical_lines     max / median of the periodogram of the mean of those two
                                            column profiles (a periodic fixed column pattern), as the
                                            normal quantile of its tail under white noise
flat_col_spectrum_peak  empirical_lines     the same of the flats' even/odd-frame column profiles less
                                            the darks', per unit of signal (a periodic column gain)
dsnu_excess             dsnu                5-sigma-clipped var of the dark mean map (rows/cols removed) /
                                            (temporal var with rows/cols removed / n)
hot_pixel_tail          hot_pixels          fraction of pixels whose dark temporal median is
                                            > 6 robust sigma (persistent outliers)
telegraph_pixels        rtn                 fraction of pixels whose dark frames sit on two levels
                                            >= 5 read-noise sigma apart, each as tight as the read
                                            noise (>= 2 frames on each: switching)
prnu_excess             prnu                per plane (even/odd flat-map covariance - same of the
                                            darks) / signal^2, mean over planes
flat_spread_growth      empirical_response  relative fixed-pattern variance of the brightest flat minus
                                            that of a dimmer one at 10-80 % of its signal (a gain's is
                                            the same at every level; a per-pixel response curvature's
                                            grows with the signal squared)
black_offset            black_level_offset  median of dark mean map - declared black (DN)
dark_signal_slope       dark_current        least-squares slope of the dark level (1 %-trimmed mean of
                                            each sequence's temporal-mean image: hot pixels left out)
                                            against exposure time, darks at every exposure time (DN/s)
dark_variance_slope     dark_current        least-squares slope of the dark temporal variance (1 %-trimmed
                                            mean over pixels, frame means removed) against exposure time
                                            (DN^2/s; EMVA 1288's variance method)
frame_mean_jitter       frame_flicker       frame-to-frame var of flat frame means (from their successive
                                            differences about their mean) / signal^2
frame_mean_drift        empirical_offset    log(var of frame means / half their mean square successive
                                            difference), darks and flats (a level drifting over frames)
dark_frame_jitter       empirical_offset    var of dark frame means / what rows, columns and pixels put
                                            there, - 1 (a black level moving from frame to frame)
dark_tail_mass          heavy_tail_read     fraction of dark residuals beyond 4 IQR-sigma
dark_ppcc_lambda        heavy_tail_read     Tukey-lambda shape maximising the PPCC of dark residuals
code_occupancy          quantization        used / possible integer codes in the central 98 % of darks
                                            (of the dimmest flat where the darks sit on one code)
code_width_spread       adc_dnl             relative spread of the ADC's code widths: histogram of the
                                            codes of darks and flats (those spread over >= 3
                                            codes), each code's count against a local quadratic
                                            through its 6 neighbours, Poisson part taken off
                                            (IEEE Std 1241-2010 histogram test of DNL)
lag1_corr / lag2_corr   spatial_correlation lag-1 / lag-2 autocorrelation inside each CFA plane
adjacent_corr           spatial_correlation lag-1 autocorrelation on the mosaic (adjacent pixels)
flat_adjacent_corr      charge_crosstalk    the same on the flats' temporal residuals (shot noise
                                            shared between adjacent pixels)
glow_field              amp_glow            largest t-value of a smooth field rising to a corner or an
                                            edge in the per-pixel dark slope map (DN/s), darks at
                                            every exposure time (:func:`glow_field`)
======================  ==================  =====================================================

The temporal residual is a frame minus the per-pixel mean of its sequence,
with each frame's row and column means removed where a statistic should not
see row/column noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import median_filter
from scipy import fft as sfft
from scipy import stats as sst
from scipy.special import ndtri_exp

from .emva1288 import DARK_VARIANCE_FLOOR_DN2
from .pixelwise import RTN_GAP_SIGMA, RTN_LEVEL_VAR, median_box, temporal_median, two_level_splits

PLANE_OFFSETS = ((0, 0), (0, 1), (1, 0), (1, 1))

#: The battery, in report order. The effect each one proposes is on the effect's card
#: (``EffectCard.diagnostics``, :mod:`simcam.calibration.effects`); a diagnostic no card claims
#: (``dark_checker_jitter``) proposes none; ``col_temporal_excess``, ``frame_mean_drift``, ``dark_frame_jitter``,
#: ``col_fpn_spectrum_peak``, ``flat_col_spectrum_peak``, ``row_mean_lag1`` and ``flat_spread_growth`` propose
#: empirical components.
DIAGNOSTICS = (
    "ptc_curvature", "plane_gain_spread", "row_mean_excess", "row_spectrum_peak", "col_spectrum_peak",
    "col_temporal_excess", "row_mean_lag1", "dark_checker_jitter", "col_fpn_excess", "col_fpn_spectrum_peak",
    "flat_col_spectrum_peak", "dsnu_excess",
    "hot_pixel_tail", "prnu_excess", "flat_spread_growth",
    "black_offset", "dark_signal_slope", "dark_variance_slope", "frame_mean_jitter", "frame_mean_drift",
    "dark_frame_jitter", "dark_tail_mass", "dark_ppcc_lambda", "code_occupancy", "lag1_corr",
    "lag2_corr", "defect_pixels", "glow_field",
    "telegraph_pixels", "code_width_spread", "dark_code_split", "adjacent_corr", "flat_adjacent_corr",
    "frame_spectrum_peak",
)

#: The bootstrap null of the diagnostic on the left is not valid while one on the right is
#: significant and outside the vocabulary (so absent from every simulation): temporal column
#: noise leaves the even/odd-frame covariance of column profiles unbiased but inflates its spread,
#: which the simulated captures then understate. Such a diagnostic is reported, not attributed.
NULL_NEEDS = {
    "col_fpn_excess": ("col_temporal_excess",),
}


class NotApplicable(Exception):
    """Raised by a statistic that is undefined on the data; its message is the reason the report gives."""


#: Reason reported when a statistic returns None: what it needs and the capture set lacks.
NEEDS = {
    "ptc_curvature": "needs >= 3 flat sequences, or darks and >= 2 flats",
    "plane_gain_spread": "needs a CFA sensor and flats (with darks, or >= 2 flats)",
    "row_mean_excess": "needs a dark or flat sequence",
    "col_temporal_excess": "needs a dark or flat sequence",
    "row_mean_lag1": "needs a dark sequence of >= 2 frames and >= 4 rows",
    "row_spectrum_peak": "needs a dark or flat sequence",
    "col_spectrum_peak": "needs a dark or flat sequence",
    "dark_checker_jitter": "needs a dark sequence",
    "col_fpn_excess": "needs a dark or flat sequence",
    "col_fpn_spectrum_peak": "needs a dark or flat sequence",
    "flat_col_spectrum_peak": "needs a dark sequence and a flat sequence of >= 2 frames",
    "dsnu_excess": "needs a dark sequence",
    "hot_pixel_tail": "needs a dark sequence",
    "prnu_excess": "needs a flat sequence",
    "flat_spread_growth": "needs flat sequences of >= 2 frames at two levels, the dimmer at 10-80 % of the brighter",
    "black_offset": "needs a dark sequence and a declared black level",
    "dark_signal_slope": "needs darks at >= 2 exposure times",
    "frame_mean_jitter": "needs a flat sequence",
    "frame_mean_drift": "needs a dark or flat sequence of >= 4 frames",
    "dark_frame_jitter": "needs a dark sequence",
    "dark_variance_slope": "needs darks of >= 2 frames at >= 2 exposure times",
    "dark_tail_mass": "needs a dark sequence",
    "dark_ppcc_lambda": "needs a dark sequence",
    "code_occupancy": "needs a dark or flat sequence",
    "code_width_spread": "needs a dark or flat sequence",
    "dark_code_split": "needs a dark sequence and a declared black level",
    "lag1_corr": "needs a dark sequence",
    "lag2_corr": "needs a dark sequence",
    "adjacent_corr": "needs a dark sequence",
    "flat_adjacent_corr": "needs a flat sequence",
    "defect_pixels": "needs a flat sequence (and darks or a declared black level)",
    "telegraph_pixels": "needs a dark sequence",
    "glow_field": "needs darks at >= 2 exposure times",
    "frame_spectrum_peak": "needs a dark or flat sequence",
}


def _ratio(num: float, den: float, what: str) -> float:
    """num / den, or :class:`NotApplicable` naming ``what`` when the denominator is zero or not finite."""
    den = float(den)
    if not np.isfinite(den) or den <= 0.0:
        raise NotApplicable(f"{what} is {den:g} (constant or quantisation-dominated data)")
    return float(num) / den


@dataclass
class CaptureData:
    """Frames of one ISO group as the diagnostics see them (DN, float32).

    ``darks``/``flats``: lists of (n, H, W); ``scenes``: list of ((n, H, W), clean or None);
    ``black_dn`` (2, 2) declared black or None; ``cfa`` pattern or None (mono).
    ``darks`` are those of one exposure time (the shortest); ``dark_series``: (exposure_s, frames) of
    the darks at every exposure time when there are >= 2 of them (dark current), else None.
    """

    darks: list
    flats: list
    scenes: list
    black_dn: np.ndarray | None
    white_dn: float
    cfa: str | None
    cache: dict = field(default_factory=dict)
    dark_series: list | None = None
    #: a simulated capture of the loop's bootstrap (:meth:`like`), not measured frames
    simulated: bool = False

    def cached(self, key, compute):
        """``compute()`` once per capture under ``key``; a :class:`NotApplicable` it raised is kept too
        and raised again on each call."""
        if key not in self.cache:
            try:
                self.cache[key] = compute()
            except NotApplicable as exc:
                self.cache[key] = exc
        if isinstance(self.cache[key], NotApplicable):
            raise self.cache[key]
        return self.cache[key]

    def profile_free_dark_variance(self) -> float:
        """:func:`profile_free_temporal_variance` of the darks (cached)."""
        if "pf_var" not in self.cache:
            self.cache["pf_var"] = profile_free_temporal_variance(self.darks)
        return self.cache["pf_var"]

    def like(self, frames: list, specs: list) -> "CaptureData":
        """A capture with this one's structure (black, white, CFA) holding ``frames``, one (n, H, W) stack
        per sequence of ``specs`` (``SimSpec``: kind; a scene's clean reference is its ``signal_dn``
        unless ``fixed_in_clean``): simulated captures as the diagnostics see them."""
        darks, flats, scenes, series = [], [], [], []
        for sp, f in zip(specs, frames, strict=True):
            if sp.kind == "dark":
                series.append((sp.exposure_s, f))
                if not sp.series_only:
                    darks.append(f)
            elif sp.kind == "flat":
                flats.append(f)
            else:
                scenes.append((f, None if sp.fixed_in_clean else sp.signal_dn))
        return CaptureData(darks, flats, scenes, self.black_dn, self.white_dn, self.cfa,
                           dark_series=series if self.dark_series is not None else None, simulated=True)

    # ---- shared intermediates (cached) ---------------------------------
    def temporal_residuals(self, which: str) -> list[np.ndarray]:
        """Frame minus per-pixel sequence mean, scaled by sqrt(n/(n-1)) (unit-variance preserving)."""
        key = ("res", which)
        if which == "all":  # the dark and flat residuals, not a second copy
            return self.temporal_residuals("dark") + self.temporal_residuals("flat")
        if key not in self.cache:
            seqs = self.darks if which == "dark" else self.flats
            out = []
            for f in seqs:
                f64 = f.astype(np.float64)
                n = f.shape[0]
                out.append((f64 - f64.mean(0)) * np.sqrt(n / (n - 1)))
            self.cache[key] = out
        return self.cache[key]

    def dark_map(self) -> tuple[np.ndarray, float, int] | None:
        """(mean map over all dark frames, mean temporal variance, frame count)."""
        if "dmap" not in self.cache:
            if not self.darks:
                self.cache["dmap"] = None
            else:
                allf = np.concatenate(self.darks).astype(np.float64)
                m = allf.mean(0)
                vt = float(np.mean([np.mean(np.var(d.astype(np.float64), axis=0, ddof=1)) for d in self.darks]))
                self.cache["dmap"] = (m, vt, allf.shape[0])
        return self.cache["dmap"]

    def dark_profile_free_map(self) -> np.ndarray | None:
        """:func:`remove_profiles` of the dark mean map (cached): what the DSNU and hot-pixel statistics read."""
        if "dmap_pf" not in self.cache:
            dm = self.dark_map()
            self.cache["dmap_pf"] = None if dm is None else remove_profiles(dm[0])
            if dm is not None:
                self.cache["dmap_pf"].flags.writeable = False  # shared by its readers
        return self.cache["dmap_pf"]

    def flat_map(self) -> tuple[np.ndarray, float, int] | None:
        """Mean map of the flat with the most frames (the brightest among equals), its temporal
        variance and frame count."""
        if "fmap" not in self.cache:
            if not self.flats:
                self.cache["fmap"] = None
            else:
                f = max(self.flats, key=lambda a: (a.shape[0], float(a.mean()))).astype(np.float64)
                self.cache["fmap"] = (f.mean(0), float(np.mean(np.var(f, axis=0, ddof=1))), f.shape[0])
        return self.cache["fmap"]

    def frame_means(self, kind: str) -> list[np.ndarray]:
        """Each frame's mean (float64), per dark (``kind="dark"``) or flat sequence."""
        key = f"fmeans_{kind}"
        if key not in self.cache:
            seqs = self.darks if kind == "dark" else self.flats
            self.cache[key] = [f.astype(np.float64).mean(axis=(1, 2)) for f in seqs]
        return self.cache[key]

    def flat_levels(self, black_dn) -> np.ndarray:
        """(flats, 4) per-plane flat means above the darks' per-plane mean (above ``black_dn``, per site,
        without darks): the photon-transfer points' signal."""
        darks, flats = self.ptc_points()
        mu0 = np.mean([p[:, 0] for p in darks], axis=0) if darks else np.asarray(black_dn, np.float64).ravel()
        return np.array([f[:, 0] for f in flats]) - mu0

    def ptc_points(self):
        """Per plane (mean, temporal var) of each dark and flat sequence (frame means removed)."""
        if "ptc" not in self.cache:
            def mv(f):
                out = []
                for dy, dx in PLANE_OFFSETS:
                    p = f[:, dy::2, dx::2].astype(np.float64)
                    fm = p.mean(axis=(1, 2), keepdims=True)
                    out.append((float(fm.mean()), float(np.mean(np.var(p - fm, axis=0, ddof=1)))))
                return np.array(out)
            self.cache["ptc"] = ([mv(d) for d in self.darks], [mv(f) for f in self.flats])
        return self.cache["ptc"]

    def ptc_dof(self) -> tuple[np.ndarray, np.ndarray]:
        """Degrees of freedom of each dark's and flat's per-plane temporal variance in :meth:`ptc_points`:
        (frames - 1) per pixel of a plane, the plane's pixels pooled."""
        def dof(seqs):
            return np.array([(s.shape[0] - 1) * ((s.shape[1] + 1) // 2) * ((s.shape[2] + 1) // 2) for s in seqs],
                            dtype=np.float64)
        return dof(self.darks), dof(self.flats)


def plane_medians(m: np.ndarray) -> np.ndarray:
    """Each 2x2-site plane's median, as a map of ``m``'s shape (``m``'s float dtype, else float64)."""
    out = np.empty(m.shape, dtype=m.dtype if np.issubdtype(m.dtype, np.floating) else np.float64)
    for dy, dx in PLANE_OFFSETS:
        out[dy::2, dx::2] = np.median(m[dy::2, dx::2])
    return out


def plane_centre(m: np.ndarray) -> np.ndarray:
    """Subtract each 2x2-site plane's median."""
    return m - plane_medians(m)


def robust_sigma(x: np.ndarray, med=None) -> float:
    """1.4826 * MAD (sigma of a Gaussian); ``med``: ``x``'s median where the caller has it already."""
    if med is None:
        med = np.median(x)
    return float(1.4826 * np.median(np.abs(x - med)))


#: half-width of :func:`clipped_variance`'s window, in robust sigmas
CLIP_SIGMA = 5.0


def clipped_variance(x: np.ndarray) -> float:
    """Variance of the values within :data:`CLIP_SIGMA` robust sigmas (:func:`robust_sigma`; the SD when the
    MAD is 0) of the median. Outliers (hot pixels) are left out as by the MAD, but unlike the MAD it moves
    continuously with the spread of coarsely quantised values: the temporal mean of n integer codes sits on a
    lattice of 1/n DN, where the MAD stays on one lattice step while the spread changes. For a Gaussian it is
    0.99998 of the variance (5-sigma truncation)."""
    x = np.asarray(x, dtype=np.float64).ravel()
    med = float(np.median(x))
    s = robust_sigma(x)
    if s <= 0:
        s = float(np.std(x))
    return float(np.var(x[np.abs(x - med) <= CLIP_SIGMA * s]))


def profile_free_temporal_variance(darks) -> float:
    """Temporal variance per pixel (DN^2) of dark sequences ``(n, H, W)`` once each frame's deviation
    from its sequence mean has lost its per-plane, per-row and per-column means: the temporal noise
    that is still in a mean map after :func:`~simcam.calibration.diagnostics.remove_profiles`.

    Parameters
    ----------
    darks : sequence of ndarray
        Dark sequences, each ``(n, H, W)`` with n >= 2 (DN).

    Returns
    -------
    float
        Pooled over the sequences (weights n - 1).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> white = rng.normal(0, 2.0, (8, 64, 64))
    >>> rows = rng.normal(0, 3.0, (8, 64, 1))  # row noise: shared along each row
    >>> round(profile_free_temporal_variance([white + rows]), 1)  # only the white part is left
    3.9
    """
    num = dof = 0.0
    for seq in darks:
        e = np.asarray(seq, dtype=np.float64)
        if e.shape[0] < 2:
            continue
        e = e - e.mean(0)
        for dy, dx in PLANE_OFFSETS:
            e[:, dy::2, dx::2] -= e[:, dy::2, dx::2].mean(axis=(1, 2), keepdims=True)
        e -= e.mean(axis=2, keepdims=True)
        e -= e.mean(axis=1, keepdims=True)
        num += float(np.sum(e * e)) / (e.shape[1] * e.shape[2])
        dof += e.shape[0] - 1
    return num / dof if dof else 0.0


def remove_profiles(m: np.ndarray) -> np.ndarray:
    """Map minus its per-plane median, then minus robust (median) row and column profiles."""
    r = plane_centre(m)
    r = r - np.median(r, axis=1, keepdims=True)
    r = r - np.median(r, axis=0, keepdims=True)
    return r


def _clip_robust(m: np.ndarray, k: float = 5.0) -> np.ndarray:
    s = robust_sigma(m)
    return np.clip(m, -k * s, k * s)


# ------------------------------------------------------------------ statistics

def ptc_curvature(d: CaptureData):
    """Curvature of the photon-transfer curve (temporal variance against mean above the dark level) per CFA
    plane, relative to its slope: the quadratic coefficient times the highest level over the linear one,
    averaged over the planes. The darks are a point of the curve (mean 0, the read variance), so darks and
    two flat levels already give the three points a curvature needs (an EMVA 1288-style set with two
    illuminations).

    Quantisation-limited darks (temporal variance below 0.24 step^2, the step read off the used codes,
    :func:`adc_step`) are not a point of the curve: their variance is set by where the code edges around
    the black level lie (a differential non-linearity moves it as much as the read noise does), the regime
    where Sheppard's ``step^2 / 12`` correction does not hold. 0.24 DN^2 is the EMVA 1288 Release 4.0
    Linear standard's floor for the temporal dark variance (eqs. 53-54: below it the dark noise
    is not measured, only bounded), here in units of the code width. The curvature then comes from three
    flat levels or more, else it is not applicable."""
    darks, flats = d.ptc_points()
    mu0 = np.mean([p[:, 0] for p in darks], axis=0) if darks else np.zeros(4)
    if darks and np.mean([p[:, 1] for p in darks]) < DARK_VARIANCE_FLOOR_DN2 * adc_step(d) ** 2:
        if len(flats) < 3:
            raise NotApplicable("the darks are quantisation-limited (temporal variance below 0.24 step^2, "
                                "EMVA 1288) and fewer than 3 flat levels are left for the curvature")
        darks = []
    if len(flats) + (1 if darks else 0) < 3:
        return None
    pts = np.array(darks + flats)  # (m, 4, 2)
    t = []
    for c in range(4):
        x = pts[:, c, 0] - mu0[c]
        y = pts[:, c, 1]
        if np.unique(x).size < 3:
            raise NotApplicable("fewer than 3 distinct flat levels on a CFA plane")
        c2, c1, _c0 = np.polyfit(x, y, 2)
        t.append(_ratio(c2 * x.max(), c1, "the photon-transfer slope"))
    return float(np.mean(t))


def plane_slopes(d: CaptureData) -> np.ndarray | None:
    """Per CFA plane, the photon-transfer slope (temporal variance against mean, DN) of the flats.

    With darks: the weighted least-squares line through the dark point, each flat weighted by the inverse of
    its variance estimate's sampling variance, ``2 V^2 / dof`` (its own and the dark point's; V from the
    unweighted line): a flat's variance has the same *relative* error at every level, so an unweighted fit
    would take its slope from the brightest flat alone. Without darks: the unweighted line through the
    flats."""
    darks, flats = d.ptc_points()
    if len(flats) < 1:
        return None
    if darks:
        mu0 = np.mean([p[:, 0] for p in darks], axis=0)
        v0 = np.mean([p[:, 1] for p in darks], axis=0)
        X = np.array([f[:, 0] for f in flats]) - mu0
        Y = np.array([f[:, 1] for f in flats]) - v0
        k = (X * Y).sum(0) / (X * X).sum(0)
        # the weights from the line's variances, not the measured ones (which would favour the flats whose
        # variance came out low and bias the slope down)
        dof_darks, dof_flats = d.ptc_dof()
        v = np.maximum(v0 + k * X, 1e-12)
        w = 1.0 / (v ** 2 / np.maximum(dof_flats, 1.0)[:, None] + v0 ** 2 / max(float(np.sum(dof_darks)), 1.0))
        return (w * X * Y).sum(0) / (w * X * X).sum(0)
    if len(flats) < 2:
        return None
    return np.array([np.polyfit([f[c, 0] for f in flats], [f[c, 1] for f in flats], 1)[0] for c in range(4)])


def plane_gain_spread(d: CaptureData):
    if d.cfa is None:
        return None
    k = plane_slopes(d)
    return None if k is None else _ratio(np.std(k), np.mean(k), "the mean photon-transfer slope")


def _line_means(which: str, axis: int, d: CaptureData) -> list[np.ndarray]:
    """Per frame, means along ``axis`` of the temporal residual (axis=2: row means)."""
    key = ("lm", which, axis)
    if key not in d.cache:
        d.cache[key] = [r.mean(axis=axis) for r in d.temporal_residuals(which)]
    return d.cache[key]


def _residual_vars(d: CaptureData) -> list[float]:
    """The variance of each temporal residual of ``temporal_residuals("all")`` (the darks' first), computed once."""
    if "rvar" not in d.cache:
        d.cache["rvar"] = [float(np.var(r)) for r in d.temporal_residuals("all")]
    return d.cache["rvar"]


def _excess(d: CaptureData, axis: int):
    res = d.temporal_residuals("all")
    if not res:
        return None
    lm = _line_means("all", axis, d)
    vals = []
    for r, m, v in zip(res, lm, _residual_vars(d)):
        npx = r.shape[axis]
        vals.append(_ratio(np.var(m, axis=1).mean(), v / npx, "the temporal residual's variance"))
    return float(np.mean(vals))


def dark_frame_levels(d: CaptureData) -> list[tuple[np.ndarray, float]]:
    """Per dark sequence of >= 3 frames: its frames' means of the temporal residual (about the sequence's
    mean, unit-variance preserving: their mean square is the frame level's variance) and what the rows,
    columns and pixels put into one frame mean, ``var(row means) / H + var(column means) / W - var / (H W)``
    (each line's means about the frame's mean, averaged over the frames; the pixels' share is in both line
    terms, so it is taken off once). The row and column means are those ``row_mean_excess`` and
    ``col_temporal_excess`` take (:func:`_line_means`)."""
    if "dframes" not in d.cache:
        out = []
        darks = d.temporal_residuals("dark")
        if darks:
            rows, cols, var = _line_means("all", 2, d), _line_means("all", 1, d), _residual_vars(d)
            for r, rm, cm, v in zip(darks, rows, cols, var):  # the darks come first in "all"
                n, h, w = r.shape
                if n < 3:
                    continue
                white = float(np.var(rm, axis=1).mean()) / h + float(np.var(cm, axis=1).mean()) / w - v / (h * w)
                out.append((rm.mean(axis=1), white))
        d.cache["dframes"] = out
    return d.cache["dframes"]


def dark_frame_jitter(d: CaptureData):
    """The dark frames' level variance over what the rows, columns and pixels put there, less 1, averaged
    over the dark sequences (:func:`dark_frame_levels`): 0 when a frame's level moves only by its own
    noise, positive for a black level that moves from frame to frame (a clamp or reference that wanders;
    in the darks, so not flicker, which needs light)."""
    if not d.darks:
        return None
    vals = [float(np.mean(fm * fm)) / white - 1.0 for fm, white in dark_frame_levels(d) if white > 0]
    if not vals:
        raise NotApplicable("no dark sequence of >= 3 frames with a temporal noise")
    return float(np.mean(vals))


def row_mean_excess(d):
    return _excess(d, 2)


def col_temporal_excess(d):
    return _excess(d, 1)


def row_mean_lag1(d: CaptureData):
    """Lag-1 autocorrelation along the rows of the dark temporal residual's row means (each frame's mean
    removed), pooled over frames: ``sum m_i m_(i+1) / sum m_i^2``. White row noise and pixel noise give 0
    (less 1/H); row offsets that wander slowly from row to row (1/f noise of the row reference) give a
    positive value, an offset alternating between the two kinds of CFA row a negative one. Darks only: in
    a flat, a per-frame gain times the flat's shading is a smooth row profile too. The row means are those
    ``row_mean_excess`` already took (:func:`_line_means` of all residuals, the darks' first)."""
    darks = d.temporal_residuals("dark")
    means = [m for r, m in zip(darks, _line_means("all", 2, d)) if r.shape[0] >= 2 and r.shape[1] >= 4]
    if not means:
        return None
    num = den = 0.0
    for m in means:
        m = m - m.mean(axis=1, keepdims=True)
        num += float(np.sum(m[:, 1:] * m[:, :-1]))
        den += float(np.sum(m * m))
    return _ratio(num, den, "the variance of the dark row means")


def dark_checker_jitter(d: CaptureData):
    """Per-frame offset alternating between the 2x2 sites in a checkerboard (00, 11 vs 01, 10), from
    the dark temporal residuals: the variance over frames of the residual's checkerboard-weighted
    mean over its white-noise expectation (pixel variance / pixel count; 1 for white noise).
    Row offsets (row noise, periodic patterns), column offsets and frame offsets cancel in this
    contrast, flicker needs light; what raises it is a per-frame offset between interleaved
    readout channels -- outside the effect vocabulary, so it is reported, not attributed."""
    res = d.temporal_residuals("dark")
    if not res:
        return None
    vals = []
    for r in res:
        h, w = r.shape[1:]
        sign = np.ones((h, w))
        sign[0::2, 1::2] = -1.0
        sign[1::2, 0::2] = -1.0
        c = np.einsum("fyx,yx->f", r, sign) / (h * w)
        vals.append(_ratio(np.mean(c * c), float(np.var(r)) / (h * w), "the dark temporal residual's variance"))
    # a mean of a few chi-square(1) terms is skewed (the bootstrap's normal approximation would
    # understate its right tail); its logarithm is close to symmetric
    m = float(np.mean(vals))
    if m <= 0:
        raise NotApplicable("the checkerboard contrast of the dark residuals is exactly 0 in every frame")
    return float(np.log(m))


def periodogram(d: CaptureData, axis: int) -> np.ndarray | None:
    lm = _line_means("all", axis, d)
    if not lm:
        return None
    ps = [np.abs(np.fft.rfft(m - m.mean(axis=1, keepdims=True), axis=1)) ** 2 for m in lm]
    return np.concatenate(ps).mean(0)


#: running-median width (bins) of the broadband spectral shape divided out of the periodogram.
SPECTRUM_SMOOTH_BINS = 9


def whitened_periodogram(d: CaptureData, axis: int) -> np.ndarray | None:
    """Mean over frames of each frame's periodogram divided by its own median (so dark frames,
    where a weak pattern stands out, are not drowned by the shot noise of flats), then divided by
    its running median over ``SPECTRUM_SMOOTH_BINS`` bins: a broadband colour (in-plane
    crosstalk, a low-pass row noise) is divided out and only narrow lines stand out."""
    key = ("wp", axis)
    if key not in d.cache:
        lm = _line_means("all", axis, d)
        if not lm:
            d.cache[key] = None
        else:
            ps = [np.abs(np.fft.rfft(m - m.mean(axis=1, keepdims=True), axis=1)) ** 2 for m in lm]
            meds = [np.median(p[:, 1:], axis=1, keepdims=True) for p in ps]
            if ps[0].shape[1] < 4 or any(np.any(m <= 0) for m in meds):
                d.cache[key] = NotApplicable("the periodogram of line means has a zero median (constant lines) "
                                             "or fewer than 3 frequencies")
                return d.cache[key]
            ps = [p / m for p, m in zip(ps, meds)]
            mean = np.concatenate(ps).mean(0)
            smooth = median_filter(mean[1:], size=SPECTRUM_SMOOTH_BINS, mode="nearest")
            if np.any(smooth <= 0):
                d.cache[key] = NotApplicable("the smoothed periodogram of line means has empty bins")
                return d.cache[key]
            mean[1:] /= smooth
            d.cache[key] = mean
    return d.cache[key]


def _peak(d, axis):
    p = whitened_periodogram(d, axis)
    if p is None:
        return None
    if isinstance(p, NotApplicable):
        raise p
    p = p[1:]
    return _ratio(p.max(), np.median(p), "the median of the whitened periodogram")


def row_spectrum_peak(d):
    return _peak(d, 2)


def col_spectrum_peak(d):
    return _peak(d, 1)


#: side of the square blocks the 2-D spectrum is averaged over (the side of the tiles of an analysed mosaic,
#: :mod:`simcam.calibration.region`, so a block never straddles a seam)
SPECTRUM_BLOCK_PX = 128
#: bins of the 2-D running median that divides out a broadband colour of the 2-D spectrum
SPECTRUM2D_SMOOTH_BINS = 5


def spectrum_blocks(d: CaptureData) -> tuple[list[np.ndarray], int] | None:
    """The temporal residuals the 2-D spectrum reads (the darks', else the flats'), and the block side:
    :data:`SPECTRUM_BLOCK_PX`, or the frame's shorter side rounded down to a multiple of 8 when smaller."""
    res = d.temporal_residuals("dark") or d.temporal_residuals("flat")
    if not res:
        return None
    h, w = res[0].shape[1:]
    side = min(SPECTRUM_BLOCK_PX, h - h % 8, w - w % 8)
    if side < 32:
        raise NotApplicable(f"frames of {h} x {w} pixels: the 2-D spectrum needs blocks of at least 32 x 32")
    return res, side


def iter_blocks(res: list[np.ndarray], side: int):
    """``side`` x ``side`` blocks of every residual stack on a grid from the top-left corner, each (n, side,
    side) with every frame's block mean removed."""
    for r in res:
        h, w = r.shape[1:]
        for y0 in range(0, h - side + 1, side):
            for x0 in range(0, w - side + 1, side):
                blk = r[:, y0:y0 + side, x0:x0 + side]
                yield blk - blk.mean(axis=(1, 2), keepdims=True)


def block_spectrum(d: CaptureData):
    """Whitened 2-D periodogram of the temporal residuals (:func:`spectrum_blocks`): each block's
    ``|FFT2|^2`` over its own median, averaged over blocks and frames, then divided by its running median
    over :data:`SPECTRUM2D_SMOOTH_BINS` x :data:`SPECTRUM2D_SMOOTH_BINS` bins (a broadband colour such as
    crosstalk divides out; narrow peaks stay). The axes and the Nyquist lines (a frequency of 0 or 1/2
    along the rows or along the columns: row and column patterns, also those that differ between the
    even and odd pixels of a CFA, the 1-D spectra's business) are set to 1 (:func:`axis_lines`). Index
    ``[ky, kx]`` in numpy's FFT order; ``side`` x ``side``."""
    key = "bs2"
    if key not in d.cache:
        sb = spectrum_blocks(d)
        if sb is None:
            d.cache[key] = None
            return None
        res, side = sb
        acc = np.zeros((side, side))
        count = 0
        half = side // 2
        flip = (-np.arange(side)) % side
        for blk in iter_blocks(res, side):
            # the real FFT in float32 (a quarter of the complex float64 one's time), the other half of the
            # periodogram from its symmetry P(ky, kx) = P(-ky, -kx)
            h = np.abs(sfft.rfft2(blk.astype(np.float32))) ** 2
            p = np.empty(blk.shape, np.float32)
            p[:, :, :half + 1] = h
            p[:, :, half + 1:] = h[:, flip, half - 1:0:-1]
            med = np.median(p.reshape(p.shape[0], -1), axis=1)
            if np.any(med <= 0):
                raise NotApplicable("a block of the residuals has a zero 2-D spectrum median (constant frames)")
            acc += (p / med[:, None, None]).sum(0)
            count += p.shape[0]
        mean = acc / count
        lines = axis_lines(side)
        mean[lines] = np.median(mean[~lines])
        smooth = median_filter(mean, size=SPECTRUM2D_SMOOTH_BINS, mode="wrap")
        if np.any(smooth <= 0):
            raise NotApplicable("the smoothed 2-D spectrum has empty bins")
        mean = mean / smooth
        mean[lines] = 1.0
        d.cache[key] = mean
        d.cache["bs2_n"] = count
    return d.cache[key]


def axis_lines(side: int) -> np.ndarray:
    """Mask of the 2-D spectrum's rows and columns at frequency 0 and 1/2 (numpy FFT order)."""
    m = np.zeros((side, side), bool)
    for k in (0, side // 2):
        m[k, :] = m[:, k] = True
    return m


def frame_spectrum_peak(d: CaptureData):
    """How far the highest line of :func:`block_spectrum` off its axes stands out, as a normal score.

    A line of a periodic pattern at an angle to the rows and columns (oblique read-out interference,
    EMVA 1288 Release 4.0 sec. 8, the 2-D spectrogram), which row and column means average away. The
    peak over the spectrum's median is the maximum of m = (bins off the axes) / 2 independent bins
    (the spectrum of real data is symmetric), each on white noise a mean of n periodogram values:
    Gamma(n, 1/n) over its median. The maximum of many such values has a long right tail (a Gumbel
    law: with 6 frames of 64 x 64 pixels the 99.9th percentile is 1.7 times the median), which the
    loop's t predictive law would take for a pattern; so the statistic is the normal score of the
    chance that the largest of m white bins exceeds the peak, ``Phi^-1(1 - P)``,
    ``P = 1 - exp(-m sf(peak))``: about N(0, 1) on white noise, large for a line. The bootstrap null
    still decides (the whitening's own running median is not in this law)."""
    p = block_spectrum(d)
    if p is None:
        return None
    n = int(d.cache["bs2_n"])
    q = p[~axis_lines(p.shape[0])]
    peak = _ratio(q.max(), np.median(q), "the median of the whitened 2-D spectrum")
    law = sst.gamma(n, scale=1.0 / n)
    x = peak * float(law.median())
    log_sf = float(law.logsf(x))
    if not math.isfinite(log_sf):  # far beyond double precision: the leading terms of Q(n, z) for z >> n
        z = n * x
        log_sf = (n - 1) * math.log(z) - z - math.lgamma(n) + math.log1p((n - 1) / z)
    log_tail = math.log(q.size / 2) + log_sf
    # log P with P = 1 - exp(-exp(log_tail)), exact where the tail is not tiny
    log_p = log_tail if log_tail < -30 else math.log(-math.expm1(-math.exp(min(log_tail, 700.0))))
    return float(-ndtri_exp(log_p))


def _parity_centred(profile: np.ndarray) -> np.ndarray:
    """A column profile less the mean of its even and of its odd columns. The planes' centring takes each
    plane's *median* off the mean map; on quantised darks (a 4-frame mean map on quarter codes) that
    median jumps by a step between two sets of frames, and the jump is a +-step/2 alternation of the
    columns, the same in all of a half's rows: it would count as a fixed column pattern (the even/odd
    covariance of one sensor's darks spread over +-2 of the white level from one choice of frames to
    another, against 0.07 in the model's replicates). A column-parity offset is the CFA sites' black
    level, not a column pattern."""
    out = profile.copy()
    out[0::2] -= out[0::2].mean()
    out[1::2] -= out[1::2].mean()
    return out


def _map_column_profile(mean_map: np.ndarray) -> tuple[np.ndarray, float, int]:
    """(column profile, variance, rows) of a temporal-mean map: plane-centred, clipped at 5 robust sigma,
    row means removed; the profile is the column means with each column parity's mean removed
    (:func:`_parity_centred`)."""
    m = _clip_robust(plane_centre(mean_map))
    m = m - m.mean(axis=1, keepdims=True)
    return _parity_centred(m.mean(axis=0)), float(np.var(m)), m.shape[0]


def _cross_periodogram(ca: np.ndarray, cb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Of two profiles of the same pattern (independent noise): the periodogram of their mean
    (``|rfft|^2``), each bin's share of their covariance (``2 Re(A_k conj(B_k)) / W^2``, 1 at 0 and W/2:
    the shares sum to the covariance) and the rfft coefficients of their mean, all from bin 1."""
    a, b = np.fft.rfft(ca - ca.mean()), np.fft.rfft(cb - cb.mean())
    w = ca.size
    share = 2.0 * np.real(a * np.conj(b)) / w ** 2
    if w % 2 == 0:
        share[-1] /= 2
    mean = (a + b) / 2
    return np.abs(mean)[1:] ** 2, share[1:], mean[1:]


def column_profiles(d: CaptureData):
    """Column profiles of the mean maps of the even and of the odd frames (darks, else the
    longest flat): plane-centred, clipped at 5 robust sigma, row means removed, each column parity's
    mean removed (:func:`_parity_centred`). Their covariance sees only the fixed column pattern
    (temporal column noise is independent between the halves)."""
    if "colprof" not in d.cache:
        stacks = d.darks or ([max(d.flats, key=lambda a: (a.shape[0], float(a.mean())))] if d.flats else [])
        if not stacks:
            d.cache["colprof"] = None
        else:
            allf = np.concatenate(stacks).astype(np.float64)
            d.cache["colprof"] = [_map_column_profile(half.mean(0)) for half in (allf[0::2], allf[1::2])]
    return d.cache["colprof"]


def col_fpn_excess(d: CaptureData):
    prof = column_profiles(d)
    if prof is None:
        return None
    (ca, va, h), (cb, vb, _) = prof
    cov = float(np.mean((ca - ca.mean()) * (cb - cb.mean())))
    return _ratio(cov, 0.5 * (va + vb) / h, "the variance of the even/odd-frame mean maps")


def column_profile_spectrum(d: CaptureData) -> tuple[np.ndarray, np.ndarray, int] | None:
    """Spectrum of the fixed column pattern, from :func:`column_profiles`: (periodogram of the mean of the
    even- and odd-frame profiles, ``|rfft|^2``; cross-periodogram of the two as each bin's share of
    their covariance, ``2 Re(A_k conj(B_k)) / W^2``, 1 at 0 and W/2, whose sum over the bins is
    :func:`col_fpn_excess`'s numerator; the width W), both from bin 1 (the mean is 0). The temporal
    noise, independent between the halves, cancels from the cross-periodogram in expectation."""
    if "colspec" not in d.cache:
        prof = column_profiles(d)
        if prof is None:
            d.cache["colspec"] = None
        else:
            (ca, _, _), (cb, _, _) = prof
            power, share, _ = _cross_periodogram(ca, cb)
            d.cache["colspec"] = (power, share, ca.size)
    return d.cache["colspec"]


def _peak_quantile(p: np.ndarray, what: str) -> float:
    """The largest of n periodogram bins over their median times log 2 as a normal quantile: for a white
    pattern the bins are independent exponentials and the maximum exceeds x with probability
    ``1 - (1 - exp(-x))^n``."""
    x = _ratio(float(p.max()), float(np.median(p)), what) * math.log(2)
    log_tail = math.log(p.size) - x if x > 30 else math.log(-math.expm1(p.size * math.log1p(-math.exp(-x))))
    return float(-ndtri_exp(log_tail))


def col_fpn_spectrum_peak(d: CaptureData):
    """The largest bin of the periodogram of the fixed column profile (bins 1 .. (W - 1) / 2) as a normal
    quantile: for a white column pattern (``column_fpn``'s independent offsets, DSNU averaged down the
    columns, temporal noise) the n bins are independent exponentials, the largest over the median
    times log 2 (the exponential's median) exceeds x with probability ``1 - (1 - exp(-x))^n``, and
    the statistic is the normal quantile of that tail (so the bootstrap's normal comparison holds in
    the far tail, where the maximum's own law is skewed); a periodic column pattern (column ADCs
    interleaved with an offset mismatch: EMVA 1288 Release 4.0, sec. 8, the horizontal spectrogram of
    the DSNU) puts it far out."""
    spec = column_profile_spectrum(d)
    if spec is None:
        return None
    # the Nyquist bin (a period of two columns: the CFA's column parity, which the planes' centring
    # touches) is real-valued, a chi-square of 1 degree of freedom, and left out
    p = spec[0][: (spec[2] - 1) // 2]
    if p.size < 4:
        raise NotApplicable(f"a column profile of {spec[2]} columns has fewer than 4 frequencies")
    return _peak_quantile(p, "the median of the column profile's periodogram")


@dataclass
class GainLineSpectrum:
    """Spectrum of the fixed column pattern of the flats relative to their signal, the darks' taken off
    (:func:`flat_column_gain_spectrum`), bins 1 .. W/2: ``power`` the periodogram of the mean of the
    even- and odd-frame relative profiles, ``share`` each bin's share of their covariance (as
    :func:`column_profile_spectrum`'s), ``gain`` and ``offset`` the complex rfft coefficients of the
    relative and of the darks' profile (the phase of a gain line against an offset line), ``width``."""

    power: np.ndarray
    share: np.ndarray
    gain: np.ndarray
    offset: np.ndarray
    width: int


def _profile_halves(stack: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column profiles of the mean maps of a stack's even and odd frames, as :func:`column_profiles` makes
    them (plane-centred, clipped at 5 robust sigma, row means removed, column parities centred)."""
    return (_map_column_profile(stack[0::2].mean(0, dtype=np.float64))[0],
            _map_column_profile(stack[1::2].mean(0, dtype=np.float64))[0])


def flat_column_gain_spectrum(d: CaptureData) -> GainLineSpectrum | None:
    """The flats' fixed column pattern per unit of signal: for every flat sequence of >= 2 frames, its
    even- and odd-frame column profiles less the darks' (:func:`_profile_halves`) divided by its signal
    S (DN above the darks), averaged over the flats with weights S (the relative profile's white noise,
    shot noise over S^2, falls as 1/S). What is left is a column *gain* pattern (column amplifiers or
    interleaved column ADCs with a gain mismatch: EMVA 1288 Release 4.0, sec. 8, the horizontal
    spectrogram of the PRNU) plus PRNU and temporal noise averaged down the columns (white); an offset
    pattern, the same in darks and flats, drops out."""
    if "gainspec" not in d.cache:
        flats = [f for f in d.flats if f.shape[0] >= 2]
        if sum(x.shape[0] for x in d.darks) < 2 or not flats:
            d.cache["gainspec"] = None
            return None
        (da, _, _), (db, _, _) = column_profiles(d)  # the darks' (there are darks)
        level = sum(float(x.mean(dtype=np.float64)) * x.shape[0] for x in d.darks) / sum(x.shape[0] for x in d.darks)
        lit = [(f, float(f.mean()) - level) for f in flats]
        lit = [(f, s) for f, s in lit if s > 0]
        if not lit:
            d.cache["gainspec"] = None
            return None
        # sum_j S_j r_j / sum_j S_j with r_j = (f_j - d) / S_j: sum_j (f_j - d) / sum_j S_j
        halves = [_profile_halves(f) for f, _s in lit]
        norm = sum(s for _f, s in lit)
        ra = sum(fa - da for fa, _fb in halves) / norm
        rb = sum(fb - db for _fa, fb in halves) / norm
        power, share, gain = _cross_periodogram(ra, rb)
        off = np.fft.rfft((da + db) / 2 - (da + db).mean() / 2)
        d.cache["gainspec"] = GainLineSpectrum(power, share, gain, off[1:], ra.size)
    return d.cache["gainspec"]


def flat_col_spectrum_peak(d: CaptureData):
    """:func:`col_fpn_spectrum_peak` of the flats' relative column pattern (:func:`flat_column_gain_spectrum`):
    a periodic column *gain* pattern, which grows with the light and is absent from the darks, puts it
    far out."""
    spec = flat_column_gain_spectrum(d)
    if spec is None:
        return None
    p = spec.power[: (spec.width - 1) // 2]
    if p.size < 4:
        raise NotApplicable(f"a column profile of {spec.width} columns has fewer than 4 frequencies")
    return _peak_quantile(p, "the median of the flats' relative column periodogram")


def dsnu_excess(d: CaptureData):
    dm = d.dark_map()
    if dm is None:
        return None
    n = dm[2]
    return _ratio(clipped_variance(d.dark_profile_free_map()), d.profile_free_dark_variance() / n,
                  "the dark temporal variance without row and column profiles")


def hot_pixel_mask(d: CaptureData) -> np.ndarray | None:
    """Persistent dark outliers: pixels beyond 6 robust sigma of the dark temporal-*mean* map in
    both that map and the temporal-*median* map (row/column profiles removed). A hot pixel is high
    in every frame; a heavy-tailed read-noise outlier lifts one frame, which moves the mean but
    not the median. A pixel whose dark frames sit on two tight levels (a telegraph pixel,
    :func:`telegraph_split`, even one on its low level in one frame only) is not a hot one, nor is
    a stuck one (:func:`constant_pixels`: the same code in every dark and flat frame).
    (The threshold comes from the mean map: the median of a few coarsely quantised frames sits on so
    few codes that its own robust spread can collapse to 0.)"""
    if "hotmask" not in d.cache:
        dm = d.dark_map()
        if dm is None:
            d.cache["hotmask"] = None
        else:
            r_mean = d.dark_profile_free_map()
            thr = 6 * robust_sigma(r_mean)
            r_med = remove_profiles(temporal_median(np.concatenate(d.darks)))
            d.cache["hotmask"] = (r_mean > thr) & (r_med > thr) & ~_telegraph_mask(d) & ~constant_pixels(d)
    return d.cache["hotmask"]


#: response (flat minus dark, per pixel) below this share of its CFA plane's median: no photo-response
DEAD_RESPONSE = 0.25


def defect_masks(d: CaptureData) -> tuple[np.ndarray, np.ndarray] | None:
    """(dead, stuck) pixel masks of the flat of :meth:`CaptureData.flat_map` (EMVA 1288 Release 4.0
    sec. 8.5, defect pixels; A. Abdelhamed, *Noise Modelling for Smartphone Cameras*, PhD dissertation,
    York University, 2020, ch. 2, defective pixels): *stuck* pixels read the same code in every frame
    of the flat and of the darks; *dead* pixels (not stuck) respond with less than :data:`DEAD_RESPONSE` of their CFA
    plane's median signal (flat mean map minus the dark mean map, or minus the declared black).
    A hot pixel still responds to light, so it is neither."""
    if "defects" in d.cache:
        return d.cache["defects"]
    fm = d.flat_map()
    if fm is None:
        return None
    f = max(d.flats, key=lambda a: (a.shape[0], float(a.mean())))  # the flat of flat_map
    dm = d.dark_map()
    if dm is not None and dm[0].shape == fm[0].shape:
        base = dm[0]
    elif d.black_dn is not None:
        base = np.asarray(d.black_dn, np.float64)[0, 0] if d.cfa is None else None
        if base is None:
            base = np.empty(fm[0].shape)
            for dy, dx in PLANE_OFFSETS:
                base[dy::2, dx::2] = np.asarray(d.black_dn, np.float64)[dy, dx]
    else:
        raise NotApplicable("no dark sequence and no declared black level: the flat's response is unknown")
    resp = fm[0] - base
    dead = np.zeros(resp.shape, bool)
    for dy, dx in PLANE_OFFSETS if d.cfa is not None else ((0, 0),):
        step = 2 if d.cfa is not None else 1
        r = resp[dy::step, dx::step]
        med = float(np.median(r))
        sd = np.sqrt(max(fm[1], 0.0) / fm[2])  # temporal noise of a pixel's mean over the flat's frames
        if not med > max(20.0 * sd, 1.0):
            raise NotApplicable("the flat's signal above the dark level is under 20 x the noise of its mean "
                                "map (or 1 DN): a pixel without photo-response is not told apart")
        dead[dy::step, dx::step] = r < DEAD_RESPONSE * med
    # stuck: one code in every frame of the flat and of the darks (a hot pixel clipping at white in the
    # flat still moves in the darks)
    darks = [a for a in d.darks if a.shape[0]]
    stuck = _same_code([f] + darks)
    d.cache["defects"] = (dead & ~stuck, stuck)
    d.cache["defect_inputs"] = (resp, [f] + darks)
    return d.cache["defects"]


#: a closed-form expected count below this (per capture set) is taken as this: one pixel-share statistic
#: must not outweigh the others by hundreds of nats in a held-out comparison
COUNT_NULL_MIN = 1e-9


def defect_null_count(d: CaptureData) -> float | None:
    """Expected number of :func:`defect_pixels` on ``d`` if no pixel were defective, a closed-form upper
    bound from the data's own noise (None where the statistic is undefined).

    Dead: a pixel's response (flat minus dark) below :data:`DEAD_RESPONSE` of its plane's median ``m``, for
    a Gaussian spread of the responses of robust SD ``s`` (:func:`robust_sigma`, PRNU and noise together):
    ``n_plane Phi(-(1 - DEAD_RESPONSE) m / s)`` per plane. Stuck: one code in all ``N`` frames of the flat
    and the darks. A frame of a sequence whose pixels have temporal variance ``v`` (the median over the
    pixels, quantisation's ``q^2 / 12`` taken off) lands in any one code of width ``q`` (the ADC's step,
    :func:`code_histogram`) with probability at most ``p = erf(q / (2 sqrt(2 v)))`` (the code centred on the
    mean), so all frames share the first one's code with probability at most ``prod_s p_s^n_s / max_s p_s``
    (ignoring that the flat's and the darks' means differ, which makes it far smaller still). Each pixel
    once: ``H W`` times that. Why closed form: a handful of stuck pixels in 25 k is a certain defect, but
    with 12 replicates that all count 0 the replicates' count law (:func:`count_law`) cannot put the rate
    below ~1/24 per set (p ~ 0.005 for 2 pixels, not significant among ~30 statistics)."""
    if "defect_null" in d.cache:
        return d.cache["defect_null"]
    if defect_masks(d) is None:
        d.cache["defect_null"] = None
        return None
    resp, seqs = d.cache["defect_inputs"]
    lam = 0.0
    step = 2 if d.cfa is not None else 1
    for dy, dx in PLANE_OFFSETS if d.cfa is not None else ((0, 0),):
        r = resp[dy::step, dx::step]
        med, sd = float(np.median(r)), robust_sigma(r)
        lam += r.size * (float(sst.norm.cdf(-(1.0 - DEAD_RESPONSE) * med / sd)) if sd > 0 else 0.0)
    hist = code_histogram(d)
    q = hist[1] if hist is not None else 1.0
    logp = []
    for a in seqs:
        if a.shape[0] < 2 or a.shape[1:] != seqs[0].shape[1:]:
            continue
        g = a[:, ::4, ::4].astype(np.float64)  # a thin grid: the median of the pixels' variances
        v = float(np.median(np.var(g, axis=0, ddof=1))) - q * q / 12.0
        pr = math.erf(q / (2.0 * math.sqrt(2.0 * v))) if v > 0 else 1.0
        logp.append((a.shape[0], math.log(pr) if pr > 0 else -math.inf))
    if logp:
        lam += resp.size * math.exp(sum(n * lp for n, lp in logp) - max(lp for _n, lp in logp))
    d.cache["defect_null"] = max(lam, COUNT_NULL_MIN)
    return d.cache["defect_null"]


def count_null(name: str, d: CaptureData) -> float | None:
    """The closed-form expected count of a :data:`COUNT_SHARES` statistic on ``d`` under a model without the
    effect that makes its pixels, where one exists (``defect_pixels``: :func:`defect_null_count`), else None.
    :func:`count_law` takes it where every replicate counts 0."""
    if name != "defect_pixels":
        return None
    try:
        return defect_null_count(d)
    except NotApplicable:
        return None


def _same_code(seqs) -> np.ndarray:
    """Pixels reading the code of the first frame in every frame of ``seqs`` (non-empty; sequences of
    another frame size are not compared)."""
    ref = seqs[0][0]
    same = np.ones(ref.shape, bool)
    for a in seqs:
        if a.shape[1:] != ref.shape:
            continue
        for frame in a:
            same &= frame == ref
    return same


def constant_pixels(d: CaptureData) -> np.ndarray:
    """Pixels that read one code in every frame of every dark and every flat sequence: stuck pixels,
    whatever the exposure time and the light (a shorted node). A hot pixel is not one: its signal grows
    with the exposure time and carries the read noise and its dark electrons' shot noise; nor is a hot
    pixel that clips at white in a flat only. No pixel without both darks and flats (a pixel constant
    over darks alone may be a hot one under a coarse quantiser)."""
    if "constant" not in d.cache:
        darks = [a for a in d.darks if a.shape[0]]
        flats = [a for a in d.flats if a.shape[0]]
        if darks and flats:
            d.cache["constant"] = _same_code(darks + flats)
        else:
            d.cache["constant"] = np.zeros((darks or flats)[0].shape[1:] if darks or flats else (0, 0), bool)
    return d.cache["constant"]


def clipped_constant_pixels(d: CaptureData) -> np.ndarray:
    """The :func:`constant_pixels` that read white (the clip code) in every frame: stuck at white, or hot
    pixels whose dark signal alone reaches white at this gain even in the shortest dark (from one ISO's
    frames the two look alike; the loop fits both and lets the held-out frames choose)."""
    c = constant_pixels(d)
    if not c.any():
        return c
    ref = (d.darks[0] if d.darks and d.darks[0].shape[0] else d.flats[0])[0]
    return c & (ref >= np.float32(d.white_dn - 0.5))


def defect_pixels(d: CaptureData):
    """Share of the pixels that are dead or stuck (:func:`defect_masks`)."""
    m = defect_masks(d)
    return None if m is None else float(np.mean(m[0] | m[1]))


#: the looser (gap, level variance) of a pixel that is not taken for a hot pixel (:func:`hot_pixel_mask`):
#: a telegraph pixel high in most frames looks hot, one whose step the read noise has blurred too
RTN_HOT_EXCLUDE = (4.0, 3.0)


def telegraph_split(d: CaptureData) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float] | None:
    """Random-telegraph pixels of the darks (:func:`two_level_split` on all dark frames, each frame's row
    and column means removed; sigma^2 the 1 %-trimmed mean of the per-pixel temporal variances, i.e. the
    read noise): (two-level mask, gap map (DN), high-level count map, frame count, sigma^2, mask of the
    pixels that are two-level with one frame on a level allowed and :data:`RTN_HOT_EXCLUDE`'s bounds).
    Not applicable to darks inside one ADC code (sigma^2 below ``step^2 / 12``, :func:`adc_step`): every
    pixel near a code edge then sits on two codes a step apart, many read-noise sigmas, and how many do
    depends on where the edges lie (a differential non-linearity moves them), not on traps. Computed once
    per capture, a :class:`NotApplicable` too (it is raised again on each call)."""
    return d.cached("telegraph", lambda: _telegraph(d))


def _telegraph(d: CaptureData):
    """:func:`telegraph_split`'s computation (uncached)."""
    if not d.darks:
        return None
    x = np.concatenate(d.darks).astype(np.float64)
    n = x.shape[0]
    if n < 4:
        raise NotApplicable("fewer than 4 dark frames: two levels of >= 2 frames each are not told apart")
    x -= x.mean(axis=2, keepdims=True)
    x -= x.mean(axis=1, keepdims=True)
    v = x.reshape(n, -1)
    s2 = float(sst.trim_mean(np.var(v, axis=0, ddof=1), 0.01))
    if not s2 > 0:
        raise NotApplicable("the dark frames' temporal variance is 0 (constant or quantisation-dominated darks)")
    if s2 < adc_step(d) ** 2 / 12.0:  # above it a one-code step is < 3.5 sigma, under RTN_GAP_SIGMA
        raise NotApplicable("the darks sit inside one ADC code (temporal variance below step^2/12): a pixel's "
                            "occasional step to the next code is the quantiser's, not a second level")
    (mask, gap, high), (loose, _g, _h) = two_level_splits(v, s2, [(2, RTN_GAP_SIGMA, RTN_LEVEL_VAR),
                                                                  (1, *RTN_HOT_EXCLUDE)])
    shape = x.shape[1:]
    return mask.reshape(shape), gap.reshape(shape), high.reshape(shape), n, s2, loose.reshape(shape)


def _telegraph_mask(d: CaptureData) -> np.ndarray | np.bool_:
    """The pixels of :func:`telegraph_split` that are two-level with one frame on a level allowed (a
    telegraph pixel low in only one frame is not a hot pixel), or ``np.False_`` where it is not defined
    (numpy's: ``~`` of Python's False is -1, which turned the hot-pixel mask into an integer index)."""
    try:
        t = telegraph_split(d)
    except NotApplicable:
        return np.False_
    return np.False_ if t is None else t[5]


def telegraph_pixels(d: CaptureData):
    """Share of the pixels whose dark frames sit on two levels (:func:`telegraph_split`)."""
    t = telegraph_split(d)
    return None if t is None else float(np.mean(t[0]))


def hot_pixel_tail(d: CaptureData):
    mask = hot_pixel_mask(d)
    return None if mask is None else float(np.mean(mask))


def _within(x: np.ndarray, k: float) -> np.ndarray:
    """Mask of the values of ``x`` less than ``k`` robust sigmas (:func:`robust_sigma`) from its median."""
    med = np.median(x)
    return np.abs(x - med) < k * robust_sigma(x, med)


def _fixed_planes(frames: np.ndarray):
    """Per CFA plane, the even-frame and odd-frame mean maps (profiles removed) and the mask of pixels
    within 6 robust sigma in both: ``(pa, pb, ok)``, the inputs of :func:`_fixed_cov_blocks`."""
    a = remove_profiles(frames[0::2].astype(np.float64).mean(0))
    b = remove_profiles(frames[1::2].astype(np.float64).mean(0))
    for dy, dx in PLANE_OFFSETS:
        pa, pb = a[dy::2, dx::2], b[dy::2, dx::2]
        ok = _within(pa, 6.0) & _within(pb, 6.0)
        if ok.sum() < 2:
            raise NotApplicable("fewer than 2 pixels of a CFA plane inside 6 robust sigma of the even/odd-frame "
                                "mean maps (constant or quantisation-dominated maps)")
        yield pa, pb, ok


def _fixed_cov_blocks(frames: np.ndarray, blocks: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per CFA plane, the covariance of the even-frame and odd-frame mean maps (profiles removed,
    pixels beyond 6 robust sigma in either map left out) -- the variance of the fixed pattern alone,
    temporal noise being independent between the halves -- as its centred products summed over
    ``blocks`` bands of rows: (sums, pixel counts) per plane; the covariance is ``sums.sum() /
    counts.sum()``, and the bands serve a jackknife. Median-profile removal takes ~3 % of an i.i.d.
    pattern's variance with it (64 x 64 frames)."""
    out = []
    for pa, pb, ok in _fixed_planes(frames):
        prod = np.where(ok, (pa - pa[ok].mean()) * (pb - pb[ok].mean()), 0.0)
        bands = np.array_split(np.arange(prod.shape[0]), blocks)
        out.append((np.array([prod[r].sum() for r in bands]), np.array([ok[r].sum() for r in bands], np.float64)))
    return out


#: bands of rows of :func:`fixed_cov_blocks` (the jackknife of :func:`prnu_by_level`)
FIXED_COV_BLOCKS = 16


def fixed_cov_blocks(d: CaptureData, which) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """:func:`_fixed_cov_blocks` (:data:`FIXED_COV_BLOCKS` bands) of the darks pooled (``which="darks"``)
    or of flat ``which`` (its index in ``d.flats``), computed once per capture (the PRNU statistics
    share it); None with fewer than 2 frames. A :class:`NotApplicable` is raised again on each call."""
    def compute():
        frames = np.concatenate(d.darks) if which == "darks" else d.flats[which]
        return _fixed_cov_blocks(frames, FIXED_COV_BLOCKS) if frames.shape[0] >= 2 else None

    return d.cached(("fixed_cov", which), compute)


def _cov_of_blocks(blocks: list[tuple[np.ndarray, np.ndarray]]) -> list[float]:
    """The per-plane covariances of :func:`fixed_cov_blocks`' band sums."""
    return [float(s.sum() / max(c.sum(), 1.0)) for s, c in blocks]


def prnu_by_level(d: CaptureData) -> list[tuple[float, float, float]]:
    """Per flat sequence of >= 2 frames, (signal above the darks, relative fixed-pattern variance, its
    standard error): :func:`prnu_excess`'s estimate made on each flat, the standard error by a
    jackknife over :data:`FIXED_COV_BLOCKS` bands of rows (the pattern is independent between bands). A gain
    (PRNU) gives the same relative variance at every signal level (EMVA 1288 Release 4.0, sec. 8.2:
    the PRNU is the spatial variance of the light's part over the signal squared, one number for the
    sensor). Sorted by signal."""
    if not d.flats:
        return []
    if "prnu_levels" in d.cache:
        return d.cache["prnu_levels"]
    blocks = FIXED_COV_BLOCKS
    dm = d.dark_map()
    cd = fixed_cov_blocks(d, "darks") if dm is not None else None
    out = []
    for fi, f in enumerate(d.flats):
        if f.shape[0] < 2:
            continue
        m = f.astype(np.float64).mean(0)
        levels = []
        for dy, dx in PLANE_OFFSETS:
            lv = float(np.mean(m[dy::2, dx::2]))
            if dm is not None:
                lv -= float(np.mean(dm[0][dy::2, dx::2]))
            elif d.black_dn is not None:
                lv -= float(np.asarray(d.black_dn, dtype=np.float64).reshape(2, 2)[dy, dx])
            levels.append(lv)
        if min(levels) <= 0:
            continue
        cf = fixed_cov_blocks(d, fi)

        def rel(keep):
            v = []
            for k, lv in enumerate(levels):
                fk = cf[k][0][keep].sum() / max(cf[k][1][keep].sum(), 1.0)
                dk = cd[k][0][keep].sum() / max(cd[k][1][keep].sum(), 1.0) if cd is not None else 0.0
                v.append((fk - dk) / lv ** 2)
            return float(np.mean(v))

        full = rel(np.ones(blocks, bool))
        jk = np.array([rel(np.arange(blocks) != i) for i in range(blocks)])
        se = float(np.sqrt((blocks - 1) / blocks * np.sum((jk - jk.mean()) ** 2)))
        out.append((float(np.mean(levels)), full, se))
    d.cache["prnu_levels"] = sorted(out)
    return d.cache["prnu_levels"]


def flat_level_pair(rows: list[tuple[float, float, float]]):
    """The (dimmer, brightest) rows of :func:`prnu_by_level` whose signals are two distinct levels: the
    brightest flat and the first dimmer one at 10-80 % of its signal; None without such a pair."""
    if len(rows) < 2:
        return None
    hi = rows[-1]
    lows = [r for r in rows[:-1] if 0.1 * hi[0] <= r[0] <= 0.8 * hi[0]]
    return (lows[0], hi) if lows else None


def flat_spread_growth(d: CaptureData):
    """Relative fixed-pattern variance of the brightest flat minus that of a dimmer one at 10-80 % of its
    signal (:func:`prnu_by_level`, :func:`flat_level_pair`). A gain (PRNU, EMVA 1288 Release 4.0 sec. 8.2)
    has the same relative variance at every level: 0 up to sampling noise. A response that curves by a
    different amount in each pixel (``y = x + c_p x^2 / s``) adds ``sd(c)^2 x^2 / s^2`` to it, which grows
    with the signal; a common compressive response makes it fall slightly (the elasticity)."""
    pair = flat_level_pair(prnu_by_level(d))
    if pair is None:
        return None
    lo, hi = pair
    return hi[1] - lo[1]


def prnu_excess(d: CaptureData):
    """Relative PRNU variance: per CFA plane, (fixed-pattern variance of the flat - that of the darks)
    / signal^2, averaged over the planes. Fixed-pattern variances are even/odd-frame covariances
    (:func:`fixed_cov_blocks`): no temporal variance is subtracted (which, with a robust sigma of the planes
    pooled, a scale mixture, left the estimate ~15 % low in sigma), and offsets common to dark and flat
    (DSNU, column FPN) cancel; hot pixels are left out."""
    fm = d.flat_map()
    if fm is None:
        return None
    m = fm[0]
    i = max(range(len(d.flats)), key=lambda j: (d.flats[j].shape[0], float(d.flats[j].mean())))  # flat_map's
    cf = fixed_cov_blocks(d, i)
    if cf is None:
        return None
    cf = _cov_of_blocks(cf)
    dm = d.dark_map()
    cdb = fixed_cov_blocks(d, "darks") if dm is not None else None
    cd = _cov_of_blocks(cdb) if cdb else None
    out = []
    for k, (dy, dx) in enumerate(PLANE_OFFSETS):
        level = float(np.mean(m[dy::2, dx::2]))
        base = 0.0
        if dm is not None:
            base = cd[k] if cd is not None else 0.0
            level -= float(np.mean(dm[0][dy::2, dx::2]))
        elif d.black_dn is not None:
            level -= float(np.asarray(d.black_dn, dtype=np.float64).reshape(2, 2)[dy, dx])
        if level <= 0:
            raise NotApplicable(f"the flat's signal above the dark level is {level:.3g} DN on plane {k}")
        out.append((cf[k] - base) / level ** 2)
    return float(np.mean(out))


def black_offset(d: CaptureData):
    dm = d.dark_map()
    if dm is None or d.black_dn is None:
        return None
    m = dm[0]
    return float(np.mean([np.median(m[dy::2, dx::2]) - d.black_dn[dy, dx] for dy, dx in PLANE_OFFSETS]))


def frame_mean_jitter(d: CaptureData):
    """Frame-to-frame variance of the flat frame means over the squared signal above dark, the variance
    taken from their successive differences about the differences' mean (J. von Neumann, "Distribution
    of the ratio of the mean square successive difference to the variance", Ann. Math. Statist. 12, 1941,
    takes them about 0): unbiased for frame means independent from frame to frame (flicker; E[sum (d -
    mean d)^2] = 2 sigma^2 (m - 1/m) for m differences), blind to a level that drifts slowly over the
    sequence (a linear drift adds the same step to every difference; :func:`frame_mean_drift` sees it).
    A sequence of 2 frames has one difference, taken about 0."""
    if not d.flats:
        return None
    ref = float(np.mean([x.mean() for x in d.darks])) if d.darks else (
        float(np.mean(d.black_dn)) if d.black_dn is not None else 0.0)
    vals = []
    for means in d.frame_means("flat"):
        if means.size < 2:
            continue
        dm = np.diff(means)
        m = dm.size
        # E[sum (d - mean d)^2] = 2 sigma^2 (m - 1/m) for m differences of independent frame means
        var = (float(np.sum((dm - dm.mean()) ** 2)) / (2 * (m - 1 / m)) if m >= 2 else 0.5 * float(dm[0] ** 2))
        vals.append(_ratio(var, (means.mean() - ref) ** 2,
                           "the flat's squared signal above dark"))
    if not vals:
        raise NotApplicable("no flat sequence of >= 2 frames")
    return float(np.mean(vals))


def frame_mean_drift(d: CaptureData):
    """Log of the ratio of the sample variance of a sequence's frame means to half their mean square
    successive difference (the inverse of von Neumann's ratio, 1941), averaged over the dark and flat
    sequences of >= 4 frames: about 0 when the frame means are independent from frame to frame, positive
    when the level drifts over the sequence (a black level or a gain that warms up), negative when it
    alternates. No effect of the vocabulary drifts: the bootstrap null is that of independent frames. It
    proposes the frame form of ``empirical_offset`` (the spread of the dark frames' levels, drawn per frame)."""
    vals = []
    for m in [*d.frame_means("dark"), *d.frame_means("flat")]:
        if m.size < 4:
            continue
        msd = 0.5 * float(np.mean(np.diff(m) ** 2))
        v = float(np.var(m, ddof=1))
        if msd > 0 and v > 0:
            vals.append(np.log(v / msd))
    if not vals:
        raise NotApplicable("no dark or flat sequence of >= 4 frames whose frame means vary")
    return float(np.mean(vals))


def dark_residual_sample(d: CaptureData, max_values: int = 20000) -> np.ndarray | None:
    """Dark temporal residuals (row and column means of each frame removed), deterministic subsample."""
    if "dres" not in d.cache:
        res = d.temporal_residuals("dark")
        if not res:
            d.cache["dres"] = None
        else:
            parts = []
            for r in res:
                r = r - r.mean(axis=2, keepdims=True)
                r = r - r.mean(axis=1, keepdims=True)
                parts.append(r.ravel())
            x = np.concatenate(parts)
            step = max(1, x.size // max_values)
            d.cache["dres"] = x[::step][:max_values]
    return d.cache["dres"]


def dark_tail_mass(d):
    x = dark_residual_sample(d)
    if x is None:
        return None
    q25, q75 = np.percentile(x, [25, 75])
    s = (q75 - q25) / 1.349
    if s <= 0:
        raise NotApplicable("the dark residuals' interquartile range is 0 (quantisation-dominated darks)")
    return float(np.mean(np.abs(x - np.median(x)) > 4 * s))


_PPCC_LAMBDAS = np.linspace(-0.5, 0.5, 41)
_PPCC_CACHE: dict = {}


def _tukey_order_medians(n: int) -> np.ndarray:
    """(len(lambdas), n) Tukey-lambda quantiles at Filliben's order-statistic medians."""
    if n not in _PPCC_CACHE:
        i = np.arange(1, n + 1)
        m = (i - 0.3175) / (n + 0.365)
        m[-1] = 0.5 ** (1.0 / n)
        m[0] = 1 - m[-1]
        q = np.array([sst.tukeylambda.ppf(m, lam) for lam in _PPCC_LAMBDAS])
        q = q - q.mean(axis=1, keepdims=True)
        _PPCC_CACHE[n] = q / np.linalg.norm(q, axis=1, keepdims=True)
    return _PPCC_CACHE[n]


def ppcc_lambda(x: np.ndarray) -> float:
    """Tukey-lambda shape maximising the probability-plot correlation (Filliben 1975), on a
    0.025 grid over [-0.5, 0.5] refined by a parabola through the best three points."""
    xs = np.sort(x)
    qc = _tukey_order_medians(xs.size)  # centred, unit-norm rows
    xc = xs - xs.mean()
    r = np.einsum("ij,j->i", qc, xc) / (float(np.sqrt(np.sum(xc * xc))) + 1e-300)
    i = int(np.argmax(r))
    if 0 < i < len(r) - 1:
        y0, y1, y2 = r[i - 1], r[i], r[i + 1]
        den = y0 - 2 * y1 + y2
        off = 0.5 * (y0 - y2) / den if den != 0 else 0.0
        return float(_PPCC_LAMBDAS[i] + np.clip(off, -1, 1) * (_PPCC_LAMBDAS[1] - _PPCC_LAMBDAS[0]))
    return float(_PPCC_LAMBDAS[i])


def dark_ppcc_lambda(d):
    x = dark_residual_sample(d, 4000)
    if x is None:
        return None
    if np.ptp(x) <= 0 or np.unique(x[:4000]).size < 8:
        raise NotApplicable("the dark residuals take fewer than 8 distinct values (quantisation-dominated darks)")
    return ppcc_lambda(x)


def _central_codes(src: list[np.ndarray]) -> np.ndarray:
    """The codes (rounded values) used in the central 98 % of the values of ``src``."""
    v = np.concatenate([s.ravel() for s in src])
    lo, hi = np.percentile(v, [1, 99])
    return np.unique(np.round(v[(v >= lo) & (v <= hi)]))


def code_grid_codes(d: CaptureData) -> np.ndarray | None:
    """The codes from which the ADC's grid is read: those used in the central 98 % of the darks, or,
    where the darks sit on one code (a read noise far below a coarse ADC's step: they show no grid), of
    the dimmest flat; None without darks or flats."""
    if "code_grid" in d.cache:
        return d.cache["code_grid"]
    codes = None
    for src in (d.darks, sorted(d.flats, key=lambda a: float(a.mean()))[:1]):
        if src:
            codes = _central_codes(src)
            if codes.size > 1:
                break
    d.cache["code_grid"] = codes
    return codes


def adc_step(d: CaptureData) -> float:
    """The ADC's step (DN): the median gap between the codes of :func:`code_grid_codes`, at least 1 DN."""
    codes = code_grid_codes(d)
    gaps = np.diff(codes) if codes is not None else np.zeros(0)
    return max(float(np.median(gaps)) if gaps.size else 1.0, 1.0)


#: share of a site's dark values that must sit on the declared black's code and one neighbour for them to be
#: read as split between two codes (a few hot or telegraph pixels do not count)
SPLIT_SHARE = 0.99


def black_code(values: np.ndarray, black: float, step: float) -> tuple[float, float]:
    """``(phase, code)``: a code of the data's lattice (the commonest of ``values``, codes ``step`` DN apart)
    and the code the declared ``black`` reads as on it."""
    u, n = np.unique(np.asarray(values, np.float64).ravel(), return_counts=True)
    phase = float(u[np.argmax(n)])
    return phase, float(phase + np.round((black - phase) / step) * step)


def split_on_black_code(values: np.ndarray, black: float, step: float) -> bool:
    """Whether :data:`SPLIT_SHARE` of the dark ``values`` (ADC codes ``step`` DN apart) sit on the code
    the declared ``black`` reads as and at most one neighbour, the black's code holding at least the rest
    (darks all on the next code up lie beyond the transition: an offset of at least a part of a code,
    measured; values off any lattice are not codes)."""
    v = np.asarray(values, np.float64).ravel()
    if v.size == 0:
        return False
    phase, code = black_code(v, black, step)
    r = (v - phase) / step
    if np.mean(np.abs(r - np.round(r)) < 0.01) < SPLIT_SHARE:  # not ADC codes (values between the codes)
        return False
    k = np.round((v - code) / step)
    on = k == 0
    share = max(float(np.mean(on | (k == -1))), float(np.mean(on | (k == 1))))
    return share >= SPLIT_SHARE and float(np.mean(on)) >= 1.0 - SPLIT_SHARE


def dark_code_split(d: CaptureData):
    """The share of the dark values on the code above the black's minus the share on the code below it, where
    the darks sit on the declared black's code and one neighbour of an ADC whose codes are more than 1.5 DN
    apart (:func:`split_on_black_code`): the place of the one transition level between those codes
    relative to the dark level, which decides every
    dark statistic and which a draw of the ADC's unequal codes puts anywhere within its code (IEEE Std
    1241-2010, sec. 4.1.3: a transition level from the share of a known input below it). A simulated
    capture (:attr:`CaptureData.simulated`) gets the same share without the split: a model whose darks
    spread over more codes than the data's (a read noise fitted to the split darks' temporal variance
    under ideal transitions) is the discrepancy itself."""
    if not d.darks or d.black_dn is None:
        return None
    step = adc_step(d)
    if step <= 1.5:
        raise NotApplicable(f"the ADC's codes are {step:g} DN apart (not a coarse ADC)")
    v = np.concatenate([np.asarray(a, np.float64).ravel() for a in d.darks])
    black = float(np.mean(d.black_dn))
    if not d.simulated and not split_on_black_code(v, black, step):
        raise NotApplicable("the darks do not sit on the black's code and at most one neighbour")
    code = black_code(v, black, step)[1]
    return float(np.mean(v > code + step / 2) - np.mean(v < code - step / 2))


def code_occupancy(d: CaptureData):
    codes = code_grid_codes(d)
    if codes is None:
        return None
    span = codes.max() - codes.min() + 1
    return float(codes.size / span) if span > 1 else 1.0


#: neighbours on each side from which a code's smooth expected count is predicted (code_width_spread)
CODE_HALF_WINDOW = 3
#: weights of neighbour j (both sides) in the local quadratic's value at the centre: least squares of a
#: quadratic through the counts at j = +-1, +-2, +-3 gives 1/2 - j^2/14
CODE_WEIGHTS = np.array([0.5 - j * j / 14.0 for j in (3, 2, 1)] + [0.0] + [0.5 - j * j / 14.0 for j in (1, 2, 3)])
#: codes whose predicted count is below this are left out (Poisson noise would dominate)
CODE_MIN_COUNT = 100
#: fewest codes code_width_spread needs
CODE_MIN_CODES = 8
#: a sequence enters the histogram when its values' robust SD spans at least this many codes (narrower
#: histograms bend too much over the window for a local quadratic)
CODE_MIN_SPREAD = 3.0


def code_histogram(d: CaptureData) -> tuple[np.ndarray, float] | None:
    """Counts of the ADC codes of the darks and the flats (the codes a sensor's histogram test uses)
    whose values spread over :data:`CODE_MIN_SPREAD` codes or more, on the ADC's lattice (the median gap
    between used codes: a coarser ADC's step), and that step; None without darks or flats. Every flat
    counts: under a coarse ADC the darks may sit on one code and the dimmest flat on two, while a brighter
    flat's shot noise spreads it over many."""
    key = "code_hist"
    if key in d.cache:
        return d.cache[key]
    src = list(d.darks) + sorted(d.flats, key=lambda a: float(a.mean()))
    if not src:
        return None
    lo = min(float(np.min(s)) for s in src)
    hi = max(float(np.max(s)) for s in src)
    per = []
    for s in src:
        counts = np.zeros(int(round(hi)) - int(round(lo)) + 1, dtype=np.int64)
        for f in s:  # one frame at a time: no copy of the whole stack
            counts += np.bincount((np.round(f).astype(np.int64) - int(round(lo))).ravel(), minlength=counts.size)
        per.append(counts)
    total = np.sum(per, axis=0)
    gaps = np.diff(np.flatnonzero(total))
    step = int(np.median(gaps)) if gaps.size else 1
    phase = int(np.argmax(total)) % step
    out = np.zeros_like(total[phase::step])
    for counts, s in zip(per, src):
        sub = s[0][:: max(1, s.shape[1] // 64), :: max(1, s.shape[2] // 64)]  # a spread estimate off a thin grid
        if robust_sigma(sub - np.median(sub)) >= CODE_MIN_SPREAD * step:
            out += counts[phase::step]
    d.cache[key] = (out, float(step))
    return d.cache[key]


def code_width_spread(d: CaptureData):
    """sum_k ((c_k - s_k)^2 - (1 + sum w^2) s_k) / sum_k s_k^2, c_k a code's count and s_k its count
    predicted by a local quadratic through its 2 x :data:`CODE_HALF_WINDOW` neighbours on the ADC's lattice
    (weights :data:`CODE_WEIGHTS`; codes with s_k >= :data:`CODE_MIN_COUNT`): the relative variance of the
    code widths, weighted by the squared counts (a mean of per-code ratios would be dominated by the
    few codes whose prediction is small), with the counts' Poisson variance taken off (IEEE Std 1241-2010,
    sec. 4.1.3, the histogram test of the differential non-linearity)."""
    h = code_histogram(d)
    if h is None:
        return None
    c = h[0].astype(np.float64)
    k = CODE_HALF_WINDOW
    if c.size < 2 * k + 1 or not c.any():
        raise NotApplicable(f"no dark or flat sequence spreads over {CODE_MIN_SPREAD:g} ADC codes or more")
    win = np.lib.stride_tricks.sliding_window_view(c, 2 * k + 1)
    centre = win[:, k]
    smooth = win @ CODE_WEIGHTS
    ok = smooth >= CODE_MIN_COUNT
    if int(ok.sum()) < CODE_MIN_CODES:
        raise NotApplicable(f"fewer than {CODE_MIN_CODES} ADC codes hold >= {CODE_MIN_COUNT} values in the darks "
                            f"and the dimmest flat that spread over {CODE_MIN_SPREAD:g} codes or more")
    cc, ss = centre[ok], smooth[ok]
    poisson = 1.0 + float(np.sum(CODE_WEIGHTS ** 2))
    return float(np.sum((cc - ss) ** 2 - poisson * ss) / np.sum(ss ** 2))


def _lag_corr(d: CaptureData, lag: int):
    res = d.temporal_residuals("dark")
    if not res:
        return None
    key = ("lag", lag)
    if key in d.cache:
        return d.cache[key]
    vals = []
    for r in res:
        r = r - r.mean(axis=2, keepdims=True)
        r = r - r.mean(axis=1, keepdims=True)
        for dy, dx in PLANE_OFFSETS:
            p = r[:, dy::2, dx::2]
            den = np.mean(p * p)
            if den <= 0:
                raise NotApplicable("the dark residual's variance on a CFA plane is 0 (quantisation-dominated darks)")
            if p.shape[1] <= lag or p.shape[2] <= lag:
                raise NotApplicable(f"a CFA plane is narrower than {lag + 1} pixels")
            vals.append(np.mean(p[:, :, lag:] * p[:, :, :-lag]) / den)
            vals.append(np.mean(p[:, lag:, :] * p[:, :-lag, :]) / den)
    d.cache[key] = float(np.mean(vals))
    return d.cache[key]


def lag1_corr(d):
    return _lag_corr(d, 1)


def lag2_corr(d):
    return _lag_corr(d, 2)


def _mosaic_lag1(res: list[np.ndarray]) -> float:
    """Mean lag-1 autocorrelation on the mosaic (along rows and along columns) of temporal residuals,
    each frame's row and column means removed."""
    vals = []
    for r in res:
        r = r - r.mean(axis=2, keepdims=True)
        r = r - r.mean(axis=1, keepdims=True)
        den = float(np.mean(r * r))
        if den <= 0:
            raise NotApplicable("the temporal residual's variance is 0 (constant or quantisation-dominated frames)")
        if r.shape[1] < 2 or r.shape[2] < 2:
            raise NotApplicable("the frame is narrower than 2 pixels")
        vals.append(float(np.mean(r[:, :, 1:] * r[:, :, :-1])) / den)
        vals.append(float(np.mean(r[:, 1:, :] * r[:, :-1, :])) / den)
    return float(np.mean(vals))


def adjacent_corr(d: CaptureData):
    """Lag-1 autocorrelation of the dark temporal residuals on the mosaic (adjacent pixels, of different
    colours on a CFA sensor), along rows and along columns, each frame's row and column means removed:
    electrical crosstalk between neighbouring lines couples adjacent pixels, which the in-plane statistics
    (:func:`lag1_corr`, same-colour pixels 2 px apart) do not see."""
    res = d.temporal_residuals("dark")
    return _mosaic_lag1(res) if res else None


def flat_adjacent_corr(d: CaptureData):
    """:func:`adjacent_corr` on the flats' temporal residuals: photo-electrons shared with adjacent pixels
    before read-out (charge-domain crosstalk) correlate the shot noise of neighbours, which dark frames
    (no photo-electrons) do not show; read-side coupling shows in both, and the bootstrap null carries it."""
    res = d.temporal_residuals("flat")
    return _mosaic_lag1(res) if res else None


def dark_signal_slope(d: CaptureData):
    """Slope (DN/s) of the dark level against exposure time (EMVA 1288 R4.0 sec. 4.2); the level of a
    sequence is the 1 %-trimmed mean of its temporal-mean image, so a few hot pixels (whose charge may
    grow with the exposure too) do not make a dark current."""
    if not d.dark_series or len({t for t, _ in d.dark_series}) < 2:
        return None
    t = np.array([float(t) for t, _ in d.dark_series])
    m = np.array([float(sst.trim_mean(f.astype(np.float64).mean(0).ravel(), 0.01)) for _, f in d.dark_series])
    w = np.array([f.shape[0] for _, f in d.dark_series], dtype=np.float64)
    return float(np.polyfit(t, m, 1, w=np.sqrt(w))[0])


def dark_variance_slope(d: CaptureData):
    """Slope (DN^2/s) of the dark temporal variance against exposure time (EMVA 1288 R4.0 sec. 4.2: dark
    current from the variance, which grows by K times the mean's growth when the dark signal is Poisson
    charge); the variance of a sequence is the 1 %-trimmed mean over pixels of their temporal variance
    (each frame's mean removed, so a level drifting between frames does not count). A dark level that
    rises with exposure time without this growth is no dark current (a black level that drifts)."""
    if not d.dark_series or len({t for t, f in d.dark_series if f.shape[0] >= 2}) < 2:
        return None
    t, v, w = [], [], []
    for ti, f in d.dark_series:
        if f.shape[0] < 2:
            continue
        x = f.astype(np.float64)
        x -= x.mean(axis=(1, 2), keepdims=True)
        t.append(float(ti))
        v.append(float(sst.trim_mean(x.var(axis=0, ddof=1).ravel(), 0.01)))
        w.append(f.shape[0] - 1.0)
    return float(np.polyfit(np.array(t), np.array(v), 1, w=np.sqrt(np.array(w)))[0])


def exposure_slope(times, maps) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel least-squares slope against the exposure time of ``maps`` (one temporal-mean image per
    exposure time in ``times``, every time weighted alike): ``(sum_k c_k maps_k, c)`` with
    ``c_k = (t_k - mean t) / sum (t - mean t)^2``, the coefficients the slope's noise propagates through."""
    t = np.asarray(times, dtype=np.float64)
    c = (t - t.mean()) / np.sum((t - t.mean()) ** 2)
    return sum(ci * m for ci, m in zip(c, maps)), c


def dark_slope_map(d: CaptureData) -> np.ndarray | None:
    """Per-pixel least-squares slope (DN/s) of the dark temporal-mean images against exposure time over
    :attr:`CaptureData.dark_series` (sequences of one exposure time pooled, frame-weighted), with each
    pixel that stands out of its CFA plane's 5 x 5 running median by more than 6 robust sigma (a hot
    pixel with its own dark current, a stuck or dead one) replaced by that median; None with fewer than
    two exposure times."""
    if "slopemap" in d.cache:
        return d.cache["slopemap"]
    out = None
    if d.dark_series and len({float(t) for t, _ in d.dark_series}) >= 2:
        by_t: dict[float, list] = {}
        for t, f in d.dark_series:
            by_t.setdefault(float(t), []).append(f)
        times = np.array(sorted(by_t))
        maps = []
        for t in times:
            n = np.array([f.shape[0] for f in by_t[t]], dtype=np.float64)
            maps.append(sum(ni * f.astype(np.float64).mean(0) for ni, f in zip(n, by_t[t])) / n.sum())
        out = exposure_slope(times, maps)[0]
        for dy, dx in PLANE_OFFSETS:
            p = out[dy::2, dx::2]
            med = median_box(p, 5)
            r = p - med
            s = robust_sigma(r)
            bad = np.abs(r) > 6 * s if s > 0 else np.zeros(p.shape, bool)
            p[bad] = med[bad]
    d.cache["slopemap"] = out
    return out


#: fall-off lengths (share of the frame's diagonal, or of its extent across an edge) of the glow
#: templates :func:`glow_field` tries; the card's fit refines the scale between them
GLOW_SCALES = tuple(float(s) for s in np.geomspace(0.02, 1.0, 14))
#: where an amplifier may sit: the noise stage's ``amp_glow`` origins
GLOW_ORIGINS = ("top_left", "top_right", "bottom_left", "bottom_right", "top", "bottom", "left", "right")
_GLOW_TEMPLATES: dict = {}


def glow_template(shape: tuple[int, int], origin: str, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """(field, field with each CFA plane's mean removed) of an amplifier glow of relative profile 1 at
    ``origin`` falling off as ``exp(-d / (scale L))`` (:class:`simcam.noise.effects.dark.AmpGlow`'s field)."""
    from ..noise.effects.dark import AmpGlow

    f = AmpGlow(rate=1.0, origin=origin, scale=scale, electron=1.0).field(shape)
    tc = f.copy()
    for dy, dx in PLANE_OFFSETS:
        tc[dy::2, dx::2] -= tc[dy::2, dx::2].mean()
    return f, tc


def _glow_templates(shape: tuple[int, int]) -> tuple[list, np.ndarray, np.ndarray]:
    """The grid of (origin, scale) pairs; their plane-centred templates stacked as rows of one
    (templates, pixels) matrix; and per template the squared norms of the template, of its row sums and
    of its column sums (what a row or a column offset projects onto it), as (templates, 3)."""
    if shape not in _GLOW_TEMPLATES:
        if len(_GLOW_TEMPLATES) > 8:
            _GLOW_TEMPLATES.clear()
        grid = [(o, s) for o in GLOW_ORIGINS for s in GLOW_SCALES]
        stack = np.empty((len(grid), shape[0] * shape[1]))
        norms = np.empty((len(grid), 3))
        for i, (o, s) in enumerate(grid):
            tc = glow_template(shape, o, s)[1]
            stack[i] = tc.ravel()
            norms[i] = float(np.sum(tc * tc)), float(np.sum(tc.sum(1) ** 2)), float(np.sum(tc.sum(0) ** 2))
        _GLOW_TEMPLATES[shape] = (grid, stack, norms)
    return _GLOW_TEMPLATES[shape]


def _second_diff_var(x: np.ndarray, axis: int) -> float:
    """Variance of white noise of which ``x`` along ``axis`` is a sample (plus smooth terms): the mean
    square of its second differences at lag 2 (inside a CFA plane) over 6; a linear gradient cancels."""
    x = np.moveaxis(x, axis, 0)
    if x.shape[0] < 5:
        raise NotApplicable("the dark slope map has fewer than 5 lines along an axis")
    d2 = x[4:] - 2 * x[2:-2] + x[:-4]
    return float(np.mean(d2 * d2)) / 6.0


def slope_noise(m: np.ndarray) -> tuple[float, float, float]:
    """(pixel, row, column) variances of the white noise of the slope map ``m``: second differences
    along rows see pixel + column noise, along columns pixel + row noise; those of the row means see
    row noise + pixel / W, of the column means column noise + pixel / H. Solved for the three; a smooth
    field (the glow itself) adds little to second differences."""
    h, w = m.shape
    ax = _second_diff_var(m, 1)  # pixel + column
    ay = _second_diff_var(m, 0)  # pixel + row
    br = _second_diff_var(m.mean(1), 0)  # row + pixel / W
    bc = _second_diff_var(m.mean(0), 0)  # column + pixel / H
    col = max((bc - ax / h) / (1 - 1 / h), 0.0)
    row = max((br - ay / w) / (1 - 1 / w), 0.0)
    pix = max(0.5 * ((ax - col) + (ay - row)), 0.0)
    return pix, row, col


def glow_fits(m: np.ndarray) -> list[tuple[str, float, float, float]]:
    """(origin, scale, amplitude in DN/s, t-value) of the least-squares fit of each glow template of the
    grid (with a constant per CFA plane: the flat dark current) to the slope map ``m``; the t-value's
    variance is that of white pixel, row and column noise projected on the template
    (:func:`slope_noise`)."""
    pix, row, col = slope_noise(m)
    grid, stack, norms = _glow_templates(m.shape)
    proj = stack @ np.ascontiguousarray(m, dtype=np.float64).ravel()  # every template's projection at once
    var = norms @ np.array([pix, row, col])
    if not np.all(var > 0):
        raise NotApplicable("the dark slope map has no noise (constant darks)")
    return [(o, s, float(p / n2), float(p / np.sqrt(v))) for (o, s), p, n2, v in zip(grid, proj, norms[:, 0], var)]


def glow_field(d: CaptureData):
    """Amplifier glow (EMVA 1288 Release 4.0 sec. 8, spatial non-uniformity of the dark signal at long
    exposure; J. R. Janesick, *Photon Transfer*, SPIE 2007): on the per-pixel dark slope map
    (:func:`dark_slope_map`, DN/s), the largest t-value over a grid of smooth fields rising to a corner
    or an edge (:func:`glow_fits`). The flat dark current (a constant per plane) is fitted with each
    field; DSNU and column FPN do not grow with the exposure and cancel in the slope; dark-current
    non-uniformity is pixel noise of the slope map, whose level the t-value is divided by (so an
    unmodelled DCNU does not lift it); row and column noise enter its variance through the field's
    row and column sums."""
    m = dark_slope_map(d)
    if m is None:
        return None
    return float(max(f[3] for f in glow_fits(m)))


STATISTICS = {name: globals()[name] for name in DIAGNOSTICS}

#: Smallest meaningful spread of a statistic (a floor for the bootstrap std):
#: counting statistics cannot resolve less than one pixel / one code.
def resolution(name: str, d: CaptureData) -> float:
    if name == "hot_pixel_tail":
        dm = d.dark_map()
        return 1.0 / dm[0].size if dm is not None else 0.0
    if name == "defect_pixels":  # one pixel
        fm = d.flat_map()
        return 1.0 / fm[0].size if fm is not None else 0.0
    if name == "telegraph_pixels":  # one pixel
        dm = d.dark_map()
        return 1.0 / dm[0].size if dm is not None else 0.0
    if name == "dark_tail_mass":
        x = dark_residual_sample(d)
        return 1.0 / x.size if x is not None else 0.0
    if name == "black_offset":  # one code of one plane of the dark mean map
        dm = d.dark_map()
        return 1.0 / (4 * dm[2]) if dm is not None else 0.0
    if name == "code_occupancy":  # one code of the span
        codes = code_grid_codes(d)
        span = float(codes.max() - codes.min()) + 1 if codes is not None else 1.0
        return 1.0 / max(span, 1.0)
    return 1e-12


def statistic(name: str, d: CaptureData) -> tuple[float | None, str | None]:
    """(value, None), or (None, reason) when the statistic is not applicable: the capture set lacks what
    it needs (:data:`NEEDS`), it is undefined on the data (:class:`NotApplicable`: a zero variance of
    quantised darks, constant lines), or numerically undefined (a non-finite value)."""
    try:
        with np.errstate(all="ignore"):
            v = STATISTICS[name](d)
    except NotApplicable as exc:
        return None, str(exc)
    except (ZeroDivisionError, FloatingPointError, np.linalg.LinAlgError) as exc:
        return None, f"undefined on these data ({type(exc).__name__}: {exc})"
    if v is None:
        return None, NEEDS[name]
    if not np.isfinite(v):
        return None, f"undefined on these data (value {v})"
    return float(v), None


def compute_all(d: CaptureData, names=DIAGNOSTICS, reasons: dict | None = None) -> dict:
    """{name: value or None (not applicable)}; the reason of each None goes into ``reasons`` when given."""
    out = {}
    for n in names:
        out[n], why = statistic(n, d)
        if why is not None and reasons is not None:
            reasons[n] = why
    return out


@dataclass
class Discrepancy:
    """Standardised discrepancy of a diagnostic: z = (T_data - mean_sim) / (sd_sim * sqrt(1 + 1/R));
    under the model z follows Student t with R - 1 degrees of freedom (predictive interval of a
    new draw from R simulated ones), giving the two-sided p-value (upper tail only for
    :data:`UPPER_TAIL`)."""

    name: str
    value: float
    sim_mean: float
    sim_sd: float
    z: float
    p: float
    significant: bool = False


#: diagnostics tested on their upper tail only: only an effect raises them, and a value below the null is
#: the skew of the statistic itself (``dark_checker_jitter`` is the log of a mean of a few chi-square(1)
#: terms, one per dark frame: its left tail is long, and a 6-frame dark set reached z = -5 with no effect)
UPPER_TAIL = frozenset({"dark_checker_jitter"})


#: statistics that are shares of pixels (a count over the number of pixels, :func:`resolution` being one
#: pixel): where the replicates count few pixels, tested as counts (:func:`count_law`)
COUNT_SHARES = frozenset({"defect_pixels", "telegraph_pixels", "hot_pixel_tail"})
#: statistics that are one minus a share (:func:`resolution` being one unit of it): the count is of what the
#: share leaves out (``code_occupancy``: the codes of the span no value uses)
COUNT_COMPLEMENTS = frozenset({"code_occupancy"})


def _counted(name: str, share):
    """The share a count statistic's count is of: the statistic, or one minus it (:data:`COUNT_COMPLEMENTS`)."""
    return 1.0 - share if name in COUNT_COMPLEMENTS else share


#: the replicates' mean count below which a count statistic takes the count law (above it, the t law on
#: the replicates' own spread, which also covers over-dispersion)
COUNT_LAW_MAX_MEAN = 3.0


def count_law(name: str, sims: np.ndarray, unit: float, null: float | None = None):
    """The predictive law of a new count for a :data:`COUNT_SHARES` or :data:`COUNT_COMPLEMENTS` statistic
    (of those, the count of what the share leaves out: a 5-DN ADC's darks on 2 codes of a 6-code span leave 4
    empty where a 1-DN model's replicates leave none), or None (use the t law).

    The replicates' counts (``sims / unit``) are taken as Poisson with rate lambda; with Jeffreys' prior
    the posterior of lambda is Gamma(S + 1/2, rate R) (S their sum over R replicates), and a new count
    is negative binomial with ``r = S + 1/2`` and success probability ``R / (R + 1)`` (A. Gelman et al.,
    *Bayesian Data Analysis*, 3rd ed., sec. 2.6 and 3.7's gamma-Poisson). Where every replicate counts 0
    defects and the data 5, the t law has only its one-pixel floor for the spread (z = 5, p ~ 5e-4 with
    15 degrees of freedom); the count law gives p ~ 4e-7. It is used where the replicates' mean count is
    under :data:`COUNT_LAW_MAX_MEAN` (a few pixels: the t law's continuous spread does not describe a
    count there) and they are no more dispersed than Poisson; elsewhere the t law on their own spread.

    ``null``: the closed-form bound on the count of a model without the pixels' effect (:func:`count_null`).
    Where every replicate counts 0 and the bound is below the predictive mean above (``1 / (2R)``), the
    new count is Poisson with the bound as its mean (a few replicates cannot bound a rate the physics puts
    at 1e-10); a larger bound says nothing the replicates do not (constant or quantisation-dominated frames).
    """
    if name not in COUNT_SHARES | COUNT_COMPLEMENTS or not unit > 0 or sims.size < 2:
        return None
    c = np.round(_counted(name, np.asarray(sims, dtype=np.float64)) / unit)
    if null is not None and not c.any() and null < 0.5 / c.size:
        return sst.poisson(max(float(null), COUNT_NULL_MIN))
    if c.mean() >= COUNT_LAW_MAX_MEAN or c.var(ddof=1) > max(c.mean(), 0.0):
        return None
    R = c.size
    return sst.nbinom(float(c.sum()) + 0.5, R / (R + 1.0))


def count_p_value(n_obs: int, law) -> float:
    """Two-sided p-value of the count ``n_obs`` under the discrete ``law`` (twice the smaller tail; at least
    1e-300, so that its z is finite)."""
    return max(min(1.0, 2.0 * min(float(law.sf(n_obs - 1)), float(law.cdf(n_obs)))), 1e-300)


def discrepancy(name: str, value: float, sims: list[float], floor: float, null: float | None = None) -> Discrepancy:
    s = np.asarray(sims, dtype=np.float64)
    R = s.size
    sd = max(float(s.std(ddof=1)), floor)
    law = count_law(name, s, floor, null)
    if law is not None:
        p = count_p_value(int(round(_counted(name, value) / floor)), law)
        diff = value - float(s.mean())
        z = float(np.sign(diff) * sst.t.isf(p / 2, R - 1)) if p < 1 else 0.0
        return Discrepancy(name, float(value), float(s.mean()), sd, z, p)
    z = (value - float(s.mean())) / (sd * np.sqrt(1 + 1 / R))
    p = float(sst.t.sf(z, R - 1) if name in UPPER_TAIL else 2 * sst.t.sf(abs(z), R - 1))
    return Discrepancy(name, float(value), float(s.mean()), sd, float(z), p)


def holm(discs: list[Discrepancy], alpha: float) -> list[Discrepancy]:
    """Mark significance by Holm's step-down procedure at family-wise level ``alpha``."""
    order = sorted(discs, key=lambda x: x.p)
    m = len(order)
    for k, dsc in enumerate(order):
        if dsc.p <= alpha / (m - k):
            dsc.significant = True
        else:
            break
    return discs
