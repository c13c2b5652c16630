"""Torch-free Noise Flow sampling and likelihood with onnxruntime.

Runs the graphs written by ``simcam flow export`` (:mod:`simcam.noise.flow.export`):
``model.onnx`` (clean, z, iso, camera -> noise) and ``model.loglik.onnx``
(noise, clean, iso, camera -> loglik). Needs only numpy and onnxruntime.
Packed tensors are NCHW with channels (0,0), (0,1), (1,0), (1,1) of the 2x2 CFA
cell (:data:`simcam.cfa.PACK_OFFSETS`), normalised raw. Any ISO inside the trained
range is accepted (the graph interpolates per-ISO parameters in log-ISO); outside
it, unknown cameras, bad shapes and dtypes raise :class:`NoiseModelError`.
Reference: seed ch. 6 (Noise Flow); DESIGN.md "Randomness" (the latent is an input).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import NoiseModelError, require_extra

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


class OnnxNoiseFlow:
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
