"""How ``simcam loop`` does on capture sets of a simulator it was not tuned on.

The generator is ``tests/indepsim`` (an EMVA 1288-style sensor simulator written for the loop's
issues by a different hand from the loop and from ``tests/calibration/loop_generator.py``): 192 x 128
sensors, ISOs 100/800/3200, darks at two exposure times, two flat levels and a scene, DNG, npy or
EMVA 1288 descriptor sets. Each case draws its effect magnitudes from the effect's documented range
(log-uniform where stated) at the case's seed, so different seeds give different magnitudes. About 30 %
of the cases are *held out* by a rule on their name alone (``tests.indepsim.cases.held_out``): they
are not looked at while the loop is developed, and this script reports them separately.

For every case the loop runs with its defaults; the script compares the effects it added (union over
the ISOs) with the generator's truth:

* effects of the loop's vocabulary (its effect cards, ``VOCABULARY`` below) must be named; nothing else may be named
  (a *wrong* addition: a named effect that is not in the truth);
* an effect outside the vocabulary (``charge_crosstalk``, ``undeclared_*``, ...) must not be forced
  into a named one: it may be ``unexplained``, an ``empirical_*`` component, or nothing;
* the held-out structured KL must not grow at any ISO, and must drop >= 80 % at an ISO where an
  effect was added (the loop's held-out error: ``simcam.calibration.heldout``);
* a crash (any exception) is a failure of its own.

Run: ``python benchmarks/loop_independent.py [--cases PATTERN] [--held-out include|exclude|only]
[--seed S] [--json out.json]``.  Prints the CPU model, a row per case and a summary per group
(developed / held out).
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import sys
import tempfile
import time
import traceback
from pathlib import Path

if __package__ in (None, ""):  # run as a script: the repository root makes ``tests.indepsim`` importable
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))  # benchmarks/machine.py, also when loaded by path
from machine import cpu_model  # noqa: E402

from simcam.calibration.effects import CARDS  # noqa: E402

#: the loop's named effects (its effect cards: what it may add); anything else in a truth manifest is
#: outside the vocabulary
VOCABULARY = tuple(CARDS)
#: the generator's names for what one card of the loop covers: ``dead_pixels`` is dead *and* stuck
#: pixels (defects that do not respond to light, ``simcam/calibration/effects/dead_pixels.py``)
ALIASES = {"stuck_pixels": "dead_pixels"}




def judge(truth_effects: set[str], report: dict) -> dict:
    """Compare one loop report with the generator's truth (see the module docstring)."""
    named = set()
    unexplained, kl_rows, added, taken_out = set(), [], {}, []
    for g in report["isos"]:
        added[g["iso_label"]] = list(g["effects"])
        taken_out += [f"{g['iso_label']} {b['effect']}" for b in g.get("backward", []) if b["removed"]]
        named |= {e for e in g["effects"] if not e.startswith("empirical_")}
        unexplained |= {u["diagnostic"] for u in g["unexplained"]}
        h = g["heldout"]
        kl_rows.append((g["iso_label"], h.get("kl_structured_base"), h.get("kl_structured_final"), bool(g["effects"])))
    truth_effects = {ALIASES.get(e, e) for e in truth_effects}
    in_vocab = truth_effects & set(VOCABULARY)
    missed = sorted(in_vocab - named)
    wrong = sorted(named - truth_effects)
    grew, low_drop = [], []
    for label, b, f, added in kl_rows:
        if b is None or f is None:
            continue
        if f > b * 1.10 + 1e-3:
            grew.append(f"{label} {b:.3g}->{f:.3g}")
        if added and b > 0.05 and f > 0.2 * b:
            low_drop.append(f"{label} {b:.3g}->{f:.3g}")
    return {"named": sorted(named), "added": added, "missed": missed, "wrong": wrong, "unexplained": sorted(unexplained),
            "kl": kl_rows, "kl_grew": grew, "kl_drop_below_80": low_drop, "taken_out": taken_out,
            "ok": not missed and not wrong and not grew}


def run_case(case: dict, seed: int | None, workdir: Path) -> dict:
    from simcam.calibration.loop import LoopConfig
    from simcam.calibration.report import run_and_write
    from tests.indepsim.capture import write_capture_set
    from tests.indepsim.cases import case_spec

    spec = case_spec(case, seed)
    cap = workdir / case["name"]
    truth = write_capture_set(cap, spec, seed=case["seed"] if seed is None else seed)
    root = cap / "EMVA1288_Data.txt" if spec.get("fmt") == "emva" else cap
    t0 = time.perf_counter()
    try:
        report = run_and_write(root, workdir / (case["name"] + "_out"), cfg=LoopConfig(progress=False))
    except Exception as exc:  # a crash is a result of its own here
        return {"case": case["name"], "held_out": case["held_out"], "truth": sorted(truth["effects"]),
                "crash": f"{type(exc).__name__}: {exc}".splitlines()[0][:300],
                "trace": traceback.format_exc(limit=4), "ok": False, "seconds": time.perf_counter() - t0}
    res = judge(set(truth["effects"]), report)
    res.update(case=case["name"], held_out=case["held_out"], truth=sorted(truth["effects"]), crash=None,
               seconds=time.perf_counter() - t0,
               magnitudes={k: v.get("params") for k, v in truth["effects"].items()})
    return res


def main(argv=None) -> int:
    from tests.indepsim.cases import CASES

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default="*", help="fnmatch pattern(s), comma-separated (default: all)")
    ap.add_argument("--held-out", choices=("include", "exclude", "only"), default="include")
    ap.add_argument("--seed", type=int, default=None, help="magnitude/noise seed (default: each case's own)")
    ap.add_argument("--json", type=Path, default=None, help="write every result to this JSON file")
    args = ap.parse_args(argv)
    pats = args.cases.split(",")
    cases = [c for c in CASES if any(fnmatch.fnmatch(c["name"], p) for p in pats)]
    if args.held_out == "exclude":
        cases = [c for c in cases if not c["held_out"]]
    elif args.held_out == "only":
        cases = [c for c in cases if c["held_out"]]
    print(f"CPU: {cpu_model()}; {len(cases)} cases; seed {args.seed if args.seed is not None else 'per case'}")
    print(f"{'case':52s} {'held':4s} {'truth':34s} {'named':34s} {'wrong':20s} {'missed':16s} ok   s")
    results = []
    with tempfile.TemporaryDirectory(prefix="simcam-loop-indep-") as tmp:
        for c in cases:
            r = run_case(c, args.seed, Path(tmp))
            results.append(r)
            if r["crash"]:
                print(f"{c['name']:52s} {'yes' if c['held_out'] else 'no':4s} {','.join(r['truth']) or '-':34s} "
                      f"CRASH {r['crash']}")
            else:
                print(f"{c['name']:52s} {'yes' if c['held_out'] else 'no':4s} {','.join(r['truth']) or '-':34s} "
                      f"{','.join(r['named']) or '-':34s} {','.join(r['wrong']) or '-':20s} "
                      f"{','.join(r['missed']) or '-':16s} {'yes' if r['ok'] else 'NO':4s} {r['seconds']:.0f}"
                      + (f"  KL grew: {'; '.join(r['kl_grew'])}" if r["kl_grew"] else "")
                      + (f"  taken out: {'; '.join(r['taken_out'])}" if r["taken_out"] else ""))
            sys.stdout.flush()
    for label, sel in (("developed", [r for r in results if not r["held_out"]]),
                       ("held out", [r for r in results if r["held_out"]])):
        if not sel:
            continue
        n = len(sel)
        print(f"{label}: {sum(r['ok'] for r in sel)}/{n} ok; crashes {sum(bool(r['crash']) for r in sel)}; "
              f"wrong additions {sum(len(r.get('wrong', [])) for r in sel)}; missed vocabulary effects "
              f"{sum(len(r.get('missed', [])) for r in sel)}; structured KL grew in "
              f"{sum(bool(r.get('kl_grew')) for r in sel)} cases; drop < 80 % where added in "
              f"{sum(bool(r.get('kl_drop_below_80')) for r in sel)} cases; effects taken out by the backward step "
              f"{sum(len(r.get('taken_out', [])) for r in sel)}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
