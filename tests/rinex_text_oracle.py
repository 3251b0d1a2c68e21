"""An independent reading of RINEX / SP3 text for the reader tests: plain string slicing and
float() per field, written from the format documents (RINEX 2.11 / 3.04, SP3-c), sharing no
code with gnss.rinex / gnss.sp3 and not using georinex. Each record carries the offset where
its text ends, so the records a truncated copy still holds completely are known.

Times are integer nanoseconds since the GPS epoch (seconds ≥ 60 roll into the next minute,
as datetime arithmetic does)."""

from __future__ import annotations

import bz2
import gzip
import io
import zipfile
from dataclasses import dataclass, field
from datetime import datetime
from decimal import Decimal
from pathlib import Path

GPS0 = datetime(1980, 1, 6)


def file_text(path: Path) -> str:
    """Decompressed, Hatanaka-expanded text, leading blank lines dropped."""
    raw = path.read_bytes()
    if raw[:2] == b"\x1f\x8b":
        raw = gzip.decompress(raw)
    elif raw[:3] == b"BZh":
        raw = bz2.decompress(raw)
    elif raw[:2] == b"PK":
        with zipfile.ZipFile(io.BytesIO(raw)) as z:
            raw = z.read(z.namelist()[0])
    elif raw[:2] == b"\x1f\x9d":
        from ncompress import decompress
        raw = decompress(raw)
    text = raw.decode("ascii", errors="replace")
    while text[:1] in ("\n", "\r"):
        text = text[1:]
    if "COMPACT RINEX" in text[:80]:
        import hatanaka
        text = hatanaka.crx2rnx(text)
    return text


def _lines_with_end(text: str) -> list[tuple[str, int]]:
    """(line without its line break, offset just after its last non-blank character: a cut
    of trailing blanks loses nothing)."""
    out, pos = [], 0
    for raw in text.split("\n"):
        line = raw.rstrip("\r")
        out.append((line, pos + len(line.rstrip())))
        pos += len(raw) + 1
    if out and out[-1][0] == "" and text.endswith("\n"):
        out.pop()
    return out


def _ns(y: int, mo: int, d: int, h: int, mi: int, sec: str) -> int:
    base = datetime(y, mo, d, h, mi) - GPS0
    whole_ns = (base.days * 86400 + base.seconds) * 10**9
    return whole_ns + int(Decimal(sec.strip()) * 10**9)


@dataclass
class ObsEpoch:
    t_ns: int
    end: int
    present: dict = field(default_factory=dict)  # "G05" -> set of codes with a value
    sats: dict = field(default_factory=dict)  # decoded epochs: "G05" -> {code: (value, lli)}
    decoded: bool = True


def obs_epochs(text: str, decode_every: int = 1) -> tuple[float, list[str], list[ObsEpoch]]:
    """(version, GPS observation codes, observation epochs with flag 0/1, GPS only). Values
    are decoded at every decode_every-th epoch (all epochs record which codes have a value:
    the last column of a right-aligned F14.3 field is a digit)."""
    lines = _lines_with_end(text)
    version = float(lines[0][0][:9])
    k, codes, declared_sys = 0, [], ""
    while "END OF HEADER" not in lines[k][0]:
        ln = lines[k][0]
        if version < 3 and ln[60:].startswith("# / TYPES OF OBSERV"):
            codes += ln[6:60].split()
        if version >= 3 and ln[60:].startswith("SYS / # / OBS TYPES"):
            if ln[0] != " ":
                declared_sys = ln[0]
            if declared_sys == "G":
                codes += ln[7:60].split()
        k += 1
    k += 1
    epochs: list[ObsEpoch] = []
    n_sat_lines = (len(codes) + 4) // 5
    while k < len(lines):
        ln = lines[k][0]
        if not ln.strip():
            k += 1
            continue
        if version >= 3:
            flag, n = int(ln[31]), int(ln[32:35])
        else:
            flag, n = int(ln[28]), int(ln[29:32])
        if flag > 1 and flag != 6:
            k += 1 + n
            continue
        if version >= 3:
            y, mo, d, h, mi = (int(v) for v in ln[1:18].split())
            sec = ln[18:29]
            sv = []
            rows = []
            for m in range(n):
                row = lines[k + 1 + m][0]
                sv.append(row[:3])
                rows.append(row[3:])
            end = lines[k + n][1]
            k += 1 + n
        else:
            yy, mo, d, h, mi = (int(v) for v in ln[:15].split())
            y = 1900 + yy if yy >= 80 else 2000 + yy
            sec = ln[15:26]
            sv = []
            m = 0
            while len(sv) < n:
                row = lines[k + m][0]
                sv += [row[32 + 3 * q:35 + 3 * q] for q in range(min(12, n - len(sv)))]
                m += 1
            k += m
            rows = []
            for _ in range(n):
                rows.append("".join(lines[k + q][0].ljust(80) for q in range(n_sat_lines)))
                k += n_sat_lines
            end = lines[k - 1][1]
        if flag == 6:
            continue
        ep = ObsEpoch(_ns(y, mo, d, h, mi, sec), end, decoded=len(epochs) % decode_every == 0)
        for s, row in zip(sv, rows):
            if s[0] not in "G ":
                continue
            sat = "G" + s[1:].replace(" ", "0")
            row = row.ljust(16 * len(codes))
            ep.present[sat] = {c for q, c in enumerate(codes) if row[16 * q + 13] != " "}
            if not ep.decoded:
                continue
            vals = {}
            for q, code in enumerate(codes):
                chunk = row[16 * q:16 * q + 16]
                num = chunk[:14].strip()
                lli = chunk[14:15].strip()
                vals[code] = (float(num) if num else None, int(lli) if lli else 0)
            ep.sats[sat] = vals
        epochs.append(ep)
    return version, codes, epochs


@dataclass
class NavRecord:
    prn: int
    toc_ns: int
    end: int
    values: list  # the 29 numbers after the epoch: af0 af1 af2, then 4 per orbit line


def _num(s: str) -> float | None:
    s = s.strip().replace("D", "E").replace("d", "e")
    return float(s) if s else None


def nav_gps_records(text: str) -> tuple[float, list[NavRecord]]:
    lines = [(ln, e) for ln, e in _lines_with_end(text)]
    version = float(lines[0][0][:9])
    k = next(i for i, (ln, _) in enumerate(lines) if "END OF HEADER" in ln) + 1
    body = [(ln, e) for ln, e in lines[k:] if ln.strip()]
    out = []
    i = 0
    while i < len(body):
        first = body[i][0]
        size = 8 if version < 3 or first[0] not in "RS" else 4
        if version >= 3 and first[0] != "G":
            i += size
            continue
        if version >= 3:
            prn = int(first[1:3])
            y, mo, d, h, mi = (int(v) for v in first[3:20].split())
            sec, head, pre = first[20:23], first[23:], 4
        else:
            prn = int(first[:2])
            yy, mo, d, h, mi = (int(v) for v in first[2:17].split())
            y = 1900 + yy if yy >= 80 else 2000 + yy
            sec, head, pre = first[17:22], first[22:], 3
        vals = [_num(head[19 * q:19 * q + 19]) for q in range(3)]
        for m in range(1, 8):
            row = body[i + m][0][pre:]
            vals += [_num(row[19 * q:19 * q + 19]) for q in range(4)]
        out.append(NavRecord(prn, _ns(y, mo, d, h, mi, sec), body[i + 7][1], vals))
        i += size
    return version, out


# order of the 29 numbers of a GPS record (RINEX 2.11 Table A4 / 3.04 Table A6)
NAV_ORDER = ("af0", "af1", "af2", "iode", "crs", "delta_n", "m0", "cuc", "e", "cus", "sqrt_a",
             "toe_sow", "cic", "omega0", "cis", "i0", "crc", "omega", "omega_dot", "idot",
             "l2_codes", "week", "l2p", "accuracy", "health", "tgd", "iodc", "t_tx",
             "fit_interval_h")


@dataclass
class Sp3Epoch:
    t_ns: int
    end: int
    pos: dict = field(default_factory=dict)  # prn -> (x, y, z km, clock µs)


def sp3_gps_epochs(text: str) -> list[Sp3Epoch]:
    epochs: list[Sp3Epoch] = []
    for ln, end in _lines_with_end(text):
        if ln.startswith("*"):
            p = ln[1:].split()
            epochs.append(Sp3Epoch(_ns(int(p[0]), int(p[1]), int(p[2]), int(p[3]), int(p[4]),
                                       p[5]), end))
        elif ln.startswith("P") and epochs:
            # the reader uses columns 1-60 (the std-devs and flags after them are not read)
            epochs[-1].end = end - len(ln.rstrip()) + min(len(ln.rstrip()), 60)
            if ln[1] in "G ":
                x, y, z = (float(ln[a:a + 14]) for a in (4, 18, 32))
                c = ln[46:60].strip()
                epochs[-1].pos[int(ln[2:4])] = (x, y, z, float(c) if c else 999999.999999)
        elif ln.startswith("EOF"):
            break
    return epochs
