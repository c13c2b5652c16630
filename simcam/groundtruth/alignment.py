"""Dense local spatial alignment of a burst (Abdelhamed 2020, section 5.3.3, eq. 5.5).

Per frame: sub-pixel Fourier phase correlation on overlapping patches against
the reference (patch centres = landmarks), a thin-plate-spline interpolation of
the landmark shifts to a dense field, and a warp of each CFA plane by that
field. A global-translation mode (one phase-correlation shift per frame) is
kept for comparison (Abdelhamed 2020, fig. 5.6d).

Shift convention: ``d`` is the displacement of the frame's content relative to
the reference, ``frame(p) = ref(p - d(p))``; the aligned frame is
``frame(p + d(p))``. Shifts are (row, col) in mosaic pixels.

References: Guizar-Sicairos, Thurman, Fienup (2008), "Efficient subpixel image
registration algorithms", doi:10.1364/OL.33.000156 (upsampled-DFT peak);
Bookstein (1989), doi:10.1109/34.24792 (thin-plate splines).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft
from scipy import ndimage, sparse
from scipy.interpolate import RBFInterpolator

from ..errors import DatasetError
from .planes import luma, plane_offsets, plane_step

ALIGN_MODES = ("local", "global", "none")


def _window(h: int, w: int) -> np.ndarray:
    return np.outer(np.hanning(h), np.hanning(w)).astype(np.float32)


def _prepare(patches: np.ndarray, window: bool) -> np.ndarray:
    p = patches.astype(np.float32, copy=True)
    p -= p.mean(axis=(-2, -1), keepdims=True)
    if window:
        p *= _window(*p.shape[-2:])
    return sfft.rfft2(p, axes=(-2, -1))  # complex64, half spectrum (real input)


def _half_weights(w: int) -> np.ndarray:
    """Weights that turn sums over a real signal's half spectrum (rfft, length w//2+1) into full sums."""
    k = np.full(w // 2 + 1, 2.0)
    k[0] = 1.0
    if w % 2 == 0:
        k[-1] = 1.0
    return k


def _upsampled_dft(data: np.ndarray, region: int, up: int, off_y: np.ndarray, off_x: np.ndarray,
                   w: int) -> np.ndarray:
    """Real part of the batched matrix-multiply DFT of Hermitian spectra on a ``region``^2 grid.

    ``data`` is (B, h, w//2+1), the rfft half of spectra of real signals of width ``w``
    (Guizar-Sicairos 2008, using the half spectrum: the other half adds the complex
    conjugate, so the real part is the weighted half sum). The kernel
    exp(2 pi i (u - off_b) f_k / up) factors into a batch-independent matrix and a
    per-batch phase applied to the data, so both stages are single BLAS products.
    """
    B, h, wh = data.shape
    fx = np.arange(wh) / (w * up)
    fy = np.fft.fftfreq(h, up)
    u = np.arange(region)[:, None]
    ex = np.exp(2j * np.pi * u * fx[None, :]).astype(data.dtype)            # (U, wh)
    ey = np.exp(2j * np.pi * u * fy[None, :]).astype(data.dtype)            # (U, h)
    px = (np.exp(-2j * np.pi * off_x[:, None] * fx[None, :]) * _half_weights(w)).astype(data.dtype)  # (B, wh)
    py = np.exp(-2j * np.pi * off_y[:, None] * fy[None, :]).astype(data.dtype)                       # (B, h)
    tmp = ((data * px[:, None, :]).reshape(B * h, wh) @ ex.T).reshape(B, h, region)   # (B, h, U)
    tmp = tmp * py[:, :, None]
    out = ey @ np.ascontiguousarray(tmp.transpose(1, 0, 2)).reshape(h, B * region)    # (U, B*U)
    return np.ascontiguousarray(out.reshape(region, B, region).transpose(1, 0, 2)).real / (h * w)


def phase_correlation_spectra(F_ref: np.ndarray, F_mov: np.ndarray, *, upsample: int = 4,
                              normalization: str | None = None, width: int | None = None
                              ) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel shifts between batches of prepared (rfft2) spectra (see :func:`phase_correlation`).

    ``width`` is the patches' width (needed when it is odd; default ``2 (w_half - 1)``).
    """
    R = F_ref * np.conj(F_mov)
    if normalization == "phase":
        R = R / np.maximum(np.abs(R), 1e-30)
    elif normalization is not None:
        raise DatasetError(f"phase correlation: normalization: expected 'phase' or None, got {normalization!r}")
    B = R.shape[0]
    h = R.shape[-2]
    w = width if width is not None else 2 * (R.shape[-1] - 1)
    cc = sfft.irfft2(R, s=(h, w), axes=(-2, -1))
    flat = cc.reshape(B, -1)
    idx = flat.argmax(axis=1)
    # normalised cross-correlation at the integer peak (Parseval: sum x^2 = sum |X|^2 / (h w))
    plain = flat if normalization is None else sfft.irfft2(F_ref * np.conj(F_mov), s=(h, w), axes=(-2, -1)).reshape(B, -1)
    hw = _half_weights(w)
    e_ref = ((np.abs(F_ref) ** 2) * hw).reshape(B, -1).sum(1) / (h * w)
    e_mov = ((np.abs(F_mov) ** 2) * hw).reshape(B, -1).sum(1) / (h * w)
    peak = plain[np.arange(B), idx] / np.sqrt(np.maximum(e_ref * e_mov, 1e-300))
    py, px = np.unravel_index(idx, (h, w))
    py = np.where(py > h // 2, py - h, py).astype(np.float64)
    px = np.where(px > w // 2, px - w, px).astype(np.float64)
    if upsample > 1:
        # correlation on a 1/upsample grid over +-0.75 px around the integer peak (upsampled DFT), then a
        # 3-point parabola through the grid maximum and its neighbours along each axis
        region = int(np.ceil(1.5 * upsample)) | 1
        c = float(region // 2)
        off_y, off_x = c - py * upsample, c - px * upsample
        up = _upsampled_dft(R, region, upsample, off_y, off_x, w)
        k = up.reshape(B, -1).argmax(axis=1)
        uy, ux = np.unravel_index(k, (region, region))
        b = np.arange(B)

        def vertex(m, c0, p):
            den = m - 2 * c0 + p
            return np.where(den < 0, 0.5 * (m - p) / np.where(den < 0, den, -1.0), 0.0)

        ym, yp = np.clip(uy - 1, 0, region - 1), np.clip(uy + 1, 0, region - 1)
        xm, xp = np.clip(ux - 1, 0, region - 1), np.clip(ux + 1, 0, region - 1)
        c0 = up[b, uy, ux]
        fy = np.where((uy > 0) & (uy < region - 1), vertex(up[b, ym, ux], c0, up[b, yp, ux]), 0.0)
        fx = np.where((ux > 0) & (ux < region - 1), vertex(up[b, uy, xm], c0, up[b, uy, xp]), 0.0)
        py = py + (uy + fy - c) / upsample
        px = px + (ux + fx - c) / upsample
    # correlation peaks at -d (see module docstring)
    return np.stack([-py, -px], axis=1), peak


def phase_correlation(ref: np.ndarray, mov: np.ndarray, *, upsample: int = 4, window: bool = True,
                      normalization: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel translation of ``mov`` relative to ``ref`` by Fourier phase correlation.

    Parameters
    ----------
    ref, mov : ndarray, (..., h, w)
        Images or batches of patches (same shape).
    upsample : int
        The correlation is evaluated on a 1/upsample pixel grid around its peak
        by the matrix-multiply DFT (Guizar-Sicairos 2008); a parabola through
        the grid maximum and its neighbours then gives the sub-pixel vertex
        (typically 0.01-0.02 px on noisy textured patches; see tests).
    window : bool
        Apply a Hann window after removing each patch's mean (reduces the edge
        effects of the circular correlation).
    normalization : None or "phase"
        None (default): plain Fourier cross-correlation, as in Guizar-Sicairos
        et al.; "phase": cross-power spectrum normalised to unit magnitude. The
        whitened form weights the noise-dominated high frequencies as much as
        the signal and loses accuracy on smooth, noisy patches (see tests).

    Returns
    -------
    shift : ndarray, (..., 2)
        (row, col) displacement d with ``mov(p) ~ ref(p - d)``, pixels.
    ncc : ndarray, (...)
        Normalised cross-correlation at the peak, in [-1, 1]: compare it with
        :func:`ncc_threshold` to tell a real match from a noise maximum.

    Examples
    --------
    >>> import numpy as np
    >>> from scipy import ndimage
    >>> ref = ndimage.gaussian_filter(np.random.default_rng(0).random((32, 32)), 2)
    >>> shift, ncc = phase_correlation(ref, np.roll(ref, (1, 2), axis=(0, 1)))
    >>> shift.round().tolist(), bool(ncc > 0.9)
    ([1.0, 2.0], True)
    """
    ref = np.asarray(ref)
    mov = np.asarray(mov)
    if ref.shape != mov.shape or ref.ndim < 2:
        raise DatasetError(f"phase correlation: expected two arrays of the same shape, got {ref.shape} and {mov.shape}")
    lead = ref.shape[:-2]
    h, w = ref.shape[-2:]
    Fr = _prepare(ref.reshape(-1, h, w), window)
    Fm = _prepare(mov.reshape(-1, h, w), window)
    s, pk = phase_correlation_spectra(Fr, Fm, upsample=upsample, normalization=normalization, width=w)
    return s.reshape(lead + (2,)), pk.reshape(lead)


def ncc_threshold(h: int, w: int, *, window: bool = True, margin: float = 1.5) -> float:
    """Largest normalised cross-correlation that white noise alone reaches on h x w patches.

    For independent noise the correlation at each of the h w shifts is about
    N(0, 1/n_eff), with n_eff = (sum v^2)^2 / sum v^4 for the window v (0.264 h w
    for a 2-D Hann window); the maximum over all shifts stays below
    ``(sqrt(2 ln(h w)) + margin) / sqrt(n_eff)`` (extreme-value bound). Patches
    whose peak does not exceed it carry no usable structure (e.g. a flat field)
    and are not used as landmarks.
    """
    v = _window(h, w).astype(np.float64) if window else np.ones((h, w))
    v2 = v * v
    n_eff = v2.sum() ** 2 / (v2 * v2).sum()
    return float((np.sqrt(2.0 * np.log(h * w)) + margin) / np.sqrt(n_eff))


@dataclass
class PatchGrid:
    """Patch layout on the registration image (pixel pitch ``step`` mosaic pixels)."""

    size: int
    stride: int
    ys: np.ndarray
    xs: np.ndarray
    step: int

    @property
    def centres(self) -> np.ndarray:
        """Landmarks: patch centres in mosaic (row, col) coordinates, (L, 2)."""
        cy = (self.ys + (self.size - 1) / 2.0) * self.step + (self.step - 1) / 2.0
        cx = (self.xs + (self.size - 1) / 2.0) * self.step + (self.step - 1) / 2.0
        yy, xx = np.meshgrid(cy, cx, indexing="ij")
        return np.stack([yy.ravel(), xx.ravel()], axis=1)

    def extract(self, img: np.ndarray) -> np.ndarray:
        """Patches (L, size, size) of a registration image."""
        s = self.size
        return np.stack([img[y:y + s, x:x + s] for y in self.ys for x in self.xs])


def _starts(n: int, size: int, stride: int) -> np.ndarray:
    if n <= size:
        return np.array([0])
    st = list(range(0, n - size + 1, stride))
    if st[-1] != n - size:
        st.append(n - size)
    return np.array(st)


def patch_grid(shape: tuple[int, int], cfa: str | None, *, patch: int = 512, stride: int | None = None,
               min_patch: int = 32) -> PatchGrid:
    """The 512 x 512 patches at stride 256 (mosaic pixels), scaled for small images.

    The registration image has half the mosaic resolution for a Bayer sensor,
    so the dissertation's patch is 256 pixels there. When fewer than two patches fit
    along the short side, the patch shrinks to the largest power of two that
    gives two (never below ``min_patch`` registration pixels, and never above
    the image: then one patch covers it and the alignment is global).

    Parameters
    ----------
    shape : (int, int)
        Mosaic size H x W.
    cfa : str or None
        Bayer pattern (the registration image is half size) or None.
    patch, stride : int
        Patch size and stride, mosaic pixels (stride: patch / 2 by default).
    min_patch : int
        Smallest patch, registration pixels.

    Returns
    -------
    PatchGrid
        Patch size and stride (registration pixels), patch origins ``ys``, ``xs`` and the pixel pitch.

    Examples
    --------
    >>> g = patch_grid((64, 64), "RGGB", patch=32)
    >>> g.size, g.stride, g.centres.shape
    (16, 8, (9, 2))
    """
    step = plane_step(cfa)
    hl, wl = shape[0] // step, shape[1] // step
    p = max(int(patch) // step, 2)
    short = min(hl, wl)
    if p > short // 2:
        p = max(min_patch, 1 << max(int(np.floor(np.log2(max(short // 2, 1)))), 0))
    p = min(p, short)
    s = max(1, int(stride) // step) if stride else max(1, p // 2)
    return PatchGrid(p, s, _starts(hl, p, s), _starts(wl, p, s), step)


@dataclass
class Reference:
    """A reference frame prepared for registration: patch spectra and whole-image spectrum."""

    grid: PatchGrid
    F_patches: np.ndarray
    F_whole: np.ndarray
    shape: tuple[int, int]
    cfa: str | None
    window: bool
    upsample: int
    normalization: str | None


def prepare_reference(ref: np.ndarray, cfa: str | None, *, patch: int = 512, stride: int | None = None,
                      upsample: int = 4, window: bool = True, normalization: str | None = None) -> Reference:
    """Precompute the reference's patch spectra (eq. 5.5 chooses the frame).

    Parameters
    ----------
    ref : ndarray, H x W
        The reference frame (normalised raw).
    cfa : str or None
        Bayer pattern.
    patch, stride
        As :func:`patch_grid`.
    upsample, window, normalization
        As :func:`phase_correlation`.

    Returns
    -------
    Reference
        The grid and the spectra that :func:`local_shifts` and :func:`global_shift` compare frames with.

    Examples
    --------
    >>> from simcam.groundtruth import SyntheticBurst
    >>> sb = SyntheticBurst(shape=(64, 64), n=2, drift_px=0.0, seed=0)
    >>> prepare_reference(sb.frame(0), "RGGB", patch=32).grid.size
    16
    """
    img = luma(ref, cfa)
    grid = patch_grid(ref.shape, cfa, patch=patch, stride=stride)
    return Reference(grid, _prepare(grid.extract(img), window), _prepare(img[None], window)[0],
                     tuple(ref.shape), cfa, window, upsample, normalization)


def local_shifts(reference: Reference, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-patch shifts of ``frame`` against the reference.

    Returns landmarks (L, 2) and shifts (L, 2) in mosaic pixels, and a boolean
    (L,) ``reliable``: the patch's correlation peak exceeds :func:`ncc_threshold`.

    Parameters
    ----------
    reference : Reference
        From :func:`prepare_reference`.
    frame : ndarray, H x W
        The frame to register.

    Returns
    -------
    landmarks, shifts : ndarray, (L, 2)
        Patch centres and shifts, mosaic pixels.
    reliable : ndarray of bool, (L,)
        Whether each patch's match is real.

    Examples
    --------
    >>> from simcam.groundtruth import SyntheticBurst
    >>> sb = SyntheticBurst(shape=(64, 64), n=2, drift_px=0.0, seed=0)
    >>> lm, sh, ok = local_shifts(prepare_reference(sb.frame(0), "RGGB", patch=32), sb.frame(1))
    >>> lm.shape, bool(abs(sh).max() < 0.5), bool(ok.all())
    ((9, 2), True, True)
    """
    img = luma(frame, reference.cfa)
    Fm = _prepare(reference.grid.extract(img), reference.window)
    s, ncc = phase_correlation_spectra(reference.F_patches, Fm, upsample=reference.upsample,
                                       normalization=reference.normalization, width=reference.grid.size)
    g = reference.grid
    ok = ncc > ncc_threshold(g.size, g.size, window=reference.window)
    return g.centres, s * g.step, ok


def global_shift(reference: Reference, frame: np.ndarray) -> tuple[np.ndarray, bool]:
    """One (row, col) shift of the whole frame against the reference (mosaic pixels), and its reliability.

    Parameters
    ----------
    reference, frame
        As :func:`local_shifts`.

    Returns
    -------
    shift : ndarray, (2,)
        (row, col) shift, mosaic pixels.
    reliable : bool
        Whether the correlation peak is a real match.

    Examples
    --------
    >>> from simcam.groundtruth import SyntheticBurst
    >>> sb = SyntheticBurst(shape=(64, 64), n=2, drift_px=0.0, seed=0)
    >>> shift, ok = global_shift(prepare_reference(sb.frame(0), "RGGB", patch=32), sb.frame(1))
    >>> bool(abs(shift).max() < 0.5), ok
    (True, True)
    """
    img = luma(frame, reference.cfa)
    Fm = _prepare(img[None], reference.window)
    s, ncc = phase_correlation_spectra(reference.F_whole[None], Fm, upsample=reference.upsample,
                                       normalization=reference.normalization, width=img.shape[1])
    ok = bool(ncc[0] > ncc_threshold(*img.shape, window=reference.window))
    return s[0] * plane_step(reference.cfa), ok


def reject_outliers(grid: PatchGrid, shifts: np.ndarray, reliable: np.ndarray | None = None,
                    max_dev: float = 1.0) -> np.ndarray:
    """Landmarks to keep: reliable ones within ``max_dev`` px of the median of their reliable 3x3 neighbours."""
    ny, nx = len(grid.ys), len(grid.xs)
    ok = np.ones(ny * nx, dtype=bool) if reliable is None else reliable.copy()
    if ny * nx < 4 or ok.sum() < 3:
        return ok
    g = np.where(ok[:, None], shifts, np.nan).reshape(ny, nx, 2)
    pad = np.pad(g, ((1, 1), (1, 1), (0, 0)), constant_values=np.nan)
    stack = np.stack([pad[dy:dy + ny, dx:dx + nx] for dy in range(3) for dx in range(3)])
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            med = np.nanmedian(stack, axis=0)
    dev = np.linalg.norm(g - med, axis=-1).ravel()
    return ok & ~(dev > max_dev)


def _interp_matrix(n_out: int, coords: np.ndarray, n_in: int) -> sparse.csr_matrix:
    """Sparse linear-interpolation matrix from ``n_in`` grid samples to ``coords`` (grid units)."""
    c = np.clip(coords, 0, n_in - 1)
    i0 = np.clip(np.floor(c).astype(np.int64), 0, max(n_in - 2, 0))
    f = c - i0
    rows = np.repeat(np.arange(n_out), 2)
    cols = np.stack([i0, np.minimum(i0 + 1, n_in - 1)], axis=1).ravel()
    vals = np.stack([1 - f, f], axis=1).ravel()
    return sparse.csr_matrix((vals, (rows, cols)), shape=(n_out, n_in))


def dense_field(landmarks: np.ndarray, shifts: np.ndarray, shape: tuple[int, int], cfa: str | None, *,
                smoothing: float = 0.0, field_step: int = 16) -> np.ndarray:
    """Thin-plate-spline interpolation of landmark shifts to every CFA-plane pixel.

    Returns (2, h_p, w_p) float32 shifts in mosaic pixels on the plane grid of
    site (0, 0) shifted to the 2x2 cell centre (for Bayer; the same field serves
    all four planes: the error is |grad d| x 0.5 px, negligible for the smooth
    fields met in bursts). The spline is evaluated on a ``field_step`` grid and
    linearly interpolated from there. Fewer than 3 landmarks (or all on a line)
    fall back to the mean shift or, on a line, a 1-D linear interpolation.

    Parameters
    ----------
    landmarks, shifts : ndarray, (L, 2)
        As :func:`local_shifts` gives them.
    shape : (int, int)
        Mosaic size H x W.
    cfa : str or None
        Bayer pattern.
    smoothing : float
        Smoothing of the thin-plate spline.
    field_step : int
        Pitch of the grid the spline is evaluated on.

    Returns
    -------
    ndarray
        (2, h_p, w_p) float32 field.

    Examples
    --------
    >>> import numpy as np
    >>> lm = np.array([[8.0, 8.0], [8.0, 56.0], [56.0, 8.0], [56.0, 56.0]])
    >>> d = dense_field(lm, np.full((4, 2), 0.5), (64, 64), "RGGB")
    >>> d.shape, bool(np.allclose(d, 0.5, atol=1e-4))
    ((2, 32, 32), True)
    """
    step = plane_step(cfa)
    H, W = shape
    hp, wp = (H + step - 1) // step, (W + step - 1) // step
    gy = np.arange(0, H + field_step, field_step, dtype=np.float64)
    gx = np.arange(0, W + field_step, field_step, dtype=np.float64)
    L = len(landmarks)
    uy, ux = np.unique(landmarks[:, 0]), np.unique(landmarks[:, 1])
    coarse = None
    if L < 3:
        coarse = np.broadcast_to(shifts.mean(0)[:, None, None], (2, gy.size, gx.size)).astype(np.float64)
    elif len(uy) == 1 or len(ux) == 1:  # landmarks on a line: 1-D interpolation along it
        along_y = len(ux) == 1
        pos = landmarks[:, 0] if along_y else landmarks[:, 1]
        o = np.argsort(pos)
        tgt = gy if along_y else gx
        prof = np.stack([np.interp(tgt, pos[o], shifts[o, c]) for c in range(2)])
        coarse = (prof[:, :, None] * np.ones((1, 1, gx.size)) if along_y
                  else prof[:, None, :] * np.ones((1, gy.size, 1)))
    else:
        try:
            rbf = RBFInterpolator(landmarks, shifts, kernel="thin_plate_spline", smoothing=smoothing, degree=1)
            yy, xx = np.meshgrid(gy, gx, indexing="ij")
            coarse = rbf(np.stack([yy.ravel(), xx.ravel()], axis=1)).T.reshape(2, gy.size, gx.size)
        except (ValueError, np.linalg.LinAlgError):  # degenerate layout (e.g. collinear): mean shift
            coarse = np.broadcast_to(shifts.mean(0)[:, None, None], (2, gy.size, gx.size)).astype(np.float64)
    cy = (np.arange(hp) * step + (step - 1) / 2.0) / field_step
    cx = (np.arange(wp) * step + (step - 1) / 2.0) / field_step
    Ay = _interp_matrix(hp, cy, gy.size)
    Ax = _interp_matrix(wp, cx, gx.size)
    out = np.empty((2, hp, wp), dtype=np.float32)
    for c in range(2):
        out[c] = Ay @ (Ax @ np.ascontiguousarray(coarse[c]).T).T
    return out


def constant_field(shift: np.ndarray, shape: tuple[int, int], cfa: str | None) -> np.ndarray:
    """A (2, h_p, w_p) field holding one shift everywhere (global-translation mode)."""
    step = plane_step(cfa)
    hp, wp = (shape[0] + step - 1) // step, (shape[1] + step - 1) // step
    out = np.empty((2, hp, wp), dtype=np.float32)
    out[0] = shift[0]
    out[1] = shift[1]
    return out


def warp(data: np.ndarray, field: np.ndarray, cfa: str | None, *, order: int = 3,
         mode: str = "nearest", threads: int = 2) -> np.ndarray:
    """Warp each CFA plane by ``field`` (mosaic pixels): ``out(p) = data(p + d(p))`` within the plane.

    ``order`` is the spline order of :func:`scipy.ndimage.map_coordinates`
    (3: cubic, 1: linear, 0: nearest, used for censoring flags); outside the
    frame the nearest edge sample is repeated.

    Parameters
    ----------
    data : ndarray, H x W
        The mosaic.
    field : ndarray, (2, h_p, w_p)
        From :func:`dense_field`.
    cfa : str or None
        Bayer pattern.
    order, mode : int, str
        Spline order and edge mode of :func:`scipy.ndimage.map_coordinates`.
    threads : int
        Planes warped in parallel.

    Returns
    -------
    ndarray
        The warped mosaic (float32).

    Examples
    --------
    >>> import numpy as np
    >>> mosaic = np.random.default_rng(0).random((8, 8)).astype(np.float32)
    >>> bool(np.allclose(warp(mosaic, np.zeros((2, 4, 4), np.float32), "RGGB"), mosaic, atol=1e-6))
    True
    """
    step = plane_step(cfa)
    out = np.empty(data.shape, dtype=np.float32 if order else data.dtype)

    def one(off):
        dy, dx = off
        p = data[dy::step, dx::step]
        h, w = p.shape
        f = field[:, :h, :w]
        coords = np.empty((2, h, w), dtype=np.float32)
        coords[0] = np.arange(h, dtype=np.float32)[:, None] + f[0] / step
        coords[1] = np.arange(w, dtype=np.float32)[None, :] + f[1] / step
        out[dy::step, dx::step] = ndimage.map_coordinates(p, coords, order=order, mode=mode, output=out.dtype)

    offs = plane_offsets(cfa)
    if len(offs) > 1 and threads > 1:  # map_coordinates releases the GIL; planes are independent
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(min(threads, len(offs))) as ex:
            list(ex.map(one, offs))
    else:
        for off in offs:
            one(off)
    return out


def field_stats(field: np.ndarray) -> dict:
    """Magnitude statistics of a shift field (mosaic pixels)."""
    mag = np.hypot(field[0], field[1])
    return {"mean_px": float(mag.mean()), "max_px": float(mag.max()),
            "mean_dy": float(field[0].mean()), "mean_dx": float(field[1].mean())}
