"""The Net F/T box's XML pages, as its web server serves them on port 80. No I/O.

``/netftapi2.xml[?index=N]``: the system (status, the reading, the software bias, the RDT settings, the
network) and configuration N (16 on a box; without ``index``, or with the active one, ``setcfgsel``,
the active configuration). ``/netftcalapi.xml[?index=N]``: calibration N (``cfgcalsel`` of a
configuration names its calibration). Field names and types as in ATI's manuals (Net F/T 9620-05-NET
FT, "XML"; Ethernet Axia 9610-05, table 11.2) and as ATI's Java demo and public clients read them
(``sim_devices/SOURCES.md``): HEX32 as ``0x%08X``, booleans ``Enabled`` / ``Disabled``, unit codes
beside the unit strings; arrays of counts (``runft``, ``setbias``) space-separated (a public client
converts them split on spaces) and the ranges (``cfgmr``, ``calmr``) semicolon-separated (ATI's Java
demo splits ``cfgmr`` on ``;``); the manual allows either.

Counts per unit: a calibration page's ``calcpf``/``calcpt`` in ``scalfu``/``scaltu`` (what the ROS
drivers read) and a configuration's ``cfgcpf``/``cfgcpt`` in ``scfgfu``/``scfgtu`` (what ATI's demo
reads); :func:`read_box` takes the calibration's when the box serves it, else the TCP interface's
READCALINFO when given (:mod:`ftc_hw.codecs.netft_tcp`), and checks the configuration's against it (the
same counts per SI unit, or :class:`~ftc_hw.codecs.netft_rdt.CalibrationError`).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass

from .netft_rdt import FORCE_UNITS, TORQUE_UNITS, Calibration, CalibrationError, _num, _positive, parse_calibration

CONFIG_PAGE, CALIBRATION_PAGE = "/netftapi2.xml", "/netftcalapi.xml"
CONFIG_ROOT, CALIBRATION_ROOT = "netft", "netftCalibration"
CONFIGS = 16  # configurations a box holds (index 0-15)
# the unit codes of the box's calibration (as ATI's calibration-info reply numbers them: netft_rdt_driver)
FORCE_UNIT_CODES = {"lbf": 1, "N": 2, "klbf": 3, "kN": 4, "kgf": 5, "gf": 6}
TORQUE_UNIT_CODES = {"lbf-in": 1, "lbf-ft": 2, "Nm": 3, "N-m": 3, "Nmm": 4, "N-mm": 4, "kgf-cm": 5, "kNm": 6,
                     "kN-m": 6}


@dataclass(frozen=True)
class BoxInfo:
    """What the box says about itself, beyond the counts: its calibration's identity and the state other
    programs may have left (software bias, status)."""

    serial: str = "FT00000"
    part: str = "SI-660-60"
    date: str = "2026/01/01"
    max_range: tuple[float, ...] = (660.0, 660.0, 1980.0, 60.0, 60.0, 60.0)  # calmr / cfgmr, in its units
    address: str = "192.168.1.1"
    mac: str = "00:16:BD:00:00:01"


@dataclass(frozen=True)
class BoxState:
    """The box's pages read: the calibration to decode with, where its counts came from, the software
    bias in counts (another program's ``0x0042``: subtracted from every record the box sends), the active
    configuration and calibration, the status word and whether RDT is enabled."""

    calibration: Calibration
    source: str
    bias: tuple[int, ...] = (0,) * 6
    config: int | None = None
    calibration_index: int | None = None
    status: int = 0
    rdt_enabled: bool = True


def _xml(root: str, fields: dict[str, str]) -> bytes:
    el = ET.Element(root)
    for key, value in fields.items():
        ET.SubElement(el, key).text = value
    return b'<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(el)


def _ints(values: Sequence[int]) -> str:
    return " ".join(str(int(v)) for v in values)


def _reals(values: Sequence[float]) -> str:
    return ";".join(f"{float(v):g}" for v in values)


def config_page(cal: Calibration, info: BoxInfo, *, index: int, active: int = 0, reading: Sequence[int] = (0,) * 6,
                bias: Sequence[int] = (0,) * 6, status: int = 0, extra: dict[str, str] | None = None) -> bytes:
    """``/netftapi2.xml?index=<index>``: the system's fields and configuration ``index`` (the active one
    is the scene's; the others are named but unused, on calibration 0)."""
    fields = {"runstat": f"0x{status & 0xFFFFFFFF:08X}", "runft": _ints(reading), "runmcb": "0x00000000",
              "runmco": "0x00", "runmcl": "0", "setbias": _ints(bias), "setcfgsel": str(active),
              "setuserfilter": "0", "cfgnam": "ftc-hw" if index == active else f"Config {index + 1}",
              "cfgcalsel": "0", "cfgfu": str(FORCE_UNIT_CODES.get(cal.force_unit, 0)), "scfgfu": cal.force_unit,
              "cfgtu": str(TORQUE_UNIT_CODES.get(cal.torque_unit, 0)), "scfgtu": cal.torque_unit,
              "cfgcpf": _num(cal.counts_per_force), "cfgcpt": _num(cal.counts_per_torque),
              "cfgmr": _reals(info.max_range), "comrdte": "Enabled"}
    if cal.rdt_rate_hz is not None:
        fields["comrdtrate"] = _num(cal.rdt_rate_hz)
    if cal.buffer_size is not None:
        fields["comrdtbsiz"] = str(cal.buffer_size)
    fields.update(netip=info.address, nethwaddr=info.mac, **(extra or {}))
    return _xml(CONFIG_ROOT, fields)


def calibration_page(cal: Calibration, info: BoxInfo, extra: dict[str, str] | None = None) -> bytes:
    """``/netftcalapi.xml?index=0``: the transducer's calibration."""
    fields = {"calsn": info.serial, "calpn": info.part, "caldt": info.date,
              "calfu": str(FORCE_UNIT_CODES.get(cal.force_unit, 0)), "scalfu": cal.force_unit,
              "caltu": str(TORQUE_UNIT_CODES.get(cal.torque_unit, 0)), "scaltu": cal.torque_unit,
              "calmr": _reals(info.max_range), "calcpf": _num(cal.counts_per_force),
              "calcpt": _num(cal.counts_per_torque), **(extra or {})}
    return _xml(CALIBRATION_ROOT, fields)


def page_fields(data: bytes, page: str) -> dict[str, str]:
    """A page's elements by (lower-case) name; CalibrationError naming the page when it is not XML."""
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise CalibrationError(page, f"not well-formed XML ({exc})") from None
    return {el.tag.rsplit("}", 1)[-1].lower(): (el.text or "").strip() for el in root.iter()}


def read_box(config: bytes, calibration: bytes | None = None, tcp: Calibration | None = None,
             tcp_source: str = "TCP 49151 READCALINFO") -> BoxState:
    """The box as its pages say: counts from the calibration page (``calcpf``/``calcpt``) when it has
    them, else from the TCP interface's READCALINFO (``tcp``, read from ``tcp_source``) when given, else
    the configuration's (``cfgcpf``/``cfgcpt``); the configuration's and the one taken must agree per SI
    unit. CalibrationError names the field at fault."""
    cfg = parse_calibration(config)
    values = page_fields(config, CONFIG_PAGE)
    cal, source = cfg, f"{CONFIG_PAGE} cfgcpf/cfgcpt"
    cal_values = page_fields(calibration, CALIBRATION_PAGE) if calibration is not None else {}
    if "calcpf" in cal_values or "calcpt" in cal_values:
        cpf, cpt = _positive(cal_values, "calcpf"), _positive(cal_values, "calcpt")
        fu, tu = cal_values.get("scalfu", cfg.force_unit), cal_values.get("scaltu", cfg.torque_unit)
        for key, unit, known in (("scalfu", fu, FORCE_UNITS), ("scaltu", tu, TORQUE_UNITS)):
            if unit not in known:
                raise CalibrationError(key, f"unit {unit!r} not known (known: {', '.join(known)})")
        cal = Calibration(cpf, cpt, fu, tu, cfg.rdt_rate_hz, cfg.buffer_size, ("calcpf", "calcpt"))
        source = f"{CALIBRATION_PAGE} calcpf/calcpt"
    elif tcp is not None:
        cal = Calibration(tcp.counts_per_force, tcp.counts_per_torque, tcp.force_unit, tcp.torque_unit,
                          cfg.rdt_rate_hz, cfg.buffer_size, tcp.fields)
        source = f"{tcp_source} {'/'.join(tcp.fields)}"
    if cal is not cfg:
        for ours, theirs, name in ((cal.scale[0], cfg.scale[0], "cfgcpf"), (cal.scale[3], cfg.scale[3], "cfgcpt")):
            if not math.isclose(ours, theirs, rel_tol=1e-9):
                raise CalibrationError(name, f"the configuration's counts per SI unit ({1 / theirs:g}) are not the "
                                       f"calibration's ({1 / ours:g}, {source})")
    return BoxState(cal, source, _counts(values, "setbias"), _int(values, "setcfgsel"), _int(values, "cfgcalsel"),
                    _hex(values, "runstat"), values.get("comrdte", "Enabled") != "Disabled")


def _counts(values: dict[str, str], key: str) -> tuple[int, ...]:
    text = values.get(key)
    if not text:
        return (0,) * 6
    parts = text.replace(";", " ").replace(",", " ").split()
    try:
        counts = tuple(int(p) for p in parts)
    except ValueError:
        raise CalibrationError(key, f"{text!r}: expected six integers") from None
    if len(counts) != 6:
        raise CalibrationError(key, f"{text!r}: expected six integers, not {len(counts)}")
    return counts


def _int(values: dict[str, str], key: str) -> int | None:
    text = values.get(key)
    if text is None:
        return None
    try:
        return int(text)
    except ValueError:
        raise CalibrationError(key, f"{text!r} is not an integer") from None


def _hex(values: dict[str, str], key: str) -> int:
    text = values.get(key, "0")
    try:
        return int(text, 16) if text.lower().startswith("0x") else int(text)
    except ValueError:
        raise CalibrationError(key, f"{text!r} is not a HEX32 status word") from None

