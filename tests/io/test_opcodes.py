"""DNG opcode lists: names, GainMap decoding, byte-exact round trips (DNG 1.6 spec ch. 7)."""

from __future__ import annotations

import struct

import numpy as np
import pytest
import tifffile

from shared_data import shared_path
from simcam.errors import DngError
from simcam.frame import GainMap, Opcode
from simcam.io.dng import read_dng_meta
from simcam.io.opcodes import (decode_gain_map, encode_gain_map, gain_map_opcode, parse_opcode_list,
                               serialise_opcode_list)

pytestmark = pytest.mark.shared_data


def _tag_bytes(path, code):
    with tifffile.TiffFile(str(path)) as tif:
        return bytes(tif.pages[0].tags[code].value)


@pytest.mark.parametrize("name, points", [("gopro_hero7_iso252.dng", (23, 22)), ("gopro_hero6_iso100.dng", (23, 23))])
def test_gopro_gain_maps_cover_the_four_bayer_phases(name, points):
    path = shared_path(f"dng/{name}")
    meta = read_dng_meta(path)
    ops = meta.opcode_list2
    assert [op.name for op in ops] == ["GainMap"] * 4
    maps = meta.gain_maps(2)
    assert len(maps) == 4
    h, w = meta.extra["image_size"]
    phases = set()
    for gm in maps:
        assert gm.map_points == points
        assert gm.gains.shape == points + (1,) and gm.gains.dtype == np.float32
        assert (gm.plane, gm.planes, gm.row_pitch, gm.col_pitch) == (0, 1, 2, 2)
        assert (gm.bottom, gm.right) == (h, w)
        # the spacing spans the whole image: origin + (n-1) * spacing == 1
        assert gm.map_origin_v + (points[0] - 1) * gm.map_spacing_v == pytest.approx(1.0)
        assert gm.map_origin_h + (points[1] - 1) * gm.map_spacing_h == pytest.approx(1.0)
        assert 1.0 <= gm.gains.min() and gm.gains.max() < 2.5  # a vignetting correction
        phases.add((gm.top % 2, gm.left % 2))
    assert phases == {(0, 0), (0, 1), (1, 0), (1, 1)}


def test_first_gain_map_header_matches_hand_decoding():
    """Decode the HERO7 bytes by hand (spec layout) and compare with the parser."""
    raw = _tag_bytes(shared_path("dng/gopro_hero7_iso252.dng"), 51009)
    count, oid = struct.unpack(">II", raw[:8])
    version = tuple(raw[8:12])
    flags, nbytes = struct.unpack(">II", raw[12:20])
    p = raw[20:20 + nbytes]
    top, left, bottom, right, plane, planes, rp, cp, pv, ph = struct.unpack(">10I", p[:40])
    sv, sh, ov, oh = struct.unpack(">4d", p[40:72])
    (mp,) = struct.unpack(">I", p[72:76])
    first_gain = struct.unpack(">f", p[76:80])[0]
    last_gain = struct.unpack(">f", p[-4:])[0]
    ops = parse_opcode_list(raw)
    assert (count, oid, version) == (4, 9, (1, 4, 0, 0))
    op = ops[0]
    assert (op.id, op.version, op.flags, len(op.payload)) == (oid, version, flags, nbytes)
    gm = op.parsed
    assert (gm.top, gm.left, gm.bottom, gm.right, gm.plane, gm.planes, gm.row_pitch, gm.col_pitch) == (
        top, left, bottom, right, plane, planes, rp, cp)
    assert gm.gains.shape == (pv, ph, mp)
    assert (gm.map_spacing_v, gm.map_spacing_h, gm.map_origin_v, gm.map_origin_h) == (sv, sh, ov, oh)
    assert gm.gains[0, 0, 0] == np.float32(first_gain) and gm.gains[-1, -1, -1] == np.float32(last_gain)


@pytest.mark.parametrize("name, code", [("gopro_hero7_iso252.dng", 51009), ("gopro_hero6_iso100.dng", 51009),
                                        ("gopro_fusion_front_iso100.dng", 51022)])
def test_opcode_list_round_trip_is_byte_exact(name, code):
    raw = _tag_bytes(shared_path(f"dng/{name}"), code)
    ops = parse_opcode_list(raw)
    assert serialise_opcode_list(ops) == raw
    for op in ops:
        if op.id == 9:
            assert encode_gain_map(op.parsed) == op.payload
            assert gain_map_opcode(op.parsed, version=op.version, flags=op.flags).payload == op.payload


def test_fusion_warp_is_kept_by_name():
    meta = read_dng_meta(shared_path("dng/gopro_fusion_front_iso100.dng"))
    (op,) = meta.opcode_list3
    assert op.name == "WarpRectilinear" and op.parsed is None and op.optional
    # WarpRectilinear: uint32 planes, then 6 doubles per plane + 2 doubles (centre)
    (planes,) = struct.unpack(">I", op.payload[:4])
    assert len(op.payload) == 4 + planes * 6 * 8 + 16


def _synthetic_list():
    gm = GainMap(top=1, left=0, bottom=10, right=12, plane=0, planes=1, row_pitch=2, col_pitch=2,
                 map_spacing_v=0.5, map_spacing_h=0.25, map_origin_v=0.0, map_origin_h=0.0,
                 gains=np.arange(15, dtype=np.float32).reshape(3, 5, 1) / 7 + 1)
    return [gain_map_opcode(gm), Opcode(id=99, version=(1, 6, 0, 0), flags=1, payload=b"\x01\x02\x03")]


def test_unknown_opcode_kept_as_bytes():
    raw = serialise_opcode_list(_synthetic_list())
    ops = parse_opcode_list(raw)
    assert ops[1].name == "Unknown99" and ops[1].payload == b"\x01\x02\x03" and ops[1].parsed is None
    assert ops[0].parsed.gains.shape == (3, 5, 1)
    assert serialise_opcode_list(ops) == raw


@pytest.mark.parametrize("cut", [2, 10, 30, -1])
def test_truncated_opcode_list_raises(cut):
    raw = serialise_opcode_list(_synthetic_list())
    with pytest.raises(DngError, match="OpcodeList2"):
        parse_opcode_list(raw[:cut], where="x.dng: OpcodeList2")


def test_trailing_bytes_and_bad_gain_map_size_raise():
    raw = serialise_opcode_list(_synthetic_list())
    with pytest.raises(DngError, match="trailing"):
        parse_opcode_list(raw + b"\0")
    payload = _synthetic_list()[0].payload
    with pytest.raises(DngError, match="needs"):
        decode_gain_map(payload[:-4])


def test_info_summarises_gain_maps(capsys):
    from simcam.cli import main

    assert main(["info", str(shared_path("dng/gopro_hero7_iso252.dng"))]) == 0
    out = capsys.readouterr().out
    assert "opcode_list2: 4 opcode(s)" in out
    assert out.count("GainMap (id 9") == 4 and "points [23, 22, 1]" in out
