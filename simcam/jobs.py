"""The per-item work of simcam's commands, as plain functions a batch worker can run.

Each ``*_job(payload)`` takes a dict of plain values (so it pickles to a ``dask.distributed``
worker), does one item and writes its outputs atomically, and returns a small dict for the
report. The single-item commands call the same functions, so one input rendered alone and the
same input rendered in a batch give the same bytes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable


def render_file(input: str | Path, output: str | Path, *, pipeline: Any = "srgb", depth: str | None = None,
                seed: int = 0, index: int = 0, progress: Callable[[str], None] | None = None,
                attributes: dict | None = None, frame: Any = None, quality: int = 95,
                compression: str | None = None, thumbnail: str | Path | None = None) -> dict:
    """Render one DNG to one image file (colour-tagged, with the camera's EXIF).

    Parameters
    ----------
    input, output : path
        The DNG and the image to write (its extension picks the format).
    pipeline : str, path, dict or Pipeline
        A built-in name, a YAML path, a pipeline document or a built pipeline.
    depth : str, optional
        Output sample type (see :func:`simcam.io.images.resolve_depth`).
    seed, index : int
        Random stages of item ``index`` draw from ``SeedSequence([seed, 0, index])``.
    progress : callable, optional
        Called with each stage's type after it ran.
    frame : RawFrame, optional
        ``input`` already read (it is not read again).
    quality, compression, thumbnail
        Passed to :func:`simcam.io.images.write_image`.

    Returns
    -------
    dict
        ``{"output", "width", "height", "kind"}``.
    """
    from .io.dng import read_dng
    from .io.images import ext_is_tiff, resolve_compression, resolve_depth, write_image
    from .io.tiff_stream import TiffStream
    from .pipeline import Pipeline
    from .render_samples import render_samples

    pipe = pipeline if isinstance(pipeline, Pipeline) else (
        Pipeline.from_dict(pipeline, source="<batch>") if isinstance(pipeline, dict) else Pipeline.from_yaml(pipeline))
    dtype = resolve_depth(output, depth)
    # an uncompressed TIFF (the default for .tif) is written strip by strip as the render makes it
    stream = (TiffStream(output, protect=(input,)) if ext_is_tiff(Path(output)) and not attributes
              and thumbnail is None and resolve_compression(output, compression) == "none"
              and dtype in ("uint8", "uint16", "float32") else None)
    warming = pipe.warm_in_background()  # e.g. numba's set-up for Menon 2007 while the DNG is read
    try:
        out = render_samples(pipe, read_dng(input) if frame is None else frame, dtype, seed=seed, index=index,
                             progress=progress, target=stream)
        if out.samples is None:
            stream.commit()
    finally:
        if warming is not None:
            warming.join()
        if stream is not None:
            stream.discard()
    if out.samples is not None:
        write_image(output, out, depth=dtype, protect=(input,), attributes=attributes, quality=quality,
                    compression=compression, thumbnail=thumbnail)
    h, w = out.shape[:2]
    return {"output": str(output), "width": w, "height": h, "kind": out.kind}


def render_job(payload: dict) -> dict:
    """Batch form of :func:`render_file` (keys: input, output, pipeline, depth, seed, index; optional
    quality, compression)."""
    return render_file(payload["input"], payload["output"], pipeline=payload["pipeline"],
                       depth=payload.get("depth"), seed=payload.get("seed", 0), index=payload.get("index", 0),
                       quality=payload.get("quality", 95), compression=payload.get("compression"))


def synth_patches_job(payload: dict) -> dict:
    """Noisy/clean packed patches of one clean source into its rows of a training-set Zarr group.

    Payload keys: ``source`` (clean DNG / TIFF / PNG), ``index`` (item *i*), ``seed``, ``profile``,
    ``isos`` (one is drawn per item), ``camera``, ``extrapolate``, ``sensor_seed``, ``as_``, ``cfa``,
    ``patch_size`` (mosaic side, even), ``patches`` (K), ``store`` (the group's path or URL),
    ``storage_options``. Item *i* draws everything — the ISO, the noise over the whole frame (so
    fixed patterns sit where the sensor has them) and the K crop positions — from
    ``SeedSequence([seed, i])``, and writes rows ``[i K, (i + 1) K)``: exactly one chunk of each
    array, so items never share a chunk.
    """
    import numpy as np
    import zarr

    from .cfa import pack
    from .training.crops import crop_origin
    from .synth import load_clean
    from .profiles.schema import load_profile
    from .stages.noise import Noise

    i, k, p2 = int(payload["index"]), int(payload["patches"]), int(payload["patch_size"])
    rng = np.random.default_rng(np.random.SeedSequence([int(payload["seed"]), i]))
    isos = list(payload["isos"])
    iso = float(isos[int(rng.integers(len(isos)))]) if len(isos) > 1 else float(isos[0])
    prof = load_profile(payload["profile"])
    cam = prof.camera(payload.get("camera"))
    frame = load_clean(payload["source"], as_=payload.get("as_", "raw"), profile=prof, camera=cam.id, iso=iso,
                       cfa=payload.get("cfa"))
    stage = Noise(profile=str(payload["profile"]), iso=iso, camera=cam.id,
                  extrapolate=bool(payload.get("extrapolate", False)), sensor_seed=payload.get("sensor_seed"),
                  exposure_s=payload.get("exposure"))
    noisy = stage(frame, rng).data
    clean = frame.data
    cfa = frame.meta.cfa or "RGGB"
    h = p2 // 2
    out_clean = np.empty((k, 4, h, h), np.float32)
    out_noisy = np.empty((k, 4, h, h), np.float32)
    origins = np.empty((k, 2), np.int32)
    for j in range(k):
        top, left = crop_origin(rng, clean.shape, p2, cfa, "RGGB", where=payload["source"])
        out_clean[j] = pack(clean[top:top + p2, left:left + p2])
        out_noisy[j] = pack(noisy[top:top + p2, left:left + p2])
        origins[j] = (top, left)
    group = zarr.open_group(payload["store"], mode="r+", storage_options=payload.get("storage_options"))
    rows = slice(i * k, (i + 1) * k)
    group["clean"][rows] = out_clean
    group["iso"][rows] = np.full(k, iso, np.float32)
    group["origin"][rows] = origins
    group["noisy"][rows] = out_noisy  # last: its chunk marks the item done (resume)
    return {"iso": iso, "rows": [rows.start, rows.stop]}


def ground_truth_job(payload: dict) -> dict:
    """Ground truth of one burst (``simcam gt``), written as ``npz`` / ``dng`` + a JSON ``report``.

    Payload keys: ``burst`` (folder), ``npz``, ``dng``, ``report``, ``save_defects`` (paths or None),
    ``dark``, ``flat``, ``defects`` (inputs or None), ``method``, ``alignment``, ``intensity``,
    ``patch``, ``interp_order``, ``pattern``, ``dark_pattern``, ``black_level``, ``white_level``,
    ``nan_policy``, ``scratch_dir``, ``progress``.

    Returns
    -------
    dict
        ``{"summary": one line, "outputs": [...]}``.
    """
    import json

    from .groundtruth import (Burst, DefectMap, GroundTruthConfig, estimate_ground_truth, load_defect_map,
                                      save_defect_map)
    from .errors import DatasetError

    p = payload
    kw = dict(black_level=p.get("black_level"), white_level=p.get("white_level"), nan_policy=p.get("nan_policy", "raise"))
    burst = Burst.from_directory(p["burst"], pattern=p.get("pattern"), **kw)
    inputs = {Path(n).resolve() for n in burst.names}
    outs = [o for o in (p.get("npz"), p.get("dng"), p.get("report"), p.get("save_defects")) if o]
    for o in outs:
        if Path(o).resolve() in inputs:
            raise DatasetError(f"{o}: refusing to overwrite an input frame")
    dark_b = Burst.from_directory(p["dark"], pattern=p.get("dark_pattern"), **kw) if p.get("dark") else None
    flat_b = Burst.from_directory(p["flat"], **kw) if p.get("flat") else None
    known = load_defect_map(p["defects"]) if p.get("defects") else None
    cfg = GroundTruthConfig(method=p.get("method", "wls"), alignment=p.get("alignment", "local"),
                            intensity=p.get("intensity", "additive"), patch=int(p.get("patch", 512)),
                            interp_order=int(p.get("interp_order", 3)), scratch_dir=p.get("scratch_dir"))
    res = estimate_ground_truth(burst, dark=dark_b, flat=flat_b, defects=known, config=cfg,
                                progress=bool(p.get("progress", False)))
    written = []
    if p.get("npz"):
        res.save_npz(p["npz"])
        written.append(str(p["npz"]))
    if p.get("dng"):
        from .groundtruth.dngout import write_ground_truth_dng

        write_ground_truth_dng(p["dng"], res, burst)
        written.append(str(p["dng"]))
    if p.get("save_defects"):
        save_defect_map(p["save_defects"], DefectMap(res.defects, "simcam gt", res.report["defects"].get("planes", [])))
        written.append(str(p["save_defects"]))
    rep = dict(res.report, inputs={"burst": str(p["burst"]), "dark": p.get("dark"), "flat": p.get("flat"),
                                   "defects": p.get("defects")}, outputs=written)
    from .io.atomic import atomic_output

    with atomic_output(p["report"], suffix=".json") as tmp:
        Path(tmp).write_text(json.dumps(rep, indent=2))
    a = res.report["alignment"]
    summary = (f"ground truth of {p['burst']}: {res.report['frames_used']}/{res.report['frames']} frames "
               f"(dropped {[d['index'] for d in res.report['dropped']]}), reference {res.reference}, "
               f"{res.report['defects']['count']} defective pixels, alignment {a['mode']} max shift "
               f"{a['max_shift_px']:.2f} px, {res.report['robust_mean']['fallback_pixels']} fallback pixels; "
               f"wrote {', '.join(written)} and {p['report']}")
    return {"summary": summary, "outputs": written}


def loop_job(payload: dict) -> dict:
    """The calibration loop on one capture set (``simcam loop``): profile, model, report in ``out``.

    Payload keys: ``capture`` (folder or EMVA 1288 descriptor), ``out`` (folder), ``start_profile``
    (path or None), ``config`` (:class:`~simcam.calibration.loop.LoopConfig` fields).

    Returns
    -------
    dict
        ``{"lines": [...]}``: one summary line per ISO, the EMVA 1288 figures, the files written.
    """
    from .calibration.loop import LoopConfig
    from .calibration.report import run_and_write

    out = Path(payload["out"])
    start = payload.get("start_profile")
    doc = run_and_write(Path(payload["capture"]), out, start_profile=None if start is None else Path(start),
                        cfg=LoopConfig(**payload.get("config", {})))
    lines = []
    for g in doc["isos"]:
        un = ", ".join(u["diagnostic"] for u in g["unexplained"]) or "none"
        lines.append(f"{g['iso_label']}: effects {', '.join(g['effects']) or 'none'}; unexplained {un}; "
                     f"held-out KL {g['heldout']['kl_base']:.3g} -> {g['heldout']['kl_final']:.3g}, "
                     f"structured KL {g['heldout']['kl_structured_base']:.3g} -> "
                     f"{g['heldout']['kl_structured_final']:.3g}")
    if doc.get("emva"):
        e = doc["emva"]
        lines.append(f"EMVA 1288: K = {e['K_dn_per_e']:.4f} DN/e-, sigma_d = {e['sigma_dark_e']:.2f} e-")
    lines.append(f"wrote {out / 'profile.yaml'}, {out / 'loop_model.yaml'}, {out / 'report.json'}, "
                 f"{out / 'report.html'}")
    return {"lines": lines}


def bench_job(payload: dict):
    """One denoiser on one image's blocks (``simcam bench``): a :class:`~simcam.denoise.benchmark.BenchmarkResult`.

    Payload keys: ``noisy``, ``gt`` (the image's ``[M, H, W(, 3)]`` blocks), ``denoiser`` (spec),
    ``meta`` (CameraMeta or None), ``pipeline`` (renderer for sRGB scores, with ``meta``), ``cfa``.
    """
    from .denoise.benchmark import pipeline_renderer, run_benchmark

    meta = payload.get("meta")
    renderer = pipeline_renderer(payload["pipeline"]) if meta is not None else None
    result = run_benchmark([payload["noisy"]], [payload["gt"]], payload["denoiser"],
                           metas=None if meta is None else [meta], renderer=renderer,
                           cfa=None if meta is not None else payload.get("cfa"))
    return {"result": result}


# What a batch worker starts with imported (simcam.batch: the fork server imports them once for
# every local worker): the modules each job imports when it runs.
render_job.preload = ("simcam.io.dng", "simcam.io.images", "simcam.io.icc", "simcam.io.png_write", "simcam.io.tiff_stream",
                      "simcam.pipeline", "simcam.render_samples", "simcam.colour.display_kernel",
                      # the stage modules of the built-in render pipelines (imported when a pipeline names them)
                      *(f"simcam.stages.{m}" for m in ("opcodes", "raw", "lens_shading", "white_balance", "clip",
                                                       "demosaic", "camera_to_xyz", "xyz_to_srgb", "tone", "gamma",
                                                       "orientation")))
synth_patches_job.preload = ("zarr", "simcam.synth", "simcam.profiles.schema", "simcam.stages.noise",
                             "simcam.noise", "simcam.noise.noise_profile", "simcam.io.normalized", "simcam.training.crops")
ground_truth_job.preload = ("simcam.groundtruth", "simcam.io.atomic", "simcam.io.dng", "simcam.io.npz", "simcam.raw")
loop_job.preload = ("simcam.calibration.loop", "simcam.calibration.report")
bench_job.preload = ("simcam.denoise.benchmark",)
