"""The effect card: what the calibration loop knows about one effect of its vocabulary.

A card (a subclass of :class:`EffectCard`, one instance in the registry) holds for one effect:

* ``name``: the effect's name in the loop, in ``loop_model.yaml`` and ``report.json``; it is also
  the ``type`` of the effect's entry in the noise stage's composite model (``profile.yaml``);
* ``params``: its typed parameters, a frozen dataclass derived from :class:`EffectParams` with
  the unit of each field in the field's doc (``quantity``);
* ``diagnostics``: the residual diagnostics (:mod:`simcam.calibration.diagnostics`) that propose it;
* :meth:`EffectCard.fit`: the fit of its parameters on a capture (moments, or indirect inference
  through ``FitContext.simulate``);
* its part of the closed-form marginal variance (:meth:`EffectCard.marginal`, ``marginal_rank``,
  ``gaussian``, ``fixed_pattern``) and of the read-noise bookkeeping
  (:meth:`EffectCard.dark_variance_dn2`: what ``LoopModel.refit_read`` takes off the measured dark
  variance to leave the read noise);
* its conversion to and from the noise stage's profile entry (:meth:`EffectCard.to_profile`,
  :meth:`EffectCard.from_profile`, :meth:`EffectCard.from_base`, :meth:`EffectCard.profile_read_dn`);
* its formatting for the report (:meth:`EffectCard.format`) and when a fit is the identity
  (:meth:`EffectCard.is_null`);
* in its module docstring, the physics, with the sources.

The registry (:mod:`simcam.calibration.effects`, the package's ``__init__``) lists the cards in one
place, in signal-chain order; this module imports none of them. Cards see the loop's model
(``LoopModel``) only through its attributes, so ``model`` imports the registry and not the reverse.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import MISSING, dataclass, field, fields
from typing import Any, ClassVar

import numpy as np


def quantity(unit: str, doc: str, *, scale: float | None = 1.0, default: Any = MISSING,
             profile: str | None = None, per_full_scale: bool = False, profile_default: Any = MISSING):
    """A parameter field: ``doc`` says what it is, ``unit`` is the unit the report shows it in and
    ``scale`` the factor from the stored value to that unit (None: shown as it is, e.g. a name).

    ``profile``: the key of the field in the noise stage's effect entry, when the card's default
    conversion (:class:`DeclaredProfileCard`) writes it there;
    ``per_full_scale``: the entry holds it on normalised raw, ``value / (white - black)`` (the field
    is in DN); ``profile_default``: the value read where an entry lacks the key (else a KeyError).
    A ``list`` field is one value per 2x2 site (an entry's scalar is broadcast to the four sites).
    """
    meta = {"unit": unit, "scale": scale, "doc": doc, "profile": profile, "per_full_scale": per_full_scale,
            "profile_default": profile_default}
    return field(metadata=meta) if default is MISSING else field(default=default, metadata=meta)


def format_number(v: float | None, digits: int = 3) -> str:
    """``digits`` significant digits (``g`` format: an exponent only below 1e-4 or beyond the digits)."""
    if v is None:
        return "–"
    return f"{float(v):.{digits}g}"


class EffectParams(Mapping):
    """Typed parameters of one effect (subclasses are frozen dataclasses; units in the field docs).

    They also read as a mapping field -> value (optional fields that are None left out), the
    loop's former dicts: :meth:`to_dict` is what ``loop_model.yaml`` and ``report.json`` hold.
    A subclass declares its fields with :func:`quantity` and is made a frozen dataclass on its
    definition (no decorator).

    Attributes
    ----------
    fields
        The subclass's fields, each declared with :func:`quantity` (unit, doc, profile key).

    Examples
    --------
    >>> from simcam.calibration.effects.dsnu import Dsnu
    >>> p = Dsnu(sigma_dn=2.5)
    >>> dict(p), p.format()
    ({'sigma_dn': 2.5}, 'sigma_dn = 2.5 DN')
    """

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        dataclass(frozen=True)(cls)

    @classmethod
    def from_dict(cls, values: Mapping) -> EffectParams:
        """The parameters from a mapping of field names (``loop_model.yaml``, ``report.json``);
        values are taken as they are. ValueError on an unknown or a missing field."""
        names = [f.name for f in fields(cls)]
        unknown = [k for k in values if k not in names]
        missing = [f.name for f in fields(cls) if f.default is MISSING and f.name not in values]
        if unknown or missing:
            raise ValueError(", ".join(
                ([f"unknown parameter(s) {', '.join(map(str, unknown))}"] if unknown else [])
                + ([f"missing parameter(s) {', '.join(missing)}"] if missing else []))
                + f"; expected {', '.join(names)}")
        return cls(**values)

    def to_dict(self) -> dict:
        """Field -> value, in field order (optional fields that are None left out)."""
        return {k: getattr(self, k) for k in self}

    def __iter__(self) -> Iterator[str]:
        for f in fields(self):
            if not (f.default is None and getattr(self, f.name) is None):
                yield f.name

    def __len__(self) -> int:
        return sum(1 for _ in self)

    def __getitem__(self, key: str):
        if key in list(self):
            return getattr(self, key)
        raise KeyError(key)

    def format(self) -> str:
        """Parameters with their units, e.g. ``sigma_dn = 2.66 DN`` (three significant digits)."""
        out = []
        for f in fields(self):
            if f.name not in self:
                continue
            v = getattr(self, f.name)
            unit, scale = f.metadata.get("unit", ""), f.metadata.get("scale", 1.0)
            if scale is None or isinstance(v, str):
                out.append(f"{f.name} = {v}")
            elif isinstance(v, (list, tuple)):
                out.append(f"{f.name} = [{', '.join(format_number(x * scale) for x in v)}] {unit}".rstrip())
            else:
                out.append(f"{f.name} = {format_number(v * scale)} {unit}".rstrip())
        return "; ".join(out)


@dataclass(frozen=True)
class Fit:
    """A fit that also re-estimates the system gain K (DN/e-), or the read noise, with the effect's
    parameters.

    Parameters
    ----------
    params : EffectParams
        The fitted parameters.
    K : float, optional
        The system gain re-estimated with them (DN/e-); None: unchanged.
    read_dn : float, optional
        The read noise re-estimated with them (DN, before the ADC); None: the model's bookkeeping
        (measured dark variance less the modelled terms, :meth:`LoopModel.refit_read`).

    Attributes
    ----------
    params, K, read_dn
        As the parameters.

    Examples
    --------
    >>> from simcam.calibration.effects.channel_gain import ChannelGain
    >>> fit = Fit(ChannelGain(gains=[1.1, 1.0, 1.0, 0.9]), K=2.05)
    >>> fit.K, fit.params.gains[0]
    (2.05, 1.1)
    """

    params: EffectParams
    K: float | None = None
    read_dn: float | None = None


@dataclass(frozen=True)
class FitContext:
    """What a card's fit may use besides the capture and the current model.

    ``diagnostic``: the diagnostic that proposed the effect; ``value`` / ``sim_mean``: its value on
    the data and its mean over the bootstrap replicates of the current model; ``seed``: the seed of
    an indirect fit's simulations; ``dark_specs``: the dark sequences as
    :class:`~simcam.calibration.model.SimSpec`; ``simulate``: the loop's bootstrap,
    :func:`simcam.calibration.simulate.simulate_capture` (passed in: the cards sit below the
    simulator, which converts models through them); ``shot_factors``: the factor the current model's
    effects put on the shot-noise term at given flat levels,
    :func:`simcam.calibration.model.shot_factors` (passed in for the same reason; None: 1).

    Parameters
    ----------
    diagnostic, value, sim_mean, seed, dark_specs, simulate, shot_factors
        As described above; all have defaults ("no such information").

    Attributes
    ----------
    fields
        As the parameters.

    Examples
    --------
    >>> ctx = FitContext(diagnostic="frame_mean_jitter", value=3e-4, sim_mean=1e-4)
    >>> round(ctx.value - ctx.sim_mean, 6), ctx.simulate is None
    (0.0002, True)
    """

    diagnostic: str = ""
    value: float = math.nan
    sim_mean: float = math.nan
    seed: int = 0
    dark_specs: Sequence = ()
    simulate: Callable | None = None
    shot_factors: Callable | None = None
    #: the form to fit, for a card with several forms from one diagnostic (:meth:`EffectCard.variants`)
    form: str = ""

    def shot_factor(self, model, y: np.ndarray) -> np.ndarray:
        """``shot_factors(model, y)``, or ones (shape of ``y`` as 2-D) when none was passed in."""
        y = np.atleast_2d(np.asarray(y, dtype=np.float64))
        return np.ones_like(y) if self.shot_factors is None else self.shot_factors(model, y)


@dataclass(frozen=True)
class ProfileTerm:
    """What one effect contributes to the noise stage's composite entry: ``effect``, its entry in
    the composite's effect list (None: none); ``beta1`` / ``beta2``, values that replace the
    Poisson-Gaussian base's (normalised raw; None: unchanged).

    Parameters
    ----------
    effect : dict or None
        The effect's entry in the composite's effect list.
    beta1 : list or None
        Per-site beta1 that replaces the base's (normalised raw).
    beta2 : float or None
        beta2 that replaces the base's (normalised raw).

    Attributes
    ----------
    effect, beta1, beta2
        As the parameters.

    Examples
    --------
    >>> term = ProfileTerm(effect={"type": "dsnu", "sigma": 0.002})
    >>> term.effect["type"], term.beta1, term.beta2
    ('dsnu', None, None)
    """

    effect: dict | None = None
    beta1: list | None = None
    beta2: float | None = None


class EffectCard:
    """One effect of the calibration loop's vocabulary (module docstring). Subclasses set the class
    attributes and override the methods their effect needs; the defaults are "no contribution".

    Attributes
    ----------
    name : str
        The effect's name (and the noise stage's effect ``type``).
    params : type
        Its :class:`EffectParams` subclass.
    diagnostics : tuple of str
        The residual diagnostics that propose it.
    fixed_pattern, gaussian, needs_darks, refit_on_change : bool
        How the loop treats it (see the class attributes' comments).
    refit_after : tuple of str
        Effects whose addition makes the loop refit it.
    excludes : tuple of str
        Effects it cannot sit beside (either way round).
    marginal_rank : int or None
        Position of its term in the closed-form marginal variance.
    null_field, null_value : str or None, float
        The parameter, and its value, that make the effect the identity.
    family : str or None
        For an empirical component, the residual family it stands for (None: a named effect).

    Examples
    --------
    >>> from simcam.calibration.effects import card_for
    >>> card = card_for("row_noise")
    >>> card.diagnostics, card.marginal_rank, card.format({"sigma_dn": 1.5})
    (('row_mean_excess',), 10, 'sigma_dn = 1.5 DN')
    """

    #: the effect's name (and the noise stage's effect ``type``)
    name: ClassVar[str]
    #: its typed parameters
    params: ClassVar[type[EffectParams]]
    #: residual diagnostics that propose it
    diagnostics: ClassVar[tuple[str, ...]] = ()
    #: a pattern drawn once per sensor: not drawn again (nor in the marginal variance) where a scene's
    #: clean reference is its temporal mean, which already holds it
    fixed_pattern: ClassVar[bool] = False
    #: the pixel marginal stays Gaussian with it (else the model has no closed-form density)
    gaussian: ClassVar[bool] = True
    #: position of :meth:`marginal` in the closed-form marginal variance
    #: (:func:`simcam.calibration.model.marginal_variance` applies the model's effects in ascending
    #: rank to the base variance K g x + read^2; None: no term). Terms added before the response's
    #: slope (rank 50) act on the noisy value before the response, those after it are offsets added
    #: after it. The ranks also fix the order of the floating-point sums.
    marginal_rank: ClassVar[int | None] = None
    #: its fit simulates dark sequences (indirect inference): not fitted without darks
    needs_darks: ClassVar[bool] = False
    #: its fit depends on the rest of the model: refitted whenever another effect is added
    refit_on_change: ClassVar[bool] = False
    #: effects whose addition changes its estimate: it is refitted when one of them is added
    refit_after: ClassVar[tuple[str, ...]] = ()
    #: effects it cannot sit beside (it replaces them: ``adc_dnl`` is the model's ADC instead of
    #: ``quantization``); it is not proposed while one of them is in the model, nor they while it is
    excludes: ClassVar[tuple[str, ...]] = ()
    #: the parameter whose zero makes the effect the identity (:meth:`is_null`; None: no such parameter)
    null_field: ClassVar[str | None] = None
    #: the value of ``null_field`` that makes the effect the identity
    null_value: ClassVar[float] = 0.0
    #: an empirical component (not in the physical vocabulary): the residual family it was fitted for
    #: ("column, temporal, additive ..."); None for a named effect
    family: ClassVar[str | None] = None

    def __init_subclass__(cls, **attrs):
        """A card declares its class attributes as keywords of its class statement
        (``class RowNoiseCard(OffsetSigmaCard, name="row_noise", params=RowNoise, ...)``)."""
        super().__init_subclass__()
        for key, value in attrs.items():
            if key not in EffectCard.__annotations__:
                raise TypeError(f"effect card {cls.__name__}: unknown attribute {key!r}")
            setattr(cls, key, value)

    def fit(self, d, model, ctx: FitContext) -> EffectParams | Fit:
        """Parameters fitted on the capture ``d`` (``CaptureData``) given the current ``model``."""
        raise NotImplementedError(f"{self.name}: no fit")

    def prerequisite(self, d, model) -> str | None:
        """An effect this one can only be fitted beside, where the model lacks it: the loop fits it first
        and the candidate adds both (None: none)."""
        return None

    def variants(self, proposed_by: list) -> list:
        """The proposing diagnostics (``Discrepancy`` objects, strongest first) to fit a candidate from,
        one candidate each: an effect with several forms, each seen first by its own diagnostic, is
        fitted in every form the proposals point to; an item ``(diagnostic, form)`` asks for a named form
        fitted from that diagnostic (``FitContext.form``). Default: one candidate, from the strongest."""
        return [proposed_by[0]]

    def marginal(self, p: EffectParams, v: np.ndarray, lin: np.ndarray, model) -> np.ndarray:
        """The marginal variance (DN^2) ``v`` with this effect's term; ``lin``: the expected linear
        signal above black (DN, before the response)."""
        return v

    def dark_variance_dn2(self, p: EffectParams) -> float:
        """Temporal variance (DN^2) it adds to a dark pixel besides the read noise: what the read
        noise is not (``LoopModel.refit_read``)."""
        return 0.0

    def linear_signal(self, p: EffectParams, y: np.ndarray, model) -> np.ndarray:
        """The expected signal before this effect (DN above black) whose image through it is ``y``."""
        return y

    def to_profile(self, p: EffectParams, model) -> ProfileTerm:
        """Its part of the noise stage's composite entry (normalised raw)."""
        raise NotImplementedError(f"{self.name}: no profile entry")

    def from_profile(self, entry: Mapping, full_scale_dn: float) -> EffectParams:
        """Parameters from the composite's effect entry of this ``type`` (``full_scale_dn``: white - black)."""
        raise NotImplementedError(f"{self.name}: no conversion from a profile entry")

    def profile_read_dn(self, entry: Mapping, full_scale_dn: float, read_dn: float) -> float:
        """The loop's read-noise sigma (DN) given this effect's entry and the one the base's beta2 gives."""
        return read_dn

    def from_base(self, beta1_sites: np.ndarray) -> EffectParams | None:
        """Parameters carried by the base's per-site ``beta1`` (4 values), or None."""
        return None

    def is_null(self, p: EffectParams) -> bool:
        """True when the fitted effect is the identity (nothing to add): its ``null_field`` is
        ``null_value`` (within 1e-9; a per-site list: at every site)."""
        if self.null_field is None:
            return False
        v = getattr(p, self.null_field)
        return max(abs(float(x) - self.null_value) for x in (v if isinstance(v, list) else [v])) < 1e-9

    def family_of(self, p: EffectParams) -> str | None:
        """The residual family of the fitted component ``p`` (a card with several forms tells them apart;
        default :attr:`family`)."""
        return self.family

    def null_reason(self, p: EffectParams) -> str | None:
        """Why a fit came out null, where the card can say more than "zero magnitude" (None: it cannot)."""
        return None

    def format(self, p: EffectParams | Mapping) -> str:
        """Parameters as the report shows them, with units (a mapping is read as this card's parameters)."""
        if not isinstance(p, EffectParams):
            p = self.params.from_dict(p)
        return p.format()

    def __repr__(self) -> str:
        return f"<effect card {self.name}>"


def _profile_fields(params: type[EffectParams]) -> list:
    """The fields of ``params`` declared with a ``profile`` key, in field order."""
    return [f for f in fields(params) if f.metadata.get("profile") is not None]


class DeclaredProfileCard(EffectCard):
    """A card whose noise-stage entry is declared by its parameter fields: each field with a ``profile``
    key (:func:`quantity`) is one key of ``{type: <name>, ...}``, on normalised raw where
    ``per_full_scale``; the conversion both ways is built from that declaration."""

    def to_profile(self, p: EffectParams, model) -> ProfileTerm:
        """Its part of the noise stage's composite entry (normalised raw):
        ``{type: <name>, <key>: value}`` for each field declared with a ``profile`` key (:func:`quantity`)."""
        entry: dict = {"type": self.name}
        for f in _profile_fields(self.params):
            v = getattr(p, f.name)
            fs = model.full_scale_dn if f.metadata["per_full_scale"] else 1.0
            entry[f.metadata["profile"]] = [float(x) / fs for x in v] if isinstance(v, list) else float(v / fs)
        return ProfileTerm(effect=entry)

    def from_profile(self, entry: Mapping, full_scale_dn: float) -> EffectParams:
        """Parameters from the composite's effect entry of this ``type`` (``full_scale_dn``: white - black):
        the inverse of :meth:`to_profile`'s, field by field."""
        values = {}
        for f in _profile_fields(self.params):
            key, default = f.metadata["profile"], f.metadata.get("profile_default", MISSING)
            raw = entry[key] if default is MISSING else entry.get(key, default)
            if f.type in (list, "list"):  # one value per 2x2 site
                a = np.asarray(raw, float)
                values[f.name] = list(np.broadcast_to(a * full_scale_dn if f.metadata["per_full_scale"] else a, (4,)))
            else:
                values[f.name] = float(raw) * full_scale_dn if f.metadata["per_full_scale"] else float(raw)
        return self.params(**values)


class OffsetSigmaCard(DeclaredProfileCard, null_field="sigma_dn"):
    """An effect that is a zero-mean Gaussian offset of rms ``sigma_dn`` (DN) drawn per row and frame, per
    column or per pixel: it adds ``sigma_dn^2`` to the marginal variance, and its noise-stage entry is
    ``{type: <name>, sigma: sigma_dn / (white - black)}`` (normalised raw; the field declared with
    ``profile="sigma", per_full_scale=True``)."""

    def marginal(self, p, v, lin, model):
        return v + p.sigma_dn ** 2


class GainSigmaCard(DeclaredProfileCard, null_field="sigma"):
    """An effect that is a zero-mean Gaussian relative gain of rms ``sigma`` (dimensionless) on the expected
    signal, drawn per pixel or per frame: it adds ``(sigma x)^2`` to the marginal variance (x the linear
    signal above black, DN), and its noise-stage entry is ``{type: <name>, sigma}`` (the field declared
    with ``profile="sigma"``)."""

    def marginal(self, p, v, lin, model):
        return v + (p.sigma * lin) ** 2
