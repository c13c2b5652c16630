"""Render benchmark: a 12 MP DNG -> 8-bit sRGB, simcam against rawpy (LibRaw).

Writes a synthetic 4000 x 3000 RGGB DNG (a lit colour chart, colour ramps and a
zone plate, with shot and read noise) with simcam's DNG writer, then times the
whole render DNG -> sRGB 8-bit:

* simcam: ``read_dng`` + the built-in ``srgb`` pipeline with ``demosaic.method``
  ``bilinear`` and ``malvar2004`` to uint8 samples, as ``simcam render`` runs it
  (:func:`simcam.render_samples.render_samples`: the stages up to demosaic and crop one by
  one, then the display tail camera -> XYZ -> sRGB -> clip -> OETF -> uint8 ->
  orientation fused into one parallel pass);
* rawpy: ``rawpy.imread`` + ``postprocess(demosaic_algorithm=LINEAR | AHD,
  use_camera_wb=True, output_bps=8, no_auto_bright=True, gamma=(2.4, 12.92))``.

Runs are interleaved (each round runs every configuration once) and the median
of ``--runs`` rounds is reported, with MP/s and the ratio to rawpy AHD measured
in the same run. A second table breaks the simcam render into its steps.

A third table times whole processes, start to exit (interpreter, imports,
render, file write), as a user waits for them: ``python -m simcam render X.dng
-o out.tif --depth 16`` against a Python process doing rawpy AHD (16-bit) and
``tifffile.imwrite`` of the same TIFF, the ``sidd-srgb`` and ``srgb`` renders to
PNG, and ``python -m simcam --help`` (``--process-runs``, default 5; 0 skips it).

Threads: numpy runs its element-wise kernels on one thread; simcam's demosaic
strips and the fused display tail run on a thread pool (``SIMCAM_THREADS``, default: all cores; its output
is the same whatever the count); LibRaw uses OpenMP (``OMP_NUM_THREADS``,
default: all cores). Set ``OMP_NUM_THREADS`` (or ``--omp-threads N``),
``SIMCAM_THREADS`` and ``OPENBLAS_NUM_THREADS`` in the environment to change
them; all are printed, with the CPU model and the load average (the machine may
be shared: compare ratios measured in the same run).

Usage::

    python benchmarks/render.py                # 4000x3000, 5 rounds
    python benchmarks/render.py --quick        # 1000x750, 3 rounds (smoke test)
    python benchmarks/render.py --size 3000x4000 --runs 7
    python benchmarks/render.py --dng ../shared/data/dng/gopro_hero7_iso252.dng
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/machine.py, also when loaded by path
from machine import compile_simcam, cpu_model as _cpu_model  # noqa: E402

from simcam.frame import CameraMeta, RawFrame  # noqa: E402

#: Canon EOS 550D ColorMatrix (XYZ D65 -> camera), dcraw/Adobe ``adobe_coeff`` / 10000.
COLOR_MATRIX_D65 = np.array([[0.6941, -0.1164, -0.0857], [-0.3825, 1.1597, 0.2534], [-0.0416, 0.1540, 0.6039]])
BLACK_DN, WHITE_DN = 512.0, 16383.0
AS_SHOT_NEUTRAL = np.array([0.47, 1.0, 0.68])  # camera response to white (G = 1)
DEMOSAIC_METHODS = ("bilinear", "malvar2004")
RAWPY_ALGOS = ("LINEAR", "AHD")


# -- synthetic capture ---------------------------------------------------------------------
def synthetic_scene(h: int, w: int, seed: int = 0) -> np.ndarray:
    """Linear camera-RGB radiance (H x W x 3 float32, white = AS_SHOT_NEUTRAL at 1.0).

    Left: a 6 x 4 chart of flat patches under a smooth vignette; right: colour
    ramps; bottom-right quarter: a zone plate (fine detail for the demosaicers).
    """
    rng = np.random.default_rng(seed)
    y = np.linspace(-1.0, 1.0, h, dtype=np.float32)[:, None]
    x = np.linspace(-1.0, 1.0, w, dtype=np.float32)[None, :]
    light = 0.75 * (1.0 - 0.25 * (x * x + y * y))  # smooth fall-off
    patches = rng.uniform(0.03, 0.9, size=(4, 6, 3)).astype(np.float32)
    rows = np.minimum((np.arange(h) * 4) // h, 3)
    cols = np.minimum((np.arange(w) * 6) // w, 5)
    refl = patches[rows][:, cols]  # H x W x 3
    xr = (x + 1.0) / 2.0
    yr = (y + 1.0) / 2.0
    right = np.broadcast_to(xr > 0.5, (h, w))
    ramp = np.stack(np.broadcast_arrays(np.float32(0.9) * xr, yr * np.float32(0.8) + 0.05, 1.0 - xr * yr), axis=-1)
    refl = np.where(right[..., None], ramp, refl)
    zone = (xr > 0.5) & (yr > 0.5)
    r2 = ((x - 0.5) ** 2 + (y - 0.5) ** 2) * np.float32(min(h, w) * 0.8)
    zp = np.float32(0.5) + np.float32(0.4) * np.cos(r2)
    refl = np.where(zone[..., None], zp[..., None] * np.float32([0.9, 0.85, 0.8]), refl)
    return (refl * light[..., None] * AS_SHOT_NEUTRAL.astype(np.float32)).astype(np.float32)


def synthetic_frame(h: int, w: int, cfa: str = "RGGB", seed: int = 0) -> RawFrame:
    """A ``raw_dn`` frame of :func:`synthetic_scene` through the CFA, with shot + read noise."""
    from simcam.cfa import channel_masks

    rgb = synthetic_scene(h, w, seed)
    masks = channel_masks(cfa, (h, w))
    mosaic = np.zeros((h, w), np.float32)
    for i, c in enumerate("RGB"):
        mosaic[masks[c]] = rgb[..., i][masks[c]]
    rng = np.random.default_rng(seed + 1)
    scale = WHITE_DN - BLACK_DN
    full_well_e = 20000.0
    electrons = rng.poisson(np.clip(mosaic, 0, None) * full_well_e).astype(np.float32)
    dn = BLACK_DN + electrons / np.float32(full_well_e) * np.float32(scale)
    dn += rng.standard_normal((h, w), dtype=np.float32) * np.float32(2.0)
    dn = np.clip(np.round(dn), 0, WHITE_DN).astype(np.float32)
    meta = CameraMeta(
        make="simcam", model="synthetic", unique_camera_model="simcam synthetic", cfa=cfa,
        black_level=np.full((1, 1), BLACK_DN), white_level=WHITE_DN,
        as_shot_neutral=AS_SHOT_NEUTRAL.copy(), color_matrix1=COLOR_MATRIX_D65.copy(),
        calibration_illuminant1=21, iso=100.0, exposure_time_s=0.01,
    )
    return RawFrame(dn, meta, kind="raw_dn")


def write_synthetic_dng(path: str | Path, h: int, w: int, seed: int = 0) -> Path:
    """Write the synthetic capture as an uncompressed 16-bit DNG with simcam's writer."""
    from simcam.io.dng_write import write_dng

    return Path(write_dng(path, synthetic_frame(h, w, seed=seed)))


# -- renders ---------------------------------------------------------------------------------
def simcam_pipeline(method: str):
    """The built-in ``srgb`` pipeline with ``demosaic.method`` set."""
    from simcam.pipeline import Pipeline

    return Pipeline.from_yaml("srgb").with_overrides({"demosaic.method": method})


def simcam_render(path: Path, pipe, *, steps: dict[str, float] | None = None) -> np.ndarray:
    """DNG -> uint8 sRGB as ``simcam render`` does (:func:`simcam.render_samples.render_samples`: the demosaic
    streamed into the fused display tail where the pipeline allows, its raw head made strip by strip inside it);
    optionally accumulate per-step seconds in ``steps`` (the streamed part is one step)."""
    from simcam.io.dng import read_dng
    from simcam.render_samples import fusable_tail, render_samples, streamed_demosaic
    from simcam.row_fusion import row_source

    t = [_clock()]
    frame = read_dng(path)
    t[0] = _add(steps, "read_dng", t[0])
    start = fusable_tail(pipe.stages)
    k = streamed_demosaic(pipe.stages, start)
    if k < start and k and row_source(pipe.stages[:k], frame) is not None:
        k = 0  # the head's rows are made inside the demosaic's strips: all one step
    fused = pipe.stages[k:] if k < start else pipe.stages[start:]
    label = ("streamed: " if k < start else "fused tail: ") + " + ".join(st.type for st in fused) + " + uint8"
    seen: dict[str, int] = {}
    calls = [0]

    def progress(name: str) -> None:
        i = calls[0]
        calls[0] += 1
        if i >= len(pipe.stages) - len(fused):  # the fused part: one step, timed to its last stage's report
            if i == len(pipe.stages) - 1:
                t[0] = _add(steps, label, t[0])
            return
        n = seen[name] = seen.get(name, 0) + 1
        t[0] = _add(steps, name if n == 1 else f"{name}[{n}]", t[0])

    return render_samples(pipe, frame, "uint8", progress=progress).samples


def _clock() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def _add(steps, key, since: tuple[float, float]) -> tuple[float, float]:
    """Record (wall, CPU) seconds since ``since`` under ``key``; return the new clock."""
    now = _clock()
    if steps is not None:
        steps.setdefault(key, []).append((now[0] - since[0], now[1] - since[1]))
    return now


def rawpy_render(path: Path, algo: str) -> np.ndarray:
    """DNG -> uint8 sRGB through LibRaw (camera white balance, no auto-brightening, sRGB curve)."""
    import rawpy

    with rawpy.imread(str(path)) as raw:
        return raw.postprocess(
            demosaic_algorithm=getattr(rawpy.DemosaicAlgorithm, algo), use_camera_wb=True,
            output_bps=8, no_auto_bright=True, gamma=(2.4, 12.92), output_color=rawpy.ColorSpace.sRGB,
        )


# -- benchmark -------------------------------------------------------------------------------
def run_benchmark(h: int, w: int, runs: int, *, workdir: str | Path | None = None, save: str | Path | None = None,
                  dng: str | Path | None = None, out=print, process_runs: int = 0) -> dict:
    """Time every configuration ``runs`` times (interleaved) and print the tables.

    Returns a dict with ``"results"`` (label -> list of wall seconds), ``"cpu"``
    (label -> list of process CPU seconds, all threads), ``"steps"`` (method ->
    step -> list of (wall, CPU) seconds) and ``"mean_abs_diff"`` (label -> mean absolute 8-bit
    difference to rawpy AHD, a sanity check of the render).
    """
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        if dng is None:
            path = Path(tmp) / "synthetic.dng"
            t0 = time.perf_counter()
            write_synthetic_dng(path, h, w)
            out(f"wrote {w}x{h} synthetic DNG ({path.stat().st_size / 1e6:.1f} MB) in {time.perf_counter() - t0:.2f} s")
        else:
            path = Path(dng)
            out(f"input: {path}")
        pipes = {m: simcam_pipeline(m) for m in DEMOSAIC_METHODS}
        p0 = pipes[DEMOSAIC_METHODS[0]]
        out(f"simcam pipeline: built-in srgb, stages {[s.type for s in p0.stages]}, "
            f"demosaic.method in {list(DEMOSAIC_METHODS)}")
        results: dict[str, list[float]] = {}
        cpu: dict[str, list[float]] = {}
        steps: dict[str, dict[str, list[float]]] = {m: {} for m in DEMOSAIC_METHODS}
        images: dict[str, np.ndarray] = {}
        for r in range(runs + 1):  # round 0 warms caches and imports; not counted
            for m in DEMOSAIC_METHODS:
                st: dict[str, list[float]] = {}
                t0, c0 = time.perf_counter(), time.process_time()
                img = simcam_render(path, pipes[m], steps=st)
                dt, dc = time.perf_counter() - t0, time.process_time() - c0
                if r:
                    results.setdefault(f"simcam {m}", []).append(dt)
                    cpu.setdefault(f"simcam {m}", []).append(dc)
                    for k, v in st.items():
                        steps[m].setdefault(k, []).extend(v)
                images[f"simcam {m}"] = img
            for a in RAWPY_ALGOS:
                t0, c0 = time.perf_counter(), time.process_time()
                img = rawpy_render(path, a)
                dt, dc = time.perf_counter() - t0, time.process_time() - c0
                if r:
                    results.setdefault(f"rawpy {a}", []).append(dt)
                    cpu.setdefault(f"rawpy {a}", []).append(dc)
                images[f"rawpy {a}"] = img
        proc = time_processes(path, Path(tmp), process_runs) if process_runs > 0 else None
    if save is not None:
        from simcam.io.images import write_image

        for k, img in images.items():
            write_image(Path(save) / (k.replace(" ", "_") + ".png"), img.astype(np.float32) / 255.0)
    ref = images["rawpy AHD"].astype(np.float32)
    diffs = {}
    for k, img in images.items():
        if img.shape != ref.shape:  # e.g. a DefaultCrop LibRaw does not apply
            out(f"note: {k} output is {img.shape}, rawpy AHD's {ref.shape}: no difference computed")
            diffs[k] = float("nan")
            continue
        b = 8  # ignore borders, where demosaicers legitimately differ
        diffs[k] = float(np.mean(np.abs(img[b:-b, b:-b].astype(np.float32) - ref[b:-b, b:-b])))
    h, w = images["simcam malvar2004"].shape[:2]
    print_tables(h, w, runs, results, cpu, steps, diffs, out=out)
    if proc is not None:
        print_process_table(proc, process_runs, out=out)
    out("")
    out(f"1-min / 5-min / 15-min load average at the end: {_load()}")
    return {"results": results, "cpu": cpu, "steps": steps, "mean_abs_diff": diffs, "processes": proc}


RAWPY_TIFF_SCRIPT = """
import sys, rawpy, tifffile
with rawpy.imread(sys.argv[1]) as raw:
    rgb = raw.postprocess(demosaic_algorithm=rawpy.DemosaicAlgorithm.AHD, use_camera_wb=True, output_bps=16,
                          no_auto_bright=True, gamma=(2.4, 12.92), output_color=rawpy.ColorSpace.sRGB)
tifffile.imwrite(sys.argv[2], rgb, photometric="rgb")
"""


def process_commands(dng: Path, tmp: Path) -> dict[str, list[str]]:
    """The whole-process commands timed by :func:`time_processes`."""
    py = sys.executable
    return {
        "simcam render -o out.tif --depth 16": [py, "-m", "simcam", "render", str(dng), "-o",
                                                 str(tmp / "simcam16.tif"), "--depth", "16"],
        "python: rawpy AHD + tifffile.imwrite (16-bit)": [py, "-c", RAWPY_TIFF_SCRIPT, str(dng),
                                                           str(tmp / "rawpy16.tif")],
        "simcam render -p sidd-srgb -o out.png": [py, "-m", "simcam", "render", str(dng), "-o",
                                                  str(tmp / "sidd.png"), "-p", "sidd-srgb"],
        "simcam render -o out.png (8-bit)": [py, "-m", "simcam", "render", str(dng), "-o", str(tmp / "srgb8.png")],
        "simcam --help": [py, "-m", "simcam", "--help"],
    }


def time_processes(dng: Path, tmp: Path, runs: int) -> dict[str, list[float]]:
    """Wall seconds of each command of :func:`process_commands`, ``runs`` interleaved rounds after a warm-up."""
    import subprocess

    compile_simcam()  # as a pip install does (machine.compile_simcam)
    env = dict(os.environ)
    repo = str(Path(__file__).resolve().parent.parent)
    env["PYTHONPATH"] = repo + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    cmds = process_commands(dng, tmp)
    out: dict[str, list[float]] = {k: [] for k in cmds}
    for r in range(runs + 1):  # round 0 warms the file cache and numba's on-disk cache
        for k, cmd in cmds.items():
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            if r:
                out[k].append(time.perf_counter() - t0)
    return out


def print_process_table(proc: dict[str, list[float]], runs: int, *, out=print) -> None:
    base = float(np.median(proc["python: rawpy AHD + tifffile.imwrite (16-bit)"]))
    out("")
    out(f"### Whole process, start to exit (imports, render, write), median of {runs} runs")
    out("")
    out("| process | median s | min s | ratio to rawpy + tifffile |")
    out("|---|---:|---:|---:|")
    for k, v in proc.items():
        med = float(np.median(v))
        out(f"| {k} | {med:.3f} | {min(v):.3f} | {med / base:.2f} |")


def print_tables(h, w, runs, results, cpu, steps, diffs, *, out=print) -> None:
    mp = h * w / 1e6
    ahd = float(np.median(results["rawpy AHD"]))
    out("")
    out(f"### Render DNG -> sRGB 8-bit, {w}x{h} ({mp:.1f} MP), median of {runs} runs")
    out("")
    out(f"{_thread_line()}")
    out("")
    out("| render | median s | min s | MP/s (median) | ratio to rawpy AHD | median CPU s (all threads) "
        "| mean abs diff to AHD (8-bit levels) |")
    out("|---|---:|---:|---:|---:|---:|---:|")
    for k in [f"simcam {m}" for m in DEMOSAIC_METHODS] + [f"rawpy {a}" for a in RAWPY_ALGOS]:
        med = float(np.median(results[k]))
        out(f"| {k} | {med:.3f} | {min(results[k]):.3f} | {mp / med:.1f} | {med / ahd:.2f} "
            f"| {np.median(cpu[k]):.3f} | {diffs[k]:.2f} |")
    out("")
    out(f"### simcam render steps, median seconds of {runs} runs (wall; CPU of this process)")
    out("")
    keys = list(next(iter(steps.values())).keys())
    out("| step | " + " | ".join(f"{m} wall | {m} CPU" for m in DEMOSAIC_METHODS) + " |")
    out("|---|" + "---:|---:|" * len(DEMOSAIC_METHODS))

    def med(m, k, i):
        return float(np.median([v[i] for v in steps[m][k]]))

    for k in keys:
        out(f"| {k} | " + " | ".join(f"{med(m, k, 0):.3f} | {med(m, k, 1):.3f}" for m in DEMOSAIC_METHODS) + " |")
    out("| **sum of steps** | " + " | ".join(
        f"{sum(med(m, k, 0) for k in keys):.3f} | {sum(med(m, k, 1) for k in keys):.3f}" for m in DEMOSAIC_METHODS)
        + " |")


def _thread_line() -> str:
    omp = os.environ.get("OMP_NUM_THREADS", f"unset (LibRaw OpenMP uses all {os.cpu_count()} cores)")
    blas = os.environ.get("OPENBLAS_NUM_THREADS", "unset")
    from simcam.colour.display_kernel import threads

    return (f"Threads: simcam's demosaic strips and fused display tail on {threads()} threads, other steps "
            f"single-threaded numpy (SIMCAM_THREADS={os.environ.get('SIMCAM_THREADS', 'unset')}); OMP_NUM_THREADS={omp}; "
            f"OPENBLAS_NUM_THREADS={blas}. Machine: {_cpu_model()}, {os.cpu_count()} cores; numpy {np.__version__}, "
            f"rawpy {_rawpy_version()}. Load average (1/5/15 min) now: {_load()}.")




def _load() -> str:
    return " / ".join(f"{v:.1f}" for v in os.getloadavg()) if hasattr(os, "getloadavg") else "n/a"


def _rawpy_version() -> str:
    import rawpy

    return f"{rawpy.__version__} (LibRaw {rawpy.libraw_version})"


def _parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size: expected WIDTHxHEIGHT like 4000x3000, got {text!r}") from None
    if w < 64 or h < 64:
        raise argparse.ArgumentTypeError(f"--size: expected at least 64x64, got {text!r}")
    return h, w


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=_parse_size, default=None, help="WIDTHxHEIGHT (default 4000x3000)")
    ap.add_argument("--runs", type=int, default=None, help="timed rounds (default 5; 3 with --quick)")
    ap.add_argument("--quick", action="store_true", help="smoke test: 1000x750, 3 rounds")
    ap.add_argument("--workdir", default=None, help="folder for the temporary DNG (default: system temp)")
    ap.add_argument("--dng", default=None, help="benchmark this DNG instead of the synthetic one (--size ignored)")
    ap.add_argument("--save", default=None, help="folder to write the four renders as PNG (for a look)")
    ap.add_argument("--process-runs", type=int, default=None,
                    help="rounds of whole-process timings (default 5; 0 with --quick; 0 skips them)")
    ap.add_argument("--omp-threads", type=int, default=None,
                    help="set OMP_NUM_THREADS for LibRaw (must happen before rawpy is imported)")
    args = ap.parse_args(argv)
    if args.omp_threads is not None:
        if "rawpy" in sys.modules:
            ap.error("--omp-threads: rawpy is already imported in this process; set OMP_NUM_THREADS instead")
        os.environ["OMP_NUM_THREADS"] = str(args.omp_threads)
    h, w = args.size or ((750, 1000) if args.quick else (3000, 4000))
    runs = args.runs or (3 if args.quick else 5)
    if runs < 1:
        ap.error(f"--runs: expected at least 1, got {runs}")
    process_runs = args.process_runs if args.process_runs is not None else (0 if args.quick else 5)
    return run_benchmark(h, w, runs, workdir=args.workdir, save=args.save, dng=args.dng, process_runs=process_runs)


if __name__ == "__main__":
    main()
