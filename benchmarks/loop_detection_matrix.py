"""Which hidden effects does ``simcam loop`` name? Every effect alone, several pairs, base only.

Capture set per case: 64x64 RGGB 10-bit sensor (K = 2 DN/e-, read 3 DN, black 64 DN), one dark
and four flat sequences of 12 frames (6 fit / 6 held out), made by the test-owned generator
``tests/calibration/loop_generator.py`` (independent of simcam's noise code). The loop runs with its defaults
(12 held-out replicates per scored model, which are also the bootstrap null here: 6 fit / 6 held-out
frames per sequence; Holm at alpha = 0.01).

Run: ``python benchmarks/loop_detection_matrix.py [--seeds 7,8,9]`` (capture-noise seeds; the
first prints the full table with fitted parameters, the others only the summary). Columns: the
held-out one-pixel KL (Noise Flow binning) at the base fit and the final model, its sampling floor and
drop; the structured marginal KL (``simcam.calibration.heldout``: sum over aggregated-noise families of
their significant floor-corrected KLs) at base and final and its drop (``Sdrop``); ``Udrop`` the
drop of the ungated sum (every family's floor-corrected excess, significant or not).
"""

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "calibration"))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from loop_matrix import CASES, run_case, scaled  # noqa: E402


def _short(params: dict) -> str:
    out = []
    for k, v in params.items():
        if k in ("count", "log_sigma"):
            continue
        if isinstance(v, list):
            v = "[" + ",".join(f"{x:.3g}" for x in v) + "]"
        elif isinstance(v, float):
            v = f"{v:.3g}"
        out.append(f"{k}={v}")
    return " ".join(out)


def _ungated(held: dict) -> float:
    """Structured KL without the significance gate: every family's floor-corrected excess, summed."""
    return float(sum(f["excess"] for f in held["structured"].values()))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="7")
    ap.add_argument("--scale", type=float, default=1.0, help="effect magnitude relative to DEFAULT_EFFECTS")
    ap.add_argument("--singles", action="store_true", help="only the 13 single-effect cases")
    args = ap.parse_args()
    cases = [c for c in CASES if len(c) == 1] if args.singles else CASES
    seeds = [int(s) for s in args.seeds.split(",")]
    for j, seed in enumerate(seeds):
        n_ok, t0 = 0, time.perf_counter()
        if j == 0:
            print(f"seed {seed}")
            print(f"{'hidden effects':34s} {'named by the loop':34s} {'unexplained':12s} {'KL base':>9s} "
                  f"{'KL final':>9s} {'floor':>9s} {'drop':>5s} {'SKL base':>9s} {'SKL final':>9s} {'Sdrop':>5s} {'Udrop':>5s} "
                  "ok  fitted (hidden) parameters")
        misses, low, low_u = [], [], []
        for case in cases:
            r = run_case(case, seed=seed, scale=args.scale)
            named = tuple(r.model.effects)
            un = ",".join(u["diagnostic"] for u in r.unexplained) or "-"
            ok = set(case) == set(named) and not r.unexplained
            n_ok += ok
            if not ok:
                misses.append(f"{'+'.join(case) or 'base'} -> {'+'.join(named) or '-'} (unexplained {un})")
            if j == 0:
                kb, kf = r.heldout_base["kl"], r.heldout_final["kl"]
                drop = f"{100 * (1 - kf / kb):.0f}%" if kb > 0 and named else "-"
                sb, sf = r.heldout_base["kl_structured"], r.heldout_final["kl_structured"]
                sdrop = f"{100 * (1 - sf / sb):.0f}%" if sb > 0 else "-"
                ub, uf = _ungated(r.heldout_base), _ungated(r.heldout_final)
                udrop = f"{100 * (1 - uf / ub):.0f}%" if ub > 0 and case else "-"
                pars = "; ".join(f"{e}: {_short(r.model.effects[e])} ({_short(scaled(e, args.scale))})"
                                 for e in case if e in r.model.effects)
                print(f"{'+'.join(case) or '(base only)':34s} {'+'.join(named) or '-':34s} {un:12s} {kb:9.2e} "
                      f"{kf:9.2e} {r.heldout_final['kl_floor']:9.2e} {drop:>5s} {sb:9.2e} {sf:9.2e} {sdrop:>5s} {udrop:>5s} "
                      f"{'yes' if ok else 'NO ':3s} {pars}")
            if case:
                sb, sf = r.heldout_base["kl_structured"], r.heldout_final["kl_structured"]
                if not (sb > 0 and sf <= 0.2 * sb):
                    low.append(f"{'+'.join(case)} ({sb:.2e} -> {sf:.2e})")
                ub, uf = _ungated(r.heldout_base), _ungated(r.heldout_final)
                if not (ub > 0 and uf <= 0.2 * ub):
                    low_u.append(f"{'+'.join(case)} ({100 * (1 - uf / ub) if ub > 0 else 0:.0f}%)")
        print(f"seed {seed}, scale {args.scale}: {n_ok}/{len(cases)} cases named exactly ({time.perf_counter() - t0:.0f} s)"
              + ("" if not misses else "; misses: " + " | ".join(misses)))
        print(f"seed {seed}: structured KL drop >= 80 % in {len(cases) - (() in cases) - len(low)}/"
              f"{len(cases) - (() in cases)} effect cases" + ("" if not low else "; below: " + " | ".join(low)))
        print(f"seed {seed}: ungated (every family's floor-corrected excess summed) drop >= 80 % in "
              f"{len(cases) - (() in cases) - len(low_u)}/{len(cases) - (() in cases)}"
              + ("" if not low_u else "; below: " + " | ".join(low_u)))


if __name__ == "__main__":
    main()
