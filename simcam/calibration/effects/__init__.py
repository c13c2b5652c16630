"""The calibration loop's effect vocabulary: one card per effect (:mod:`.card`), listed here.

Each module of this package holds one effect: its typed parameters, its card (fit, diagnostics that
propose it, marginal variance and read-noise bookkeeping, profile conversion, report formatting)
and its physics with the sources. :data:`CARDS` below is the registry, the only list of the effects;
the loop, the model, the profile conversion and the report all go through it.

To add an effect: write its module (parameters, card, docstring), add its card to :data:`CARDS`
at its place in the signal chain, and give it an example in
``tests/calibration/test_effect_cards.py``.
"""

from __future__ import annotations

from .. import diagnostics as _dg
from . import (black_level_offset, channel_gain, column_fpn, dark_current, dead_pixels, dsnu, frame_flicker,
               heavy_tail_read, hot_pixels,
               nonlinearity, periodic_pattern, prnu, quantization, row_noise, spatial_correlation)
from . import (adc_dnl, amp_glow, charge_crosstalk, empirical_lines, empirical_offset, empirical_response,
               empirical_spectrum, rtn)
from .card import EffectCard, EffectParams, Fit, FitContext, ProfileTerm

__all__ = ["CARDS", "DIAGNOSTIC_EFFECT", "EffectCard", "EffectParams", "Fit", "FitContext", "ProfileTerm",
           "card_for", "effect_for", "excluded_by", "params_from_dict"]

#: name -> card, in signal-chain order (the order of the noise stage's composite entry): effects on
#: the signal (before photon counting / the gain), then readout effects, the response, fixed offsets,
#: and the ADC last (its unequal codes, then the quantiser of its grid).
CARDS: dict[str, EffectCard] = {c.name: c for c in (
    prnu.PrnuCard(),
    channel_gain.ChannelGainCard(),
    frame_flicker.FrameFlickerCard(),
    charge_crosstalk.ChargeCrosstalkCard(),
    heavy_tail_read.HeavyTailReadCard(),
    spatial_correlation.SpatialCorrelationCard(),
    rtn.RtnCard(),
    row_noise.RowNoiseCard(),
    empirical_spectrum.EmpiricalSpectrumCard(),
    empirical_offset.EmpiricalOffsetCard(),
    periodic_pattern.PeriodicPatternCard(),
    dark_current.DarkCurrentCard(),
    amp_glow.AmpGlowCard(),
    nonlinearity.NonlinearityCard(),
    empirical_response.EmpiricalResponseCard(),
    column_fpn.ColumnFpnCard(),
    empirical_lines.EmpiricalLinesCard(),
    dsnu.DsnuCard(),
    hot_pixels.HotPixelsCard(),
    dead_pixels.DeadPixelsCard(),
    black_level_offset.BlackLevelOffsetCard(),
    adc_dnl.AdcDnlCard(),  # before the quantiser: its codes are on the quantiser's grid (adc_dnl.py)
    quantization.QuantizationCard(),
)}


def _diagnostic_effect() -> dict[str, str | None]:
    out: dict[str, str | None] = {name: None for name in _dg.DIAGNOSTICS}
    for c in CARDS.values():
        for name in c.diagnostics:
            if name not in out:
                raise ValueError(f"effect card {c.name}: diagnostic {name!r} is not in the residual battery")
            if out[name] is not None:
                raise ValueError(f"diagnostic {name!r} proposes both {out[name]} and {c.name}")
            out[name] = c.name
    return out


#: diagnostic -> the effect it proposes (from the cards' ``diagnostics``); None: no effect of the vocabulary
DIAGNOSTIC_EFFECT: dict[str, str | None] = _diagnostic_effect()


def excluded_by(name: str, effects) -> str | None:
    """The effect of ``effects`` that effect ``name`` cannot sit beside (either card's ``excludes``), or None.

    Parameters
    ----------
    name : str
        An effect of the loop's vocabulary.
    effects : iterable of str
        The effects already in a model.

    Returns
    -------
    str or None
        The first of ``effects`` that excludes ``name`` or that ``name`` excludes.

    Examples
    --------
    >>> excluded_by("adc_dnl", ["dsnu", "quantization"]), excluded_by("dsnu", ["quantization"])
    (None, None)
    """
    for other in effects:
        if other in CARDS[name].excludes or name in CARDS[other].excludes:
            return other
    return None


def card_for(name: str) -> EffectCard:
    """The card of effect ``name``; KeyError naming the vocabulary when there is none.

    Parameters
    ----------
    name : str
        An effect of the loop's vocabulary (a key of :data:`CARDS`).

    Returns
    -------
    EffectCard
        Its card (the registry's one instance).

    Examples
    --------
    >>> card_for("dsnu").fixed_pattern
    True
    """
    try:
        return CARDS[name]
    except KeyError:
        raise KeyError(f"unknown effect {name!r}; the loop's effects are {', '.join(CARDS)}") from None


def effect_for(diagnostic: str) -> str | None:
    """The effect a significant ``diagnostic`` proposes (None: no effect of the vocabulary explains it).

    Parameters
    ----------
    diagnostic : str
        A diagnostic of the loop's residual battery (:mod:`simcam.calibration.diagnostics`).

    Returns
    -------
    str or None
        The name of the effect whose card lists the diagnostic.

    Examples
    --------
    >>> effect_for("col_fpn_excess"), effect_for("dark_checker_jitter")
    ('column_fpn', None)
    """
    return DIAGNOSTIC_EFFECT[diagnostic]


def params_from_dict(name: str, values) -> EffectParams:
    """Typed parameters of effect ``name`` from a mapping of its fields (loop_model.yaml, report.json).

    Parameters
    ----------
    name : str
        An effect of the loop's vocabulary.
    values : mapping
        Field name -> value (as :meth:`EffectParams.to_dict` gives them).

    Returns
    -------
    EffectParams
        The effect's parameters; ValueError on an unknown or a missing field.

    Examples
    --------
    >>> params_from_dict("quantization", {"step_dn": 4.0})
    Quantization(step_dn=4.0)
    """
    return card_for(name).params.from_dict(values)
