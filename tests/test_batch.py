"""Batch commands on dask.distributed: the same bytes as the serial path, failures reported per item.

A LocalCluster of 2 worker processes against ``--workers 0`` (the items one after the other in
this process) and against the single-item command, on small inputs: render, synth (Zarr
training set), gt. A truncated DNG among the inputs fails alone, with one line, and the other
items complete.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")
pytest.importorskip("zarr")

REPO = Path(__file__).resolve().parent.parent
CHART = REPO / "examples" / "data" / "chart.dng"
PROFILE = REPO / "profiles" / "sidd-gp.yaml"


def run_cli(*args: str):
    return subprocess.run([sys.executable, "-m", "simcam", *map(str, args)], capture_output=True, text=True, cwd=REPO)


def tree_hashes(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """Three clean DNGs (the chart, cropped differently by synth) and one truncated DNG."""
    d = tmp_path_factory.mktemp("dngs")
    for i in range(3):
        r = run_cli("synth", CHART, "-o", d / f"s{i}", "--profile", PROFILE, "--iso", 400, "--seed", i)
        assert r.returncode == 0, r.stderr
        shutil.copy(d / f"s{i}" / "frame_000.dng", d / f"img{i}.dng")
    (d / "broken.dng").write_bytes(CHART.read_bytes()[:3000])
    return d


def test_render_batch_same_bytes_as_serial_and_single(inputs, tmp_path):
    dngs = sorted(inputs.glob("*.dng"))
    r2 = run_cli("render", *dngs, "-o", tmp_path / "w2", "--workers", 2, "-p", "linear-srgb", "--format", "exr")
    r0 = run_cli("render", *dngs, "-o", tmp_path / "w0", "--workers", 0, "-p", "linear-srgb", "--format", "exr")
    for r in (r2, r0):
        assert r.returncode == 1  # the broken input
        lines = [ln for ln in r.stderr.splitlines() if "failed" in ln]
        assert len(lines) == 1 and "broken.dng" in lines[0] and "Traceback" not in r.stderr
    h2, h0 = tree_hashes(tmp_path / "w2"), tree_hashes(tmp_path / "w0")
    assert sorted(h2) == ["img0.exr", "img1.exr", "img2.exr"] and h2 == h0
    single = tmp_path / "one.exr"
    assert run_cli("render", inputs / "img1.dng", "-o", single, "-p", "linear-srgb").returncode == 0
    assert hashlib.sha256(single.read_bytes()).hexdigest() == h2["img1.exr"]


def test_render_batch_resume_skips_done(inputs, tmp_path):
    out = tmp_path / "o"
    good = [p for p in sorted(inputs.glob("img*.dng"))]
    assert run_cli("render", *good[:2], "-o", out, "--workers", 0).returncode == 0
    before = tree_hashes(out)
    r = run_cli("render", *good, "-o", out, "--workers", 0, "--resume")
    assert r.returncode == 0 and "2 already there" in r.stdout
    after = tree_hashes(out)
    assert {k: after[k] for k in before} == before and len(after) == 3


def test_synth_training_set_same_bytes_for_any_worker_count(inputs, tmp_path):
    torch = pytest.importorskip("torch")
    from simcam.training.zarr_dataset import TrainingSetDataset

    srcs = [inputs / f"s{i}" / "clean.dng" for i in range(3)] + [inputs / "broken.dng"]
    common = ["--profile", PROFILE, "--isos", "100,800,1600", "--patches-per-source", 4, "--patch-size", 32,
              "--seed", 7]
    r2 = run_cli("synth", *srcs, "-o", tmp_path / "w2.zarr", "--workers", 2, *common)
    r0 = run_cli("synth", *srcs, "-o", tmp_path / "w0.zarr", "--workers", 0, *common)
    for r in (r2, r0):
        assert r.returncode == 1 and r.stderr.count("failed:") == 1 and "broken.dng" in r.stderr
    assert tree_hashes(tmp_path / "w2.zarr") == tree_hashes(tmp_path / "w0.zarr")
    ds = TrainingSetDataset(f"file://{tmp_path / 'w2.zarr'}")
    assert len(ds) == 12
    s = ds[5]
    assert tuple(s["noisy"].shape) == (4, 16, 16) and s["noisy"].dtype == torch.float32
    assert s["meta"]["iso"] in (100.0, 800.0, 1600.0)
    # the noise is the profile's: noisy - clean has the NLF variance of the drawn ISO (loose check)
    assert float((s["noisy"] - s["clean"]).std()) > 0


def test_gt_batch_same_bytes_as_serial_and_single(inputs, tmp_path):
    bursts = tmp_path / "bursts"
    for i in range(2):
        r = run_cli("synth", CHART, "-o", bursts / f"b{i}", "--profile", PROFILE, "--iso", 800, "--frames", 4,
                    "--seed", 10 + i)
        assert r.returncode == 0, r.stderr
    (bursts / "broken").mkdir()
    shutil.copy(inputs / "broken.dng", bursts / "broken" / "f.dng")
    common = ["--alignment", "global"]
    r2 = run_cli("gt", bursts, "-o", tmp_path / "w2", "--workers", 2, *common)
    r0 = run_cli("gt", bursts, "-o", tmp_path / "w0", "--workers", 0, *common)
    for r in (r2, r0):
        assert r.returncode == 1 and r.stderr.count("failed:") == 1 and "broken" in r.stderr
    h2, h0 = tree_hashes(tmp_path / "w2"), tree_hashes(tmp_path / "w0")
    assert sorted(h2) == ["b0.json", "b0.npz", "b1.json", "b1.npz"]
    assert h2["b0.npz"] == h0["b0.npz"] and h2["b1.npz"] == h0["b1.npz"]
    for name in ("b0.json", "b1.json"):  # the reports differ only in their timings and output paths
        a, b = (json.loads((tmp_path / w / name).read_text()) for w in ("w2", "w0"))
        for rep in (a, b):
            rep.pop("timing_s"), rep.pop("outputs")
        assert a == b
    assert run_cli("gt", bursts / "b1", "-o", tmp_path / "one.npz", "--no-progress", *common).returncode == 0
    a, b = np.load(tmp_path / "one.npz"), np.load(tmp_path / "w2" / "b1.npz")
    assert all(np.array_equal(a[k], b[k]) for k in a.files)
    assert hashlib.sha256((tmp_path / "one.npz").read_bytes()).hexdigest() == h2["b1.npz"]


def test_batch_without_a_reachable_scheduler_is_one_line(tmp_path):
    r = run_cli("render", CHART, CHART, "-o", tmp_path / "o", "--scheduler", "tcp://127.0.0.1:9")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "scheduler" in r.stderr


def test_bench_images_x_denoisers_on_two_workers_equals_the_serial_scores(tmp_path):
    """simcam bench -d none -d nlm --workers 2: per-block scores equal the one-process run's."""
    import json

    from simcam.io.sidd_blocks import write_blocks

    rng = np.random.default_rng(3)
    gt = (0.2 + 0.5 * rng.random((3, 2, 1, 1)) + np.zeros((3, 2, 32, 32))).astype(np.float32)
    noisy = (gt + 0.03 * rng.standard_normal(gt.shape)).astype(np.float32)
    write_blocks(tmp_path / "noisy.mat", noisy, "ValidationNoisyBlocksRaw", format="v5")
    write_blocks(tmp_path / "gt.mat", gt, "ValidationGtBlocksRaw", format="v5")
    common = ["bench", "--noisy", tmp_path / "noisy.mat", "--gt", tmp_path / "gt.mat", "-d", "none", "-d", "nlm"]
    assert run_cli(*common, "--json", tmp_path / "serial.json").returncode == 0
    r = run_cli(*common, "--json", tmp_path / "batch.json", "--workers", 2)
    assert r.returncode == 0, r.stderr
    a = json.loads((tmp_path / "serial.json").read_text())["results"]
    b = json.loads((tmp_path / "batch.json").read_text())["results"]
    for x, y in zip(a, b):
        assert x["denoiser"] == y["denoiser"] and x["raw"] == y["raw"]
        strip = [{k: v for k, v in blk.items() if k != "seconds"} for blk in x["per_block"]]
        assert strip == [{k: v for k, v in blk.items() if k != "seconds"} for blk in y["per_block"]]


def test_local_cluster_workers_run_with_one_thread_and_glibc_malloc_defaults():
    """Workers cap simcam's own row bands (SIMCAM_THREADS) like numba/BLAS/OpenMP, and do not inherit
    dask's MALLOC_TRIM_THRESHOLD_ (it turns off glibc's dynamic mmap threshold: every image band
    becomes a fresh mmap, ~7x the page faults per render). Their ``distributed`` loggers are at
    CRITICAL (a heartbeat meeting a closed scheduler at shutdown logged a traceback); the client's
    loggers get their levels back after the batch."""
    import logging
    import os

    from simcam.batch import THREAD_VARIABLES, BatchConfig, Task, run_batch
    from simcam.parallel import threads

    def environment(names):  # pickled by value (a local function) to the workers
        import numba  # imported by the fork server: it read NUMBA_NUM_THREADS there

        return {"env": {n: os.environ.get(n) for n in names}, "threads": threads(),
                "numba": numba.config.NUMBA_NUM_THREADS,
                "log": logging.getLogger("distributed.worker").getEffectiveLevel()}

    environment.preload = ("numba", "numpy")

    names = [*THREAD_VARIABLES, "MALLOC_TRIM_THRESHOLD_"]
    client_level = logging.getLogger("distributed.comm").level
    out = run_batch(environment, [Task("a", names)], BatchConfig(workers=1, progress=False), echo=lambda s: None)
    assert out[0].ok, out[0].error
    assert out[0].info["log"] == logging.CRITICAL
    assert logging.getLogger("distributed.comm").level == client_level
    env = out[0].info["env"]
    assert {n: env[n] for n in THREAD_VARIABLES} == {n: "1" for n in THREAD_VARIABLES}
    assert out[0].info["threads"] == 1 and out[0].info["numba"] == 1
    assert env["MALLOC_TRIM_THRESHOLD_"] is None or "MALLOC_TRIM_THRESHOLD_" in os.environ


PRELOAD_CHECK = """
import importlib, json, sys
from simcam import jobs
job = getattr(jobs, sys.argv[1])
for m in job.preload:
    importlib.import_module(m)
payload = json.loads(sys.argv[2])
if sys.argv[1] == "synth_patches_job":
    from simcam.trainingset import create_store
    create_store(payload["store"], sources=[payload["source"]], patches=4, patch_size=16, overwrite=True)
before = set(sys.modules)
job(payload)
print(json.dumps(sorted(m for m in set(sys.modules) - before
                        if m.split(".")[0] in ("simcam", "numba", "zarr", "distributed", "scipy"))))
"""


@pytest.mark.parametrize("job", ["render_job", "synth_patches_job", "ground_truth_job"])
def test_job_preload_covers_what_its_first_item_imports(job, inputs, tmp_path):
    """Local workers fork from a server that imported the job's ``preload`` (simcam.batch): a module a
    job imports on its first item is imported by each worker after the cluster started, on the way to
    its first result (simcam.noise and numba: ~0.5 s per worker before this list was completed)."""
    src = str(inputs / "img0.dng")
    if job == "render_job":  # the pipeline as the client sends it (its stage modules not imported by the worker)
        from simcam.pipeline import Pipeline

        payload = {"input": src, "output": str(tmp_path / "x.png"), "seed": 0, "index": 0,
                   "pipeline": Pipeline.from_yaml("srgb").to_dict()}
    elif job == "ground_truth_job":
        r = run_cli("synth", CHART, "-o", tmp_path / "burst", "--profile", PROFILE, "--iso", 800, "--frames", 3,
                    "--seed", 4)
        assert r.returncode == 0, r.stderr
        (tmp_path / "burst" / "clean.dng").unlink()
        payload = {"burst": str(tmp_path / "burst"), "npz": str(tmp_path / "gt.npz"),
                   "report": str(tmp_path / "gt.json"), "alignment": "global", "progress": False}
    else:
        payload = {"seed": 1, "profile": str(PROFILE), "isos": [800], "camera": None, "extrapolate": False,
                   "sensor_seed": None, "as_": "raw", "cfa": None, "patch_size": 16, "patches": 4,
                   "store": str(tmp_path / "set.zarr"), "source": src, "index": 0}
    r = subprocess.run([sys.executable, "-c", PRELOAD_CHECK, job, json.dumps(payload)], capture_output=True,
                       text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr[-2000:]
    assert json.loads(r.stdout.strip().splitlines()[-1]) == []


def test_many_items_run_in_chunks_and_fail_one_by_one(tmp_path):
    """More items than ``TASKS_PER_SLOT`` per worker thread go to dask in chunks (one task runs several
    items: a task costs the client ~4 ms of CPU); each item still has its own outcome, in task order, and a
    failing item fails alone — its chunk-mates complete and its partial output is removed."""
    from simcam.batch import TASKS_PER_SLOT, BatchConfig, Task, chunks, run_batch

    def job(payload):  # pickled by value to the workers
        import os
        from pathlib import Path

        Path(payload["out"]).write_text(str(payload["i"]))
        if payload["i"] == 77:
            raise ValueError("item 77 is bad")
        return {"i": payload["i"], "pid": os.getpid()}

    n = 5 * TASKS_PER_SLOT
    tasks = [Task(f"item{i}", {"i": i, "out": str(tmp_path / f"{i}.txt")}, outputs=(str(tmp_path / f"{i}.txt"),))
             for i in range(n)]
    assert len(chunks(range(n), 2)) == 2 * TASKS_PER_SLOT < n
    out = run_batch(job, tasks, BatchConfig(workers=2, progress=False), echo=lambda s: None)
    assert [o.key for o in out] == [t.key for t in tasks]
    assert [o.ok for o in out] == [i != 77 for i in range(n)]
    assert out[77].error == "ValueError: item 77 is bad"
    assert [o.info["i"] for o in out if o.ok] == [i for i in range(n) if i != 77]
    assert len({o.info["pid"] for o in out if o.ok}) == 2  # both workers took chunks
    assert not (tmp_path / "77.txt").exists() and (tmp_path / "76.txt").read_text() == "76"


def test_a_worker_killed_in_a_chunk_fails_only_that_item(tmp_path):
    """A worker that dies (here: ``os._exit``, as the kernel's OOM killer would end it) takes its whole chunk
    with it; the chunk's items then run again one by one, so the item that kills its worker fails with one
    line and the items beside it succeed."""
    from simcam.batch import TASKS_PER_SLOT, BatchConfig, Task, run_batch

    def job(payload):
        import os

        if payload == 5:
            os._exit(3)
        return {"i": payload}

    n = 2 * TASKS_PER_SLOT + 6  # one worker thread: chunks of 2 or 3 items
    out = run_batch(job, [Task(f"item{i}", i) for i in range(n)], BatchConfig(workers=1, progress=False),
                    echo=lambda s: None)
    assert [o.ok for o in out] == [i != 5 for i in range(n)]
    assert out[5].error.startswith("worker failed: ") and "\n" not in out[5].error
    assert [o.info["i"] for o in out if o.ok] == [i for i in range(n) if i != 5]
