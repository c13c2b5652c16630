"""DNG opcode lists applied where the DNG SDK applies them (DNG 1.7 ch. 7), against closed forms.

Payloads are packed here by hand from the specification's layouts (big-endian), independently of
simcam's decoder.
"""

from __future__ import annotations

import struct
import warnings

import numpy as np
import pytest

from simcam.errors import SimcamWarning, StageError
from simcam.frame import CameraMeta, Opcode, RawFrame
from simcam.stages.opcodes import Opcodes


def area(t=0, l=0, b=0, r=0, plane=0, planes=1, rp=1, cp=1) -> bytes:
    return struct.pack(">4i4I", t, l, b, r, plane, planes, rp, cp)


def frame(data, kind, n, ops, cfa="RGGB"):
    meta = CameraMeta(cfa=cfa, black_level=np.zeros((1, 1)), white_level=65535.0)
    setattr(meta, f"opcode_list{n}", ops)
    return RawFrame(np.asarray(data, np.float32), meta, kind=kind)


def op(oid, payload, flags=0):
    return Opcode(id=oid, version=(1, 3, 0, 0), flags=flags, payload=payload)


def test_warp_rectilinear_moves_a_dot_radially():
    h = w = 101
    img = np.zeros((h, w, 3), np.float32)
    img[50, 90, :] = 1.0  # 40 px right of the centre (50, 50)
    k = 1.02  # source = c + k (d - c): a dot at distance 40 lands at 40 / k
    coef = [k, 0, 0, 0, 0, 0]
    payload = struct.pack(">I", 1) + struct.pack(">6d", *coef) + struct.pack(">2d", 50 / w, 50 / h)
    out = Opcodes(list=3, interpolation=1)(frame(img, "camera_rgb", 3, [op(1, payload)])).data
    row = out[50, :, 0]
    centroid = float((row * np.arange(w)).sum() / row.sum())
    assert centroid == pytest.approx(50 + 40 / k, abs=0.02)


def test_warp_rectilinear_tangential_term():
    """Only kt0: a point on the horizontal axis (u_v = 0) moves vertically by R kt0 r^2."""
    h = w = 201
    c = 100.0
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    img = np.stack([yy, xx, yy], -1)  # the image holds its own coordinates
    kt0 = 0.01
    payload = struct.pack(">I", 1) + struct.pack(">6d", 1, 0, 0, 0, kt0, 0) + struct.pack(">2d", c / w, c / h)
    out = Opcodes(list=3)(frame(img, "camera_rgb", 3, [op(1, payload)])).data
    radius = np.hypot(c + 1, c + 1)  # largest distance from (100, 100) to a corner of the bounds [0, 201)
    u = 60 / radius
    assert out[100, 160, 0] == pytest.approx(100 + radius * kt0 * u * u, abs=1e-3)  # row moved
    assert out[100, 160, 1] == pytest.approx(160, abs=1e-3)  # column kept


def test_fix_bad_pixels_list_and_constant():
    rng = np.random.default_rng(0)
    mosaic = rng.uniform(100, 200, (16, 16)).astype(np.float32)
    bad = (5, 6)  # a green site in RGGB (row odd, col even)
    want = np.mean([mosaic[3, 6], mosaic[7, 6], mosaic[5, 4], mosaic[5, 8],
                    mosaic[4, 5], mosaic[4, 7], mosaic[6, 5], mosaic[6, 7]])
    payload = struct.pack(">3I", 0, 1, 0) + struct.pack(">2I", *bad)
    out = Opcodes(list=1)(frame(mosaic, "raw_dn", 1, [op(5, payload)])).data
    assert out[bad] == pytest.approx(want, rel=1e-6)
    assert np.array_equal(np.delete(out.ravel(), 5 * 16 + 6), np.delete(mosaic.ravel(), 5 * 16 + 6))
    m2 = mosaic.copy()
    m2[4, 4] = 0  # a red site holding the "bad" constant 0
    out = Opcodes(list=1)(frame(m2, "raw_dn", 1, [op(4, struct.pack(">2I", 0, 0))])).data
    assert out[4, 4] == pytest.approx(np.mean([m2[2, 4], m2[6, 4], m2[4, 2], m2[4, 6]]), rel=1e-6)


def test_map_table_polynomial_delta_scale_on_list2():
    x = np.linspace(0, 1, 64, dtype=np.float32).reshape(8, 8)
    table = (np.arange(65536) // 2).astype(">u2")  # halves every code
    ops = [op(7, area() + struct.pack(">I", 65536) + table.tobytes())]
    out = Opcodes(list=2)(frame(x, "raw", 2, ops)).data
    assert out == pytest.approx(np.floor(np.rint(x * 65535) / 2) / 65535, abs=1e-7)
    poly = op(8, area(0, 0, 8, 8, rp=2) + struct.pack(">I", 2) + struct.pack(">3d", 0.1, 0.5, 0.25))
    out = Opcodes(list=2)(frame(x, "raw", 2, [poly])).data
    assert out[0::2] == pytest.approx(0.1 + 0.5 * x[0::2] + 0.25 * x[0::2] ** 2, rel=1e-6)
    assert np.array_equal(out[1::2], x[1::2])  # rows outside the pitch untouched
    deltas = (np.arange(8) * 0.01).astype(">f4")
    out = Opcodes(list=2)(frame(x, "raw", 2, [op(10, area() + struct.pack(">I", 8) + deltas.tobytes())])).data
    assert out == pytest.approx(np.clip(x + deltas.astype(np.float32)[:, None], -1, 1), abs=1e-7)
    scales = np.linspace(0.5, 1.5, 8).astype(">f4")
    out = Opcodes(list=2)(frame(x, "raw", 2, [op(13, area() + struct.pack(">I", 8) + scales.tobytes())])).data
    assert out == pytest.approx(np.clip(x * scales.astype(np.float32)[None, :], 0, 1), abs=1e-7)


def test_trim_bounds_crops_and_relabels_the_cfa():
    x = np.arange(100, dtype=np.float32).reshape(10, 10)
    f = Opcodes(list=2)(frame(x, "raw", 2, [op(6, struct.pack(">4i", 1, 2, 9, 8))]))
    assert f.data.shape == (8, 6) and f.data[0, 0] == 12 and f.meta.cfa == "GBRG" and f.meta.origin == (1, 2)


def test_unsupported_opcode_optional_warns_required_raises():
    x = np.zeros((8, 8, 3), np.float32)
    fisheye = op(2, b"\0" * 8, flags=1)
    with pytest.warns(SimcamWarning, match="WarpFisheye"):
        Opcodes(list=3)(frame(x, "camera_rgb", 3, [fisheye]))
    with pytest.raises(StageError, match="Optional flag is clear"):
        Opcodes(list=3)(frame(x, "camera_rgb", 3, [op(3, b"\0" * 8, flags=0)]))


def test_fusion_lateral_chromatic_aberration_is_applied():
    """The GoPro Fusion's OpcodeList3 WarpRectilinear (per-plane scale): red and blue move at the edge only."""
    from shared_data import shared_path

    from simcam.io.dng import read_dng
    from simcam.pipeline import Pipeline

    path = shared_path("dng/gopro_fusion_front_iso100.dng")
    with warnings.catch_warnings():
        warnings.simplefilter("error", SimcamWarning)
        out = Pipeline.from_yaml("linear-srgb")(read_dng(path)).data
    assert out.shape[0] > 1000 and np.isfinite(out).all()
