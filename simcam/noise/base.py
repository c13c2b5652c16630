"""The NoiseModel contract, the noise condition, the model registry and shared helpers.

A noise model is a pydantic model whose fields are its parameters (so the
model *is* its profile entry: ``to_entry()`` / :func:`model_from_entry`), with

``sample(clean, cond, rng, *, chunk_rows=None) -> noisy``
    noisy normalised raw (float32, H x W) for clean normalised raw;
``log_prob(noisy, clean, cond) -> per-pixel log-likelihood`` in nats (float64),
    where the density is tractable (a design choice: log_prob only where the density has a closed form).

Per-CFA-site parameters are a float (all sites) or a list of 4 floats in the
packed site order (0,0), (0,1), (1,0), (1,1) of :mod:`simcam.cfa`.

Randomness and tiling. ``sample`` draws a 128-bit *frame key* from ``rng``;
rows are processed in fixed blocks of :data:`BLOCK_ROWS` rows and block ``b``
draws from ``SeedSequence(key + [b])``. The noise therefore depends only on
(key, block index, clean values): any ``chunk_rows`` (rounded up to a multiple of
``BLOCK_ROWS``) gives byte-identical output, and :meth:`NoiseModel.sample_rows`
lets callers produce any row range of a frame on its own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Union

import numpy as np
from pydantic import BaseModel, ConfigDict, ValidationError, field_validator

from ..cfa import check_pattern
from ..errors import NoiseModelError, SimcamError
from ..registry import Registry

#: rows per independently seeded block (even, so the CFA phase is the same in every block).
BLOCK_ROWS = 32
#: target elements per kernel call inside a block (kernels reuse workspace
#: buffers of this size, see kernels.py).
SUB_ELEMENTS = 131072


def sub_rows(width: int) -> int:
    """Rows per kernel call inside a block (even; depends only on the width)."""
    r = max(2, (SUB_ELEMENTS // max(int(width), 1)) // 2 * 2)
    return min(r, BLOCK_ROWS)

SiteParam = Union[float, list[float]]

_MODELS = Registry("noise model type")


@dataclass(frozen=True)
class NoiseCondition:
    """What a noise model is conditioned on besides the clean signal.

    Attributes
    ----------
    iso : float or None
        ISO speed of the capture.
    camera : str or None
        Camera id (profile key).
    cfa : str or None
        2x2 Bayer pattern of the mosaic (``"RGGB"``...); None for a mosaic of
        unknown layout (then only site-independent parameters can be used).
    source : str
        Where the data came from (for error messages).
    exposure_s : float or None
        Exposure time in seconds (exposure-dependent effects: ``dark_current``, ``amp_glow``).

    Parameters
    ----------
    iso, camera, cfa, source, exposure_s
        As the attributes; ``cfa`` is checked (a bad pattern is a :class:`~simcam.errors.CfaError`).

    Examples
    --------
    >>> cond = NoiseCondition(iso=800.0, camera="GP", cfa="GRBG")
    >>> cond.iso, cond.cfa, cond.exposure_s is None
    (800.0, 'GRBG', True)
    """

    iso: float | None = None
    camera: str | None = None
    cfa: str | None = "RGGB"
    source: str = ""
    exposure_s: float | None = None

    def __post_init__(self) -> None:
        if self.cfa is not None:
            object.__setattr__(self, "cfa", check_pattern(self.cfa, where=f"{self.source or 'cond'}: cfa"))


class ProfileEntryModel(BaseModel):
    """A pydantic model that is one entry of a noise profile, ``{type: NAME, **params}``: the base of the
    noise models (:class:`NoiseModel`) and of their effects (:class:`simcam.noise.effects.Effect`)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    type: str

    def to_entry(self) -> dict[str, Any]:
        """The profile entry (JSON-compatible dict, ``type`` first)."""
        return self.model_dump(mode="json")


class NoiseModel(ProfileEntryModel):
    """Base of parametric noise models (see module docstring).

    Parameters
    ----------
    type : str
        The model's registered name (its subclasses fix it as a ``Literal`` default).
    **params
        The model's own fields (pydantic, ``extra="forbid"``, frozen).

    Attributes
    ----------
    tractable : bool
        False for models whose :meth:`log_prob` raises.

    Examples
    --------
    >>> import numpy as np
    >>> import simcam.noise
    >>> model = model_types()["poisson_gaussian"](beta1=1e-3, beta2=1e-5)
    >>> noisy = model.sample(np.full((32, 32), 0.5, np.float32), NoiseCondition(), np.random.default_rng(0))
    >>> noisy.shape, model.to_entry()["type"]
    ((32, 32), 'poisson_gaussian')
    """

    #: False for models whose log_prob raises (documented per model).
    tractable: ClassVar[bool] = True

    # -- serialisation ----------------------------------------------------
    @classmethod
    def from_entry(cls, entry: dict[str, Any], *, where: str = "model") -> "NoiseModel":
        return model_from_entry(entry, where=where)

    # -- contract ---------------------------------------------------------
    def sample(self, clean: np.ndarray, cond: NoiseCondition, rng: np.random.Generator, *,
               chunk_rows: int | None = None, threads: int = 1) -> np.ndarray:
        """Noisy normalised raw for ``clean`` (float32 H x W), drawn from ``rng``.

        ``chunk_rows`` only bounds the rows processed per call and ``threads``
        samples row blocks in parallel; the result is byte-identical for every
        value of either (see module docstring).
        """
        clean = check_clean(clean, where=f"{cond.source or 'clean'}")
        self.check_cond(cond, clean.shape)
        key = frame_key(rng)
        h = clean.shape[0]
        step = h if not chunk_rows else max(BLOCK_ROWS, -(-int(chunk_rows) // BLOCK_ROWS) * BLOCK_ROWS)
        out = np.empty(clean.shape, dtype=np.float32)
        for r0 in range(0, h, step):
            self.sample_rows(clean[r0:r0 + step], cond, key, r0, out=out[r0:r0 + step], threads=threads)
        return out

    def sample_rows(self, clean_rows: np.ndarray, cond: NoiseCondition, key: np.ndarray,
                    row0: int, *, out: np.ndarray | None = None, threads: int = 1) -> np.ndarray:
        """Rows ``row0 ...`` of the frame sampled with frame key ``key`` (row0 % BLOCK_ROWS == 0).

        ``out`` (float32, shape of ``clean_rows``) receives the result when
        given; ``threads > 1`` processes row blocks on a thread pool (numpy
        releases the GIL in its kernels; each block has its own generator and
        rows, so the bytes do not depend on it).
        """
        if row0 % BLOCK_ROWS:
            raise NoiseModelError(f"sample_rows: row0 must be a multiple of {BLOCK_ROWS}, got {row0}")
        if out is None:
            out = np.empty(clean_rows.shape, dtype=np.float32)
        h = clean_rows.shape[0]
        sub = sub_rows(clean_rows.shape[1])

        def block(r: int) -> None:
            rng = block_rng(key, (row0 + r) // BLOCK_ROWS)
            for s in range(r, min(r + BLOCK_ROWS, h), sub):
                e = min(s + sub, r + BLOCK_ROWS, h)
                self._sample_block(clean_rows[s:e], cond, rng, row0 + s, out[s:e])

        starts = range(0, h, BLOCK_ROWS)
        if threads and threads > 1 and len(starts) > 1:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(max_workers=int(threads)) as pool:
                list(pool.map(block, starts))
        else:
            for r in starts:
                block(r)
        return out

    def sample_stack(self, clean: np.ndarray, cond: NoiseCondition, rng: np.random.Generator) -> np.ndarray:
        """Noisy float32 frames for a stack of clean frames (n x H x W, H even) in one kernel pass.

        For Monte-Carlo use (many small frames, e.g. the calibration loop's
        bootstrap), where per-block seeding would dominate the cost: the stack
        is sampled as one tall mosaic from ``rng`` directly. Same law as
        :meth:`sample` frame by frame, deterministic given ``rng``, but not the
        same bytes (no per-block frame keys, so no tiling invariance).
        """
        a = np.asarray(clean)
        if a.ndim != 3 or a.shape[1] % 2:
            raise NoiseModelError(f"{cond.source or 'clean'}: sample_stack expects n x H x W frames with H even, "
                                  f"got shape {a.shape}")
        n, h, w = a.shape
        flat = check_clean(a.reshape(n * h, w), where=f"{cond.source or 'clean'}")
        self.check_cond(cond, flat.shape)
        out = np.empty(flat.shape, dtype=np.float32)
        if flat.size:
            self._sample_block(flat, cond, rng, 0, out)
        return out.reshape(n, h, w)

    def read_split(self) -> tuple["NoiseModel", SiteParam] | None:
        """(the model without its signal-independent Gaussian read noise, that noise's variance), or None.

        ``noisy = without.sample(clean) + N(0, variance)`` in law; used by composites whose effects act
        on the read noise alone (``spatial_correlation``). None when the model has no such part.
        """
        return None

    def _sample_block(self, clean: np.ndarray, cond: NoiseCondition, rng: np.random.Generator,
                      row0: int, out: np.ndarray) -> None:
        """Fill ``out`` (float32, shape of ``clean``) with noisy values for these rows."""
        raise NotImplementedError

    def log_prob(self, noisy: np.ndarray, clean: np.ndarray, cond: NoiseCondition) -> np.ndarray:
        """Per-pixel log-likelihood (nats, float64) of ``noisy`` given ``clean``."""
        raise NoiseModelError(f"model {self.type!r}: log_prob is not tractable")

    def variance(self, clean: np.ndarray, cond: NoiseCondition) -> np.ndarray:
        """Theoretical per-pixel noise variance for ``clean`` (normalised raw^2)."""
        raise NoiseModelError(f"model {self.type!r}: no closed-form variance")

    def check_cond(self, cond: NoiseCondition, shape: tuple[int, ...]) -> None:
        """Raise if per-site parameters are used without a known CFA."""
        if cond.cfa is None and self._has_site_params():
            raise NoiseModelError(
                f"{cond.source or 'frame'}: cfa: model {self.type!r} has per-CFA-site parameters but the frame's CFA is unknown")

    def _has_site_params(self) -> bool:
        for name in type(self).model_fields:
            v = getattr(self, name)
            if isinstance(v, list) and len(v) == 4 and all(isinstance(x, (int, float)) for x in v):
                return True
        return False


class PoissonScaleModel(NoiseModel):
    """Shared parameters of the Poisson-based models: ``beta1`` (normalised raw per
    photo-electron, > 0) and ``beta2`` (Gaussian read variance, normalised raw^2, >= 0),
    each one float or 4 per-CFA-site floats. Not registered itself."""

    beta1: SiteParam
    beta2: SiteParam

    @field_validator("beta1")
    @classmethod
    def _check_beta1(cls, v):
        return validate_positive_site_param(v, "beta1")

    @field_validator("beta2")
    @classmethod
    def _check_beta2(cls, v):
        return validate_site_param(v, "beta2")

    def _maps(self, shape, row0, dtype=np.float32):
        return (site_map(self.beta1, shape, row0, name="beta1", dtype=dtype),
                site_map(self.beta2, shape, row0, name="beta2", dtype=dtype))


# -- registry -------------------------------------------------------------

def register_model(cls: type[NoiseModel]) -> type[NoiseModel]:
    """Class decorator: register a model under its ``type`` literal default.

    Parameters
    ----------
    cls : type
        A :class:`NoiseModel` subclass whose field ``type`` has a string default.

    Returns
    -------
    type
        ``cls`` itself, now found by :func:`model_from_entry` and :func:`model_types`.

    Raises
    ------
    TypeError
        No string default, or another class already holds the name.

    Examples
    --------
    >>> from typing import Literal
    >>> class Silent(NoiseModel):
    ...     type: Literal["silent_doc_example"] = "silent_doc_example"
    >>> register_model(Silent) is Silent, "silent_doc_example" in model_types()
    (True, True)
    >>> _ = _MODELS.pop("silent_doc_example")
    """
    key = cls.model_fields["type"].default
    if not isinstance(key, str):
        raise TypeError(f"{cls.__name__}: field 'type' needs a string default")
    return _MODELS.add(key, cls)


def model_types() -> dict[str, type[NoiseModel]]:
    """All registered model classes by ``type`` name (:mod:`simcam.noise` registers the built-in ones).

    Returns
    -------
    dict
        ``{type name: NoiseModel subclass}``; a copy, so changing it leaves the registry as it is.

    Examples
    --------
    >>> import simcam.noise
    >>> model_types()["nlf"].__name__, "poisson_gaussian" in model_types()
    ('NLF', True)
    """
    return _MODELS.types()


def from_registry(entry: Any, registry: dict[str, type], *, base: type, noun: str, expected: list[str],
                  where: str) -> Any:
    """Validate a ``{type: ..., **params}`` entry into the registered class, or raise NoiseModelError."""
    if isinstance(entry, base):
        return entry
    if not isinstance(entry, dict) or "type" not in entry:
        raise NoiseModelError(f"{where}: expected a mapping with a 'type' key, got {entry!r}")
    cls = registry.get(entry["type"])
    if cls is None:
        raise NoiseModelError(f"{where}.type: unknown {noun} {entry['type']!r}; expected one of {', '.join(expected)}")
    try:
        return cls.model_validate(entry)
    except ValidationError as exc:
        raise NoiseModelError(f"{where} ({entry['type']}): {describe_validation_error(exc)}") from None
    except SimcamError as exc:
        raise NoiseModelError(f"{where} ({entry['type']}): {exc}") from None


def model_from_entry(entry: Any, *, where: str = "model") -> NoiseModel:
    """Build a model from its profile entry ``{type: ..., **params}`` or raise NoiseModelError.

    Parameters
    ----------
    entry : dict or NoiseModel
        ``{"type": NAME, **params}`` as in a profile's ``model:`` node (a model is returned as is).
    where : str
        Location named in the error message.

    Returns
    -------
    NoiseModel
        An instance of the class registered under ``entry["type"]`` (see :func:`model_types`).

    Examples
    --------
    >>> import numpy as np
    >>> import simcam.noise
    >>> model = model_from_entry({"type": "nlf", "beta1": 1e-3, "beta2": 1e-5})
    >>> clean = np.full((64, 64), 0.25, np.float32)
    >>> noisy = model.sample(clean, NoiseCondition(), np.random.default_rng(0))
    >>> var = float(np.var(noisy - clean))  # var = beta1 * x + beta2 (Abdelhamed 2020, eq. 5.2)
    >>> abs(var / (1e-3 * 0.25 + 1e-5) - 1) < 0.1
    True
    """
    return from_registry(entry, _MODELS, base=NoiseModel, noun="noise model", expected=sorted(_MODELS), where=where)


def wrapped_base(entry: Any, wrapper: type, message: str) -> NoiseModel:
    """The ``base`` model of a wrapper model (clipped, composite); ValueError ``message`` if it is a ``wrapper`` too."""
    m = model_from_entry(entry, where="base")
    if isinstance(m, wrapper):
        raise ValueError(message)
    return m


def describe_validation_error(exc: ValidationError) -> str:
    err = exc.errors()[0]
    loc = ".".join(str(p) for p in err["loc"]) or "(parameters)"
    if err["type"] == "extra_forbidden":
        return f"{loc}: unknown parameter (value {err.get('input')!r})"
    return f"{loc}: {err['msg']}, got {err.get('input')!r}"


# -- randomness -------------------------------------------------------------

def frame_key(rng: np.random.Generator) -> np.ndarray:
    """128 bits drawn from ``rng`` that seed every block of one frame."""
    return rng.integers(0, 2**32, size=4, dtype=np.uint32)


def block_rng(key: np.ndarray, block: int, stream: int = 0) -> np.random.Generator:
    """Generator of row block ``block`` (``stream`` separates independent uses)."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([int(x) for x in key] + [int(stream), int(block)])))


# -- validation and per-site parameters ---------------------------------------

def check_clean(clean: Any, *, where: str = "clean") -> np.ndarray:
    """float32 H x W clean normalised raw, finite and >= 0, or NoiseModelError."""
    a = np.asarray(clean)
    if a.ndim != 2:
        raise NoiseModelError(f"{where}: expected an H x W mosaic, got shape {a.shape}")
    if a.dtype != np.float32:
        a = a.astype(np.float32)
    if not a.size:
        return a
    # two reductions without temporaries: min/max are NaN if any value is NaN
    lo, hi = a.min(), a.max()
    if not (np.isfinite(lo) and np.isfinite(hi)):
        bad = int(np.size(a) - np.count_nonzero(np.isfinite(a)))
        raise NoiseModelError(f"{where}: expected finite clean values, got {bad} NaN/inf pixel(s)")
    if lo < 0:
        raise NoiseModelError(
            f"{where}: expected clean normalised raw >= 0 (an expected signal cannot be negative), got min {float(lo):.6g}")
    return a


def check_same_shape(noisy: Any, clean: np.ndarray, *, where: str = "noisy") -> np.ndarray:
    n = np.asarray(noisy)
    if n.shape != clean.shape:
        raise NoiseModelError(f"{where}: expected the clean image's shape {clean.shape}, got {n.shape}")
    return n


def site_values(value: SiteParam, *, name: str) -> np.ndarray:
    """A per-site parameter as 4 float64 values (site order (0,0), (0,1), (1,0), (1,1))."""
    v = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if v.size == 1:
        return np.repeat(v, 4)
    if v.size != 4:
        raise NoiseModelError(f"{name}: expected a float or 4 per-site values, got {value!r}")
    return v


def site_map(value: SiteParam, shape: tuple[int, int], row0: int = 0, *, name: str = "param",
             dtype=np.float32) -> np.ndarray | np.floating:
    """The per-pixel map of a per-site parameter (a scalar when all sites agree)."""
    v = site_values(value, name=name)
    if np.all(v == v[0]):
        return dtype(v[0])
    h, w = shape
    cell = v.reshape(2, 2).astype(dtype)
    rows = cell[(row0 + np.arange(h)) % 2]  # h x 2
    return np.tile(rows, (1, (w + 1) // 2))[:, :w]


def validate_site_param(value: Any, name: str, *, minimum: float | None = 0.0) -> SiteParam:
    """pydantic helper: float or 4 floats, all >= ``minimum``."""
    vals = site_values(value, name=name)
    if not np.isfinite(vals).all():
        raise ValueError(f"{name} must be finite, got {value!r}")
    if minimum is not None and (vals < minimum).any():
        raise ValueError(f"{name} must be >= {minimum}, got {value!r}")
    return value


def validate_positive_site_param(value: Any, name: str) -> SiteParam:
    """pydantic helper: float or 4 floats, all finite and > 0."""
    validate_site_param(value, name)
    if (site_values(value, name=name) <= 0).any():
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return value
