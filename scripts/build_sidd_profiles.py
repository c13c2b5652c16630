"""Build ``profiles/sidd-{ip,gp,s6,n6,g4}.yaml`` from the measured SIDD NLF table.

Input: ``cam_iso_nlf_all.txt`` (CSV ``cam_iso,beta1,beta2``, rows like
``GP_00800,0.001764,0.000012``), the per-camera, per-ISO noise level functions
of the five SIDD phones on normalised raw, as published with Noise Flow
(Abdelhamed, Brubaker & Brown, ICCV 2019; SIDD: Abdelhamed, Lin & Brown,
CVPR 2018). The numbers are measured facts; no other part of that release is
used. One NLF (shared by every CFA site) per camera and ISO.

Usage::

    python scripts/build_sidd_profiles.py [../shared/data/noiseflow/cam_iso_nlf_all.txt] [-o profiles]
"""

from __future__ import annotations

import argparse
import csv
import sys
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from simcam.profiles.schema import CalibrationProfile  # noqa: E402

CAMERAS = {
    "IP": ("Apple", "iPhone 7"),
    "GP": ("Google", "Pixel"),
    "S6": ("Samsung", "Galaxy S6 Edge"),
    "N6": ("Motorola", "Nexus 6"),
    "G4": ("LGE", "LG G4"),
}


def read_table(path: Path) -> dict[str, list[tuple[float, float, float]]]:
    rows: dict[str, list[tuple[float, float, float]]] = defaultdict(list)
    with open(path, newline="") as f:
        for rec in csv.DictReader(f):
            cam, iso = rec["cam_iso"].split("_")
            rows[cam].append((float(iso), float(rec["beta1"]), float(rec["beta2"])))
    return rows


def build(table: Path, out_dir: Path) -> list[Path]:
    rows = read_table(table)
    written = []
    for cam, (make, model) in CAMERAS.items():
        entries = [{"iso": iso, "model": {"type": "nlf", "beta1": b1, "beta2": b2}} for iso, b1, b2 in sorted(rows[cam])]
        prof = CalibrationProfile.model_validate({
            "schema_version": 1,
            "provenance": {
                "source": f"{table.name} (SIDD per-camera/ISO noise level functions, normalised raw, as published with "
                          "Noise Flow: Abdelhamed, Brubaker & Brown, ICCV 2019, doi:10.1109/ICCV.2019.00326; "
                          "SIDD: Abdelhamed, Lin & Brown, CVPR 2018, doi:10.1109/CVPR.2018.00182)",
                "method": "measured NLF var = beta1 * I + beta2 per camera and ISO, one pair for all CFA sites; "
                          "numbers copied as published (measured facts)",
                "tool": "scripts/build_sidd_profiles.py",
                "licence": "numbers: facts, free to use",
                "notes": "CFA not recorded in the table (the NLF does not depend on the site): cfa null. "
                         "The same (beta1, beta2) serve a poisson_gaussian entry (beta1 = gain).",
            },
            "cameras": [{"id": cam, "make": make, "model": model, "cfa": None, "entries": entries}],
        })
        written.append(prof.save(out_dir / f"sidd-{cam.lower()}.yaml"))
    return written


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("table", nargs="?", default=str(REPO.parent / "shared" / "data" / "noiseflow" / "cam_iso_nlf_all.txt"))
    ap.add_argument("-o", "--out", default=str(REPO / "profiles"))
    a = ap.parse_args(argv)
    for p in build(Path(a.table), Path(a.out)):
        print(f"wrote {p}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
