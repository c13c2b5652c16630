"""False-alarm rate of ``simcam loop`` on base-only capture sets (no hidden effect).

Same capture geometry as ``loop_detection_matrix.py``; N independent sensors and capture noises.
With Holm at family-wise alpha = 0.01 the expected rate of any addition is <= 1 % per set (if the
bootstrap null is right). Run: ``python benchmarks/loop_false_positives.py [N]``.
"""

import sys
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests" / "calibration"))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from loop_matrix import run_case  # noqa: E402


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    t0 = time.perf_counter()
    added, unexpl, sets_with_any = Counter(), Counter(), 0
    for i in range(n):
        r = run_case((), seed=1000 + i, sensor_seed=2000 + i)
        added.update(r.model.effects)
        unexpl.update(u["diagnostic"] for u in r.unexplained)
        sets_with_any += bool(r.model.effects or r.unexplained)
    print(f"{n} base-only sets: {sets_with_any} with any addition or unexplained residual "
          f"({100 * sets_with_any / n:.0f} %); added {dict(added) or '-'}; unexplained {dict(unexpl) or '-'} "
          f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
