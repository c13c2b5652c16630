"""Training data for Noise Flow: packed noisy/clean patch sets (numpy only).

A *patch set* is a dict of arrays:
``clean`` float32 [N, 4, h, w] (packed, :data:`simcam.cfa.PACK_OFFSETS` order,
normalised raw), ``noise`` float32 [N, 4, h, w] (noisy - clean), ``iso`` float64 [N],
``camera`` [N] (str). Sources: a ``.npz`` with those keys (``noisy`` may replace
``noise``), a folder of SIDD-style ``.MAT`` pairs, DNG bursts with a ground truth
(``clean.dng`` or ``gt.npz``), or pairs synthesised from an NLF
table (Abdelhamed 2020, eq. 3.8: ``var = beta1 * clean + beta2``).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ...errors import DatasetError

KEYS = ("clean", "noise", "iso", "camera")


def check_patch_set(ps: dict, where: str = "patch set") -> dict:
    """Validate shapes/dtypes; returns the set with float32 arrays and str cameras."""
    for k in ("clean", "iso", "camera"):
        if k not in ps:
            raise DatasetError(f"{where}: missing array {k!r} (expected clean, noise or noisy, iso, camera)")
    clean = np.asarray(ps["clean"])
    if "noise" in ps:
        noise = np.asarray(ps["noise"], dtype=np.float32)
    elif "noisy" in ps:
        noise = np.asarray(ps["noisy"], dtype=np.float32) - clean.astype(np.float32)
    else:
        raise DatasetError(f"{where}: missing array 'noise' (or 'noisy')")
    if clean.ndim != 4 or clean.shape[1] != 4:
        raise DatasetError(f"{where}: clean: expected shape [N, 4, h, w] packed raw, got {clean.shape}")
    if noise.shape != clean.shape:
        raise DatasetError(f"{where}: noise: shape {noise.shape} differs from clean {clean.shape}")
    n = clean.shape[0]
    iso = np.asarray(ps["iso"], dtype=np.float64).reshape(-1)
    cam = np.asarray(ps["camera"]).astype(str).reshape(-1)
    if iso.size != n or cam.size != n:
        raise DatasetError(f"{where}: iso/camera: expected {n} values each, got {iso.size} and {cam.size}")
    if not np.all(iso > 0):
        raise DatasetError(f"{where}: iso: expected positive values, got min {iso.min():g}")
    if not (np.all(np.isfinite(clean)) and np.all(np.isfinite(noise))):
        raise DatasetError(f"{where}: clean/noise: non-finite values")
    return {"clean": clean.astype(np.float32), "noise": noise, "iso": iso, "camera": cam}


def load_npz(path) -> dict:
    """Read a patch set from ``.npz`` (keys clean, noise|noisy, iso, camera)."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            ps = {k: z[k] for k in z.files}
    except (OSError, ValueError) as exc:
        raise DatasetError(f"{path}: cannot read as .npz ({exc})") from None
    return check_patch_set(ps, str(path))


def save_npz(path, ps: dict) -> None:
    """Write a patch set (compressed ``.npz``)."""
    ps = check_patch_set(ps)
    np.savez_compressed(path, clean=ps["clean"], noise=ps["noise"], iso=ps["iso"], camera=ps["camera"])


# ----------------------------------------------------------------- NLF synthesis
def read_nlf_table(path) -> dict[tuple[str, float], tuple[float, float]]:
    """``cam_iso,beta1,beta2`` rows like ``GP_00100,0.000228,0.000002`` -> {(cam, iso): (b1, b2)}."""
    path = Path(path)
    out = {}
    for i, line in enumerate(path.read_text().splitlines()):
        line = line.strip()
        if not line or line.startswith("#") or line.startswith("cam_iso"):
            continue
        m = re.fullmatch(r"([A-Za-z0-9]+)_0*(\d+)\s*,\s*([0-9.eE+-]+)\s*,\s*([0-9.eE+-]+)", line)
        if not m:
            raise DatasetError(f"{path}: line {i + 1}: expected CAM_ISO,beta1,beta2, got {line!r}")
        out[(m.group(1), float(m.group(2)))] = (float(m.group(3)), float(m.group(4)))
    if not out:
        raise DatasetError(f"{path}: no CAM_ISO,beta1,beta2 rows")
    return out


def synthetic_clean(n: int, size: int, rng: np.random.Generator) -> np.ndarray:
    """Clean packed patches [n, 4, size, size] in [0, 1]: smooth random scenes.

    Each patch is a random low-frequency field (sum of a few random cosines plus a
    random step edge), mapped through a random gamma (skewed towards dark values,
    as raw data are) and scaled per channel by a random white-balance-like gain.
    """
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float64) / size
    out = np.empty((n, 4, size, size), np.float32)
    for i in range(n):
        f = np.zeros((size, size))
        for _ in range(3):
            fy, fx = rng.uniform(-2.5, 2.5, 2)
            f += rng.uniform(0.2, 1.0) * np.cos(2 * np.pi * (fy * yy + fx * xx) + rng.uniform(0, 2 * np.pi))
        ang = rng.uniform(0, np.pi)
        f += rng.uniform(0, 1.5) * ((np.cos(ang) * (xx - 0.5) + np.sin(ang) * (yy - 0.5)) > rng.uniform(-0.3, 0.3))
        f = (f - f.min()) / max(np.ptp(f), 1e-9)
        lo, hi = np.sort(rng.uniform(0.0, 1.0, 2))
        f = (lo + (hi - lo) * f) ** rng.uniform(1.0, 3.0)
        gains = rng.uniform(0.4, 1.0, 4)
        gains[1:3] = gains[1]  # the two greens alike
        out[i] = (f[None] * gains[:, None, None]).astype(np.float32)
    return out


def synthesize_nlf_pairs(nlf: dict, n_per: int, *, size: int = 32, seed: int = 0, cameras=None, isos=None) -> dict:
    """Noisy/clean pairs from an NLF table: ``noise ~ N(0, beta1 * clean + beta2)``.

    Parameters
    ----------
    nlf : dict
        ``{(camera, iso): (beta1, beta2)}`` (see :func:`read_nlf_table`).
    n_per : int
        Patches per (camera, ISO).
    size : int
        Packed patch side (32 = 64x64 mosaic).
    seed : int
        Group g draws from ``SeedSequence([seed, g])``.
    cameras, isos : sequence, optional
        Restrict the table.

    Returns
    -------
    dict
        A patch set. Noise is not clipped (normalised raw keeps negatives).
    """
    keys = sorted(k for k in nlf if (cameras is None or k[0] in cameras) and (isos is None or k[1] in isos))
    if not keys:
        raise DatasetError(f"NLF table: no rows for cameras {cameras} and ISOs {isos}")
    parts = {k: [] for k in KEYS}
    for g, (cam, iso) in enumerate(keys):
        rng = np.random.default_rng(np.random.SeedSequence([seed, g]))
        b1, b2 = nlf[(cam, iso)]
        clean = synthetic_clean(n_per, size, rng)
        noise = rng.standard_normal(clean.shape) * np.sqrt(b1 * clean.astype(np.float64) + b2)
        parts["clean"].append(clean)
        parts["noise"].append(noise.astype(np.float32))
        parts["iso"].append(np.full(n_per, iso))
        parts["camera"].append(np.full(n_per, cam))
    return check_patch_set({k: np.concatenate(v) for k, v in parts.items()})


def nlf_nll_per_dim(ps: dict, nlf: dict) -> float:
    """Mean NLL per dimension (nats) of a patch set under the true NLF Gaussian."""
    var = np.empty(ps["clean"].shape, np.float64)
    for i, (cam, iso) in enumerate(zip(ps["camera"], ps["iso"])):
        b1, b2 = nlf[(str(cam), float(iso))]
        var[i] = b1 * ps["clean"][i].astype(np.float64) + b2
    x = ps["noise"].astype(np.float64)
    return float(np.mean(0.5 * np.log(2 * np.pi * var) + 0.5 * x * x / var))


# ------------------------------------------------------------------------ split
def split_by_condition(ps: dict, test_fraction: float = 0.2, seed: int = 0) -> tuple[dict, dict]:
    """Split a patch set so every (camera, ISO) appears in both train and test.

    Groups with fewer than 2 patches cannot be split and raise :class:`DatasetError`.
    """
    if not 0.0 < test_fraction < 1.0:
        raise DatasetError(f"test_fraction: expected 0 < f < 1, got {test_fraction}")
    rng = np.random.default_rng(np.random.SeedSequence([seed, 7919]))
    groups = {}
    for i, key in enumerate(zip(ps["camera"], ps["iso"])):
        groups.setdefault((str(key[0]), float(key[1])), []).append(i)
    tr, te = [], []
    for key in sorted(groups):
        idx = np.array(groups[key])
        if idx.size < 2:
            raise DatasetError(f"split: camera {key[0]} ISO {key[1]:g} has {idx.size} patch; need 2+ to be in both sets")
        idx = rng.permutation(idx)
        k = min(max(1, int(round(test_fraction * idx.size))), idx.size - 1)
        te.extend(idx[:k])
        tr.extend(idx[k:])
    take = lambda ii: {k: ps[k][np.sort(ii)] for k in KEYS}  # noqa: E731
    return take(np.array(tr)), take(np.array(te))


# ------------------------------------------------------------------ SIDD .MAT
_SIDD_DIR = re.compile(r"^\d{4}_\d{3}_([A-Z0-9]{2})_(\d{5})_\d+_\d+_[A-Z]$")


def _read_mat(path: Path) -> np.ndarray:
    """The SIDD raw image of a .MAT (variable ``x``, else the first one) as float32."""
    from ...io.matlab import load_mat

    variables = load_mat(path, DatasetError)
    key = "x" if "x" in variables else next(iter(variables), None)
    if key is None:
        raise DatasetError(f"{path}: no variables; expected a SIDD raw image")
    return np.asarray(variables[key], dtype=np.float32)


def _add_patches(parts: dict, noisy: np.ndarray, gt: np.ndarray, rng: np.random.Generator, count: int,
                 size: int, *, where: str) -> None:
    """Append ``count`` packed patch pairs of ``2*size`` mosaic pixels at random even offsets.

    Packing is by position (:data:`simcam.cfa.PACK_OFFSETS`); the noise is
    ``clip(noisy, 0, 1) - clip(clean, 0, 1)`` as in the Noise Flow code.
    """
    from ...cfa import pack

    s = 2 * size
    if noisy.shape[0] < s or noisy.shape[1] < s:
        raise DatasetError(f"{where}: image {noisy.shape} smaller than a {s}x{s} patch")
    ys = 2 * rng.integers(0, (noisy.shape[0] - s) // 2 + 1, count)
    xs = 2 * rng.integers(0, (noisy.shape[1] - s) // 2 + 1, count)
    for y, x in zip(ys, xs):
        c = np.clip(gt[y : y + s, x : x + s], 0, 1)
        parts["clean"].append(pack(c))
        parts["noise"].append(pack(np.clip(noisy[y : y + s, x : x + s], 0, 1) - c))


def load_sidd_pairs(root, *, patches_per_image: int = 64, size: int = 32, seed: int = 0) -> dict:
    """Patch set from SIDD-style folders ``SSSS_III_CC_IIIII_...`` holding
    ``*NOISY_RAW_*.MAT`` and ``*GT_RAW_*.MAT`` (normalised raw mosaics).

    Camera and ISO come from the folder name (Abdelhamed 2020, ch. 5.2); patches of
    ``2*size`` x ``2*size`` mosaic pixels at even offsets are packed by position
    (:data:`simcam.cfa.PACK_OFFSETS`). Noise is ``clip(noisy,0,1) - clip(clean,0,1)``
    as in the Noise Flow code.
    """
    root = Path(root)
    dirs = sorted(d for d in root.rglob("*") if d.is_dir() and _SIDD_DIR.match(d.name))
    if not dirs:
        raise DatasetError(f"{root}: no SIDD scene folders (expected names like 0001_001_S6_00100_00060_3200_L)")
    parts = {k: [] for k in KEYS}
    for d_i, d in enumerate(dirs):
        cam, iso = _SIDD_DIR.match(d.name).groups()
        noisy_files = sorted(d.glob("*NOISY_RAW_*.MAT"))
        for f_i, nf in enumerate(noisy_files):
            gf = nf.with_name(nf.name.replace("NOISY_RAW", "GT_RAW"))
            if not gf.is_file():
                raise DatasetError(f"{nf}: ground truth {gf.name} missing beside it")
            noisy, gt = _read_mat(nf), _read_mat(gf)
            if noisy.shape != gt.shape or noisy.ndim != 2:
                raise DatasetError(f"{nf}: shape {noisy.shape} vs ground truth {gt.shape}; expected equal 2-D mosaics")
            _add_pair(parts, noisy, gt, [seed, d_i, f_i], patches_per_image, size, float(iso), cam, where=str(nf))
    return _patch_set(parts, f"{root}: no *NOISY_RAW_*.MAT files in the SIDD folders")


def _add_pair(parts: dict, noisy, gt, seed_key: list[int], n: int, size: int, iso: float, camera: str, *, where: str):
    """``n`` patches of one noisy/clean pair, drawn from ``SeedSequence(seed_key)``, with their ISO and camera."""
    rng = np.random.default_rng(np.random.SeedSequence(seed_key))
    _add_patches(parts, noisy, gt, rng, n, size, where=where)
    parts["iso"].append(np.full(n, iso))
    parts["camera"].append(np.full(n, camera))


def _patch_set(parts: dict, empty: str, **where) -> dict:
    """The collected patches as one checked set; DatasetError ``empty`` when there are none."""
    if not parts["clean"]:
        raise DatasetError(empty)
    return check_patch_set({
        "clean": np.stack(parts["clean"]), "noise": np.stack(parts["noise"]),
        "iso": np.concatenate(parts["iso"]), "camera": np.concatenate(parts["camera"]),
    }, **where)


def load_dng_bursts(root, *, patches_per_image: int = 64, size: int = 32, seed: int = 0) -> dict:
    """Patch set from DNG bursts with a ground truth.

    Every folder under ``root`` (``root`` included) that holds noisy frames
    ``*.dng`` plus a ground truth — ``clean.dng`` (as written by ``simcam synth``)
    or ``gt.npz`` with key ``gt`` (as written by ``simcam gt``: normalised raw of
    the whole stored image) — is one burst. Frames are normalised with their own
    black/white levels (the ``normalize`` stage, whole stored image); ISO from the
    EXIF tags, camera from ``UniqueCameraModel`` (else Make Model).
    """
    from ...io.dng import read_dng
    from ...io.normalized import read_normalized
    from ...raw import normalize

    root = Path(root)
    dirs = sorted({p.parent for p in root.rglob("*.dng")} | ({root} if any(root.glob("*.dng")) else set()))
    parts = {k: [] for k in KEYS}
    for d_i, d in enumerate(dirs):
        frames = sorted(p for p in d.glob("*.dng") if p.name != "clean.dng")
        if not frames:
            continue
        if (d / "clean.dng").is_file():
            gt = read_normalized(d / "clean.dng").data
        elif (d / "gt.npz").is_file():
            with np.load(d / "gt.npz") as z:
                if "gt" not in z:
                    raise DatasetError(f"{d / 'gt.npz'}: missing array 'gt' (as written by simcam gt)")
                gt = np.asarray(z["gt"], dtype=np.float32)
        else:
            raise DatasetError(f"{d}: {len(frames)} DNG frames but no ground truth; expected clean.dng or gt.npz beside them")
        for f_i, f in enumerate(frames):
            frame = read_dng(f)
            if frame.meta.iso is None:
                raise DatasetError(f"{f}: ISO: missing from the tags; expected the capture's ISO")
            noisy = normalize(frame).data
            if noisy.shape != gt.shape:
                raise DatasetError(f"{f}: shape {noisy.shape} differs from its ground truth {gt.shape}")
            camera = frame.meta.unique_camera_model or f"{frame.meta.make} {frame.meta.model}".strip()
            _add_pair(parts, noisy, gt, [seed, d_i, f_i], patches_per_image, size, float(frame.meta.iso), camera,
                      where=str(f))
    return _patch_set(parts, f"{root}: no DNG bursts (folders of *.dng frames with clean.dng or gt.npz)", where=str(root))


def load_data(path, **kw) -> dict:
    """A patch set from ``.npz``, a folder of SIDD .MAT pairs, or a folder of DNG bursts."""
    path = Path(path)
    if path.is_file() and path.suffix == ".npz":
        return load_npz(path)
    if path.is_dir():
        if any(d.is_dir() and _SIDD_DIR.match(d.name) for d in path.rglob("*")):
            return load_sidd_pairs(path, **kw)
        return load_dng_bursts(path, **kw)
    raise DatasetError(f"{path}: expected a .npz patch set, a folder of SIDD .MAT pairs or a folder of DNG bursts")
