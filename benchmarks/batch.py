"""Batch benchmark: simcam's dask batch layer against a plain loop and multiprocessing.Pool.

Three jobs, each run five ways in the same process tree, one after the other:

* ``for loop``: the items one after the other in this process (the per-item functions of
  ``simcam.jobs``, no batch layer);
* ``Pool(1)`` / ``Pool(2)``: ``multiprocessing.Pool.map`` over the same items;
* ``dask 1`` / ``dask 2``: ``simcam.batch.run_batch`` on a LocalCluster of 1 / 2 worker
  processes (one thread each: simcam's row bands, numba, BLAS and OpenMP limited to one thread),
  each in a fresh process as a command runs it (its wall time: run_batch from the cluster's start
  to its close, the fork server's start and imports included).

Jobs: ``render`` (N renders of a synthetic 12 MP DNG -> 8-bit PNG, pipeline srgb), ``synth``
(a training set of P noisy/clean patches, packed 4 x 32 x 32, into Zarr: 20 from each of P / 20 clean
1 MP DNGs, the shape of a denoising set cut from thousands of raws; 100 distinct files, the others
hard links to them), ``synth-few`` (the same P patches, 250 from each of P / 250 sources: few long
items, where the dask runs' fixed cost weighs most),
``gt`` (ground truth of B bursts of 16 frames of 1 MP). Every configuration writes fresh
outputs; the outputs of all five are checked byte-identical (PNG, Zarr chunks, npz).
Prints the CPU model, thread settings and load average, wall times, the speed-up of 2 workers
over 1, the fixed cost of the dask runs (wall time of ``dask 1`` minus its items' own seconds:
starting and closing the LocalCluster; a worker's first imports count in its first item), and the
peak RSS of a worker.

Usage::

    python benchmarks/batch.py                 # 64 renders, 20,000 patches, 8 bursts
    python benchmarks/batch.py --quick         # tiny sizes (smoke test)
    python benchmarks/batch.py --jobs synth --repeats 5   # one job, medians of 5 interleaved rounds
"""

from __future__ import annotations

import argparse
import hashlib
import json
import multiprocessing
import os
import pickle
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

if __package__ in (None, ""):  # run as a script: make the repository importable
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    sys.path.insert(0, str(Path(__file__).resolve().parent))

from machine import compile_simcam, cpu_model  # noqa: E402
from render import write_synthetic_dng  # noqa: E402  (benchmarks/render.py)

from simcam.batch import Task  # noqa: E402
from simcam.jobs import ground_truth_job, render_job, synth_patches_job  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
PROFILE = REPO / "profiles" / "sidd-gp.yaml"
CONFIGS = ("for loop", "Pool(1)", "Pool(2)", "dask 1", "dask 2")




def _call(job_task):
    job, task = job_task
    t0 = time.perf_counter()
    job(task.payload)
    import resource

    return time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run_config(name: str, job, tasks: list[Task]) -> tuple[float, float, float]:
    """Wall seconds, the peak RSS (MiB) of a process that ran items, and the items' own seconds summed."""
    t0 = time.perf_counter()
    if name == "for loop":
        res = [_call((job, t)) for t in tasks]
    elif name.startswith("Pool"):
        n = int(name[5])
        with multiprocessing.get_context("fork").Pool(n, initializer=_one_thread) as pool:
            res = pool.map(_call, [(job, t) for t in tasks], chunksize=1)
    else:  # in a fresh process, as a command would run it: each configuration starts its own fork server
        n = int(name.split()[1])
        with tempfile.TemporaryDirectory() as tmp:
            spec = Path(tmp) / "batch.pkl"
            spec.write_bytes(pickle.dumps((job.__module__, job.__name__, tasks, n, name)))
            proc = subprocess.run([sys.executable, "-c", _DASK_RUN, str(spec)], capture_output=True, text=True,
                                  cwd=str(REPO))
            if proc.returncode != 0:
                raise RuntimeError(f"{name}: {proc.stderr.strip()[-2000:]}")
            wall, res = json.loads(proc.stdout.strip().splitlines()[-1])
        return wall, max(r[1] for r in res), sum(r[0] for r in res)
    return time.perf_counter() - t0, max(r[1] for r in res), sum(r[0] for r in res)


#: one dask configuration in a fresh process: the wall time of run_batch (cluster start to close)
_DASK_RUN = """
import importlib, json, pickle, sys, time
from pathlib import Path
from simcam.batch import BatchConfig, run_batch
mod, fn, tasks, n, name = pickle.loads(Path(sys.argv[1]).read_bytes())
job = getattr(importlib.import_module(mod), fn)
t0 = time.perf_counter()
out = run_batch(job, tasks, BatchConfig(workers=n, progress=False), label=name, echo=lambda s: None)
wall = time.perf_counter() - t0
bad = [o for o in out if not o.ok]
if bad:
    sys.exit(f"{bad[0].key}: {bad[0].error}")
print(json.dumps([wall, [(o.seconds, o.info.get("peak_rss_mib", 0.0)) for o in out]]))
"""


def _one_thread():
    from simcam.batch import THREAD_VARIABLES

    for v in THREAD_VARIABLES:
        os.environ[v] = "1"
    try:
        import numba

        numba.set_num_threads(1)
    except Exception:  # noqa: BLE001 - numba absent or already initialised
        pass


def digest(paths: list[Path]) -> str:
    h = hashlib.sha256()
    for p in paths:
        for f in sorted(p.rglob("*")) if p.is_dir() else [p]:
            if f.is_file() and not f.name.endswith(".json"):  # gt reports hold timings
                h.update(f.read_bytes())
    return h.hexdigest()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="tiny sizes: a smoke test of the script")
    ap.add_argument("--renders", type=int, default=64)
    ap.add_argument("--size", default="4000x3000", help="render DNG width x height")
    ap.add_argument("--patches", type=int, default=20000)
    ap.add_argument("--per-source", type=int, default=20,
                    help="synth: patches cropped from each source (synth-few: 250 from each of patches/250 sources)")
    ap.add_argument("--synth-size", default="1024x1024",
                    help="synth source DNG width x height (4000x3000: camera-sized raws, the noise drawn over 12 MP per item)")
    ap.add_argument("--synth-distinct", type=int, default=100,
                    help="distinct synth source files (the others hard links to them; 0: all distinct)")
    ap.add_argument("--bursts", type=int, default=8)
    ap.add_argument("--jobs", default="render,synth,synth-few,gt")
    ap.add_argument("--workdir", default=None)
    ap.add_argument("--repeats", type=int, default=1, help="rounds of all five configurations; medians reported")
    args = ap.parse_args(argv)
    if args.quick:
        args.renders, args.size, args.patches, args.bursts = 4, "640x480", 400, 2
    w, h = (int(v) for v in args.size.split("x"))
    work = Path(args.workdir or tempfile.mkdtemp(prefix="simcam-batch-bench-"))
    work.mkdir(parents=True, exist_ok=True)
    compile_simcam()  # the dask runs are fresh processes, as a command is: with simcam's bytecode, as installed
    print(f"CPU: {cpu_model()} ({os.cpu_count()} logical cores); Python {platform.python_version()}; "
          f"load average {os.getloadavg()[0]:.2f} at start")
    print("Threads: every worker and Pool process 1 thread (SIMCAM_THREADS and OMP/NUMBA/MKL/OPENBLAS_NUM_THREADS=1); "
          "the for loop runs with the process defaults (simcam's row bands on every core)")
    rows = []
    jobs = args.jobs.split(",")
    if "render" in jobs:
        src = write_synthetic_dng(work / "scene.dng", h, w)
        dngs = []
        for i in range(args.renders):
            d = work / "render_in" / f"img{i:03d}.dng"
            d.parent.mkdir(exist_ok=True)
            if not d.exists():
                os.link(src, d)
            dngs.append(d)
        from simcam.pipeline import Pipeline

        doc = Pipeline.from_yaml("srgb").to_dict()
        rows.append(bench("render", f"{args.renders} renders of a {w}x{h} DNG -> PNG", render_job, work, lambda out: [
            Task(str(d), {"input": str(d), "output": str(out / f"{d.stem}.png"), "pipeline": doc, "seed": 0,
                          "index": i}) for i, d in enumerate(dngs)], lambda out: [out], args.repeats))
    for name, per in (("synth", args.per_source), ("synth-few", 250)):
        if name not in jobs:
            continue
        per = per if not args.quick else 50
        n_src = max(1, args.patches // per)
        sw, sh = (int(v) for v in args.synth_size.split("x"))
        if args.quick:
            sw, sh = 1024, 768
        distinct = min(n_src, args.synth_distinct or n_src)
        srcs = []
        for i in range(n_src):
            p = work / f"synth_in_{sw}x{sh}" / f"clean{i:04d}.dng"
            p.parent.mkdir(exist_ok=True)
            if not p.exists():
                if i < distinct:
                    write_synthetic_dng(p, sh, sw, seed=i)
                else:  # the same pixels as source i % distinct; item i still draws its own noise and crops
                    os.link(srcs[i % distinct], p)
            srcs.append(p)
        from simcam.trainingset import create_store

        def synth_tasks(out, srcs=srcs, per=per):
            store = out / "set.zarr"
            create_store(str(store), sources=[str(s) for s in srcs], patches=per, patch_size=64, overwrite=True)
            base = {"seed": 1, "profile": str(PROFILE), "isos": [100, 800, 1600], "camera": None,
                    "extrapolate": False, "sensor_seed": None, "as_": "raw", "cfa": None, "patch_size": 64,
                    "patches": per, "store": str(store)}
            return [Task(str(s), {**base, "source": str(s), "index": i}) for i, s in enumerate(srcs)]

        mp = sw * sh / 1e6
        shared = f", {distinct} distinct" if distinct < n_src else ""
        rows.append(bench(name, f"{n_src * per} patches (4x32x32), {per} from each of {n_src} {mp:.0f} MP DNGs{shared} "
                          "-> Zarr", synth_patches_job, work, synth_tasks, lambda out: [out / "set.zarr"], args.repeats))
    if "gt" in jobs:
        from simcam.io.dng import read_dng
        from simcam.synth import synth
        from simcam.stages.noise import Noise
        from simcam.stages.raw import Normalize

        bursts = []
        clean = Normalize()(read_dng(write_synthetic_dng(work / "gt_clean.dng", 1024, 1024, seed=5)))
        for b in range(args.bursts):
            d = work / "gt_in" / f"burst{b}"
            if not d.exists():
                synth(clean, d, stage=Noise(profile=str(PROFILE), iso=800), frames=16 if not args.quick else 4, seed=b)
                (d / "clean.dng").unlink()
            bursts.append(d)
        rows.append(bench("gt", f"{args.bursts} bursts of {16 if not args.quick else 4} frames of 1 MP", ground_truth_job,
                          work, lambda out: [Task(str(b), {"burst": str(b), "npz": str(out / f"{b.name}.npz"),
                                                            "report": str(out / f"{b.name}.json"), "alignment": "local",
                                                            "progress": False}) for b in bursts],
                          lambda out: [out], args.repeats))
    print()
    print(f"Medians of {args.repeats} interleaved round(s); 'dask 2 vs 1' is the ratio of the medians, with the "
          "range of the per-round ratios")
    print("| job | items | " + " | ".join(f"{c} s" for c in CONFIGS) + " | dask 2 vs 1 | dask 2 vs for loop | "
          "dask 2 vs Pool(2) | Pool(2) vs Pool(1) | dask 1 fixed cost s | peak RSS / worker |")
    print("|---|---|" + "---:|" * (len(CONFIGS) + 6))
    for r in rows:
        t = r["times"]
        lo, hi = r["ratio_range"]
        print(f"| {r['job']} | {r['what']} | " + " | ".join(f"{t[c]:.1f}" for c in CONFIGS)
              + f" | **{t['dask 1'] / t['dask 2']:.2f}x** ({lo:.2f}-{hi:.2f}) | {t['for loop'] / t['dask 2']:.2f}x | "
              f"{t['Pool(2)'] / t['dask 2']:.2f}x | {t['Pool(1)'] / t['Pool(2)']:.2f}x | "
              f"{t['dask 1'] - r['items']['dask 1']:.1f} | {r['rss']:.0f} MiB |")
    print(f"\nload average {os.getloadavg()[0]:.2f} at the end; outputs byte-identical across the five "
          f"configurations: {all(r['same'] for r in rows)}")
    if not args.workdir:
        shutil.rmtree(work, ignore_errors=True)
    return 0 if all(r["same"] for r in rows) else 1


def bench(job_name, what, job, work: Path, make_tasks, outputs, repeats: int = 1) -> dict:
    """Each configuration ``repeats`` times, interleaved (round r runs all five before round r + 1, so a
    slow spell of the machine hits every configuration); the medians are reported."""
    walls: dict[str, list] = {c: [] for c in CONFIGS}
    own: dict[str, list] = {c: [] for c in CONFIGS}
    digests, rss = {}, 0.0
    for rnd in range(repeats):
        for c in CONFIGS:
            out = work / f"{job_name}_out" / c.replace(" ", "_").replace("(", "").replace(")", "")
            shutil.rmtree(out, ignore_errors=True)
            out.mkdir(parents=True)
            tasks = make_tasks(out)
            wall, r, summed = run_config(c, job, tasks)
            walls[c].append(wall)
            own[c].append(summed)
            if c.startswith("dask"):
                rss = max(rss, r)
            d = digest(outputs(out))
            digests.setdefault(c, d)
            if digests[c] != d:
                digests[c] = "differs between repeats"
            print(f"{job_name}: round {rnd + 1}: {c}: {wall:.2f} s (the items themselves: {summed:.2f} s summed)",
                  flush=True)
            shutil.rmtree(out, ignore_errors=True)
    same = len(set(digests.values())) == 1
    if not same:
        print(f"{job_name}: outputs differ between configurations: {digests}")
    times = {c: float(np.median(v)) for c, v in walls.items()}
    items = {c: float(np.median(v)) for c, v in own.items()}
    ratios = [a / b for a, b in zip(walls["dask 1"], walls["dask 2"])]
    return {"job": job_name, "what": what, "times": times, "items": items, "rss": rss, "same": same,
            "ratio_range": (min(ratios), max(ratios)), "repeats": repeats}

if __name__ == "__main__":
    sys.exit(main())
