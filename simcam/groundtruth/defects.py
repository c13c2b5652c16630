"""Defective-pixel detection and correction (Abdelhamed 2020, section 5.3.1).

Detection: the mean image of a dark sequence (or of a flat sequence, after
removing its smooth shading), one Gaussian per CFA plane fitted to its values by
WLS on the CDF (the same estimator as the robust mean, Abdelhamed 2020, eq. 5.10-5.11), and
every pixel outside the central ``confidence`` interval of that Gaussian flagged.
Correction: cubic interpolation from same-colour neighbours within each CFA plane.

A :class:`DefectMap` saves to ``.npz`` and loads from ``.npz`` or from the SIDD
``DefectivePixelsMask_*.mat`` files.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np
from scipy import ndimage, special

from ..errors import DatasetError
from .planes import plane_offsets, plane_step, planes
from .robust_mean import wls_cdf_fit


@dataclass
class DefectMap:
    """Boolean H x W map of defective pixels plus how it was found.

    ``stats`` holds, per CFA plane, the fitted ``mu`` and ``sigma`` (normalised
    raw) and the interval limits used.

    Parameters
    ----------
    mask : ndarray of bool, H x W
        True at a defective pixel.
    source : str
        How it was found (a file, ``dark``, ``flat``).
    stats : list of dict
        Per CFA plane: the fitted ``mu``, ``sigma`` and the interval limits.

    Attributes
    ----------
    mask, source, stats
        As the parameters; ``count`` is the number of defective pixels.

    Examples
    --------
    >>> import numpy as np
    >>> m = np.zeros((4, 4), bool)
    >>> m[1, 2] = True
    >>> (DefectMap(m, "dark") | DefectMap(m.T, "flat")).count
    2
    """

    mask: np.ndarray
    source: str = ""
    stats: list[dict[str, Any]] = field(default_factory=list)

    @property
    def count(self) -> int:
        return int(np.count_nonzero(self.mask))

    def __or__(self, other: "DefectMap") -> "DefectMap":
        if self.mask.shape != other.mask.shape:
            raise DatasetError(f"{other.source}: defect map shape {other.mask.shape}, expected {self.mask.shape}")
        return DefectMap(self.mask | other.mask, f"{self.source}+{other.source}", self.stats + other.stats)

    def summary(self) -> dict[str, Any]:
        return {"source": self.source, "count": self.count,
                "fraction": float(self.count / max(self.mask.size, 1)), "planes": self.stats}


def fit_gaussian_wls(values: np.ndarray, *, max_points: int = 200_000) -> tuple[float, float]:
    """Gaussian (mu, sigma) of a set of values by WLS fit of the normal CDF (Abdelhamed 2020, section 5.3.1).

    For more than ``max_points`` values the fit uses ``max_points`` evenly spaced
    order statistics (the empirical CDF sampled at their plotting positions),
    which leaves the estimate unchanged to well below its standard error.

    Parameters
    ----------
    values : ndarray
        The sample (any shape; flattened).
    max_points : int
        Most order statistics the fit uses.

    Returns
    -------
    (float, float)
        ``mu`` and ``sigma``.

    Examples
    --------
    >>> import numpy as np
    >>> mu, sigma = fit_gaussian_wls(np.random.default_rng(2).normal(1.0, 0.1, 5000))
    >>> round(mu, 2), round(sigma, 2)
    (1.0, 0.1)
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[np.isfinite(v)]
    if v.size < 3:
        raise DatasetError(f"defect detection: expected at least 3 finite pixel values, got {v.size}")
    if v.size > max_points:
        v = np.sort(v)
        idx = np.round((np.arange(max_points) + 0.5) / max_points * v.size - 0.5).astype(np.int64)
        v = v[np.clip(idx, 0, v.size - 1)]
    r = wls_cdf_fit(v[:, None], lo=-np.inf, hi=np.inf, refine=3)
    return float(r.mu[0]), float(r.sigma[0])


def _flag(mean_image: np.ndarray, cfa: str | None, confidence: float, side: str, what: str,
          residual: bool) -> DefectMap:
    if not 0.5 < confidence < 1.0:
        raise DatasetError(f"defect detection: confidence: expected a value in (0.5, 1), got {confidence}")
    if side not in ("both", "high", "low"):
        raise DatasetError(f"defect detection: side: expected both, high or low, got {side!r}")
    img = np.asarray(mean_image, dtype=np.float32)
    mask = np.zeros(img.shape, dtype=bool)
    k = float(special.ndtri(0.5 + confidence / 2.0))  # two-sided interval half-width in sigmas
    stats = []
    s = plane_step(cfa)
    for (dy, dx), p in zip(plane_offsets(cfa), planes(img, cfa)):
        vals = p - ndimage.median_filter(p, size=7, mode="reflect") if residual else p
        mu, sg = fit_gaussian_wls(vals)
        lo, hi = mu - k * sg, mu + k * sg
        flag = np.zeros(p.shape, dtype=bool)
        if side in ("both", "high"):
            flag |= vals > hi
        if side in ("both", "low"):
            flag |= vals < lo
        mask[dy::s, dx::s] = flag
        stats.append({"plane": [dy, dx], "mu": mu, "sigma": sg, "low": lo, "high": hi,
                      "flagged": int(flag.sum())})
    return DefectMap(mask, what, stats)


def detect_defects_dark(dark_mean: np.ndarray, cfa: str | None, *, confidence: float = 0.999,
                        side: str = "both") -> DefectMap:
    """Defective pixels from the mean image of a dark sequence (Abdelhamed 2020, section 5.3.1).

    Parameters
    ----------
    dark_mean : ndarray, H x W
        Mean of the dark frames, normalised raw.
    cfa : str or None
        Bayer pattern (one Gaussian per plane) or None for a mono sensor.
    confidence : float
        Central probability of the fitted N(mu_dark, sigma_dark) kept as normal
        (Abdelhamed 2020: 0.999, i.e. |x - mu| > 3.29 sigma is defective).
    side : {"both", "high", "low"}
        Which tail is flagged (hot/stuck are high, dead are low).

    Returns
    -------
    DefectMap
        The flagged pixels, with the fitted Gaussian of each CFA plane in ``stats``.

    Examples
    --------
    >>> import numpy as np
    >>> dark = np.random.default_rng(0).normal(0.01, 0.001, (16, 16)).astype(np.float32)
    >>> dark[5, 6] = 0.2  # a hot pixel
    >>> np.argwhere(detect_defects_dark(dark, "RGGB").mask).tolist()
    [[5, 6]]
    """
    return _flag(dark_mean, cfa, confidence, side, "dark", residual=False)


def detect_hot_flat(flat_mean: np.ndarray, cfa: str | None, *, confidence: float = 0.999,
                    side: str = "both") -> DefectMap:
    """Defective pixels from the mean image of a flat sequence.

    The smooth shading is removed by a 7x7 median per CFA plane first; the
    residual is fitted and thresholded like :func:`detect_defects_dark`.

    Parameters
    ----------
    flat_mean : ndarray, H x W
        Mean of the flat frames, normalised raw.
    cfa, confidence, side
        As :func:`detect_defects_dark`.

    Returns
    -------
    DefectMap
        Pixels outside the interval of their plane's shading residual.

    Examples
    --------
    >>> import numpy as np
    >>> flat = 0.5 + np.random.default_rng(1).normal(0, 0.001, (16, 16)).astype(np.float32)
    >>> flat[9, 4] = 0.9
    >>> bool(detect_hot_flat(flat, "RGGB").mask[9, 4])
    True
    """
    return _flag(flat_mean, cfa, confidence, side, "flat", residual=True)


_CUBIC = np.array([-1.0, 4.0, 4.0, -1.0]) / 6.0  # Lagrange cubic through -2,-1,+1,+2 evaluated at 0


def _fill_plane(p: np.ndarray, bad: np.ndarray, max_rounds: int = 16) -> int:
    """Fill ``bad`` pixels of one plane in place; returns how many needed the global fallback."""
    h, w = p.shape
    bad = bad.copy()
    for _ in range(max_rounds):
        ys, xs = np.nonzero(bad)
        if ys.size == 0:
            return 0
        good = ~bad
        est_sum = np.zeros(ys.size)
        est_n = np.zeros(ys.size)
        for ay, ax in ((0, 1), (1, 0)):
            offs = (-2, -1, 1, 2)
            vals, oks = [], []
            for o in offs:
                yy, xx = ys + ay * o, xs + ax * o
                inb = (yy >= 0) & (yy < h) & (xx >= 0) & (xx < w)
                yc, xc = np.clip(yy, 0, h - 1), np.clip(xx, 0, w - 1)
                vals.append(p[yc, xc].astype(np.float64))
                oks.append(inb & good[yc, xc])
            cubic_ok = oks[0] & oks[1] & oks[2] & oks[3]
            lin_ok = oks[1] & oks[2] & ~cubic_ok
            cub = sum(c * v for c, v in zip(_CUBIC, vals))
            lin = 0.5 * (vals[1] + vals[2])
            est_sum += np.where(cubic_ok, cub, 0.0) + np.where(lin_ok, lin, 0.0)
            est_n += cubic_ok | lin_ok
        # pixels without a same-line pair: mean of any good 8-neighbour
        none = est_n == 0
        if none.any():
            acc = np.zeros(ys.size)
            cnt = np.zeros(ys.size)
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    if dy == 0 and dx == 0:
                        continue
                    yy, xx = ys + dy, xs + dx
                    inb = (yy >= 0) & (yy < h) & (xx >= 0) & (xx < w)
                    yc, xc = np.clip(yy, 0, h - 1), np.clip(xx, 0, w - 1)
                    ok = inb & good[yc, xc] & none
                    acc += np.where(ok, p[yc, xc], 0.0)
                    cnt += ok
            est_sum = np.where(none, acc, est_sum)
            est_n = np.where(none, cnt, est_n)
        fill = est_n > 0
        if not fill.any():
            break
        p[ys[fill], xs[fill]] = (est_sum[fill] / est_n[fill]).astype(p.dtype)
        bad[ys[fill], xs[fill]] = False
    ys, xs = np.nonzero(bad)
    if ys.size:
        p[ys, xs] = np.median(p[~bad]) if (~bad).any() else 0.0
    return int(ys.size)


def correct_defects(data: np.ndarray, mask: np.ndarray, cfa: str | None) -> np.ndarray:
    """Replace defective pixels by cubic interpolation within their CFA plane.

    Each defective pixel gets the mean of the horizontal and vertical cubic
    (Lagrange, same-colour neighbours at -2, -1, +1, +2 plane pixels) estimates;
    where a neighbour is itself defective the line falls back to linear (+-1),
    then to the mean of good 8-neighbours, rounds repeating inward for clusters.
    Exact for images cubic along rows and columns (see tests).

    Returns a new float32 array (the input is not modified).

    Parameters
    ----------
    data : ndarray, H x W
        The mosaic (normalised raw).
    mask : ndarray of bool, H x W
        True at a defective pixel.
    cfa : str or None
        Bayer pattern (None: one plane).

    Returns
    -------
    ndarray
        A corrected copy of ``data``.

    Examples
    --------
    >>> import numpy as np
    >>> mosaic = np.full((8, 8), 0.25, np.float32)
    >>> mosaic[3, 3] = 1.0
    >>> float(correct_defects(mosaic, mosaic > 0.5, "RGGB")[3, 3])
    0.25
    """
    if mask.shape != data.shape:
        raise DatasetError(f"defect map: shape {mask.shape} does not match the frame {data.shape}")
    out = np.array(data, dtype=np.float32, copy=True)
    s = plane_step(cfa)
    for dy, dx in plane_offsets(cfa):
        pv = out[dy::s, dx::s]  # a view: filled in place
        pb = mask[dy::s, dx::s]
        if pb.any():
            _fill_plane(pv, pb)
    return out


def mean_image(frames: Iterable[np.ndarray]) -> tuple[np.ndarray, int]:
    """Streaming float64 mean of frames (H x W); returns (mean float32, count)."""
    acc = None
    n = 0
    for f in frames:
        f = np.asarray(f, dtype=np.float64)
        acc = f.copy() if acc is None else acc + f
        n += 1
    if acc is None:
        raise DatasetError("defect detection: the dark/flat sequence has no frames")
    return (acc / n).astype(np.float32), n


def save_defect_map(path: str | Path, dm: DefectMap) -> Path:
    """Save as ``.npz``: ``mask`` (bool H x W), ``source``, ``stats`` (JSON).

    Parameters
    ----------
    path : path
        The ``.npz`` to write.
    dm : DefectMap
        The map.

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import tempfile
    >>> import numpy as np
    >>> out = save_defect_map(tempfile.mkdtemp() + "/defects.npz", DefectMap(np.eye(4, dtype=bool), "dark"))
    >>> load_defect_map(out, (4, 4)).count
    4
    """
    import json

    path = Path(path)
    np.savez_compressed(path, mask=dm.mask, source=np.array(dm.source), stats=np.array(json.dumps(dm.stats)))
    return path


def load_defect_map(path: str | Path, shape: tuple[int, int] | None = None) -> DefectMap:
    """Load a defect map from our ``.npz`` or a SIDD ``DefectivePixelsMask_*.mat``.

    The SIDD file holds ``DefectivePixelsMask`` (uint8, H x W, nonzero =
    defective). ``shape`` (H, W), if given, must match.

    Parameters
    ----------
    path : path
        A ``.npz`` written by :func:`save_defect_map` or a SIDD ``.mat``.
    shape : (int, int), optional
        The size the map must have.

    Returns
    -------
    DefectMap
        The map, ``source`` naming the file.

    Examples
    --------
    >>> import tempfile
    >>> import numpy as np
    >>> path = save_defect_map(tempfile.mkdtemp() + "/d.npz", DefectMap(np.zeros((2, 6), bool), "flat"))
    >>> load_defect_map(path).mask.shape
    (2, 6)
    """
    import json

    path = Path(path)
    if not path.exists():
        raise DatasetError(f"{path}: defect map not found")
    try:
        if path.suffix.lower() == ".mat":
            from ..io.sidd import load_defect_mask

            dm = DefectMap(load_defect_mask(path), str(path))
        else:
            with np.load(path, allow_pickle=False) as z:
                if "mask" not in z:
                    raise DatasetError(f"{path}: expected an array 'mask' in the defect map, found {list(z.keys())}")
                stats = json.loads(str(z["stats"])) if "stats" in z else []
                dm = DefectMap(np.asarray(z["mask"]).astype(bool), str(z["source"]) if "source" in z else str(path), stats)
    except DatasetError:
        raise
    except Exception as exc:  # unreadable file
        raise DatasetError(f"{path}: cannot read defect map ({type(exc).__name__}: {exc})") from None
    if dm.mask.ndim != 2:
        raise DatasetError(f"{path}: defect mask: expected a 2-D array, got shape {dm.mask.shape}")
    if shape is not None and tuple(dm.mask.shape) != tuple(shape):
        raise DatasetError(f"{path}: defect mask shape {dm.mask.shape}, expected {tuple(shape)} (the frames' H x W)")
    return dm
