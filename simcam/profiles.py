"""Calibration profiles: schema-versioned YAML of per-camera, per-ISO noise models.

Layout (``schema_version: 1``)::

    schema_version: 1
    provenance: {source: ..., method: ..., tool: ..., created: ..., licence: ..., notes: ...}
    cameras:
      - id: GP                      # the key of lookup(camera=...)
        make: Google
        model: Pixel
        cfa: RGGB                   # or null: parameters do not depend on the site
        black_level_dn: 64.0        # optional, DN
        white_level_dn: 1023.0      # optional, DN
        entries:
          - iso: 100.0
            model: {type: nlf, beta1: 2.28e-4, beta2: 2.0e-6}

Lookup by camera and ISO (:meth:`CalibrationProfile.model_for`): an exact ISO
returns that entry; between two calibrated ISOs every float parameter is
interpolated linearly in log-ISO (so NLF beta1 and beta2 are linear in
log-ISO); outside the calibrated range the lookup refuses unless
``extrapolate=True``, which extrapolates linearly in log-ISO from the two
nearest entries (a single-entry camera: the entry itself) and warns
(:class:`ProfileExtrapolationWarning`).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any, Optional

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from .cfa import check_pattern
from .errors import ProfileError, SimcamError
from .yamlio import load_yaml

SCHEMA_VERSION = 1


class ProfileExtrapolationWarning(UserWarning):
    """A noise model was extrapolated outside a profile's calibrated ISO range."""


class Provenance(BaseModel):
    """Where the numbers come from."""

    model_config = ConfigDict(extra="forbid")
    source: str
    method: str = ""
    tool: str = ""
    created: str = ""
    licence: str = ""
    notes: str = ""


class ISOEntry(BaseModel):
    """One calibrated ISO: a noise-model entry (any registered model type)."""

    model_config = ConfigDict(extra="forbid")
    iso: float = Field(gt=0)
    model: dict[str, Any]

    @field_validator("model")
    @classmethod
    def _model(cls, v):
        from .noise.base import model_from_entry

        return model_from_entry(v, where="model").to_entry()


class CameraProfile(BaseModel):
    """Noise calibration of one camera."""

    model_config = ConfigDict(extra="forbid")
    id: str = Field(min_length=1)
    make: str = ""
    model: str = ""
    cfa: Optional[str] = None
    black_level_dn: Optional[float] = None
    white_level_dn: Optional[float] = None
    entries: list[ISOEntry] = Field(min_length=1)

    @field_validator("cfa")
    @classmethod
    def _cfa(cls, v):
        return None if v is None else check_pattern(v)

    @field_validator("entries")
    @classmethod
    def _sorted(cls, v):
        v = sorted(v, key=lambda e: e.iso)
        isos = [e.iso for e in v]
        if len(set(isos)) != len(isos):
            raise ValueError(f"duplicate ISO entries {isos}")
        return v

    @property
    def iso_range(self) -> tuple[float, float]:
        return self.entries[0].iso, self.entries[-1].iso


class CalibrationProfile(BaseModel):
    """A profile file: cameras with per-ISO noise models, and provenance."""

    model_config = ConfigDict(extra="forbid")
    schema_version: int = SCHEMA_VERSION
    provenance: Provenance
    cameras: list[CameraProfile] = Field(min_length=1)
    source: str = Field("", exclude=True)  # file it was loaded from (error messages)

    @field_validator("cameras")
    @classmethod
    def _unique(cls, v):
        ids = [c.id for c in v]
        if len(set(ids)) != len(ids):
            raise ValueError(f"duplicate camera ids {ids}")
        return v

    # -- lookup --------------------------------------------------------------
    def camera(self, camera: str | None = None) -> CameraProfile:
        """The camera with this id (case-insensitive), or the only camera when None."""
        where = self.source or "profile"
        if camera is None:
            if len(self.cameras) == 1:
                return self.cameras[0]
            raise ProfileError(f"{where}: camera: the profile holds {len(self.cameras)} cameras "
                               f"{[c.id for c in self.cameras]}; name one")
        for c in self.cameras:
            if c.id.lower() == str(camera).lower():
                return c
        raise ProfileError(f"{where}: camera: unknown camera {camera!r}; expected one of {[c.id for c in self.cameras]}")

    def entry_for(self, iso: float, camera: str | None = None, *, extrapolate: bool = False) -> dict[str, Any]:
        """The (interpolated) model entry for ``iso`` (see module docstring)."""
        cam = self.camera(camera)
        where = f"{self.source or 'profile'}: camera {cam.id!r}"
        try:
            iso = float(iso)
        except (TypeError, ValueError):
            raise ProfileError(f"{where}: iso: expected a positive number, got {iso!r}") from None
        if not (iso > 0 and math.isfinite(iso)):
            raise ProfileError(f"{where}: iso: expected a positive number, got {iso!r}")
        isos = [e.iso for e in cam.entries]
        for e in cam.entries:
            if math.isclose(e.iso, iso, rel_tol=1e-9):
                return e.model
        lo, hi = isos[0], isos[-1]
        if iso < lo or iso > hi:
            if not extrapolate:
                raise ProfileError(
                    f"{where}: iso: {iso:g} is outside the calibrated range [{lo:g}, {hi:g}]; expected an ISO inside "
                    f"it, or allow extrapolation (simcam synth --extrapolate; extrapolate: true in a noise stage) to extrapolate linearly in log-ISO")
            warnings.warn(f"{where}: ISO {iso:g} is outside the calibrated range [{lo:g}, {hi:g}]: extrapolating "
                          f"linearly in log-ISO", ProfileExtrapolationWarning, stacklevel=2)
            if len(isos) == 1:
                return cam.entries[0].model
            pair = (cam.entries[0], cam.entries[1]) if iso < lo else (cam.entries[-2], cam.entries[-1])
        else:
            j = next(i for i, v in enumerate(isos) if v > iso)
            pair = (cam.entries[j - 1], cam.entries[j])
        a, b = pair
        t = (math.log(iso) - math.log(a.iso)) / (math.log(b.iso) - math.log(a.iso))
        return interpolate_entries(a.model, b.model, t, where=f"{where}: ISO {a.iso:g}..{b.iso:g}")

    def model_for(self, iso: float, camera: str | None = None, *, extrapolate: bool = False):
        """The noise model (:class:`simcam.noise.NoiseModel`) for ``iso`` and ``camera``."""
        from .noise.base import model_from_entry

        entry = self.entry_for(iso, camera, extrapolate=extrapolate)
        try:
            return model_from_entry(entry, where=f"{self.source or 'profile'}: model at ISO {float(iso):g}")
        except SimcamError as exc:
            raise ProfileError(str(exc)) from None

    # -- I/O -----------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        doc = self.model_dump(mode="json", exclude_none=False)
        return {"schema_version": doc.pop("schema_version"), **doc}

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False, default_flow_style=False, width=100, allow_unicode=True)

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(self.to_yaml())
        return path


def interpolate_entries(a: Any, b: Any, t: float, *, where: str = "entry", path: str = "model") -> Any:
    """``a + t (b - a)`` for every float of two entries of the same structure."""
    if isinstance(a, bool) or isinstance(b, bool) or isinstance(a, str) or a is None:
        if a != b:
            raise ProfileError(f"{where}: {path}: cannot interpolate between {a!r} and {b!r} (expected equal values)")
        return a
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        if isinstance(a, int) and isinstance(b, int):
            if a != b:
                raise ProfileError(f"{where}: {path}: cannot interpolate integers {a} and {b}")
            return a
        return float(a) + t * (float(b) - float(a))
    if isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            raise ProfileError(f"{where}: {path}: entries differ in keys {sorted(set(a) ^ set(b))}; cannot interpolate")
        return {k: interpolate_entries(a[k], b[k], t, where=where, path=f"{path}.{k}") for k in a}
    if isinstance(a, list) and isinstance(b, list):
        if len(a) == 1 and len(b) != 1:
            a = a * len(b)
        if len(b) == 1 and len(a) != 1:
            b = b * len(a)
        if len(a) != len(b):
            raise ProfileError(f"{where}: {path}: lists of length {len(a)} and {len(b)}; cannot interpolate")
        return [interpolate_entries(x, y, t, where=where, path=f"{path}[{i}]") for i, (x, y) in enumerate(zip(a, b))]
    if isinstance(a, (int, float)) and isinstance(b, list):
        return interpolate_entries([a] * len(b), b, t, where=where, path=path)
    if isinstance(a, list) and isinstance(b, (int, float)):
        return interpolate_entries(a, [b] * len(a), t, where=where, path=path)
    raise ProfileError(f"{where}: {path}: cannot interpolate {a!r} and {b!r} (different types)")


def profile_from_dict(doc: Any, *, source: str = "<profile>") -> CalibrationProfile:
    """Validate a profile document or raise :class:`ProfileError` naming the field."""
    if not isinstance(doc, dict):
        raise ProfileError(f"{source}: expected a mapping with schema_version, provenance and cameras, got {type(doc).__name__}")
    ver = doc.get("schema_version")
    if ver != SCHEMA_VERSION:
        raise ProfileError(f"{source}: schema_version: expected {SCHEMA_VERSION}, got {ver!r}")
    try:
        prof = CalibrationProfile.model_validate(doc)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err["loc"])
        raise ProfileError(f"{source}: {loc}: {err['msg']}, got {str(err.get('input'))[:120]!r}") from None
    except SimcamError as exc:
        raise ProfileError(f"{source}: {exc}") from None
    prof.source = source
    return prof


def load_profile(path: str | Path) -> CalibrationProfile:
    """Load and validate a profile YAML file."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ProfileError(f"{path}: cannot read profile ({exc.strerror})") from None
    doc = load_yaml(text, source=str(path), error=ProfileError)
    if isinstance(doc, dict):  # measured maps (FILE.npz#KEY) are relative to the profile's folder
        from .noise.maps import resolve_map_refs

        doc = resolve_map_refs(doc, path.resolve().parent)
    return profile_from_dict(doc, source=str(path))


def save_profile(profile: CalibrationProfile, path: str | Path) -> Path:
    return profile.save(path)
