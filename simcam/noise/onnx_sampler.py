"""Torch-free Noise Flow sampling and likelihood with onnxruntime.

Runs the graphs written by ``simcam flow export`` (:mod:`simcam.noise.flow.export`):
``model.onnx`` (clean, z, iso, camera -> noise) and ``model.loglik.onnx``
(noise, clean, iso, camera -> loglik). Needs only numpy and onnxruntime.
Packed tensors are NCHW with channels (0,0), (0,1), (1,0), (1,1) of the 2x2 CFA
cell (:data:`simcam.cfa.PACK_OFFSETS`), normalised raw. Any ISO inside the trained
range is accepted (the graph interpolates per-ISO parameters in log-ISO); outside
it, unknown cameras, bad shapes and dtypes raise :class:`NoiseModelError`.
Reference: Abdelhamed 2020, ch. 6 (Noise Flow) (the latent is an input, so sampling is deterministic given it).

:class:`NoiseFlowModel` registers the export as the pipeline noise model
``noiseflow_onnx`` (profile entry ``{type: noiseflow_onnx, path: ..., camera: ...}``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import ClassVar, Literal, Optional

import numpy as np

from ..errors import NoiseModelError, require_extra
from .base import (BLOCK_ROWS, NoiseCondition, NoiseModel, block_rng, check_clean, check_same_shape, frame_key,
                   register_model)

FORMAT = "simcam-noiseflow-onnx/1"
PACKING = "(0,0),(0,1),(1,0),(1,1)"
#: metadata_props every simcam Noise Flow export carries.
META_KEYS = ("simcam_format", "simcam_version", "simcam_role", "packing_order", "iso_min", "iso_max",
             "cameras", "default_temperature")


def loglik_path(sampler_path) -> Path:
    """``model.onnx`` -> ``model.loglik.onnx`` (same folder, same stem)."""
    p = Path(sampler_path)
    return p.with_name(p.stem + ".loglik.onnx")


def _session(path: Path, threads: int | None):
    ort = require_extra("onnxruntime", "onnx")
    if not path.is_file():
        raise NoiseModelError(f"{path}: ONNX file not found")
    opts = ort.SessionOptions()
    # "extended": the NCHWc layout pass of "all" adds reorders that cost more than they
    # save on 4-channel convolutions (measured in benchmarks/flow.py)
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_EXTENDED
    if threads:
        opts.intra_op_num_threads = int(threads)
        opts.inter_op_num_threads = 1
    try:
        return ort.InferenceSession(str(path), sess_options=opts, providers=["CPUExecutionProvider"])
    except Exception as exc:  # noqa: BLE001 - onnxruntime raises its own types
        raise NoiseModelError(f"{path}: not a loadable ONNX model ({str(exc).splitlines()[0][:120]})") from None


def _metadata(path: Path, sess, role: str) -> dict:
    meta = dict(sess.get_modelmeta().custom_metadata_map)
    missing = [k for k in META_KEYS if k not in meta]
    if missing:
        raise NoiseModelError(
            f"{path}: metadata_props: missing {missing[0]!r}; expected a simcam Noise Flow export "
            f"(simcam flow export)"
        )
    if meta["simcam_format"] != FORMAT:
        raise NoiseModelError(f"{path}: simcam_format: {meta['simcam_format']!r}, expected {FORMAT!r}")
    if meta["simcam_role"] != role:
        raise NoiseModelError(f"{path}: simcam_role: {meta['simcam_role']!r}, expected {role!r}")
    if meta["packing_order"] != PACKING:
        raise NoiseModelError(f"{path}: packing_order: {meta['packing_order']!r}, expected {PACKING!r}")
    return meta


class NoiseFlowRuntime:
    """A Noise Flow exported to ONNX, run with onnxruntime (no torch).

    Parameters
    ----------
    path : path-like
        The sampler ``model.onnx``; ``model.loglik.onnx`` beside it is used by
        :meth:`log_prob` when present.
    threads : int, optional
        onnxruntime intra-op threads (default: onnxruntime's choice).

    Attributes
    ----------
    cameras : list of str
    iso_range : (float, float)
        Trained ISO range (inclusive).
    default_temperature : float
    """

    def __init__(self, path, *, threads: int | None = None):
        self.path = Path(path)
        self.threads = threads
        self._sess = _session(self.path, threads)
        self.meta = _metadata(self.path, self._sess, "sampler")
        self.cameras = list(json.loads(self.meta["cameras"]))
        self.iso_range = (float(self.meta["iso_min"]), float(self.meta["iso_max"]))
        self.default_temperature = float(self.meta["default_temperature"])
        self._loglik = None

    # ------------------------------------------------------------ validation
    def _array(self, name, x, batch=None, shape=None):
        if not isinstance(x, np.ndarray):
            raise NoiseModelError(f"{name}: expected a numpy float32 array, got {type(x).__name__}")
        if x.dtype != np.float32:
            raise NoiseModelError(f"{name}: expected dtype float32, got {x.dtype}")
        if x.ndim != 4 or x.shape[1] != 4:
            raise NoiseModelError(f"{name}: expected shape (B, 4, H, W) packed raw, got {x.shape}")
        if shape is not None and x.shape != shape:
            raise NoiseModelError(f"{name}: shape {x.shape} differs from clean's {shape}")
        if x.shape[2] < 1 or x.shape[3] < 1:
            raise NoiseModelError(f"{name}: empty spatial size {x.shape}")
        return np.ascontiguousarray(x)

    def iso_array(self, iso, batch: int) -> np.ndarray:
        """ISO scalar or (B,) -> float32 (B,); outside the trained range -> error."""
        a = np.asarray(iso, dtype=np.float64).reshape(-1)
        if a.size == 1:
            a = np.full(batch, a[0])
        if a.size != batch:
            raise NoiseModelError(f"iso: expected a scalar or {batch} values, got {a.size}")
        lo, hi = self.iso_range
        bad = a[~((a >= lo * (1 - 1e-6)) & (a <= hi * (1 + 1e-6)))]
        if bad.size:
            raise NoiseModelError(f"{self.path.name}: iso: {bad[0]:g} is outside the trained range {lo:g}..{hi:g}")
        return a.astype(np.float32)

    def camera_array(self, camera, batch: int) -> np.ndarray:
        """Camera name(s)/index(es) -> int64 (B,); unknown -> error."""
        if isinstance(camera, (str, int, np.integer)):
            items = [camera] * batch
        elif isinstance(camera, (list, tuple)):
            items = list(camera)
        else:
            items = np.asarray(camera).ravel().tolist()
        if len(items) != batch:
            raise NoiseModelError(f"camera: expected {batch} values (one per patch), got {len(items)}")
        out = []
        for c in items:
            if isinstance(c, str):
                if str(c) not in self.cameras:
                    raise NoiseModelError(f"{self.path.name}: camera: {str(c)!r} is not one of {self.cameras}")
                out.append(self.cameras.index(str(c)))
            else:
                if not 0 <= int(c) < len(self.cameras):
                    raise NoiseModelError(
                        f"{self.path.name}: camera: index {int(c)} outside 0..{len(self.cameras) - 1} ({self.cameras})"
                    )
                out.append(int(c))
        return np.asarray(out, dtype=np.int64)

    # ------------------------------------------------------------- inference
    def sample(self, clean, *, iso, camera, z=None, rng=None, temperature=None) -> np.ndarray:
        """Noise for packed clean patches.

        Parameters
        ----------
        clean : float32 (B, 4, H, W)
            Clean packed raw, normalised (0..1).
        iso : float or (B,)
            Inside :attr:`iso_range`.
        camera : str, int or sequence
        z : float32 (B, 4, H, W), optional
            Latent; default ``temperature * rng.standard_normal``.
        rng : numpy.random.Generator, optional
            Used when ``z`` is None (required then).
        temperature : float, optional
            Default :attr:`default_temperature`.

        Returns
        -------
        float32 (B, 4, H, W)
            Noise to add to ``clean``.
        """
        clean = self._array("clean", clean)
        if z is None:
            if rng is None:
                raise NoiseModelError("sample: give either z or rng (numpy Generator)")
            t = self.default_temperature if temperature is None else float(temperature)
            z = (t * rng.standard_normal(clean.shape)).astype(np.float32)
        z = self._array("z", z, shape=clean.shape)
        b = clean.shape[0]
        feeds = {"clean": clean, "z": z, "iso": self.iso_array(iso, b), "camera": self.camera_array(camera, b)}
        return self._sess.run(["noise"], feeds)[0]

    def sample_mosaic(self, clean, *, iso, camera, rng, temperature=None) -> np.ndarray:
        """Noise for an H x W Bayer mosaic (H, W even), returned as a mosaic."""
        from ..cfa import pack, unpack

        if not isinstance(clean, np.ndarray) or clean.ndim != 2:
            raise NoiseModelError(f"clean: expected an H x W mosaic array, got {getattr(clean, 'shape', type(clean))}")
        if clean.shape[0] % 2 or clean.shape[1] % 2:
            raise NoiseModelError(f"clean: mosaic height and width must be even, got {clean.shape[0]}x{clean.shape[1]}")
        if clean.dtype != np.float32:
            raise NoiseModelError(f"clean: expected dtype float32, got {clean.dtype}")
        packed = pack(clean)[None]
        return unpack(self.sample(packed, iso=iso, camera=camera, rng=rng, temperature=temperature)[0])

    def log_prob(self, noise, *, clean, iso, camera) -> np.ndarray:
        """Per-patch log-likelihood (B,) in nats, from ``<stem>.loglik.onnx``."""
        if self._loglik is None:
            lp = loglik_path(self.path)
            sess = _session(lp, self.threads)
            _metadata(lp, sess, "loglik")
            self._loglik = sess
        clean = self._array("clean", clean)
        noise = self._array("noise", noise, shape=clean.shape)
        b = clean.shape[0]
        feeds = {"noise": noise, "clean": clean, "iso": self.iso_array(iso, b), "camera": self.camera_array(camera, b)}
        return self._loglik.run(["loglik"], feeds)[0]


# ---------------------------------------------------------------------------
# ``noiseflow_onnx``: the exported flow as a registered pipeline noise model
# ---------------------------------------------------------------------------
#: mosaic rows of context on each side of a tile: 8 couplings x 2 packed pixels of
#: receptive radius = 16 packed rows = 32 mosaic rows (tiles are then exact).
HALO_ROWS = 32
_PROFILES = Path(__file__).resolve().parents[2] / "profiles"
_SESSIONS: dict = {}


def _cached_flow(path: Path, threads: int) -> NoiseFlowRuntime:
    key = (str(path.resolve()), path.stat().st_mtime_ns, int(threads))
    if key not in _SESSIONS:
        _SESSIONS[key] = NoiseFlowRuntime(path, threads=threads)
    return _SESSIONS[key]


@register_model
class NoiseFlowModel(NoiseModel):
    """Noise Flow exported to ONNX (``simcam flow export``) as a pipeline noise model.

    ``noisy = clean + flow(z; clean, ISO, camera)`` with ``z = T * N(0, I)``; the
    mosaic is packed by position ((0,0), (0,1), (1,0), (1,1)), as the flow was trained.
    The latent of row block ``b`` is drawn from ``block_rng(key, b)`` and the flow runs
    on tiles of ``tile_rows`` with a :data:`HALO_ROWS` halo, so the bytes do not depend
    on ``chunk_rows``, ``threads`` or ``tile_rows``. Needs the frame's ISO (inside the
    export's trained range, interpolated in log-ISO) and even H and W. Abdelhamed 2020, ch. 6.

    Parameters
    ----------
    path : str
        The sampler ``.onnx`` (``<stem>.loglik.onnx`` beside it for :meth:`log_prob`);
        a relative path is looked up in the working directory, then in ``profiles/``.
    camera : str, optional
        Camera name in the export (default: the condition's camera, or the only one).
    temperature : float, optional
        Latent scale T (default: the export's ``default_temperature``).
    threads : int
        onnxruntime intra-op threads.
    tile_rows : int
        Mosaic rows per onnxruntime call (multiple of BLOCK_ROWS; memory bound only).
    """

    type: Literal["noiseflow_onnx"] = "noiseflow_onnx"
    path: str
    camera: Optional[str] = None
    temperature: Optional[float] = None
    threads: int = 1
    tile_rows: int = 512
    tractable: ClassVar[bool] = True

    def flow(self) -> NoiseFlowRuntime:
        """The onnxruntime sampler (cached per file and thread count)."""
        p = Path(self.path)
        for cand in ([p] if p.is_absolute() else [p, _PROFILES / p]):
            if cand.is_file():
                return _cached_flow(cand, self.threads)
        raise NoiseModelError(f"noiseflow_onnx: path: {self.path!r} not found (looked in the working directory and {_PROFILES})")

    def _camera(self, flow: NoiseFlowRuntime, cond: NoiseCondition) -> str:
        cam = self.camera or cond.camera
        if cam is None:
            if len(flow.cameras) == 1:
                return flow.cameras[0]
            raise NoiseModelError(f"noiseflow_onnx: camera: the export holds cameras {flow.cameras}; name one")
        return cam

    def _check(self, clean: np.ndarray, cond: NoiseCondition) -> None:
        where = cond.source or "frame"
        if cond.iso is None:
            raise NoiseModelError(f"{where}: iso: model 'noiseflow_onnx' needs the frame's ISO, got none")
        h, w = clean.shape
        if h % 2 or w % 2:
            raise NoiseModelError(f"{where}: expected even mosaic height and width for 'noiseflow_onnx', got {h}x{w}")

    def sample(self, clean, cond, rng, *, chunk_rows=None, threads=1):
        clean = check_clean(clean, where=f"{cond.source or 'clean'}")
        self._check(clean, cond)
        flow = self.flow()
        cam = self._camera(flow, cond)
        flow.iso_array(cond.iso, 1)
        flow.camera_array(cam, 1)
        key = frame_key(rng)
        t = flow.default_temperature if self.temperature is None else float(self.temperature)
        h, w = clean.shape
        z = np.empty((1, 4, h // 2, w // 2), np.float32)
        for b, r in enumerate(range(0, h, BLOCK_ROWS)):
            rows = min(BLOCK_ROWS, h - r) // 2
            z[0, :, r // 2:r // 2 + rows] = block_rng(key, b).standard_normal((4, rows, w // 2), dtype=np.float32)
        z *= np.float32(t)
        from ..cfa import pack, unpack

        cp = pack(clean)[None]
        out = np.empty_like(clean)
        step = max(BLOCK_ROWS, int(self.tile_rows) // BLOCK_ROWS * BLOCK_ROWS) // 2
        halo = HALO_ROWS // 2
        for p0 in range(0, h // 2, step):
            p1 = min(p0 + step, h // 2)
            a, b_ = max(0, p0 - halo), min(h // 2, p1 + halo)
            n = flow.sample(np.ascontiguousarray(cp[:, :, a:b_]), z=np.ascontiguousarray(z[:, :, a:b_]),
                            iso=cond.iso, camera=cam)[0]
            out[2 * p0:2 * p1] = unpack(n[:, p0 - a:p1 - a])
        out += clean
        return out

    def sample_rows(self, clean_rows, cond, key, row0, *, out=None, threads=1):
        raise NoiseModelError("model 'noiseflow_onnx': sample_rows is not available (the flow couples rows across "
                              "blocks); call sample() (chunk_rows is accepted and does not change the result)")

    def log_prob(self, noisy, clean, cond):
        """Per-pixel share of the frame's log-likelihood (nats, float64).

        A flow gives the joint density of the whole frame, not per-pixel marginals:
        every pixel gets ``loglik / (H W)`` so that the map sums to the frame's
        log-likelihood (from ``<stem>.loglik.onnx``).
        """
        clean = check_clean(clean, where=f"{cond.source or 'clean'}")
        noisy = check_same_shape(noisy, clean)
        self._check(clean, cond)
        from ..cfa import pack

        flow = self.flow()
        n = pack(np.asarray(noisy, np.float32) - clean)[None]
        ll = float(flow.log_prob(n, clean=pack(clean)[None], iso=cond.iso, camera=self._camera(flow, cond))[0])
        return np.full(clean.shape, ll / clean.size, np.float64)
