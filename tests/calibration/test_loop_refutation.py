"""A candidate that breaks a diagnostic the current model passes on the held-out frames is refuted
(``Loop._broken``): the decision rule on hand-made discrepancies (p-values from their definition)."""

from types import SimpleNamespace

from simcam.calibration.diagnostics import Discrepancy
from simcam.calibration.loop import Loop, LoopConfig


def disc(name, z, p):
    return Discrepancy(name, 0.0, 0.0, 1.0, z, p)


def broken(held, cur, names):
    return Loop._broken(SimpleNamespace(cfg=LoopConfig(alpha=0.01), applicable=names), held, cur)


def test_a_newly_failed_diagnostic_refutes_the_candidate():
    names = ["dark_signal_slope", "dark_variance_slope", "dsnu_excess", "lag1_corr"]
    cur = {"dark_signal_slope": disc("dark_signal_slope", 127.0, 1e-18),
           "dark_variance_slope": disc("dark_variance_slope", -0.2, 0.85),
           "dsnu_excess": disc("dsnu_excess", 1.0, 0.3), "lag1_corr": disc("lag1_corr", 0.5, 0.6)}
    cand = {"dark_signal_slope": disc("dark_signal_slope", 1.7, 0.12),
            "dark_variance_slope": disc("dark_variance_slope", -18.7, 1e-9),
            "dsnu_excess": disc("dsnu_excess", 1.2, 0.25), "lag1_corr": disc("lag1_corr", -0.4, 0.7)}
    out = broken(cand, cur, names)
    assert [b["diagnostic"] for b in out] == ["dark_variance_slope"]
    assert out[0]["z_before"] == -0.2 and out[0]["z"] == -18.7


def test_no_refutation_below_the_family_wise_level_or_for_a_diagnostic_already_failed():
    names = ["a", "b", "c", "d"]
    cur = {"a": disc("a", 5.0, 1e-4), "b": disc("b", 0.5, 0.6), "c": disc("c", 0.1, 0.9), "d": disc("d", 0.0, 1.0)}
    # a: failed before (not a new failure); b: p 0.004 > 0.01 / 4; c: closer to the data than before
    cand = {"a": disc("a", 9.0, 1e-8), "b": disc("b", 3.4, 0.004), "c": disc("c", 0.05, 0.95), "d": None}
    assert broken(cand, cur, names) == []
    # near the edge under the current model (p 0.013 < 0.1): crossing the family-wise level is no refutation
    cur["b"] = disc("b", 2.9, 0.013)
    cand["b"] = disc("b", 5.3, 2.7e-4)
    assert broken(cand, cur, names) == []
