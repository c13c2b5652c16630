"""Denoiser benchmark on SIDD-format blocks (seed sections 5.4 and 7.2).

Scores, per block, PSNR and SSIM against the ground truth in raw (the
mosaic, ``data_range=1``) and -- when each image's metadata and a rendering
pipeline are given -- in sRGB after rendering noisy-denoised and ground truth
blocks alike; see :mod:`simcam.dataset.metrics` for the exact conventions.
Set scores are means over blocks (as the SIDD evaluation reports them).
Runtime is the denoiser's wall time per megapixel of input (mosaic pixels
for raw, pixels for sRGB), ``seconds_per_mp``.

A block array whose last axis has length 3 (``[N, M, H, W, 3]``, the sRGB
track) is denoised and scored in sRGB only (``raw`` is then None).
"""

from __future__ import annotations

import csv
import json
import math
import re
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..errors import DatasetError
from ..frame import CameraMeta, RawFrame
from .denoisers import BlockInfo, get_denoiser
from .metrics import psnr, ssim

Renderer = Callable[[np.ndarray, CameraMeta], np.ndarray]


@dataclass
class BlockScore:
    image: int
    block: int
    psnr_raw: float | None
    ssim_raw: float | None
    psnr_srgb: float | None
    ssim_srgb: float | None
    seconds: float


@dataclass
class BenchmarkResult:
    """Scores of one denoiser on one block set; ``to_dict`` gives the JSON layout."""

    denoiser: str
    raw: dict[str, float] | None
    srgb: dict[str, float] | None
    seconds_per_mp: float
    per_block: list[BlockScore]
    settings: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"denoiser": self.denoiser, "raw": self.raw, "srgb": self.srgb,
                "seconds_per_mp": self.seconds_per_mp,
                "per_block": [_finite(asdict(b)) for b in self.per_block], "settings": self.settings}

    def write_json(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=1) + "\n")
        return path

    def write_csv(self, path: str | Path) -> Path:
        path = Path(path)
        with path.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["image", "block", "psnr_raw", "ssim_raw", "psnr_srgb", "ssim_srgb", "seconds"])
            for b in self.per_block:
                w.writerow([b.image, b.block] + ["" if v is None else f"{v:.6g}" for v in
                                                 (b.psnr_raw, b.ssim_raw, b.psnr_srgb, b.ssim_srgb, b.seconds)])
        return path


def _finite(d: dict) -> dict:
    # JSON has no inf: identical blocks (PSNR = inf) are written as null
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}


def _mean(values: list[float | None]) -> float | None:
    vals = [v for v in values if v is not None]
    if not vals:
        return None
    return float(np.mean(vals))


def as_image_list(blocks: np.ndarray | Sequence[np.ndarray], what: str) -> list[np.ndarray]:
    """``[N, M, H, W(, 3)]`` array or a list of ``[M, H, W(, 3)]`` arrays -> list of float arrays in [0, 1] scale.

    uint8 data (SIDD sRGB blocks) is divided by 255.
    """
    if isinstance(blocks, np.ndarray):
        if not (blocks.ndim == 4 or (blocks.ndim == 5 and blocks.shape[-1] == 3)):
            raise DatasetError(f"{what}: expected [N, M, H, W] or [N, M, H, W, 3] blocks, got shape {blocks.shape}")
        blocks = list(blocks)
    out = []
    for i, b in enumerate(blocks):
        b = np.asarray(b)
        if not (b.ndim == 3 or (b.ndim == 4 and b.shape[-1] == 3)):
            raise DatasetError(f"{what}[{i}]: expected [M, H, W] or [M, H, W, 3] blocks, got shape {b.shape}")
        out.append(b.astype(np.float32) / 255.0 if b.dtype == np.uint8 else b.astype(np.float32, copy=False))
    return out


#: stages that need the full frame's geometry, which a block does not have
BLOCK_SKIP_STAGES = ("crop", "lens_shading", "orientation")


def pipeline_renderer(pipeline, *, skip: Sequence[str] = BLOCK_SKIP_STAGES) -> Renderer:
    """A renderer running a :class:`~simcam.pipeline.Pipeline` on a normalised-raw block.

    Blocks are already normalised raw, so a pipeline whose input is ``raw_dn``
    must start with ``normalize``, which is skipped. Stages in ``skip`` (by
    default those that need the full frame's geometry: active-area crop,
    GainMap lens shading, orientation -- a SIDD block file does not say where
    a block lies) are dropped too. Ground truth and denoised blocks go through
    the same renderer. The output is clipped to [0, 1].
    """
    from ..pipeline import Pipeline

    pipe = Pipeline.from_yaml(pipeline) if isinstance(pipeline, (str, Path)) else pipeline
    kept = [st for st in pipe.stages if st.type not in set(skip)]
    if len(kept) != len(pipe.stages):
        pipe = Pipeline(kept, input_kind=pipe.input_kind, name=pipe.name, source=pipe.source)
    if pipe.input_kind == "raw_dn":
        if not pipe.stages or pipe.stages[0].type != "normalize":
            raise DatasetError(f"{pipe.source or pipe.name}: stages[0]: a raw_dn pipeline must start with "
                               f"'normalize' to render normalised-raw blocks")
        pipe = Pipeline(pipe.stages[1:], input_kind="raw", name=pipe.name, source=pipe.source)
    elif pipe.input_kind != "raw":
        raise DatasetError(f"{pipe.source or pipe.name}: input: expected a raw or raw_dn pipeline, got {pipe.input_kind!r}")
    if pipe.output_kind in ("raw", "raw_dn"):
        raise DatasetError(f"{pipe.source or pipe.name}: output: expected an RGB pipeline, got {pipe.output_kind!r}")

    def render(block: np.ndarray, meta: CameraMeta) -> np.ndarray:
        out = pipe(RawFrame(block, meta, kind="raw"), seed=0)
        return np.clip(out.data, 0.0, 1.0)

    render.name = pipe.name or pipe.source  # type: ignore[attr-defined]
    return render


def nlf_from_meta(meta: CameraMeta | None) -> tuple[float, float] | None:
    """(beta1, beta2) from a DNG NoiseProfile (mean over planes), or None."""
    if meta is None or meta.noise_profile is None:
        return None
    npf = np.asarray(meta.noise_profile, dtype=np.float64).reshape(-1, 2)
    return float(npf[:, 0].mean()), float(npf[:, 1].mean())


def run_benchmark(noisy, gt, denoiser: str | Callable = "none", *,
                  metas: Sequence[CameraMeta] | None = None, renderer: Renderer | None = None,
                  cfa: str | None = None, use_metadata_nlf: bool = True,
                  progress: Callable[[int, int], None] | None = None) -> BenchmarkResult:
    """Denoise every block and score it against the ground truth.

    Parameters
    ----------
    noisy, gt : array or list of arrays
        ``[N, M, H, W]`` raw or ``[N, M, H, W, 3]`` sRGB blocks (or per-image lists).
    denoiser : str or callable
        Spec for :func:`~simcam.dataset.denoisers.get_denoiser`, or ``f(noisy, info)``.
    metas : list of CameraMeta, optional
        One per image: CFA, NoiseProfile (handed to the denoiser as NLF) and
        the colour metadata for rendering.
    renderer : callable, optional
        ``render(block, meta) -> H x W x 3`` in [0, 1]; with ``metas`` it
        turns on the sRGB scores of a raw benchmark.
    cfa : str, optional
        Pattern of the blocks when ``metas`` is not given.
    """
    name, den = get_denoiser(denoiser)
    noisy_l, gt_l = as_image_list(noisy, "noisy"), as_image_list(gt, "gt")
    if len(noisy_l) != len(gt_l):
        raise DatasetError(f"gt: {len(gt_l)} images, expected as many as noisy ({len(noisy_l)})")
    if metas is not None and len(metas) != len(noisy_l):
        raise DatasetError(f"metadata: {len(metas)} entries, expected one per image ({len(noisy_l)})")
    srgb_track = noisy_l[0].ndim == 4
    if srgb_track:
        renderer = None
    per_block: list[BlockScore] = []
    pixels = 0
    total_blocks = sum(b.shape[0] for b in noisy_l)
    done = 0
    for i, (nb, gb) in enumerate(zip(noisy_l, gt_l)):
        if nb.shape != gb.shape:
            raise DatasetError(f"image {i}: noisy blocks {nb.shape} and ground truth {gb.shape} differ")
        meta = metas[i] if metas is not None else None
        info_cfa = meta.cfa if meta is not None else cfa
        nlf = nlf_from_meta(meta) if use_metadata_nlf else None
        for j in range(nb.shape[0]):
            x, ref = nb[j], gb[j]
            info = BlockInfo(cfa=info_cfa, nlf=nlf, iso=getattr(meta, "iso", None), image=i, block=j, meta=meta)
            t0 = time.perf_counter()
            out = np.asarray(den(x, info))
            dt = time.perf_counter() - t0
            if out.shape != x.shape:
                raise DatasetError(f"denoiser {name}: returned shape {out.shape} for a block of shape {x.shape}")
            pixels += x.shape[0] * x.shape[1]
            if srgb_track:
                score = BlockScore(i, j, None, None, psnr(ref, out, data_range=1.0),
                                   ssim(ref, out, data_range=1.0, channel_axis=-1), dt)
            else:
                p_s = s_s = None
                if renderer is not None and meta is not None:
                    r_ref, r_out = renderer(ref, meta), renderer(out.astype(np.float32), meta)
                    p_s, s_s = psnr(r_ref, r_out, data_range=1.0), ssim(r_ref, r_out, data_range=1.0, channel_axis=-1)
                score = BlockScore(i, j, psnr(ref, out, data_range=1.0), ssim(ref, out, data_range=1.0), p_s, s_s, dt)
            per_block.append(score)
            done += 1
            if progress:
                progress(done, total_blocks)
    raw = None if srgb_track else {"psnr": _mean([b.psnr_raw for b in per_block if b.psnr_raw != math.inf]),
                                   "ssim": _mean([b.ssim_raw for b in per_block])}
    srgb_p = _mean([b.psnr_srgb for b in per_block if b.psnr_srgb != math.inf])
    srgb = None if srgb_p is None else {"psnr": srgb_p, "ssim": _mean([b.ssim_srgb for b in per_block])}
    seconds = float(sum(b.seconds for b in per_block))
    settings = {"track": "srgb" if srgb_track else "raw", "images": len(noisy_l), "blocks": len(per_block),
                "block_shape": list(noisy_l[0].shape[1:]), "data_range": 1.0,
                "ssim": "gaussian sigma 1.5, population covariance (Wang 2004)",
                "renderer": getattr(renderer, "name", None) if renderer and metas is not None else None}
    return BenchmarkResult(name, raw, srgb, seconds / (pixels / 1e6), per_block, settings)


def merge_results(parts: Sequence[BenchmarkResult], images: Sequence[int]) -> BenchmarkResult:
    """One result from per-image results of one denoiser (a batch splits the images).

    ``parts[k]`` scored image ``images[k]`` alone (its blocks carry image 0); the merged result
    renumbers them and recomputes the means and seconds per megapixel exactly as
    :func:`run_benchmark` does over all the blocks at once.
    """
    from dataclasses import replace

    if not parts:
        raise DatasetError("merge_results: no partial results")
    per_block = [replace(b, image=int(i)) for part, i in zip(parts, images) for b in part.per_block]
    srgb_track = parts[0].settings.get("track") == "srgb"
    raw = None if srgb_track else {"psnr": _mean([b.psnr_raw for b in per_block if b.psnr_raw != math.inf]),
                                   "ssim": _mean([b.ssim_raw for b in per_block])}
    srgb_p = _mean([b.psnr_srgb for b in per_block if b.psnr_srgb != math.inf])
    srgb = None if srgb_p is None else {"psnr": srgb_p, "ssim": _mean([b.ssim_srgb for b in per_block])}
    seconds = float(sum(b.seconds for b in per_block))
    mp = sum(sum(b.seconds for b in p.per_block) / p.seconds_per_mp for p in parts if p.seconds_per_mp > 0)
    settings = dict(parts[0].settings, images=len(parts), blocks=len(per_block))
    return BenchmarkResult(parts[0].denoiser, raw, srgb, seconds / mp if mp > 0 else 0.0, per_block, settings)


# ------------------------------------------------------------------------------- leaderboard
_BOARD_TAG = re.compile(r"<!-- simcam-leaderboard (\{.*?\}) -->", re.DOTALL)


def leaderboard_markdown(entries: list[dict[str, Any]]) -> str:
    """A Markdown table of results (dicts from ``BenchmarkResult.to_dict``), best raw PSNR first."""
    def key(e):
        s = (e.get("raw") or e.get("srgb") or {}).get("psnr")
        return -(s if s is not None else -math.inf)

    lines = ["| # | denoiser | raw PSNR (dB) | raw SSIM | sRGB PSNR (dB) | sRGB SSIM | s/MP | blocks |",
             "|---|---|---|---|---|---|---|---|"]
    for k, e in enumerate(sorted(entries, key=key), 1):
        r, s = e.get("raw") or {}, e.get("srgb") or {}

        def f(v, fmt):
            return "-" if v is None else format(v, fmt)

        lines.append(f"| {k} | {e['denoiser']} | {f(r.get('psnr'), '.2f')} | {f(r.get('ssim'), '.4f')} | "
                     f"{f(s.get('psnr'), '.2f')} | {f(s.get('ssim'), '.4f')} | {f(e.get('seconds_per_mp'), '.3g')} | "
                     f"{e.get('settings', {}).get('blocks', '-')} |")
    return "\n".join(lines) + "\n"


def update_leaderboard(path: str | Path, result: BenchmarkResult | dict[str, Any]) -> Path:
    """Add (or replace, by denoiser name) one entry of a Markdown leaderboard file.

    The entries live in an HTML comment at the end of the file, so the table
    can be regenerated; anything else in the file is replaced.
    """
    path = Path(path)
    entry = result.to_dict() if isinstance(result, BenchmarkResult) else dict(result)
    entry = {k: v for k, v in entry.items() if k != "per_block"}
    entries: list[dict] = []
    if path.exists():
        m = _BOARD_TAG.search(path.read_text())
        if m is None:
            raise DatasetError(f"{path}: not a simcam leaderboard (no simcam-leaderboard comment); refusing to overwrite")
        entries = json.loads(m.group(1))["entries"]
    entries = [e for e in entries if e["denoiser"] != entry["denoiser"]] + [entry]
    text = ("# Denoiser leaderboard\n\nMean over blocks; PSNR/SSIM with data_range 1 (see simcam.dataset.metrics).\n\n"
            + leaderboard_markdown(entries)
            + f"\n<!-- simcam-leaderboard {json.dumps({'entries': entries})} -->\n")
    path.write_text(text)
    return path


# ------------------------------------------------------------------------------- metadata
def load_metadata_dir(folder: str | Path, n_images: int) -> list[CameraMeta]:
    """One CameraMeta per image from a folder, in sorted file-name order.

    Accepted files: SIDD metadata ``*METADATA*.MAT`` (read by :mod:`simcam.io.sidd`)
    or DNG files (their tags; pixels are not used).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise DatasetError(f"{folder}: --metadata: expected a folder of SIDD metadata .MAT or DNG files")
    files = sorted(p for p in folder.iterdir()
                   if p.is_file() and (p.suffix.lower() == ".dng" or
                                       (p.suffix.lower() == ".mat" and "metadata" in p.name.lower())))
    if len(files) != n_images:
        raise DatasetError(f"{folder}: --metadata: {len(files)} metadata files (*METADATA*.MAT or .dng), "
                           f"expected one per image ({n_images})")
    return [_read_meta(p) for p in files]


def _read_meta(path: Path) -> CameraMeta:
    if path.suffix.lower() == ".dng":
        from ..io.dng import read_dng_meta

        return read_dng_meta(path)
    from ..io.sidd import read_sidd_meta

    return read_sidd_meta(path)
