"""Noisy raw frames from a clean image: the engine behind ``simcam synth``.

Inputs
    * a DNG: pixels normalised with its own black/white levels (the ``normalize``
      stage); every tag is kept;
    * a 16-bit or float32 TIFF/PNG taken as clean **normalised raw** (``as_="raw"``,
      one channel; integer files scaled by 1/65535): metadata made up from the
      profile (make, model, CFA, black/white levels when the profile has them,
      else black 1024 and white 65535 DN, so that noise below black survives
      the uint16 DNG), ISO = the requested ISO, no colour matrices;
    * a 16-bit or float32 TIFF/PNG taken as **linear sRGB** (``as_="linear-srgb"``,
      3 channels): mosaicked through the inverse of the colour matrices. With no
      reference camera the camera space *is* linear sRGB: ColorMatrix1 = XYZ ->
      linear sRGB (IEC 61966-2-1), CalibrationIlluminant1 = 21 (D65),
      AsShotNeutral = (1, 1, 1), so a DNG renderer maps the mosaic back to the
      input colours; each CFA site takes its colour's channel.

Outputs (``out_dir``): ``clean.dng`` and ``frame_000.dng`` ... with the same
metadata and NoiseProfile set from the model. DNG samples are uint16 DN:
values are rounded and clipped to 0..65535 DN (negative noise below the black
level is kept down to ``-black``).

Seeding: frame ``i`` is what ``Pipeline([noise], seed=seed)`` produces for
epoch 0, index ``i`` (``SeedSequence([seed, 0, i])``, first child), so frames
can be regenerated one at a time or in parallel.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from ..errors import ImageIOError, SimcamError
from ..frame import CameraMeta, RawFrame

#: XYZ (D65) -> linear sRGB, IEC 61966-2-1.
XYZ_TO_SRGB = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]])


def load_clean(path: str | Path, *, as_: str = "raw", profile=None, camera: str | None = None,
               iso: float | None = None, cfa: str | None = None, notes: list[str] | None = None) -> RawFrame:
    """The clean input as a normalised-raw frame (see module docstring).

    A DNG's samples below black (a real raw used as the clean image carries its own noise) are
    set to 0, and a line saying how many is appended to ``notes``.
    """
    path = Path(path)
    if not path.exists():
        raise ImageIOError(f"{path}: no such file")
    if path.suffix.lower() == ".dng":
        from ..io.dng import read_dng
        from ..stages.raw import Normalize

        frame = read_dng(path)
        out = Normalize()(frame)
        # a real raw used as the clean image carries its own noise: samples below black are
        # expected-signal estimates under 0, which no noise model accepts; they become 0
        below = out.data < 0
        if below.any():
            out = out.evolve(data=np.maximum(out.data, np.float32(0)))
            if notes is not None:
                notes.append(f"{path}: {int(below.sum())} samples below black set to 0 (a clean signal is >= 0)")
        if iso is not None:
            out = out.evolve(meta=out.meta.replace(iso=float(iso)))
        return out
    if as_ not in ("raw", "linear-srgb"):
        raise SimcamError(f"--as: expected 'raw' or 'linear-srgb', got {as_!r}")
    data = _read_pixels(path)
    cam = profile.camera(camera) if profile is not None else None
    cfa = cfa or (cam.cfa if cam is not None else None) or "RGGB"
    black = cam.black_level_dn if cam is not None and cam.black_level_dn is not None else 1024.0
    white = cam.white_level_dn if cam is not None and cam.white_level_dn is not None else 65535.0
    meta = CameraMeta(make=cam.make if cam else "", model=cam.model if cam else "",
                      unique_camera_model=(f"{cam.make} {cam.model}".strip() if cam else "") or "simcam synthetic",
                      cfa=cfa, black_level=np.full((1, 1), float(black)), white_level=float(white),
                      iso=None if iso is None else float(iso), source=str(path))
    if as_ == "raw":
        if data.ndim == 3 and data.shape[2] != 1:
            raise ImageIOError(f"{path}: --as raw: expected a single-channel mosaic, got {data.shape[2]} channels")
        mosaic = data.reshape(data.shape[0], data.shape[1])
    else:
        if data.ndim != 3 or data.shape[2] < 3:
            raise ImageIOError(f"{path}: --as linear-srgb: expected 3 channels, got shape {data.shape}")
        mosaic = mosaic_rgb(data[:, :, :3], cfa)
        meta.color_matrix1 = XYZ_TO_SRGB.copy()
        meta.calibration_illuminant1 = 21
        meta.as_shot_neutral = np.ones(3)
    if mosaic.shape[0] % 2 or mosaic.shape[1] % 2:
        raise ImageIOError(f"{path}: expected even height and width for a Bayer mosaic, got {mosaic.shape}")
    bad = int(np.count_nonzero(~np.isfinite(mosaic)))
    if bad:
        raise ImageIOError(f"{path}: pixels: {bad} NaN or infinite samples; expected finite values")
    return RawFrame(np.ascontiguousarray(mosaic, dtype=np.float32), meta, kind="raw")


def _read_pixels(path: Path) -> np.ndarray:
    import tifffile

    if path.suffix.lower() in (".tif", ".tiff"):
        try:
            a = tifffile.imread(path)
        except Exception as exc:  # tifffile raises several types
            raise ImageIOError(f"{path}: cannot read TIFF ({exc})") from None
    elif path.suffix.lower() == ".png":
        from ..io.images import read_image

        import OpenImageIO as oiio

        spec = oiio.ImageInput.open(str(path))
        if spec is None:
            raise ImageIOError(f"{path}: cannot read PNG")
        fmt = str(spec.spec().format)
        spec.close()
        if fmt != "uint16":
            raise ImageIOError(f"{path}: expected a 16-bit PNG, got {fmt}")
        return read_image(path)  # scaled to [0, 1]
    else:
        raise ImageIOError(f"{path}: expected .dng, .tif/.tiff or .png")
    if a.dtype == np.uint16:
        a = a.astype(np.float32) / 65535.0
    elif a.dtype == np.float32:
        pass
    else:
        raise ImageIOError(f"{path}: expected 16-bit integer or float32 samples, got {a.dtype}")
    if a.ndim == 3 and a.shape[0] in (1, 3) and a.shape[2] not in (1, 3):
        a = np.moveaxis(a, 0, -1)  # planar TIFF
    return a


def mosaic_rgb(rgb: np.ndarray, cfa: str) -> np.ndarray:
    """Sample an H x W x 3 image on a Bayer pattern (each site keeps its colour's channel)."""
    from ..cfa import PACK_OFFSETS, check_pattern

    cfa = check_pattern(cfa)
    h, w = rgb.shape[:2]
    out = np.empty((h, w), dtype=np.float32)
    for (dy, dx), c in zip(PACK_OFFSETS, cfa):
        out[dy::2, dx::2] = rgb[dy::2, dx::2, "RGB".index(c)]
    return out


def synth(clean: RawFrame, out_dir: str | Path, *, stage, frames: int, seed: int,
          progress: Callable[[Iterable], Iterable] | None = None, protect: tuple = ()) -> list[Path]:
    """Write ``clean.dng`` and ``frames`` noisy DNGs into ``out_dir`` (see module docstring)."""
    from ..io.dng_write import write_dng
    from ..noise.importers import model_noise_profile

    out_dir = Path(out_dir)
    created = not out_dir.exists()
    nlf = model_noise_profile(stage.model, clean.meta.cfa)
    meta = clean.meta if nlf is None else clean.meta.replace(noise_profile=nlf)
    base = clean.evolve(meta=meta)
    written: list[Path] = []
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        written.append(write_dng(out_dir / "clean.dng", base, protect=protect))
        it = range(int(frames))
        for i in (progress(it) if progress else it):
            rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0, i]).spawn(1)[0])
            noisy = stage(base, rng)
            written.append(write_dng(out_dir / f"frame_{i:03d}.dng", noisy, protect=protect))
    except BaseException:
        for p in written:  # nothing partial: what this call wrote goes
            p.unlink(missing_ok=True)
        if created and out_dir.exists() and not any(out_dir.iterdir()):
            out_dir.rmdir()
        raise
    return written
