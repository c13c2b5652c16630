"""simcam.torch on a CUDA device against the numpy noise models: every model and effect case of the
torch equivalence tests (``tests/torch/torch_cases.py``), drawn on the device in both layouts and
checked with the same law test (``assert_same_law``: moments and histograms within their sampling
error) as the CPU tests. CI has no GPU; run this where one is: ``python scripts/cuda_equivalence.py``.
Prints one line per case and exits non-zero if any fails.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests"), str(ROOT / "tests" / "torch")]


def main() -> int:
    import torch

    if not torch.cuda.is_available():
        print("no CUDA device (torch.cuda.is_available() is False)")
        return 2
    from test_torch_equivalence import _clean, _numpy_frames, _torch_frames, assert_same_law
    from torch_cases import EFFECT_CASES, MODEL_CASES, effect_entry

    from simcam.noise import model_from_entry

    print(f"CUDA: {torch.cuda.get_device_name(0)}; torch {torch.__version__}")
    cases = [(f"model {n}", MODEL_CASES[n]) for n in sorted(MODEL_CASES)]
    cases += [(f"effect {n}", effect_entry(n)) for n in sorted(EFFECT_CASES)]
    failed = 0
    clean = _clean()
    for label, entry in cases:
        model = model_from_entry(entry)
        ref = _numpy_frames(model, clean)
        for layout in ("packed", "mosaic"):
            t0 = time.perf_counter()
            try:
                assert_same_law(ref, _torch_frames(model, clean, layout, device="cuda"))
                verdict = "ok"
            except Exception as exc:  # report every case, then fail
                failed += 1
                verdict = f"FAIL {type(exc).__name__}: {str(exc).splitlines()[0][:160]}"
            print(f"{label:40s} {layout:7s} {verdict} ({time.perf_counter() - t0:.2f} s)", flush=True)
    print(f"{len(cases) * 2 - failed}/{len(cases) * 2} passed on CUDA")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
