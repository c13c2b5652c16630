"""Ground truth from a burst: the Abdelhamed 2020, section 5.3 pipeline, streamed.

Steps (Abdelhamed 2020, fig. 5.4): defective-pixel correction (5.3.1), frame outlier removal
and intensity alignment (5.3.2, eq. 5.4), reference choice (eq. 5.5) and dense
local alignment (5.3.3), robust per-pixel mean (5.3.4, eq. 5.6-5.12).

Memory: two input frames at a time (pass A reads the next frame on a second thread while it sums
one: :func:`_prefetched`); the working frames live in a
:class:`FrameStore` (RAM when they fit ``memory_budget_bytes``, else a scratch
file), and the robust mean runs on row tiles of ``tile_pixels`` pixels. The
result does not depend on the tiling (every estimator is per pixel).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ..errors import DatasetError
from ..parallel import map_threads, run_bands, threads
from .alignment import (ALIGN_MODES, constant_field, dense_field, field_stats, global_shift, local_shifts,
                        prepare_reference, reject_outliers, warp)
from .burst import Burst
from .defects import DefectMap, correct_defects, detect_defects_dark, detect_hot_flat
from .intensity import align_intensity, frame_outliers
from .robust_mean import METHODS, robust_mean
from .store import FrameStore

_EPS = 1e-6


@dataclass
class GroundTruthConfig:
    """Settings of :func:`estimate_ground_truth` (defaults follow Abdelhamed 2020 where it says).

    Parameters
    ----------
    method, refine, uncensored_mean, nlf, min_samples, alignment, patch, stride, upsample, normalization
        The robust mean and the alignment (see the comments on the fields).
    tps_smoothing, outlier_px, interp_order, intensity, drop_outliers, outlier_confidence
        The warp and the frame-intensity steps.
    robust_outliers, defect_confidence, ...
        The outlier and defect intervals, and the remaining fields (all with defaults).

    Attributes
    ----------
    fields
        As the parameters; :meth:`check` validates them.

    Examples
    --------
    >>> cfg = GroundTruthConfig(method="mle", alignment="global")
    >>> cfg.method, cfg.patch, cfg.outlier_confidence
    ('mle', 512, 0.999)
    """

    method: str = "wls"               #: robust mean: wls (Abdelhamed 2020), mle (censored MLE) or mean (plain)
    refine: int = 0                   #: Gauss-Newton steps on eq. 5.10 after the closed form (wls)
    uncensored_mean: bool = True      #: pixels without censored samples get the plain mean (efficient)
    #: wls sigma: "auto" = sigma from an NLF (beta1, beta2) fitted to the burst's own unclipped pixels
    #: (extension: far less noisy than a per-pixel sigma on clipped pixels); a known (beta1, beta2);
    #: or None = sigma fitted per pixel as in Abdelhamed 2020 (eq. 5.10)
    nlf: tuple[float, float] | str | None = "auto"
    min_samples: int = 3              #: fewest uncensored samples for a fit; fewer -> fallback, invalid
    alignment: str = "local"          #: local (TPS from patch shifts), global (one shift), none
    patch: int = 512                  #: patch size, mosaic pixels (Abdelhamed 2020: 512); shrinks for small frames
    stride: int | None = None         #: patch stride, mosaic pixels (default patch / 2; Abdelhamed 2020: 256)
    upsample: int = 4                 #: correlation grid 1/upsample px around the peak, then a parabola
    normalization: str | None = None  #: cross-power normalisation: None (cross-correlation) or "phase"
    tps_smoothing: float = 0.0        #: RBFInterpolator smoothing of the thin-plate spline
    outlier_px: float = 1.0           #: landmark shifts this far from their 3x3 median are dropped
    interp_order: int = 3             #: warp interpolation: 3 cubic, 1 linear
    intensity: str = "additive"       #: eq. 5.4 (additive), multiplicative, or none
    drop_outliers: bool = True        #: drop frames whose mean is outside the confidence interval
    outlier_confidence: float = 0.999
    robust_outliers: bool = True      #: median/MAD for the frame-mean interval (see intensity.py)
    defect_confidence: float = 0.999
    defect_side: str = "both"
    tile_pixels: int = 1 << 18        #: pixels per robust-mean tile
    memory_budget_bytes: int = 2 << 30  #: working frames kept in RAM below this, else a scratch file
    scratch_dir: str | None = None
    min_frames: int = 3

    def check(self) -> None:
        if self.method not in METHODS:
            raise DatasetError(f"ground truth: method: expected one of {METHODS}, got {self.method!r}")
        if self.alignment not in ALIGN_MODES:
            raise DatasetError(f"ground truth: alignment: expected one of {ALIGN_MODES}, got {self.alignment!r}")
        if self.interp_order not in (1, 3):
            raise DatasetError(f"ground truth: interp_order: expected 1 or 3, got {self.interp_order}")
        if self.min_frames < 3:
            raise DatasetError(f"ground truth: min_frames: expected >= 3, got {self.min_frames}")
        if isinstance(self.nlf, str) and self.nlf != "auto":
            raise DatasetError(f"ground truth: nlf: expected 'auto', (beta1, beta2) or None, got {self.nlf!r}")


def fit_burst_nlf(store, kept, shape, rows: int, *, max_tiles: int = 64, bins: int = 64):
    """Fit ``var = beta1 * mean + beta2`` (Abdelhamed 2020, eq. 3.8) to the aligned burst's unclipped pixels.

    Per-pixel temporal mean and variance (ddof 1) of pixels with no censored or missing
    sample, from up to ``max_tiles`` evenly spread row tiles; pixels binned by mean
    (quantiles), then weighted least squares with weights ``count / var_bin^2`` (the
    variance of a sample variance is ``2 var^2 / (n - 1)``). Returns ``(beta1, beta2)``
    (beta1 > 0, beta2 >= 0), or None when too few pixels or a degenerate fit.
    """
    H, W = shape
    starts = list(range(0, H, rows))
    step = max(1, len(starts) // max_tiles)
    means, vars_ = [], []
    for r0 in starts[::step]:
        block = store.rows(kept, r0, min(H, r0 + rows)).reshape(kept.size, -1).astype(np.float64)
        ok = np.isfinite(block).all(axis=0)
        if ok.any():
            b = block[:, ok]
            means.append(b.mean(axis=0))
            vars_.append(b.var(axis=0, ddof=1))
    if not means:
        return None
    m, v = np.concatenate(means), np.concatenate(vars_)
    if m.size < 4 * bins:
        return None
    edges = np.unique(np.quantile(m, np.linspace(0, 1, bins + 1)))
    if edges.size < 3:  # (nearly) one intensity: the slope is not identifiable
        return None
    idx = np.clip(np.searchsorted(edges, m, side="right") - 1, 0, edges.size - 2)
    cnt = np.bincount(idx, minlength=edges.size - 1).astype(np.float64)
    use = cnt > 1
    mb = np.bincount(idx, weights=m, minlength=cnt.size)[use] / cnt[use]
    vb = np.bincount(idx, weights=v, minlength=cnt.size)[use] / cnt[use]
    w = cnt[use] / np.maximum(vb, 1e-30) ** 2
    A = np.stack([mb, np.ones_like(mb)], axis=1)
    try:
        beta1, beta2 = np.linalg.solve(A.T @ (A * w[:, None]), A.T @ (w * vb))
    except np.linalg.LinAlgError:
        return None
    if not (np.isfinite(beta1) and np.isfinite(beta2)) or beta1 <= 0:
        return None
    return float(beta1), float(max(beta2, 0.0))


@dataclass
class GroundTruth:
    """Estimated ground truth of the reference frame.

    Attributes
    ----------
    gt : float32 H x W
        Normalised raw estimate (the reference frame's geometry).
    sigma : float32 H x W
        Per-pixel noise standard deviation of one sample (normalised raw).
    valid : bool H x W
        False where the robust fit fell back (too few uncensored samples).
    defects : bool H x W
        Pixels treated as defective (interpolated before averaging).
    n_used : int16 H x W
        Uncensored samples per pixel that entered the estimate.
    reference : int
        Index of the reference frame in the burst (eq. 5.5).
    report : dict
        JSON-friendly account of every step.

    Parameters
    ----------
    gt, sigma, valid, defects, n_used, reference, report
        As the attributes.

    Examples
    --------
    >>> import numpy as np
    >>> z = np.zeros((2, 2), np.float32)
    >>> g = GroundTruth(z, z, np.ones((2, 2), bool), np.zeros((2, 2), bool), np.full((2, 2), 5, np.int16), 0)
    >>> g.reference, int(g.n_used.sum())
    (0, 20)
    """

    gt: np.ndarray
    sigma: np.ndarray
    valid: np.ndarray
    defects: np.ndarray
    n_used: np.ndarray
    reference: int
    report: dict[str, Any] = field(default_factory=dict)

    def save_npz(self, path: str | Path) -> Path:
        """Write ``gt``, ``sigma``, ``defects``, ``valid``, ``n_used`` (compressed npz, deterministic bytes)."""
        from ..io.npz import write_npz

        return write_npz(path, {"gt": self.gt, "sigma": self.sigma, "defects": self.defects, "valid": self.valid,
                                "n_used": self.n_used, "reference": np.int64(self.reference)})


def _bar(progress: bool, total: int, desc: str):
    if not progress:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="frame", leave=False)


def _tick(bar) -> None:
    if bar is not None:
        bar.update(1)


def _close(bar) -> None:
    if bar is not None:
        bar.close()


def _prefetched(burst: Burst, n: int):
    """``burst.load(i)`` for i < n, in order, each frame read on a second thread while the caller works on
    the one before (a DNG's decode releases the GIL), when :func:`simcam.parallel.threads` allows more than
    one (a batch worker runs on one). Pass A's sums stay in frame order, so the result is the same bytes; a
    frame that fails to load raises when its turn comes, as a plain loop would."""
    from concurrent.futures import ThreadPoolExecutor

    if n == 0:
        return
    if threads() < 2:
        yield from (burst.load(i) for i in range(n))
        return
    with ThreadPoolExecutor(1, thread_name_prefix="simcam-gt-load") as ex:
        ahead = ex.submit(burst.load, 0)
        for i in range(n):
            x = ahead.result()
            if i + 1 < n:
                ahead = ex.submit(burst.load, i + 1)
            yield x


def stream_mean(burst: Burst, shape: tuple[int, int] | None = None, what: str = "dark") -> np.ndarray:
    """Mean image of a burst (float32), one frame at a time; checks the size against ``shape``.

    Parameters
    ----------
    burst : Burst
        The frames (a dark or a flat sequence).
    shape : (int, int), optional
        The size every frame must have (that of the burst to estimate).
    what : str
        What the burst is, for the error message.

    Returns
    -------
    ndarray
        float32 H x W mean of the frames.

    Examples
    --------
    >>> darks = Burst.from_arrays([np.full((4, 4), v) for v in (0.1, 0.3)], cfa="RGGB")
    >>> m = stream_mean(darks, (4, 4))
    >>> m.shape, round(float(m.mean()), 3)
    ((4, 4), 0.2)
    """
    acc = None
    for i in range(len(burst)):
        x = burst.load(i)
        if shape is not None and x.shape != tuple(shape):
            raise DatasetError(f"{burst.names[i]}: {what} frame shape {x.shape}, expected {tuple(shape)} like the burst")
        acc = x.astype(np.float64) if acc is None else acc + x
    if acc is None:
        raise DatasetError(f"{what} sequence: no frames")
    return (acc / len(burst)).astype(np.float32)


def estimate_ground_truth(burst: Burst, *, dark: Burst | None = None, flat: Burst | None = None,
                          defects: DefectMap | None = None, config: GroundTruthConfig | None = None,
                          progress: bool = False) -> GroundTruth:
    """Estimate the noise-free image of a burst (Abdelhamed 2020, section 5.3).

    Parameters
    ----------
    burst : Burst
        The frames (normalised raw, one scene, one ISO / exposure), at least 3.
    dark : Burst, optional
        A dark sequence: defective pixels from its mean image (Abdelhamed 2020, section 5.3.1).
    flat : Burst, optional
        A flat sequence: more defective (hot/dead) pixels from its shading-free mean.
    defects : DefectMap, optional
        A known defect map (e.g. :func:`load_defect_map`), combined with the above.
    config : GroundTruthConfig
    progress : bool
        Show tqdm progress bars on stderr.

    Returns
    -------
    GroundTruth
        ``gt`` (float32 normalised raw), ``sigma``, ``defects``, ``valid`` and a report.

    Examples
    --------
    >>> import numpy as np
    >>> from simcam.groundtruth import Burst, SyntheticBurst
    >>> sb = SyntheticBurst(shape=(64, 64), n=8, beta1=1e-4, beta2=1e-6, drift_px=0.0, seed=1)
    >>> burst = Burst.from_arrays([sb.frame(i) for i in range(8)], cfa="RGGB")
    >>> g = estimate_ground_truth(burst, config=GroundTruthConfig(alignment="none"))
    >>> noise = float(np.std(sb.frame(0) - sb.truth(0)))
    >>> float(np.std(g.gt - sb.truth(0))) < noise / 2  # eight frames: about noise / sqrt(8)
    True
    """
    cfg = config or GroundTruthConfig()
    cfg.check()
    N = len(burst)
    if N < cfg.min_frames:
        raise DatasetError(f"burst: {N} frame(s); expected at least {cfg.min_frames} for a ground truth")
    t0 = time.perf_counter()
    timing: dict[str, float] = {}
    lo, hi = float(burst.clip_low), float(burst.clip_high)

    first = burst.load(0)
    shape, cfa = first.shape, burst.cfa
    del first

    # -- 1. defective pixels ---------------------------------------------------------------------
    dmap = None
    if defects is not None:
        if defects.mask.shape != shape:
            raise DatasetError(f"{defects.source}: defect mask shape {defects.mask.shape}, expected {shape} (the frames)")
        dmap = defects
    for seq, fn, what in ((dark, detect_defects_dark, "dark"), (flat, detect_hot_flat, "flat")):
        if seq is None:
            continue
        if seq.cfa is not None and cfa is not None and seq.cfa != cfa:
            raise DatasetError(f"{seq.names[0]}: cfa {seq.cfa!r}, expected {cfa!r} like the burst")
        m = fn(stream_mean(seq, shape, what), cfa, confidence=cfg.defect_confidence, side=cfg.defect_side)
        m.source = f"{what}:{len(seq)} frames"
        dmap = m if dmap is None else dmap | m
    dmask = dmap.mask if dmap is not None else np.zeros(shape, dtype=bool)
    timing["defects"] = time.perf_counter() - t0

    store = FrameStore(N, shape, budget_bytes=cfg.memory_budget_bytes, scratch_dir=cfg.scratch_dir)
    try:
        return _run(burst, cfg, store, shape, cfa, lo, hi, dmap, dmask, timing, t0, progress)
    finally:
        store.close()


def _run(burst, cfg, store, shape, cfa, lo, hi, dmap, dmask, timing, t0, progress) -> GroundTruth:
    N = len(burst)
    # -- 2. pass A: load, correct defects, frame means -----------------------------------------
    t = time.perf_counter()
    means = np.empty(N)
    acc = np.zeros(shape, dtype=np.float64)
    acc_scaled = np.zeros(shape, dtype=np.float64) if cfg.intensity == "multiplicative" else None
    any_nan = False
    bar = _bar(progress, N, "gt: load")
    for i, x in enumerate(_prefetched(burst, N)):
        if dmap is not None and dmask.any():
            x = correct_defects(x, dmask, cfa)
        nan = np.isnan(x)
        any_nan |= bool(nan.any())
        means[i] = float(np.nanmean(x)) if not nan.all() else np.nan
        if not np.isfinite(means[i]):
            raise DatasetError(f"{burst.names[i]}: every sample is missing (NaN)")
        store.put(i, x)
        xn = np.where(nan, 0.0, x)
        acc += xn
        if acc_scaled is not None:
            if means[i] == 0:
                raise DatasetError(f"{burst.names[i]}: frame mean is 0; multiplicative intensity alignment impossible")
            acc_scaled += xn / means[i]
        _tick(bar)
    _close(bar)
    timing["load"] = time.perf_counter() - t

    # -- 3. intensity outliers and alignment (eq. 5.4) ----------------------------------------
    if cfg.drop_outliers:
        io = frame_outliers(means, confidence=cfg.outlier_confidence, robust=cfg.robust_outliers)
    else:
        io = frame_outliers(means, confidence=1.0 - 1e-15, robust=cfg.robust_outliers)
        io.keep[:] = True
        io.mu_a = float(means.mean())
    kept = np.nonzero(io.keep)[0]
    if kept.size < cfg.min_frames:
        raise DatasetError(f"burst: only {kept.size} frame(s) left after dropping intensity outliers "
                           f"{[burst.names[i] for i in np.nonzero(~io.keep)[0]]}; expected at least {cfg.min_frames}")
    for j in np.nonzero(~io.keep)[0]:
        x = store.get(j)
        xn = np.where(np.isnan(x), 0.0, x)
        acc -= xn
        if acc_scaled is not None:
            acc_scaled -= xn / means[j]
    mu_a = io.mu_a
    if cfg.intensity == "multiplicative":
        x_a = (acc_scaled * (mu_a / kept.size)).astype(np.float32)
    else:
        x_a = (acc / kept.size).astype(np.float32)
    del acc, acc_scaled

    def aligned(i):
        return align_intensity(store.get(i), means[i], mu_a, cfg.intensity)

    # -- 4. reference frame (eq. 5.5) -------------------------------------------------------------
    t = time.perf_counter()
    dist = np.full(N, np.inf)
    bar = _bar(progress, kept.size, "gt: reference")

    def distance(i):  # frames on threads (numpy releases the GIL); each its own entry of dist
        d = aligned(i) - x_a
        dist[i] = float(np.sqrt(np.nansum(d.astype(np.float64) ** 2)))
        _tick(bar)

    map_threads(distance, [int(i) for i in kept])
    _close(bar)
    ref_idx = int(np.argmin(dist))
    timing["reference"] = time.perf_counter() - t

    # -- 5. spatial alignment, censoring marks --------------------------------------------------
    t = time.perf_counter()
    ref_img = aligned(ref_idx)
    if any_nan:
        ref_img = np.where(np.isnan(ref_img), x_a, ref_img)
    reference = None
    if cfg.alignment != "none":
        reference = prepare_reference(ref_img, cfa, patch=cfg.patch, stride=cfg.stride, upsample=cfg.upsample,
                                      normalization=cfg.normalization)
    censor = cfg.method != "mean"
    bar = _bar(progress, kept.size, "gt: align")

    def align_frame(i) -> dict:  # frame i only (its own slot of the store): frames run on threads
        raw = store.get(i)
        x = align_intensity(raw, means[i], mu_a, cfg.intensity)
        nan = np.isnan(x)
        has_nan = bool(nan.any())
        if has_nan:
            x = np.where(nan, x_a, x)
        info: dict[str, Any] = {"index": int(i)}
        fieldmap = None
        if reference is not None and i != ref_idx:
            if cfg.alignment == "local":  # BLAS on one thread: see the map_threads call below
                lm, sh, rel = local_shifts(reference, x)
                keep = reject_outliers(reference.grid, sh, rel, cfg.outlier_px)
                fieldmap = (dense_field(lm[keep], sh[keep], shape, cfa, smoothing=cfg.tps_smoothing)
                            if keep.any() else None)
                info["landmarks_unreliable"] = int((~rel).sum())
                info["landmarks_rejected"] = int((rel & ~keep).sum())
                if fieldmap is None:  # no structure to register against: leave the frame where it is
                    fieldmap = constant_field(np.zeros(2), shape, cfa)
            else:
                shift, ok = global_shift(reference, x)
                info["unreliable"] = not ok
                fieldmap = constant_field(shift if ok else np.zeros(2), shape, cfa)
            info.update(field_stats(fieldmap))
            if info["max_px"] > 0:
                x = warp(x, fieldmap, cfa, order=cfg.interp_order)
            else:
                fieldmap = None
        if censor:
            low = raw <= lo + _EPS
            high = raw >= hi - _EPS
            x = np.clip(x, lo + 2 * _EPS, hi - 2 * _EPS)
            if low.any() or high.any():
                flag = low.astype(np.int8) - high.astype(np.int8)  # +1 low, -1 high
                if fieldmap is not None:
                    flag = warp(flag, fieldmap, cfa, order=0)
                x[flag > 0] = -np.inf
                x[flag < 0] = np.inf
        if has_nan:
            if fieldmap is not None:
                nan = warp(nan.astype(np.int8), fieldmap, cfa, order=0) > 0
            x[nan] = np.nan
        store.put(i, x)
        _tick(bar)
        return info

    # The matrix DFT and the thin-plate spline are BLAS products whose rounding depends on the BLAS
    # thread count: one thread, so the field is the same bytes on any machine. The limit is set here,
    # once around all frames: threadpoolctl's limit is process-wide, and entered and left in each
    # frame's thread, one frame's exit restored the BLAS threads while another frame was still inside
    # (ground truths that differed from run to run in their last bits with 2 threads).
    with threadpool_limits(limits=1, user_api="blas"):
        per_frame = map_threads(align_frame, [int(i) for i in kept])
    _close(bar)
    timing["align"] = time.perf_counter() - t

    # -- 6. robust mean, row tiles ---------------------------------------------------------------
    t = time.perf_counter()
    H, W = shape
    gt = np.empty(shape, dtype=np.float32)
    sigma = np.empty(shape, dtype=np.float32)
    valid = np.empty(shape, dtype=bool)
    n_used = np.empty(shape, dtype=np.int16)
    n_cens = np.empty(shape, dtype=np.int16)
    rows = max(1, int(cfg.tile_pixels) // W)
    kw: dict[str, Any] = {"min_samples": cfg.min_samples}
    if cfg.method != "mean":
        kw["uncensored_mean"] = cfg.uncensored_mean
    nlf_used = None
    if cfg.method == "wls":
        kw["refine"] = cfg.refine
        if isinstance(cfg.nlf, str):
            nlf_used = fit_burst_nlf(store, kept, shape, max(1, int(cfg.tile_pixels) // shape[1]))
        elif cfg.nlf is not None:
            nlf_used = tuple(float(v) for v in cfg.nlf)
        if nlf_used is not None:
            kw["nlf"] = nlf_used
    # censored samples are marked +-inf above, so the clip points themselves only matter for MLE
    flo, fhi = (lo, hi)
    bar = _bar(progress, len(range(0, H, rows)), "gt: robust mean")

    def tile(r0: int, r1: int) -> None:  # rows r0:r1 only: tiles run on threads, same bytes for any count
        block = store.rows(kept, r0, r1).reshape(kept.size, -1)
        res = robust_mean(block, cfg.method, lo=flo, hi=fhi, **kw)
        gt[r0:r1] = res.mu.reshape(r1 - r0, W)
        sigma[r0:r1] = res.sigma.reshape(r1 - r0, W)
        valid[r0:r1] = res.valid.reshape(r1 - r0, W)
        n_used[r0:r1] = res.n_used.reshape(r1 - r0, W)
        n_cens[r0:r1] = (res.n_low + res.n_high).reshape(r1 - r0, W)
        _tick(bar)

    with threadpool_limits(limits=1, user_api="blas"):  # the tiles are the parallelism
        run_bands(H, tile, rows=rows)
    _close(bar)
    timing["robust_mean"] = time.perf_counter() - t
    timing["total"] = time.perf_counter() - t0

    mags = [f["max_px"] for f in per_frame if "max_px" in f]
    report = {
        "frames": N,
        "frames_used": int(kept.size),
        "shape": list(shape),
        "cfa": cfa,
        "clip": [lo, hi],
        "intensity": {"mode": cfg.intensity, "mu_a": float(mu_a), "sigma_a": float(io.sigma_a),
                      "z_limit": float(io.limit), "means": [float(m) for m in means]},
        "dropped": [{"index": int(j), "name": burst.names[j], "mean": float(means[j]), "z": float(io.z[j])}
                    for j in np.nonzero(~io.keep)[0]],
        "reference": {"index": ref_idx, "name": burst.names[ref_idx]},
        "defects": dmap.summary() if dmap is not None else {"count": 0},
        "alignment": {
            "mode": cfg.alignment,
            "patch_px": (reference.grid.size * reference.grid.step) if reference is not None else None,
            "stride_px": (reference.grid.stride * reference.grid.step) if reference is not None else None,
            "landmarks": (len(reference.grid.ys) * len(reference.grid.xs)) if reference is not None else 0,
            "max_shift_px": float(max(mags)) if mags else 0.0,
            "mean_shift_px": float(np.mean([f["mean_px"] for f in per_frame if "mean_px" in f])) if mags else 0.0,
            "per_frame": per_frame,
        },
        "robust_mean": {"method": cfg.method, "refine": cfg.refine if cfg.method == "wls" else None,
                        "nlf": list(nlf_used) if nlf_used is not None else None,
                        "nlf_source": ("burst fit" if isinstance(cfg.nlf, str) else "given" if cfg.nlf is not None
                                       else "per-pixel sigma") if cfg.method == "wls" else None,
                        "uncensored_mean": cfg.uncensored_mean if cfg.method != "mean" else None,
                        "pixels_with_censored_samples": int(np.count_nonzero(n_cens)),
                        "fallback_pixels": int(np.count_nonzero(~valid)),
                        "median_sigma": float(np.median(sigma))},
        "scratch": "file" if store.on_disk else "memory",
        "timing_s": {k: round(v, 3) for k, v in timing.items()},
        "config": dataclasses.asdict(cfg),
    }
    return GroundTruth(gt, sigma, valid, dmask.copy(), n_used, ref_idx, report)
