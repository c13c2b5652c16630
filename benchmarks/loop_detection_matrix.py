"""Which hidden effects does ``simcam loop`` name? Every effect alone, several pairs, base only.

Capture set per case: 64x64 RGGB 10-bit sensor (K = 2 DN/e-, read 3 DN, black 64 DN), one dark
and four flat sequences of 12 frames (6 fit / 6 held out), made by the test-owned generator
``tests/loop_generator.py`` (independent of simcam's noise code).
Run: ``python benchmarks/loop_detection_matrix.py``.
"""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from loop_matrix import CASES, run_case  # noqa: E402


def main():
    print(f"{'hidden effects':42s} {'named by the loop':42s} {'unexpl.':10s} {'KL base':>9s} {'KL final':>9s} {'drop':>6s} ok   s")
    n_ok = 0
    for case in CASES:
        t = time.perf_counter()
        r = run_case(case)
        dt = time.perf_counter() - t
        named = tuple(r.model.effects)
        un = ",".join(u["diagnostic"] for u in r.unexplained) or "-"
        ok = set(case) == set(named) and not r.unexplained
        n_ok += ok
        kb, kf = r.heldout_base["kl"], r.heldout_final["kl"]
        drop = f"{100 * (1 - kf / kb):.0f}%" if kb > 0 and named else "-"
        print(f"{'+'.join(case) or '(base only)':42s} {'+'.join(named) or '-':42s} {un:10s} {kb:9.2e} {kf:9.2e} "
              f"{drop:>6s} {'yes' if ok else 'NO ':4s} {dt:.1f}")
    print(f"{n_ok}/{len(CASES)} cases named exactly")


if __name__ == "__main__":
    main()
