"""ICC colour profiles for the output images: sRGB and linear sRGB (matrix/TRC display profiles).

Built by hand (no colour-management library) after ICC.1:2022 (profile version
4.4): a 128-byte header, a tag table, and the tags ``desc``, ``cprt``
(``multiLocalizedUnicodeType``), ``wtpt`` (PCS D50), ``chad`` (Bradford
D65 -> D50), ``rXYZ``/``gXYZ``/``bXYZ`` (the IEC 61966-2-1 primaries adapted to
D50) and ``rTRC``/``gTRC``/``bTRC`` (``parametricCurveType``: the sRGB
curve as function type 3, ``Y = ((X + 0.055) / 1.055)^2.4`` for ``X >= 0.04045``
else ``X / 12.92``; gamma 1 for linear sRGB). The bytes are a pure function of
the arguments (fixed creation date), so outputs are reproducible.
"""

from __future__ import annotations

import struct
from functools import lru_cache

import numpy as np

#: ICC profile connection space white (D50) as the ICC specification gives it.
PCS_D50 = (0.9642, 1.0, 0.8249)


def _s15(v: float) -> bytes:
    return struct.pack(">i", round(v * 65536.0))


def _xyz_tag(xyz) -> bytes:
    return b"XYZ \0\0\0\0" + b"".join(_s15(v) for v in xyz)


def _mluc(text: str) -> bytes:
    s = text.encode("utf-16-be")
    return b"mluc\0\0\0\0" + struct.pack(">II", 1, 12) + b"enUS" + struct.pack(">II", len(s), 28) + s


def _para(linear: bool) -> bytes:
    if linear:
        return b"para\0\0\0\0" + struct.pack(">HH", 0, 0) + _s15(1.0)
    params = (2.4, 1 / 1.055, 0.055 / 1.055, 1 / 12.92, 0.04045)
    return b"para\0\0\0\0" + struct.pack(">HH", 3, 0) + b"".join(_s15(v) for v in params)


def srgb_primaries_d50() -> np.ndarray:
    """3 x 3: columns are the XYZ (PCS D50) of the sRGB red, green and blue primaries at full scale."""
    from ..colour.display import SRGB_WHITE_XY, XYZ_TO_SRGB
    from ..colour.dng import bradford_matrix, xy_to_xyz

    rgb_to_xyz = np.linalg.inv(XYZ_TO_SRGB)
    return bradford_matrix(xy_to_xyz(SRGB_WHITE_XY), np.array(PCS_D50)) @ rgb_to_xyz


@lru_cache(maxsize=4)
def srgb_icc_profile(linear: bool = False) -> bytes:
    """An ICC v4 display profile for sRGB (IEC 61966-2-1) or, with ``linear``, linear sRGB (gamma 1)."""
    from ..colour.display import SRGB_WHITE_XY
    from ..colour.dng import bradford_matrix, xy_to_xyz

    prim = srgb_primaries_d50()
    chad = bradford_matrix(xy_to_xyz(SRGB_WHITE_XY), np.array(PCS_D50))
    name = "simcam linear sRGB (IEC 61966-2-1 primaries, gamma 1)" if linear else "simcam sRGB (IEC 61966-2-1)"
    trc = _para(linear)
    tags = [
        (b"desc", _mluc(name)),
        (b"cprt", _mluc("No copyright, use freely")),
        (b"wtpt", _xyz_tag(PCS_D50)),
        (b"chad", b"sf32\0\0\0\0" + b"".join(_s15(v) for v in chad.ravel())),
        (b"rXYZ", _xyz_tag(prim[:, 0])),
        (b"gXYZ", _xyz_tag(prim[:, 1])),
        (b"bXYZ", _xyz_tag(prim[:, 2])),
        (b"rTRC", trc),
        (b"gTRC", trc),
        (b"bTRC", trc),
    ]
    table_size = 4 + 12 * len(tags)
    offset = 128 + table_size
    table, data, placed = b"", b"", {}
    for sig, body in tags:
        if body in placed:  # identical curves share one copy
            off = placed[body]
        else:
            off = offset + len(data)
            placed[body] = off
            data += body + b"\0" * (-len(body) % 4)
        table += sig + struct.pack(">II", off, len(body))
    size = 128 + table_size + len(data)
    header = (struct.pack(">I", size) + b"\0\0\0\0" + struct.pack(">I", 0x04400000) + b"mntr" + b"RGB " + b"XYZ "
              + struct.pack(">6H", 2024, 1, 1, 0, 0, 0) + b"acsp" + b"\0" * 4 + b"\0" * 4 + b"\0" * 8
              + b"\0" * 8 + struct.pack(">I", 0) + b"".join(_s15(v) for v in PCS_D50) + b"\0" * 4)
    header += b"\0" * (128 - len(header))
    profile = bytearray(header + struct.pack(">I", len(tags)) + table + data)
    # profile ID: MD5 of the profile with flags, rendering intent and ID zeroed (ICC.1 7.2.18)
    import hashlib

    md5 = hashlib.md5(bytes(profile)).digest()
    profile[84:100] = md5
    return bytes(profile)
