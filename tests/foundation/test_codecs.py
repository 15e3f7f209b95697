"""F/T codecs, fuzzed: only typed errors escape, frames survive any split, no corrupted frame decodes."""
from __future__ import annotations

import contextlib
import math
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymodbus.framer.rtu import FramerRTU

from ftc_hw.codecs import (
    AXES,
    FT300_MAP,
    FT300_STREAM,
    FTC_1K,
    ChecksumError,
    CodecError,
    FrameFormatError,
    RegisterMap,
    StreamFormat,
    StreamParser,
    crc16_ccitt,
    crc16_modbus,
    register_map,
    stream_format,
)
from ftc_hw.codecs import netft_pages as pages
from ftc_hw.codecs import netft_rdt as rdt
from ftc_hw.codecs import serial_can as scan
from ftc_hw.codecs.modbus_frames import mbap_decode, mbap_encode, rtu_decode_request, rtu_encode
from ftc_hw.codecs.netft_can import NetFTAssembler, NetFTCodec
from ftc_hw.codecs.registers import IDENTITY_DECODERS, encode_identity

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FORMATS = [FT300_STREAM, FTC_1K]


def _sample(fmt: StreamFormat, k: int) -> tuple[tuple[float, ...], int, int, int]:
    """A sample representable exactly in ``fmt``: wrench, seq, t_device_ns, status."""
    w = tuple(((k * 37 + 11 * i) % 2001 - 1000) * (0.01 if i < 3 else 0.001) for i in range(6))
    return w, k, k * 1_000_000, k % 64


def _frames(fmt: StreamFormat, ks: list[int]) -> list[bytes]:
    return [fmt.encode(w, seq=s, t_device_ns=t, status=st_) for w, s, t, st_ in (_sample(fmt, k) for k in ks)]


def _key(fmt: StreamFormat, w: tuple[float, ...]) -> tuple[int, ...]:
    return tuple(round(x / f.scale) for x, f in zip(w, (fmt.field(a) for a in AXES), strict=True))


def _originals(fmt: StreamFormat, ks: list[int]) -> set[tuple[int, ...]]:
    return {_key(fmt, _sample(fmt, k)[0]) for k in ks}


# -- checksums -------------------------------------------------------------------------------------
def test_checksums_match_reference_values_and_pymodbus():
    assert crc16_modbus(b"123456789") == 0x4B37  # CRC-16/MODBUS check value
    assert crc16_ccitt(b"123456789") == 0x29B1  # CRC-16/CCITT-FALSE check value
    frame = FT300_STREAM.encode([1.0, -2.0, 3.5, 0.1, -0.2, 0.3])
    assert FramerRTU.compute_CRC(frame[:14]) == int.from_bytes(frame[14:], "big")  # pymodbus keeps it byte-swapped


# -- stream formats --------------------------------------------------------------------------------
@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: f.name)
def test_stream_frame_layout(fmt: StreamFormat):
    frame = fmt.encode(*_sample(fmt, 5)[:1], seq=5, t_device_ns=5_000_000, status=5)
    assert len(frame) == fmt.size and frame.startswith(fmt.header)
    n, s = fmt.decode(frame)
    assert n == fmt.size and s is not None and _key(fmt, s.wrench) == _key(fmt, _sample(fmt, 5)[0])
    if fmt is FTC_1K:
        assert fmt.size == 35 and (s.seq, s.t_device_ns, s.status) == (5, 5_000_000, 5)
        assert FTC_1K.seq_modulus == 1 << 16 and FTC_1K.t_device_modulus_ns == (1 << 32) * 1000
    else:  # the FT 300 frame of Robotiq's driver: 20 4E, six int16 LE, CRC over the first 14 bytes
        assert fmt.size == 16 and struct.unpack("<6h", frame[2:14])[2] == round(_sample(fmt, 5)[0][2] * 100)
        assert int.from_bytes(frame[14:], "little") == crc16_modbus(frame[:14])


@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: f.name)
@FUZZ
@given(data=st.binary(max_size=300))
def test_random_bytes_raise_only_typed_errors(fmt: StreamFormat, data: bytes):
    try:
        n, _ = fmt.decode(data)
        assert 0 <= n <= len(data)
    except CodecError as exc:
        assert 1 <= exc.consumed <= len(data)
    parser = StreamParser(fmt)
    out = parser.feed(data)  # must terminate, whatever the bytes
    assert parser.frames == len(out)


@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: f.name)
def test_valid_stream_split_at_every_byte_boundary(fmt: StreamFormat):
    ks = list(range(4))
    stream = b"".join(_frames(fmt, ks))
    for cut in range(len(stream) + 1):
        p = StreamParser(fmt)
        out = p.feed(stream[:cut]) + p.feed(stream[cut:])
        assert [_key(fmt, s.wrench) for s in out] == [_key(fmt, _sample(fmt, k)[0]) for k in ks], cut
        assert p.checksum_errors == p.resyncs == p.bytes_discarded == 0


@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: f.name)
@FUZZ
@given(ks=st.lists(st.integers(0, 10_000), min_size=1, max_size=12), data=st.data())
def test_valid_frames_any_chunking_and_duplicates(fmt: StreamFormat, ks: list[int], data):
    ks = ks + [ks[-1]]  # a duplicated frame decodes twice: the adapter drops it by its sequence number
    stream = b"".join(_frames(fmt, ks))
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=8)))
    p = StreamParser(fmt)
    out = []
    for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        out += p.feed(stream[a:b])
    assert [_key(fmt, s.wrench) for s in out] == [_key(fmt, _sample(fmt, k)[0]) for k in ks]


@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: f.name)
@FUZZ
@given(n=st.integers(3, 10), data=st.data())
def test_corrupted_frame_never_decodes_and_is_counted_once(fmt: StreamFormat, n: int, data):
    ks = list(range(100, 100 + n))
    frames = _frames(fmt, ks)
    i = data.draw(st.integers(0, n - 2))  # a later frame must follow so the error region closes
    bit = data.draw(st.integers(8 * len(fmt.header), 8 * fmt.size - 1))
    bad = bytearray(frames[i])
    bad[bit // 8] ^= 1 << (bit % 8)
    frames[i] = bytes(bad)
    p = StreamParser(fmt)
    out = p.feed(b"".join(frames))
    assert [_key(fmt, s.wrench) for s in out] == [_key(fmt, _sample(fmt, k)[0]) for j, k in enumerate(ks) if j != i]
    assert p.checksum_errors == 1 and p.resyncs == 0


@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: f.name)
@FUZZ
@given(garbage=st.lists(st.binary(min_size=1, max_size=40), min_size=1, max_size=4),
       cut=st.integers(1, 34), data=st.data())
def test_garbage_and_truncation_lose_nothing_else(fmt: StreamFormat, garbage, cut, data):
    ks = list(range(200, 210))
    frames = _frames(fmt, ks)
    sent = list(frames)
    t = data.draw(st.integers(1, 8))
    frames[t] = frames[t][:min(cut, fmt.size - 1)]  # truncated
    chunks = list(frames)
    for g in garbage:
        chunks.insert(data.draw(st.integers(1, len(chunks) - 1)), g)
    stream = b"".join(chunks)
    p = StreamParser(fmt)
    out = p.feed(stream)
    got = [_key(fmt, s.wrench) for s in out]
    assert set(got) <= _originals(fmt, ks)  # nothing that was not sent
    # garbage that happens to be the truncated frame's missing bytes makes it whole again: then it counts
    mended = sent[t] in stream
    intact = [_key(fmt, _sample(fmt, k)[0]) for j, k in enumerate(ks) if j != t or mended]
    assert got == intact  # and everything that was sent whole
    assert p.checksum_errors + p.resyncs + p.format_errors >= 1 or stream == b"".join(sent)


def test_stream_format_tables():
    assert stream_format("ftc-1k") is FTC_1K
    table = {"name": "mine", "header": "aa55", "checksum": "xor8", "checksum_from": 2,
             "fields": [{"name": a, "type": "f32"} for a in AXES] + [{"name": "seq", "type": "u8"}]}
    fmt = stream_format(table)
    assert fmt.size == 2 + 25 + 1 and fmt.seq_modulus == 256
    n, s = fmt.decode(fmt.encode([1.5, 2, 3, 4, 5, 6], seq=300))
    assert n == fmt.size and s.wrench == (1.5, 2, 3, 4, 5, 6) and s.seq == 300 % 256
    nan = bytearray(fmt.encode([1, 2, 3, 4, 5, 6]))
    nan[2:6] = struct.pack("<f", math.nan)
    nan[-1] = 0
    from ftc_hw.codecs.checksums import xor8
    nan[-1] = xor8(bytes(nan[2:-1]))
    with pytest.raises(CodecError):
        fmt.decode(bytes(nan))
    for bad in ({**table, "fields": table["fields"][1:]}, {**table, "checksum": "md5"}, {**table, "header": ""},
                {"header": "aa"}):
        with pytest.raises(ValueError):
            stream_format(bad)
    with pytest.raises(ValueError):
        stream_format("nope")


# -- register maps ---------------------------------------------------------------------------------
ORDERS = [(b, w) for b in ("big", "little") for w in ("big", "little")]


@pytest.mark.parametrize("typ", ["int16", "uint16", "int32", "uint32", "float32"])
@pytest.mark.parametrize(("byte_order", "word_order"), ORDERS)
@FUZZ
@given(counts=st.lists(st.integers(0, 30000), min_size=6, max_size=6))
def test_register_map_roundtrip(typ, byte_order, word_order, counts):
    size = 1 if typ.endswith("16") else 2
    m = RegisterMap.from_dict({"axes": [{"name": a, "address": 40 + size * i, "type": typ, "scale": 0.5}
                                        for i, a in enumerate(AXES)],
                               "byte_order": byte_order, "word_order": word_order,
                               "status": {"address": 40 + 6 * size, "type": "uint16"}})
    w = [c * 0.5 for c in counts]
    regs = m.encode(w, status=7)
    start, count = m.block()
    assert count == 6 * size + 1
    got, status = m.decode([regs[a] for a in range(start, start + count)], start)
    assert got == pytest.approx(w) and status == 7


@FUZZ
@given(regs=st.lists(st.integers(0, 0xFFFF), min_size=13, max_size=13))
def test_register_decode_of_any_registers_raises_only_typed_errors(regs):
    m = register_map("generic-float32")
    try:
        w, _ = m.decode(regs, 0)
        assert all(math.isfinite(x) for x in w)
    except CodecError:
        pass


def test_ft300_map_and_identity_as_robotiqs_driver_reads_them():
    m = register_map("ft300")
    assert m is FT300_MAP and m.block() == (180, 6) and m.function == 3
    regs = m.encode([300.0, -1.25, 0.01, 30.0, -0.001, 12.345])
    assert [regs[a] for a in range(180, 186)] == [30000, (-125) & 0xFFFF, 1, 30000, 0xFFFF, 12345]
    fw = encode_identity("robotiq-firmware", "FTS-3.0.1", 3)
    assert fw[0] >> 8 == ord("F") and IDENTITY_DECODERS["robotiq-firmware"](fw) == "FTS-3.0.1"
    assert IDENTITY_DECODERS["robotiq-serial"](encode_identity("robotiq-serial", "FTS-0042", 4)) == "FTS-0042"
    assert IDENTITY_DECODERS["uint16"](encode_identity("uint16", "2019", 1)) == "2019"
    assert [f.address for f in m.identity] == [500, 510, 514]
    with pytest.raises(ValueError):
        RegisterMap.from_dict({"axes": [{"name": a, "address": 0} for a in AXES]})  # overlapping
    with pytest.raises(ValueError):
        register_map("nope")


# -- Modbus framing (emulator side) ----------------------------------------------------------------
@FUZZ
@given(data=st.binary(max_size=64))
def test_rtu_and_mbap_decoders_raise_only_typed_errors(data):
    for decode in (rtu_decode_request, mbap_decode, scan.decode):
        try:
            n, _ = decode(data)
            assert 0 <= n <= len(data)
        except CodecError as exc:
            assert exc.consumed >= 0


def test_rtu_request_roundtrip_and_crc():
    req = rtu_encode(9, bytes([3, 0, 180, 0, 6]))
    assert req.hex() == "090300b40006" + req[-2:].hex()
    for cut in range(len(req)):
        assert rtu_decode_request(req[:cut]) == (0, None)
    assert rtu_decode_request(req + b"\x00") == (8, (9, bytes([3, 0, 180, 0, 6])))
    with pytest.raises(ChecksumError):
        rtu_decode_request(req[:-1] + bytes([req[-1] ^ 1]))
    assert mbap_decode(mbap_encode(7, 9, b"\x03\x00\xb4\x00\x06")) == (12, (7, 9, b"\x03\x00\xb4\x00\x06"))


# -- CAN -------------------------------------------------------------------------------------------
def test_netft_codec_frames_follow_the_dbc_and_base_id():
    codec = NetFTCodec("ati_netft_can.dbc", base_id=0x20)
    frames = codec.encode_sample([1500.0, -2.5, -3750.0, 240.0, 0.001, -0.5], counter=7, status=0b101)
    assert [i for i, _ in frames] == [0x21, 0x22, 0x23, 0x24]
    assert struct.unpack("<ii", frames[0][1]) == (1_500_000, 240_000)
    asm = NetFTAssembler(codec)
    assert asm.feed(*codec.encode_sample([0] * 6, counter=6)[3]) is None  # a status first: counter known
    out = [asm.feed(i, d) for i, d in frames]
    assert out[:3] == [None] * 3 and out[3].seq == 7 and out[3].status == 0b101
    assert out[3].wrench == pytest.approx((1500.0, -2.5, -3750.0, 240.0, 0.001, -0.5))
    assert codec.encode_request(2) == (0x20, b"\x02")


def test_netft_assembler_cannot_be_fooled_by_a_lost_status_and_lost_data():
    """status(3) and data(4) lost: data(3) and status(4) would make a plausible, wrong sample."""
    codec = NetFTCodec()
    asm = NetFTAssembler(codec)
    frames = [f for k in range(6) for f in codec.encode_sample([10.0 * k] * 6, counter=k)]
    lost = {15, 16, 17, 18}
    out = [s for i, f in enumerate(frames) if i not in lost and (s := asm.feed(*f)) is not None]
    assert [s.seq for s in out] == [1, 2, 5]  # 0 only sets the counter; 4 cannot be attributed
    assert all(s.wrench == (10.0 * s.seq,) * 6 for s in out)
    assert asm.unverified == 1 and asm.incomplete == 1


@FUZZ
@given(ops=st.lists(st.sampled_from(["ok", "drop", "dup", "short", "foreign"]), min_size=40, max_size=40),
       data=st.data())
def test_netft_assembler_never_emits_a_mixed_or_partial_sample(ops, data):
    codec = NetFTCodec()
    asm = NetFTAssembler(codec)
    sent: dict[int, tuple] = {}
    emitted = []
    frames = []
    for k in range(10):
        w = tuple(float(k * 10 + i) for i in range(6))
        sent[k] = w
        frames += codec.encode_sample(w, counter=k)
    for (arb, payload), op in zip(frames, ops, strict=True):
        if op == "drop":
            continue
        if op == "short":
            payload = payload[:data.draw(st.integers(0, len(payload) - 1))]
        if op == "foreign":
            emitted.append(asm.feed(0x700, b"\x01"))
        emitted.append(asm.feed(arb, payload))
        if op == "dup":
            emitted.append(asm.feed(arb, payload))
    samples = [s for s in emitted if s is not None]
    for s in samples:  # never a sample made of another sample's frames
        assert s.wrench == pytest.approx(sent[s.seq])
    assert [s.seq for s in samples] == sorted({s.seq for s in samples})
    damaged = {i // 4 for i, op in enumerate(ops) if op in ("drop", "short")}
    assert not {s.seq for s in samples} & damaged
    # an intact sample whose predecessor's status frame arrived is always delivered
    status_ok = {i // 4 for i, op in enumerate(ops) if i % 4 == 3 and op not in ("drop", "short")}
    assert {k for k in range(1, 10) if k not in damaged and k - 1 in status_ok} <= {s.seq for s in samples}


# -- Net F/T RDT (UDP) -----------------------------------------------------------------------------
def _rdt_records(n: int, first: int = 1) -> list[rdt.RdtRecord]:
    return [rdt.RdtRecord(first + i, 1000 + i, i % 64, tuple((i * 97 + 13 * a) % 4001 - 2000 for a in range(6)))
            for i in range(n)]


def test_rdt_layout_is_atis_network_byte_order():
    assert rdt.encode_request(rdt.CMD_START_BUFFERED, 10) == bytes.fromhex("12340003") + (10).to_bytes(4, "big")
    rec = rdt.RdtRecord(1, 2, 0x80000001, (1, -1, 2, -2, 3, -3))
    data = rdt.encode_records([rec])
    assert len(data) == 36 and struct.unpack("!3I6i", data) == (1, 2, 0x80000001, 1, -1, 2, -2, 3, -3)
    assert rdt.decode_packet(data) == [rec] and rdt.status_errors(rec.status) == 0x80000000
    assert rdt.decode_request(rdt.encode_request(rdt.CMD_SET_BIAS)) == rdt.RdtRequest(rdt.CMD_SET_BIAS, 0)


@FUZZ
@given(n=st.integers(1, 40), cut=st.integers(-36, 36))
def test_rdt_packets_of_whole_records_decode_and_any_other_length_is_a_typed_error(n, cut):
    recs = _rdt_records(n)
    data = rdt.encode_records(recs)
    bad = data[:len(data) + cut] if cut < 0 else data + bytes(cut)
    if cut % 36 == 0 and len(bad) > 0:
        assert len(rdt.decode_packet(bad)) == n + cut // 36
    else:
        with pytest.raises(FrameFormatError):
            rdt.decode_packet(bad)
    assert rdt.decode_packet(data, records=n) == recs
    with pytest.raises(FrameFormatError):
        rdt.decode_packet(data, records=n + 1)  # long: more records than the mode sends


@FUZZ
@given(data=st.binary(max_size=400))
def test_rdt_random_datagrams_raise_only_typed_errors(data):
    for decode in (rdt.decode_packet, rdt.decode_request, rdt.parse_calibration):
        with contextlib.suppress(CodecError):  # CalibrationError is one
            decode(data)


@FUZZ
@given(header=st.integers(0, 0xFFFF), command=st.integers(0, 0xFFFF), count=st.integers(0, 2**32 - 1))
def test_rdt_request_with_a_wrong_header_or_command_is_a_typed_error(header, command, count):
    data = struct.pack("!HHI", header, command, count)
    if header == rdt.HEADER and command in rdt.COMMANDS:
        assert rdt.decode_request(data) == rdt.RdtRequest(command, count)
    else:
        with pytest.raises(FrameFormatError):
            rdt.decode_request(data)


@FUZZ
@given(cpf=st.sampled_from([1e6, 1e5, 1000.0, 16.0]), cpt=st.sampled_from([1e6, 1e4, 32.0]),
       fu=st.sampled_from(sorted(rdt.FORCE_UNITS)), tu=st.sampled_from(sorted(rdt.TORQUE_UNITS)),
       counts=st.lists(st.integers(-(2**31), 2**31 - 1), min_size=6, max_size=6))
def test_rdt_calibration_page_roundtrip_and_counts_to_si(cpf, cpt, fu, tu, counts):
    cal = rdt.Calibration(cpf, cpt, fu, tu, 7000.0, 10)
    assert rdt.parse_calibration(rdt.encode_calibration(cal)) == cal
    si = cal.to_si(counts)
    assert si[0] == pytest.approx(counts[0] / cpf * rdt.FORCE_UNITS[fu])
    assert si[5] == pytest.approx(counts[5] / cpt * rdt.TORQUE_UNITS[tu])
    assert cal.to_counts(si) == tuple(counts)


@pytest.mark.parametrize(("page", "field"), [
    (b"<netft><cfgcpf>1000000</cfgcpf>", "/netftapi2.xml"),  # not well-formed
    (b"<netft><cfgcpt>1000000</cfgcpt></netft>", "cfgcpf"),  # missing
    (b"<netft><cfgcpf>lots</cfgcpf><cfgcpt>1</cfgcpt></netft>", "cfgcpf"),
    (b"<netft><cfgcpf>1</cfgcpf><cfgcpt>-5</cfgcpt></netft>", "cfgcpt"),
    (b"<netft><cfgcpf>1</cfgcpf><cfgcpt>1</cfgcpt><scfgfu>furlong</scfgfu></netft>", "scfgfu"),
    (b"<netft><cfgcpf>1</cfgcpf><cfgcpt>1</cfgcpt><comrdtrate>nan</comrdtrate></netft>", "comrdtrate"),
])
def test_rdt_malformed_calibration_page_names_the_field(page, field):
    with pytest.raises(rdt.CalibrationError) as err:
        rdt.parse_calibration(page)
    assert err.value.field == field and field in str(err.value)


def test_rdt_request_and_record_bytes_as_atis_layout_fixes_them():
    assert rdt.encode_request(rdt.CMD_LOOP, 1) == bytes.fromhex("1234000100000001")
    assert rdt.encode_request(rdt.CMD_SET_BIAS) == bytes.fromhex("1234004200000000")
    for command in (0x0000, 0x0001, 0x0002, 0x0003, 0x0004, 0x0041, 0x0042):
        assert rdt.decode_request(rdt.encode_request(command, 7)) == rdt.RdtRequest(command, 7)
    record = rdt.encode_records([rdt.RdtRecord(1, 2, 0x80000000, (1, -1, 2, -2, 3, -3))])
    assert record == bytes.fromhex("00000001" "00000002" "80000000" "00000001" "ffffffff" "00000002"
                                   "fffffffe" "00000003" "fffffffd")


def _box_pages(bias=(0,) * 6, cal_extra=None, cfg_extra=None, cal=None):
    cal = cal or rdt.Calibration(1e5, 1e6, "N", "Nm", 7000.0, 10)
    info = pages.BoxInfo()
    return (pages.config_page(cal, info, index=0, bias=bias, extra=cfg_extra),
            pages.calibration_page(cal, info, cal_extra))


def test_netft_pages_round_trip_and_the_calibration_page_comes_first():
    config, calibration = _box_pages(bias=(1, -2, 3, -4, 5, -6))
    box = pages.read_box(config, calibration)
    assert box.source == "/netftcalapi.xml calcpf/calcpt" and box.calibration.fields == ("calcpf", "calcpt")
    assert box.calibration == rdt.Calibration(1e5, 1e6, "N", "Nm", 7000.0, 10)
    assert (box.bias, box.config, box.calibration_index, box.status, box.rdt_enabled) == (
        (1, -2, 3, -4, 5, -6), 0, 0, 0, True)
    fallback = pages.read_box(config, None)  # a box without netftcalapi.xml
    assert fallback.source == "/netftapi2.xml cfgcpf/cfgcpt" and fallback.calibration == box.calibration
    lbf = rdt.Calibration(1e5 * 4.4482216152605, 1e6, "lbf", "Nm", 7000.0, 10)  # the same counts per N
    config, _ = _box_pages(cal=lbf)
    assert pages.read_box(config, _box_pages()[1]).calibration.force_unit == "N"


@pytest.mark.parametrize(("pages_", "field"), [
    (_box_pages(cfg_extra={"cfgcpf": "1000000"}), "cfgcpf"),  # the configuration disagrees with the calibration
    (_box_pages(cal_extra={"calcpt": "many"}), "calcpt"),
    (_box_pages(cal_extra={"scalfu": "stone"}), "scalfu"),
    (_box_pages(cfg_extra={"setbias": "1 2 3"}), "setbias"),
    (_box_pages(cfg_extra={"runstat": "0xZZ"}), "runstat"),
    (_box_pages(cfg_extra={"setcfgsel": "first"}), "setcfgsel"),
    ((_box_pages()[0], b"<netftCalibration><calcpf>"), "/netftcalapi.xml"),
])
def test_netft_pages_wrong_fields_are_named(pages_, field):
    with pytest.raises(rdt.CalibrationError) as err:
        pages.read_box(*pages_)
    assert err.value.field == field


def test_rdt_scene_counts_are_compared_per_si_unit():
    box = rdt.Calibration(1e6, 1e6 * 0.1129848290276167, "N", "lbf-in", 7000.0, 10)
    assert rdt.reconcile(box, counts_per_torque=1e6) is box  # 1e6 per N m either way
    with pytest.raises(rdt.CalibrationError, match=r"cfgcpt: the box says 8850745.791327184 per SI unit \(its "
                       r"unit is lbf-in\), the scene 100000"):
        rdt.reconcile(rdt.Calibration(1e6, 1e6, "N", "lbf-in"), counts_per_torque=1e5)


@FUZZ
@given(data=st.binary(max_size=400))
def test_netft_pages_random_bytes_raise_only_typed_errors(data):
    with contextlib.suppress(CodecError):
        pages.read_box(data, data)
    with contextlib.suppress(CodecError):
        pages.read_box(_box_pages()[0], data)


def test_rdt_calibration_that_disagrees_with_the_scene_names_both_values():
    box = rdt.Calibration(1e6, 1e6, rdt_rate_hz=7000.0, buffer_size=10)
    assert rdt.reconcile(box, counts_per_force=1e6, rate_hz=7000.0) is box
    with pytest.raises(rdt.CalibrationError, match=r"cfgcpt: the box says 1000000, the scene 100000"):
        rdt.reconcile(box, counts_per_torque=1e5)
    with pytest.raises(rdt.CalibrationError, match="comrdtrate"):
        rdt.reconcile(box, rate_hz=1000.0)
    with pytest.raises(rdt.CalibrationError, match="comrdtbsiz"):
        rdt.reconcile(box, buffer_size=40)
    assert rdt.reconcile(None, counts_per_force=10.0, counts_per_torque=20.0).scale == (0.1,) * 3 + (0.05,) * 3
    with pytest.raises(rdt.CalibrationError, match="not read"):
        rdt.reconcile(None, counts_per_force=10.0)
