"""Capture sets: sequences of raw frames of a static scene at fixed settings.

Two layouts are read:

* a **directory of sequences**: each sub-directory holds the frames of one
  sequence (``*.dng``, or ``*.npy`` arrays in DN with a ``sequence.yaml``
  giving ``iso``, ``exposure_s``, ``cfa``, ``black_level``, ``white_level``).
  A name starting with ``dark`` means no light, ``flat`` uniform light, any
  other name a scene. ``clean.dng`` / ``clean.npy`` is the optional clean
  reference of a scene (DN, black included).
* the **EMVA 1288 descriptor** (``EMVA1288_Data.txt``: ``n bits width height``,
  ``b exposure_ns photons`` / ``d exposure_ns`` followed by ``i path`` lines,
  Windows separators; monochrome PNGs). EMVA 1288 Release 3.0, sec. 6.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import DatasetError
from .streaming import kernel_input, moments_add

#: A flat is refused when more than this fraction of its pixels sit at the white level.
SATURATION_LIMIT = 0.01
#: Largest EMVA 1288 descriptor read (bytes); real ones are a few kB.
MAX_DESCRIPTOR_BYTES = 1 << 20


@dataclass
class Sequence:
    """Frames of one static scene at fixed settings.

    ``frames`` is (n, H, W) float32 in DN (black included). ``black_dn`` is the
    *declared* black level per 2x2 CFA site (metadata), or None when unknown.
    ``clean`` is the clean reference in DN (H, W) or None.
    """

    name: str
    kind: str  # "dark" | "flat" | "scene"
    frames: np.ndarray
    iso: int
    exposure_s: float | None
    cfa: str | None
    black_dn: np.ndarray | None
    white_dn: float
    clean: np.ndarray | None = None
    photons: float | None = None  # EMVA: mean photons per pixel
    source: str = ""
    #: whole-frame statistics (:class:`FrameSummary`) accumulated while reading; computed from
    #: ``frames`` on first use when absent
    summary: "FrameSummary | None" = None
    #: True when ``frames`` holds only the loop's analysed region (:mod:`simcam.calibration.region`)
    region_applied: bool = False
    #: EMVA 1288 R4.0 per-channel point statistics over whole frames (dark and flat sequences with
    #: an exposure time; :class:`simcam.calibration.emva1288.PointStats`), else None
    emva_stats: list | None = None

    @property
    def n(self) -> int:
        return int(self.frames.shape[0])

    @property
    def shape(self) -> tuple[int, int]:
        """Size (H, W) of the whole frame."""
        return self.stats().shape if self.region_applied else tuple(self.frames.shape[1:])

    def stats(self) -> "FrameSummary":
        """Whole-frame statistics (streamed at reading time, else from ``frames``)."""
        if self.summary is None:
            acc = FrameAccumulator(keep_mean_map=self.kind == "dark")
            for f in self.frames:
                acc.add(f, self.white_dn)
            self.summary = acc.result()
        return self.summary

    def saturated_fraction(self) -> float:
        return self.stats().saturated_fraction


@dataclass
class FrameSummary:
    """Whole-frame sufficient statistics of one sequence, per 2x2 CFA site (index 4 = all pixels).

    ``pair_mean`` / ``pair_var``: mean of the first two frames and half the variance of their
    difference (EMVA 1288 R3.0 eq. 26); ``avg_mean`` / ``avg_var``: mean and spatial variance (ddof 1)
    of the temporal-mean image; ``temporal_var``: mean over pixels of the per-pixel temporal variance
    (ddof 1); ``frame_means`` (n,) per-frame means; ``mean_map`` the temporal-mean image (darks only,
    float32) for the dark-current map.
    """

    n: int
    shape: tuple
    pair_mean: np.ndarray
    pair_var: np.ndarray
    avg_mean: np.ndarray
    avg_var: np.ndarray
    temporal_var: np.ndarray
    frame_means: np.ndarray
    saturated_fraction: float
    mean_map: np.ndarray | None = None


class FrameAccumulator:
    """One pass over a sequence's frames: per-pixel sums and sums of squares (float64), the first
    frame for the pair difference; memory two float64 frames and one float32 frame."""

    def __init__(self, keep_mean_map: bool = False):
        self.n = 0
        self.keep = keep_mean_map
        self.s1 = self.s2 = self.first = None
        self.pair = None
        self.means: list[float] = []
        self.sat = 0

    def add(self, frame: np.ndarray, white: float) -> None:
        frame = kernel_input(frame)
        if frame.ndim != 2:
            raise DatasetError(f"expected a 2-D frame, got shape {frame.shape}")
        if self.s1 is None:
            self.s1, self.s2 = np.zeros(frame.shape), np.zeros(frame.shape)
            self.first = np.asarray(frame, dtype=np.float32).copy()
        tot, sat = moments_add(frame, self.s1, self.s2, float(white))  # one pass (simcam.calibration.streaming)
        if self.n == 1:
            f = np.asarray(frame, dtype=np.float64)
            a = self.first.astype(np.float64)
            d = a - f
            pv = _site_mean((d - _site_mean(d, full=True)) ** 2) / 2
            pv[4] = float(np.mean((d - d.mean()) ** 2)) / 2
            self.pair = ([_site_mean(a + f) / 2], [pv])
            self.first = None
        self.means.append(tot / frame.size)
        self.sat += int(sat)
        self.n += 1

    def result(self) -> "FrameSummary":
        n = self.n
        if n < 2:
            raise DatasetError("a sequence needs >= 2 frames for temporal statistics")
        avg = self.s1 / n
        tvar = np.maximum(self.s2 - self.s1 * avg, 0.0) / (n - 1)
        avg_var = _site_var(avg)
        return FrameSummary(
            n=n, shape=tuple(avg.shape), pair_mean=self.pair[0][0], pair_var=self.pair[1][0],
            avg_mean=_site_mean(avg), avg_var=avg_var, temporal_var=_site_mean(tvar),
            frame_means=np.asarray(self.means), saturated_fraction=self.sat / float(n * avg.size),
            mean_map=avg.astype(np.float32) if self.keep else None)


def _site_mean(x: np.ndarray, full: bool = False) -> np.ndarray:
    """Means of the four 2x2 sites and of all pixels (5,), or a (H, W) map of its site means (``full``)."""
    h, w = x.shape
    vals = [float(x[dy::2, dx::2].mean()) if h > dy and w > dx else float("nan") for dy, dx in PLANE_OFFSETS]
    if full:
        out = np.empty_like(x)
        for v, (dy, dx) in zip(vals, PLANE_OFFSETS):
            out[dy::2, dx::2] = v
        return out
    return np.array(vals + [float(x.mean())])


def _site_var(x: np.ndarray) -> np.ndarray:
    h, w = x.shape
    vals = [float(np.var(x[dy::2, dx::2], ddof=1)) if x[dy::2, dx::2].size > 1 else float("nan")
            for dy, dx in PLANE_OFFSETS]
    return np.array(vals + [float(np.var(x, ddof=1))])


PLANE_OFFSETS = ((0, 0), (0, 1), (1, 0), (1, 1))


@dataclass
class CaptureSet:
    """All sequences of a capture set plus notes made while reading it."""

    root: str
    layout: str  # "directory" | "emva1288"
    sequences: list[Sequence]
    notes: list[str] = field(default_factory=list)

    def isos(self) -> list[int]:
        return sorted({s.iso for s in self.sequences})

    def group(self, iso: int) -> list[Sequence]:
        return [s for s in self.sequences if s.iso == iso]


class _SequenceBuilder:
    """Frames of one sequence as they are read: whole-frame statistics accumulated, only the loop's
    analysed region kept (all of the frame when ``region`` is None)."""

    def __init__(self, kind: str, white: float, region=None, *, exposure_s: float | None = None,
                 photons: float | None = None, cfa: str | None = None):
        self.acc = FrameAccumulator(keep_mean_map=kind == "dark")
        self.white, self.region, self.plan = white, region, None
        self.kept: list[np.ndarray] = []
        self.emva = None  # EMVA 1288 R4.0 point statistics over whole frames, in the same pass
        if kind in ("dark", "flat") and exposure_s is not None and exposure_s > 0:
            from .emva1288 import OperatingPoint, PointAccumulator

            point = OperatingPoint("dark" if kind == "dark" else "bright", float(exposure_s), (), photons)
            self.emva = PointAccumulator(point, cfa)

    def add(self, frame: np.ndarray) -> None:
        self.acc.add(frame, self.white)
        if self.emva is not None:
            self.emva.add(frame)
        if self.region is not None:
            if self.plan is None:
                self.plan = self.region.plan(*frame.shape)
            frame = np.ascontiguousarray(self.region.extract(frame, self.plan))
        self.kept.append(np.asarray(frame, dtype=np.float32))

    def finish(self) -> tuple[np.ndarray, "FrameSummary"]:
        return np.stack(self.kept), self.acc.result()

    def emva_stats(self) -> list | None:
        return None if self.emva is None else self.emva.finish(keep_map=True)


def keep_spatial_maps(seqs: list[Sequence]) -> None:
    """Keep the EMVA mean maps of one dark and one flat per ISO (the most frames: EMVA 1288 R4.0 evaluates
    the non-uniformities on one dark and one bright point); drop the others' as soon as they are read."""
    best: dict[tuple[int, str], Sequence] = {}
    for s in seqs:
        if not s.emva_stats or s.emva_stats[0].mean_map is None:
            continue
        key = (s.iso, s.kind)
        cur = best.get(key)
        if cur is None or s.n > cur.n:
            if cur is not None:
                for st in cur.emva_stats:
                    st.mean_map = None
            best[key] = s
        else:
            for st in s.emva_stats:
                st.mean_map = None


def _progress(total: int, desc: str, enabled: bool | None):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="frame", disable=None if enabled is None else not enabled, leave=False)


def sequence_kind(name: str) -> str:
    low = name.lower()
    return "dark" if low.startswith("dark") else "flat" if low.startswith("flat") else "scene"


def read_capture_set(path: str | Path, *, check_saturation: bool = True, region=None,
                     progress: bool | None = None, threads: int = 1) -> CaptureSet:
    """Read a capture-set directory or an EMVA 1288 descriptor file, one frame at a time.

    Every frame goes through the sequence's whole-frame accumulators (:class:`FrameSummary`);
    with a ``region`` (:class:`simcam.calibration.region.Region`) only its pixels are kept in
    memory (``Sequence.frames``), else whole frames. ``progress``: a progress bar over the frames
    (None: when the output is a terminal). ``threads``: sequence directories read at once (each
    sequence's frames stay in order, the accumulators release the GIL; the sequences come back in
    directory order and the first failing one, in that order, is the error raised: the same result
    for any count).

    Raises
    ------
    DatasetError
        Mixed size or CFA within a sequence, a sequence of one frame, a
        saturated flat, no sequence at all.
    """
    path = Path(path)
    if not path.exists():
        raise DatasetError(f"{path}: capture set not found; expected a directory of sequences or an EMVA 1288 descriptor")
    if path.is_file():
        return read_emva1288(path, region=region, progress=progress)
    descriptors = sorted(path.glob("EMVA1288*.txt"))
    if descriptors:
        return read_emva1288(descriptors[0], region=region, progress=progress)
    seqs = []
    dirs = sorted(p for p in path.iterdir() if p.is_dir())
    total = sum(len(_frame_files(d)) for d in dirs if not _is_sidd(d))
    with _progress(total, "reading frames", progress) as bar:
        pool = None
        if threads > 1 and len(dirs) > 1:
            from concurrent.futures import ThreadPoolExecutor

            pool = ThreadPoolExecutor(max_workers=min(threads, len(dirs)))
            futures = [pool.submit(_read_sequence_dir, d, region, bar) for d in dirs]
            read = (f.result() for f in futures)
        else:
            read = (_read_sequence_dir(d, region, bar) for d in dirs)
        try:
            for seq in read:  # in directory order; the maps not kept are dropped as each sequence arrives
                seqs.append(seq)
                keep_spatial_maps(seqs)
        finally:
            if pool is not None:  # after an error: the sequences not started are not read
                pool.shutdown(wait=True, cancel_futures=True)
    if not seqs:
        raise DatasetError(f"{path}: no sequence sub-directories; expected dark*/, flat*/ or scene directories of frames")
    cs = CaptureSet(str(path), "directory", seqs)
    _check_set(cs, check_saturation)
    return cs


def _frame_files(d: Path) -> list[Path]:
    files = sorted(p for p in d.iterdir() if p.is_file() and p.suffix.lower() in (".dng", ".npy")
                   and p.stem.lower() != "clean")
    return files


def _is_sidd(d: Path) -> bool:
    return any(p.name.upper().find("NOISY_RAW") >= 0 and p.suffix.upper() == ".MAT" for p in d.iterdir())


def _read_sequence_dir(d: Path, region=None, bar=None) -> Sequence:
    from ..yamlio import load_yaml

    if _is_sidd(d):
        return _read_sidd_dir(d)
    files = _frame_files(d)
    if not files:
        raise DatasetError(f"{d}: no frames; expected *.dng or *.npy files")
    side = {}
    if (d / "sequence.yaml").exists():
        side_path = d / "sequence.yaml"
        try:
            side = load_yaml(side_path.read_text(), source=str(side_path), error=DatasetError) or {}
        except (OSError, UnicodeDecodeError) as exc:
            raise DatasetError(f"{side_path}: cannot read ({exc})") from None
        if not isinstance(side, dict):
            raise DatasetError(f"{side_path}: expected a mapping of iso, exposure_s, cfa, black_level, white_level")
    first_shape, metas, builder = None, [], None
    for f in files:
        arr, meta = _read_frame(f, side)
        if first_shape is not None and arr.shape != first_shape:
            raise DatasetError(f"{f}: frame size {arr.shape[1]}x{arr.shape[0]} differs from {files[0].name} "
                               f"({first_shape[1]}x{first_shape[0]}); expected one size per sequence")
        if metas and meta["cfa"] != metas[0]["cfa"]:
            raise DatasetError(f"{f}: cfa {meta['cfa']!r} differs from {files[0].name} ({metas[0]['cfa']!r}); "
                               "expected one CFA pattern per sequence")
        for key in ("iso", "exposure_s"):
            if metas and meta[key] is not None and metas[0][key] is not None and \
                    not np.isclose(meta[key], metas[0][key], rtol=1e-6):
                raise DatasetError(f"{f}: {key} {meta[key]} differs from {files[0].name} ({metas[0][key]}); "
                                   "expected fixed settings within a sequence")
        if builder is None:
            first_shape = arr.shape
            builder = _SequenceBuilder(sequence_kind(d.name), float(meta["white"]), region,
                                       exposure_s=meta["exposure_s"], cfa=meta["cfa"])
        builder.add(arr)
        metas.append(meta)
        if bar is not None:
            bar.update(1)
    if len(metas) < 2:
        raise DatasetError(f"{d}: sequence has 1 frame; expected >= 2 frames of the same scene "
                           "(temporal variance needs frame pairs)")
    m = metas[0]
    clean = None
    for cname in ("clean.npy", "clean.dng"):
        if (d / cname).exists():
            clean, _ = _read_frame(d / cname, side)
            if clean.shape != first_shape:
                raise DatasetError(f"{d / cname}: clean reference size {clean.shape} differs from the frames "
                                   f"{first_shape}; expected the same size")
            if region is not None:
                clean = np.ascontiguousarray(region.extract(clean, builder.plan))
            break
    frames, summary = builder.finish()
    return Sequence(
        name=d.name, kind=sequence_kind(d.name), frames=frames,
        iso=int(round(m["iso"])) if m["iso"] is not None else 0, exposure_s=m["exposure_s"], cfa=m["cfa"],
        black_dn=m["black"], white_dn=float(m["white"]), clean=clean, source=str(d), summary=summary,
        region_applied=region is not None, emva_stats=builder.emva_stats(),
    )


def _read_frame(f: Path, side: dict) -> tuple[np.ndarray, dict]:
    if f.suffix.lower() == ".npy":
        try:
            arr = np.load(f, allow_pickle=False)
        except Exception as exc:
            raise DatasetError(f"{f}: cannot read as a numpy array ({exc})") from None
        if arr.ndim != 2:
            raise DatasetError(f"{f}: frame shape {arr.shape}; expected a 2-D H x W mosaic in DN")
        if "white_level" not in side:
            raise DatasetError(f"{f.parent / 'sequence.yaml'}: white_level missing; expected the ADC white level in DN "
                               "for .npy frames")
        black = side.get("black_level")
        if black is not None:
            black = np.broadcast_to(np.asarray(black, dtype=np.float64), (2, 2)).copy()
        cfa = side.get("cfa")
        if cfa is not None:
            from ..cfa import check_pattern

            cfa = check_pattern(str(cfa), where=f"{f.parent / 'sequence.yaml'}: cfa")
        return arr.astype(np.float32), {"cfa": cfa, "black": black, "white": float(side["white_level"]),
                                        "iso": side.get("iso"), "exposure_s": side.get("exposure_s")}
    from ..cfa import shift_pattern
    from ..io.dng import read_dng
    from ..raw import black_level_map

    fr = read_dng(f)
    meta = fr.meta
    data = np.asarray(fr.data, dtype=np.float32)
    black_map = black_level_map(meta, data.shape)
    cfa = meta.cfa
    if meta.active_area:  # analyse the active area only (masked borders are not image pixels)
        t, l, b, r = meta.active_area
        data, black_map = data[t:b, l:r], black_map[t:b, l:r]
        cfa = shift_pattern(cfa, t, l) if cfa else None
    black = np.array([[float(np.median(black_map[dy::2, dx::2])) for dx in (0, 1)] for dy in (0, 1)])
    return data, {"cfa": cfa, "black": black, "white": float(meta.white_level),
                  "iso": meta.iso, "exposure_s": meta.exposure_time_s}


def _read_sidd_dir(d: Path) -> Sequence:
    """A SIDD scene directory: ``*NOISY_RAW_*.MAT`` frames, ``*GT_RAW_*.MAT`` clean reference,
    ``*METADATA_RAW_*.MAT`` tags (Abdelhamed et al., CVPR 2018). The .MAT images (variable
    ``x``) are normalised raw in [0, 1]; they are turned back into DN with the metadata's black
    and white levels."""
    from ..io.sidd import read_sidd_image as image
    from ..io.sidd import read_sidd_meta
    from ..raw import black_level_map

    def find(tag):
        return sorted(p for p in d.iterdir() if tag in p.name.upper() and p.suffix.upper() == ".MAT")

    metas = find("METADATA_RAW")
    if not metas:
        raise DatasetError(f"{d}: SIDD scene without *METADATA_RAW_*.MAT; expected the tag file beside the frames")
    meta = read_sidd_meta(metas[0])
    noisy = [image(p) for p in find("NOISY_RAW")]
    for p, x in zip(find("NOISY_RAW"), noisy):
        if x.shape != noisy[0].shape:
            raise DatasetError(f"{p}: size {x.shape} differs from the first noisy frame {noisy[0].shape}; "
                               "expected one size per sequence")
    if len(noisy) < 2:
        raise DatasetError(f"{d}: sequence has 1 frame; expected >= 2 frames of the same scene "
                           "(temporal variance needs frame pairs)")
    black_map = black_level_map(meta, noisy[0].shape).astype(np.float64)
    scale = float(meta.white_level) - black_map
    frames = np.stack([x * scale + black_map for x in noisy]).astype(np.float32)
    gts = find("GT_RAW")
    clean = (image(gts[0]) * scale + black_map) if gts else None
    black = np.array([[float(np.median(black_map[dy::2, dx::2])) for dx in (0, 1)] for dy in (0, 1)])
    return Sequence(name=d.name, kind="scene", frames=frames, iso=int(round(meta.iso or 0)),
                    exposure_s=meta.exposure_time_s, cfa=meta.cfa, black_dn=black, white_dn=float(meta.white_level),
                    clean=clean, source=str(d))


def _check_set(cs: CaptureSet, check_saturation: bool) -> None:
    for iso in cs.isos():
        group = cs.group(iso)
        ref = group[0]
        for s in group[1:]:
            if s.shape != ref.shape or s.cfa != ref.cfa:
                raise DatasetError(f"{s.source}: size {s.shape} / cfa {s.cfa!r} differs from {ref.source} "
                                   f"({ref.shape} / {ref.cfa!r}) at ISO {iso}; expected one sensor geometry per ISO")
        if not any(s.kind == "dark" for s in group):
            cs.notes.append(f"ISO {iso}: no dark sequence; dark diagnostics (DSNU, hot pixels, black level, "
                            "read-noise tails, code occupancy, spatial correlation) are skipped")
    if check_saturation:
        for s in cs.sequences:
            if s.kind == "flat" and s.saturated_fraction() > SATURATION_LIMIT:
                raise DatasetError(f"{s.source}: flat is saturated ({100 * s.saturated_fraction():.1f}% of pixels at "
                                   f"white level {s.white_dn:g} DN); expected <= {100 * SATURATION_LIMIT:g}%: "
                                   "shorten the exposure or remove the sequence")


def read_emva1288(descriptor: str | Path, *, region=None, progress: bool | None = None) -> CaptureSet:
    """Read an EMVA 1288 descriptor (R3.0 format) into dark and flat sequences.

    Each ``b``/``d`` block becomes one sequence (``flat_NNN`` / ``dark_NNN``) in
    file order; images are monochrome PNGs whose paths use Windows separators.
    """
    descriptor = Path(descriptor)
    bits = width = height = None
    blocks: list[dict] = []
    try:
        if descriptor.stat().st_size > MAX_DESCRIPTOR_BYTES:
            raise DatasetError(f"{descriptor}: {descriptor.stat().st_size} bytes; expected an EMVA 1288 descriptor "
                               f"(a text file under {MAX_DESCRIPTOR_BYTES} bytes) or a directory of sequences")
        text = descriptor.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise DatasetError(f"{descriptor}: not a text file; expected an EMVA 1288 descriptor (EMVA1288_Data.txt) "
                           "or a directory of sequences (dark*/, flat*/, scenes)") from None
    except OSError as exc:
        raise DatasetError(f"{descriptor}: cannot read ({exc.strerror})") from None
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        tag = parts[0]
        try:
            if tag == "n":
                bits, width, height = int(parts[1]), int(parts[2]), int(parts[3])
            elif tag == "b":
                blocks.append({"kind": "flat", "exp_ns": float(parts[1].replace(",", ".")),
                               "photons": float(parts[2].replace(",", ".")), "files": []})
            elif tag == "d":
                blocks.append({"kind": "dark", "exp_ns": float(parts[1].replace(",", ".")), "photons": 0.0, "files": []})
            elif tag == "i":
                if not blocks:
                    raise DatasetError(f"{descriptor}:{lineno}: image line before any 'b' or 'd' line")
                blocks[-1]["files"].append(descriptor.parent / Path(*parts[1].replace("\\", "/").split("/")))
            elif tag == "v":
                pass
            else:
                raise DatasetError(f"{descriptor}:{lineno}: unknown line tag {tag!r}; expected v, n, b, d or i")
        except (IndexError, ValueError):
            raise DatasetError(f"{descriptor}:{lineno}: cannot parse {line!r}; expected "
                               "'n bits width height', 'b exposure_ns photons', 'd exposure_ns' or 'i path'") from None
    if bits is None:
        raise DatasetError(f"{descriptor}: no 'n bits width height' line; expected an EMVA 1288 descriptor")
    seqs = []
    counters = {"flat": 0, "dark": 0}
    white = float(2 ** bits - 1)
    with _progress(sum(len(b["files"]) for b in blocks), "reading frames", progress) as bar:
        for b in blocks:
            name = f"{b['kind']}_{counters[b['kind']]:03d}"
            counters[b["kind"]] += 1
            if len(b["files"]) < 2:
                raise DatasetError(f"{descriptor}: block {name} (exposure {b['exp_ns']:g} ns) has "
                                   f"{len(b['files'])} image(s); expected >= 2")
            builder = _SequenceBuilder(b["kind"], white, region, exposure_s=b["exp_ns"] * 1e-9,
                                       photons=b["photons"] if b["kind"] == "flat" else 0.0)
            for f in b["files"]:
                builder.add(_read_png(f, (height, width)))
                bar.update(1)
            frames, summary = builder.finish()
            seqs.append(Sequence(name=name, kind=b["kind"], frames=frames, iso=0, exposure_s=b["exp_ns"] * 1e-9,
                                 cfa=None, black_dn=None, white_dn=white, photons=b["photons"],
                                 source=f"{descriptor}:{name}", summary=summary, region_applied=region is not None,
                                 emva_stats=builder.emva_stats()))
            keep_spatial_maps(seqs)
    cs = CaptureSet(str(descriptor), "emva1288", seqs,
                    notes=["EMVA 1288 descriptor: monochrome, no declared black level (black taken from the darks), "
                           "ISO not given"])
    return cs


def _read_png(path: Path, shape: tuple[int, int]) -> np.ndarray:
    """One monochrome image (PNG / TIFF) through OpenImageIO, stored values unscaled."""
    from ..io.images import decode_image

    if not path.exists():
        raise DatasetError(f"{path}: image listed in the descriptor not found")
    arr, spec = decode_image(path, channels=1, error=DatasetError, undecodable="cannot decode image pixels")
    arr = np.asarray(arr)[..., 0] if np.ndim(arr) == 3 else np.asarray(arr)
    if spec.nchannels != 1:
        raise DatasetError(f"{path}: {spec.nchannels} channels; expected a monochrome image")
    if arr.shape != shape:
        raise DatasetError(f"{path}: image size {arr.shape[1]}x{arr.shape[0]}; expected {shape[1]}x{shape[0]} "
                           "from the descriptor's 'n' line")
    return arr.astype(np.float32)
