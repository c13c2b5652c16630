"""Raw-domain noise stages: ``noise`` (inject a noise model) and ``clip_raw`` (censor to a range).

``noise`` takes its model from a calibration profile (``profile`` + ``iso``
[+ ``camera``], interpolated in log-ISO, ``extrapolate`` to allow leaving the
calibrated range) or inline (``model: {type: nlf, beta1: ..., beta2: ...}``).
``sensor_seed`` fixes the fixed-pattern effects of a composite model (the same
sensor in every frame); ``chunk_rows`` and ``threads`` change memory use and
speed, never the bytes. ``sample(rng, frame)`` draws the noisy mosaic and
returns it as ``{"noisy": array}``; ``apply`` writes it into the frame (and the
model's NLF into ``meta.noise_profile`` as DNG NoiseProfile pairs, one or one
per R, G, B plane, when the model has the form ``beta1 x + beta2``).
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np
from pydantic import model_validator

from ..errors import StageError
from ..frame import RawFrame
from .base import Stage, StageParams, register_stage


@register_stage
class Noise(Stage, type="noise", accepts=frozenset({"raw"}), random=True):
    """Add raw noise from a profile or an inline model (see module docstring)."""

    class Params(StageParams):
        profile: Optional[str] = None
        iso: Optional[float] = None
        camera: Optional[str] = None
        extrapolate: bool = False
        model: Optional[dict[str, Any]] = None
        sensor_seed: Optional[int] = None
        #: exposure time (s) for exposure-dependent effects; default: the frame's ExposureTime
        exposure_s: Optional[float] = None
        chunk_rows: Optional[int] = None
        threads: int = 1

        @model_validator(mode="after")
        def _one_source(self):
            if (self.profile is None) == (self.model is None):
                raise ValueError("give exactly one of profile (with iso) or model")
            if self.profile is not None and self.iso is None:
                raise ValueError("profile needs iso")
            return self

    def __init__(self, params=None, **kw):
        super().__init__(params, **kw)
        self.model = self._build_model()

    def _build_model(self):
        from ..noise.base import model_from_entry
        from ..noise.composite import Composite
        from ..profiles.schema import load_profile

        p = self.params
        if p.profile is not None:
            prof = load_profile(p.profile)
            cam = prof.camera(p.camera)
            self._cam_cfa = cam.cfa
            model = prof.model_for(p.iso, cam.id, extrapolate=p.extrapolate)
        else:
            self._cam_cfa = None
            model = model_from_entry(p.model, where="model")
        if p.sensor_seed is not None:
            if isinstance(model, Composite):
                model = model.with_sensor_seed(p.sensor_seed)
        return model

    def condition(self, frame: RawFrame):
        from ..noise.base import NoiseCondition

        cfa = frame.meta.cfa
        if self._cam_cfa is not None and cfa is not None and cfa != self._cam_cfa:
            raise StageError(
                f"{frame.meta.source or 'frame'}: cfa: the profile {self.params.profile} calibrates camera "
                f"{self.params.camera or ''} with CFA {self._cam_cfa}, the frame is {cfa}")
        exposure = self.params.exposure_s if self.params.exposure_s is not None else frame.meta.exposure_time_s
        return NoiseCondition(iso=self.params.iso if self.params.iso is not None else frame.meta.iso,
                              camera=self.params.camera, cfa=cfa, source=frame.meta.source,
                              exposure_s=None if exposure is None else float(exposure))

    def sample(self, rng: np.random.Generator, frame: RawFrame) -> dict[str, Any]:
        noisy = self.model.sample(frame.data, self.condition(frame), rng, chunk_rows=self.params.chunk_rows,
                                  threads=self.params.threads)
        return {"noisy": noisy}

    def apply(self, frame: RawFrame, drawn: dict[str, Any] | None = None) -> RawFrame:
        if not drawn or "noisy" not in drawn:
            raise StageError("stage 'noise': apply needs what sample() drew ({'noisy': array})")
        noisy = np.asarray(drawn["noisy"], dtype=np.float32)
        if noisy.shape != frame.data.shape:
            raise StageError(f"stage 'noise': drawn noise has shape {noisy.shape}, the frame {frame.data.shape}")
        from ..noise.noise_profile import model_noise_profile

        meta = frame.meta
        nlf = model_noise_profile(self.model, meta.cfa)
        if nlf is not None:
            meta = meta.replace(noise_profile=nlf)
        return frame.evolve(noisy, meta=meta, step=self.type)


@register_stage
class ClipRaw(Stage, type="clip_raw", accepts=frozenset({"raw"})):
    """Clip normalised raw to [low, high] (default [0, 1]): the sensor's censoring (Abdelhamed 2020, eq. 3.9)."""

    class Params(StageParams):
        low: float = 0.0
        high: float = 1.0

    def apply(self, frame: RawFrame, drawn=None) -> RawFrame:
        if not self.params.low < self.params.high:
            raise StageError(f"stage 'clip_raw': expected low < high, got {self.params.low} and {self.params.high}")
        return frame.evolve(np.clip(frame.data, np.float32(self.params.low), np.float32(self.params.high)), step=self.type)
