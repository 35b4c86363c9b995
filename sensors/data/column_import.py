"""Import any column log (whitespace / CSV text) of one or two streams into a recording, from a spec.

A spec (``ImportSpec``, YAML or one of the built-in ``LAYOUTS``) names, per stream:
  * the files (a glob under the data folder) and a regex whose ``key`` group pairs the files of the two
    streams into one episode (default: the file stem);
  * the columns: index, name, units, role (``signal`` | ``time`` | ``event``) and an optional calibration of
    raw counts: linear (``scale``, ``offset``), two points (``points: [[raw, value], [raw, value]]``) or a
    weight-calibration file (``file``: ``counts kg`` pairs, or ``no weight: C`` / ``20g weight: C`` lines);
  * the clock: a time column (``time_units`` s/ms/us/ns), a stated ``sample_rate_hz``, or an uncertain
    ``sample_period_range_s: [lo, hi]`` (the clock uses the middle; the range is recorded per episode);
  * event columns (strings, optional on each line) are kept as the episode attribute ``events``
    ([{time_s, label}]) with the value of the other columns allowed to be absent only there.
Two streams are resampled by linear interpolation onto one uniform clock over their common span (default:
the first stream's rate rounded to 1 Hz; both need a time column or a stated rate); the logged samples are
kept beside (``<name>_native``, ``<stream>_time``). The first signal of the input stream is written as
``input`` ([T, 1], ``time, channel``), the target as ``target`` ([T], the label).
Episode attributes taken from the file name (``name_attrs``: regex with one group, times ``scale``) carry
e.g. the reference resistor of a divider (``reference_resistor_ohm``).

A bad file or spec raises ImportLogError, one line naming the file and the 1-based line number.
"""

from __future__ import annotations

import fnmatch
import json
import math
import os
import re
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from sensors.data.real_import import G, ImportLogError

__all__ = ["LAYOUTS", "ImportSpec", "import_columns", "load_spec", "read_columns", "read_weight_calibration"]

TIME_SCALE = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
# the target (force label) is written in N: a log in another force unit, or in the mass a scale shows (g, kg: its
# weight, standard gravity 9.80665 m/s^2, ISO 80000-3), is converted on import
FORCE_TO_N = {"N": 1.0, "mN": 1e-3, "kN": 1e3, "g": 9.80665e-3, "gf": 9.80665e-3, "kg": 9.80665, "kgf": 9.80665,
              "lbf": 4.4482216152605}


def to_newtons(values: np.ndarray, units: str, where: str) -> np.ndarray:
    """A force label in N from its recorded unit (FORCE_TO_N); ValueError naming ``where`` for a unit that is no
    force (a capture records it with --units / --units2, an import with the column's units)."""
    if units not in FORCE_TO_N:
        raise ValueError(f"{where} is in {units!r}, not a force (allowed: {', '.join(FORCE_TO_N)}; a capture records "
                         "it with --units / --units2, an import with the column's units)")
    return values if units == "N" else values * FORCE_TO_N[units]
_DELIMS = {"whitespace": None, "comma": ",", "semicolon": ";", "tab": "\t"}
_NAME_BAD = re.compile(r"[^A-Za-z0-9_.\-]")
_NAME_OK = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


class _M(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Calibration(_M):
    """raw -> value: ``scale * raw + offset``, or the line through ``points``, or a calibration ``file``."""

    scale: float = 1.0
    offset: float = 0.0
    points: list[tuple[float, float]] | None = None  # [(raw, value), ...], >= 2, least-squares line
    file: str | None = None  # relative to the data folder: 'counts kg' pairs or 'no weight: C' / '20g weight: C'
    file_to_newton: bool = True  # a file gives mass; value = mass * g (N)

    @model_validator(mode="after")
    def _check(self):
        if self.points is not None and self.file is not None:
            raise ValueError("give calibration points or a calibration file, not both")
        if self.points is not None and len(self.points) < 2:
            raise ValueError("a calibration needs at least 2 points")
        return self


class Column(_M):
    index: int = Field(ge=0)
    name: str
    units: str = "1"
    role: Literal["signal", "time", "event"] = "signal"
    time_units: Literal["s", "ms", "us", "ns"] = "s"
    calibration: Calibration | None = None

    @model_validator(mode="after")
    def _check(self):
        if not _NAME_OK.match(self.name):
            raise ValueError(f"column name {self.name!r} must be letters, digits, '_' (starting with a letter)")
        if self.role == "time" and "units" in self.model_fields_set:  # `units: ms` on a time column is its time unit
            if self.units not in TIME_SCALE:
                raise ValueError(f"time column {self.name!r}: units {self.units!r} (allowed: {', '.join(TIME_SCALE)})")
            if "time_units" in self.model_fields_set and self.time_units != self.units:
                raise ValueError(f"time column {self.name!r}: units {self.units!r} and time_units {self.time_units!r} differ")
            self.time_units = self.units
        return self


class NameAttr(_M):
    regex: str  # one group, a number (or a resistance), searched in the file name
    scale: float = 1.0
    kind: Literal["number", "resistance"] = "number"  # resistance: "10k", "4.7k", "4k7", "470R", "1M" (IEC 60062 RKM)


_RKM = re.compile(r"^(\d+(?:\.\d+)?)([RrKkMm]?)(\d*)$")


def parse_resistance(text: str) -> float | None:
    """Ohms from a resistor's value as written in a file name: 10k, 4.7k, 4k7, 2K2, 470R, 470, 1M (the RKM code of
    IEC 60062: the letter is the decimal point and the multiplier); None where it is none of these."""
    m = _RKM.match(text.strip())
    if not m or (m[3] and ("." in m[1] or not m[2])):
        return None
    mult = {"": 1.0, "r": 1.0, "k": 1e3, "m": 1e6}[m[2].lower()]
    return float(f"{m[1]}.{m[3]}" if m[3] else m[1]) * mult


class Stream(_M):
    name: str
    glob: str
    key: str | None = None  # regex on the path relative to the data folder; group 'key' (default: the stem)
    columns: list[Column]
    delimiter: Literal["auto", "whitespace", "comma", "semicolon", "tab"] = "auto"
    comment: str = "#"
    header_lines: int = Field(0, ge=0)
    sample_rate_hz: float | None = Field(None, gt=0)
    sample_period_range_s: tuple[float, float] | None = None
    name_attrs: dict[str, NameAttr] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _check(self):
        times = [c for c in self.columns if c.role == "time"]
        sig = [c for c in self.columns if c.role == "signal"]
        if len(times) > 1:
            raise ValueError(f"stream {self.name}: at most one time column")
        if not sig:
            raise ValueError(f"stream {self.name}: needs a signal column")
        n_clock = bool(times) + (self.sample_rate_hz is not None) + (self.sample_period_range_s is not None)
        if n_clock != 1:
            raise ValueError(f"stream {self.name}: give exactly one of a time column, sample_rate_hz, sample_period_range_s")
        if self.sample_period_range_s is not None:
            lo, hi = self.sample_period_range_s
            if not 0 < lo <= hi:
                raise ValueError(f"stream {self.name}: sample_period_range_s must be 0 < lo <= hi")
        idx = [c.index for c in self.columns]
        if len(set(idx)) != len(idx):
            raise ValueError(f"stream {self.name}: two columns share an index")
        return self

    @property
    def has_time(self) -> bool:
        return any(c.role == "time" for c in self.columns)

    def rate_hz(self) -> float | None:
        if self.sample_rate_hz:
            return self.sample_rate_hz
        if self.sample_period_range_s:
            return 2.0 / (self.sample_period_range_s[0] + self.sample_period_range_s[1])
        return None


class ImportSpec(_M):
    name: str = "custom"
    family: str = "generic"
    streams: list[Stream] = Field(min_length=1, max_length=2)
    input: str = "sensor"  # column name of the reading (first signal of its stream if not found)
    target: str = "force"
    rate_hz: float | None = Field(None, gt=0)  # common clock of two streams
    sensor_attrs: dict[str, Any] = Field(default_factory=dict)  # e.g. adc_bits, adc_samples_summed, units

    @model_validator(mode="after")
    def _check(self):
        names = [c.name for s in self.streams for c in s.columns]
        if len(set(names)) != len(names):
            raise ValueError("column names must be unique across streams")
        sig = {c.name for s in self.streams for c in s.columns if c.role == "signal"}
        for what in ("input", "target"):
            if getattr(self, what) not in sig:
                raise ValueError(f"{what} {getattr(self, what)!r} is not a signal column (have {', '.join(sorted(sig))})")
        tu = next(c.units for s in self.streams for c in s.columns if c.name == self.target)
        if tu not in FORCE_TO_N:
            raise ValueError(f"target {self.target!r}: units {tu!r} is not a force (allowed: {', '.join(FORCE_TO_N)}; "
                             "a scale's g / kg are read as their weight)")
        if len(self.streams) == 2 and not all(s.has_time or s.rate_hz() for s in self.streams):
            raise ValueError("two streams need a time column or a stated rate each")
        return self


# ------------------------------------------------------------------------------------------- built-in layouts

LAYOUTS: dict[str, dict[str, Any]] = {
    # Lupasic UR5 speed sweep: speed_<v>/attempt_<k>/exp_<v>_<k>.txt (sensor) + exp_futek_<v>_<k>.txt (N, events)
    "lupasic-sweep": {
        "name": "lupasic-sweep", "family": "velostat", "input": "sensor", "target": "force",
        "sensor_attrs": {"units": "raw"},
        "streams": [
            {"name": "sensor", "glob": "speed_*/attempt_*/exp_[0-9]*.txt",
             "key": r"(?P<key>speed_[^/]+/attempt_\d+)/",
             "columns": [{"index": 0, "name": "sensor", "units": "raw"},
                         {"index": 1, "name": "t", "role": "time", "time_units": "s"}]},
            {"name": "force", "glob": "speed_*/attempt_*/exp_futek_*.txt",
             "key": r"(?P<key>speed_[^/]+/attempt_\d+)/",
             "columns": [{"index": 0, "name": "force", "units": "N"},
                         {"index": 1, "name": "t_force", "role": "time", "time_units": "s"},
                         {"index": 2, "name": "event", "role": "event"}]},
        ],
    },
    # TAMS array calibration: 'loadcell_counts adc_sum' lines, no time; 10-20 ms per line (firmware 10 ms wait)
    "tams": {
        "name": "tams", "family": "divider", "input": "sensor", "target": "force",
        "sensor_attrs": {"units": "counts", "adc_bits": 10, "adc_samples_summed": 5, "adc_full_scale": 5115,
                         "reading_falls_with_force": True, "tip": "6 mm cylinder", "tip_diameter_m": 0.006},
        "streams": [
            {"name": "log", "glob": "*-*-*.txt", "key": r"(?P<key>[^/]+)\.\d+\.\d+\.txt$",
             "sample_period_range_s": [0.010, 0.020],
             "name_attrs": {"reference_resistor_ohm": {"regex": r"^(\d+(?:\.\d+)?[RrKkMm]?\d*)-", "kind": "resistance"}},
             "columns": [{"index": 0, "name": "force", "units": "N", "calibration": {"file": "calibration2.txt"}},
                         {"index": 1, "name": "sensor", "units": "counts"}]},
        ],
    },
}


def load_spec(spec: str | os.PathLike | dict) -> ImportSpec:
    """A built-in layout name, a YAML/JSON file, or a dict -> ImportSpec (ImportLogError: one line)."""
    if isinstance(spec, dict):
        data, where = spec, "spec"
    elif str(spec) in LAYOUTS:
        data, where = LAYOUTS[str(spec)], f"layout {spec}"
    else:
        p = Path(spec)
        if not p.is_file():
            raise ImportLogError(f"{p}: no such spec file (built-in layouts: {', '.join(LAYOUTS)})")
        import yaml

        try:
            data = yaml.safe_load(p.read_text())
        except yaml.YAMLError as exc:
            line = getattr(getattr(exc, "problem_mark", None), "line", None)
            raise ImportLogError(f"{p}:{'' if line is None else line + 1}: not valid YAML") from None
        where = str(p)
    try:
        return ImportSpec.model_validate(data)
    except ValidationError as exc:
        e = exc.errors()[0]
        loc = ".".join(str(x) for x in e["loc"])
        raise ImportLogError(f"{where}: {loc + ': ' if loc else ''}{e['msg']}") from None


# ------------------------------------------------------------------------------------------- reading

def read_weight_calibration(path: Path) -> list[tuple[float, float]]:
    """(counts, kg) points of a calibration file: 'counts kg' pairs, or 'no weight: C' / '<m>g weight: C'
    (also kg) lines; other 'key: value' lines (tip, resistance) are ignored."""
    pts: list[tuple[float, float]] = []
    try:
        lines = path.read_text(encoding="ascii").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ImportLogError(f"{path}: cannot read ({exc})") from None
    wre = re.compile(r"^\s*(no|(\d+(?:\.\d+)?)\s*(g|kg))\s+weight\s*:\s*([-+0-9.eE]+)\s*$", re.IGNORECASE)
    for i, line in enumerate(lines, 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        m = wre.match(s)
        if m:
            kg = 0.0 if m.group(1).lower() == "no" else float(m.group(2)) * (1e-3 if m.group(3).lower() == "g" else 1.0)
            try:
                pts.append((float(m.group(4)), kg))
            except ValueError:
                raise ImportLogError(f"{path}:{i}: malformed weight line: {s[:60]!r}") from None
            continue
        if ":" in s:
            continue  # tip: ..., resistance: ...
        toks = s.replace(",", " ").split()
        try:
            a, b = (float(t) for t in toks)
        except ValueError:
            raise ImportLogError(f"{path}:{i}: malformed line (expected 'counts kg' or 'no weight: C'): {s[:60]!r}") from None
        pts.append((a, b))
    pts = sorted(set(pts))
    if len({p[0] for p in pts}) < 2:
        raise ImportLogError(f"{path}: a calibration needs at least 2 distinct points")
    return pts


def _cal_line(cal: Calibration, root: Path) -> tuple[float, float, dict[str, Any]]:
    """(scale, offset, record) of value = scale * raw + offset."""
    if cal.points is None and cal.file is None:
        return cal.scale, cal.offset, {"kind": "linear", "scale": cal.scale, "offset": cal.offset}
    if cal.file is not None:
        f = root / cal.file
        pts = read_weight_calibration(f)
        k = G if cal.file_to_newton else 1.0
        pts = [(c, m * k) for c, m in pts]
        src = str(f)
    else:
        pts, src = list(cal.points), "spec"
    x = np.array([p[0] for p in pts], float)
    y = np.array([p[1] for p in pts], float)
    if np.ptp(x) == 0:
        raise ImportLogError(f"{src}: calibration points share one raw value")
    A = np.stack([x, np.ones_like(x)], 1)
    (s, o), *_ = np.linalg.lstsq(A, y, rcond=None)
    return float(s), float(o), {"kind": "two_point" if len(pts) == 2 else "least_squares", "points": pts,
                                "source": src, "scale": float(s), "offset": float(o),
                                "g_m_per_s2": G if cal.file is not None and cal.file_to_newton else None}


def _split(line: str, delimiter: str) -> list[str]:
    if delimiter == "auto":
        delimiter = "comma" if "," in line else ("semicolon" if ";" in line else "whitespace")
    d = _DELIMS[delimiter]
    return [t.strip() for t in line.split(d)] if d else line.split()


def read_columns(path: Path, st: Stream) -> tuple[dict[str, np.ndarray], list[tuple[int, str]]]:
    """Numeric columns (name -> [n]) and events [(row, label)] of one stream file."""
    num = [c for c in st.columns if c.role != "event"]
    ev = [c for c in st.columns if c.role == "event"]
    need = max(c.index for c in num) + 1
    vals: list[list[float]] = []
    events: list[tuple[int, str]] = []
    try:
        fh = open(path, "r", encoding="ascii", errors="strict")
    except OSError as exc:
        raise ImportLogError(f"{path}: cannot read ({exc.strerror or exc})") from None
    tcol = next((c for c in st.columns if c.role == "time"), None)
    last_t = -math.inf
    with fh:
        lineno = 0
        try:
            for lineno, line in enumerate(fh, 1):
                s = line.strip()
                if lineno <= st.header_lines or not s or (st.comment and s.startswith(st.comment)):
                    continue
                toks = _split(s, st.delimiter)
                if len(toks) < need:
                    raise ImportLogError(f"{path}:{lineno}: malformed line (expected at least {need} columns, got {len(toks)}): {s[:60]!r}")
                row = []
                for c in num:
                    try:
                        v = float(toks[c.index])
                    except ValueError:
                        raise ImportLogError(f"{path}:{lineno}: column {c.index} ({c.name}) is not a number: {toks[c.index][:30]!r}") from None
                    if not math.isfinite(v):
                        raise ImportLogError(f"{path}:{lineno}: column {c.index} ({c.name}) is not finite")
                    row.append(v)
                if tcol is not None:
                    t = row[num.index(tcol)]
                    if t < last_t:
                        raise ImportLogError(f"{path}:{lineno}: time goes backwards ({t} after {last_t})")
                    last_t = t
                for c in ev:
                    if c.index < len(toks) and toks[c.index]:
                        events.append((len(vals), " ".join(toks[c.index:]) if c.index == max(x.index for x in st.columns) else toks[c.index]))
                max_idx = max(c.index for c in st.columns)
                if len(toks) > max_idx + 1 and not (ev and max(x.index for x in ev) == max_idx):
                    raise ImportLogError(f"{path}:{lineno}: malformed line ({len(toks)} columns, the spec has {max_idx + 1}): {s[:60]!r}")
                vals.append(row)
        except UnicodeDecodeError:
            raise ImportLogError(f"{path}:{lineno + 1}: malformed line (not ASCII text)") from None
    if len(vals) < 2:
        raise ImportLogError(f"{path}: needs at least 2 samples, has {len(vals)}")
    a = np.asarray(vals, np.float64)
    return {c.name: a[:, i] for i, c in enumerate(num)}, events


def _key(rel: str, st: Stream) -> str:
    if st.key:
        m = re.search(st.key, rel)
        if not m:
            return ""
        return m.groupdict().get("key") or m.group(0)
    return Path(rel).stem


def find_episodes(root: Path, spec: ImportSpec) -> dict[str, list[Path]]:
    """Episode key -> one file per stream (files under root matching each stream's glob, paired by key)."""
    per = []
    for st in spec.streams:
        files = sorted(p for p in root.rglob("*") if p.is_file() and fnmatch.fnmatch(p.relative_to(root).as_posix(), st.glob))
        if root.is_file():
            files = [root]
        d: dict[str, Path] = {}
        for f in files:
            k = _key(f.relative_to(root).as_posix() if root.is_dir() else f.name, st)
            if k:
                if k in d:
                    raise ImportLogError(f"{f}: stream {st.name} has two files for episode {k!r} ({d[k].name})")
                d[k] = f
        per.append(d)
    keys = sorted(set(per[0]).intersection(*per[1:]))
    if not keys:
        raise ImportLogError(f"{root}: no file matches {' + '.join(s.glob for s in spec.streams)} (spec {spec.name})")
    return {k: [d[k] for d in per] for k in keys}


def import_columns(root: str | os.PathLike, spec: ImportSpec | str | dict, out: str | os.PathLike, *,
                   rate_hz: float | None = None, files: list[list[Path]] | None = None) -> Path:
    """Write a recording (source="real"), one episode per paired set of files under ``root``; see the module."""
    from sensors.data.recording import Channel, write_recording
    from sensors.data.resample import MAX_GAP_S
    from sensors.serial.capture import gaps_of, interp_onto

    spec = spec if isinstance(spec, ImportSpec) else load_spec(spec)
    root = Path(root)
    if not root.exists():
        raise ImportLogError(f"{root}: does not exist")
    eps = find_episodes(root, spec) if files is None else {_NAME_BAD.sub("_", Path(f[0]).stem): f for f in files}
    base = root if root.is_dir() else root.parent
    cals: dict[str, tuple[float, float, dict]] = {}
    for st in spec.streams:
        for c in st.columns:
            if c.calibration is not None:
                cals[c.name] = _cal_line(c.calibration, base)
    rate_common = rate_hz or spec.rate_hz
    episodes, ep_attrs, runs = {}, {}, []
    for key, paths in eps.items():
        ep = _NAME_BAD.sub("_", key.replace("/", "-"))
        streams = []
        for st, p in zip(spec.streams, paths):
            cols, events = read_columns(Path(p), st)
            for n, (s, o, _) in cals.items():
                if n in cols:
                    cols[n] = cols[n] * s + o
            tcol = next((c for c in st.columns if c.role == "time"), None)
            n = len(next(iter(cols.values())))
            if tcol is not None:
                t = cols.pop(tcol.name) * TIME_SCALE[tcol.time_units]
            else:
                t = np.arange(n) / st.rate_hz()
            streams.append((st, p, cols, t, events))
        if len(streams) == 2:
            t0 = max(s[3][0] for s in streams)
            t1 = min(s[3][-1] for s in streams)
            if not t1 > t0:
                raise ImportLogError(f"{paths[0]} and {paths[1]} do not overlap in time")
        else:
            t0, t1 = streams[0][3][0], streams[0][3][-1]
        st0 = streams[0]
        own_rate = (len(st0[3]) - 1) / (st0[3][-1] - st0[3][0])
        rate = float(rate_common or (round(own_rate) if st0[0].has_time else st0[0].rate_hz()))
        if not (math.isfinite(rate) and rate > 0):
            raise ImportLogError(f"{paths[0]}: its time column gives {own_rate:.3g} samples per second; check the "
                                 "column's time unit (units: s, ms, us or ns)")
        nT = int(math.floor((t1 - t0) * rate + 1e-9)) + 1
        t_rel = np.arange(nT) / rate
        grid = t0 + t_rel
        ch = {"time": Channel(t_rel, "s", ("time",), "common clock: seconds since the start of the common span")}
        attrs: dict[str, Any] = {"rate_hz": rate, "duration_s": float(nT / rate), "n_samples": nT, "start_time_s": float(t0)}
        evs = []
        for st, p, cols, t, events in streams:
            attrs[f"{st.name}_file"] = str(p)
            attrs[f"{st.name}_rate_hz"] = float((len(t) - 1) / (t[-1] - t[0]))
            if st.sample_period_range_s:
                attrs[f"{st.name}_sample_period_range_s"] = list(st.sample_period_range_s)
                attrs["time_uncertain"] = True
            for an, na in st.name_attrs.items():
                m = re.search(na.regex, Path(p).name)
                v = None if not m else parse_resistance(m.group(1)) if na.kind == "resistance" else float(m.group(1))
                if v is not None:
                    attrs[an] = v * na.scale
                else:  # named in the import's summary line
                    attrs.setdefault("name_attrs_missing", []).append(an)
            if len(streams) == 2:
                ch[f"{st.name}_time"] = Channel(t - t0, "s", (f"{st.name}_sample",), f"time of each {st.name} sample as logged")
            for c in st.columns:
                if c.role != "signal":
                    continue
                v = cols[c.name]
                same = len(streams) == 1 and nT == len(v)
                vi = v if same else interp_onto(grid, t, v, MAX_GAP_S)[:, 0]
                if not same and (gaps := gaps_of(t, MAX_GAP_S)):  # left empty (NaN), not bridged by a made-up line
                    attrs[f"{c.name}_gaps_s"] = [[g0 - t0, gl] for g0, gl in gaps]
                desc = f"column {c.index} of the {st.name} log" + (", calibrated" if c.name in cals else "") + \
                       ("" if same else ", linearly interpolated onto the common clock")
                units = c.units
                if c.name == spec.target and c.units != "N":  # FORCE_TO_N
                    k = FORCE_TO_N[c.units]
                    v, vi, units = v * k, vi * k, "N"
                    desc += f", converted from {c.units} (x {k:g} N)"
                    attrs[f"{c.name}_units_logged"] = c.units
                if c.name == spec.input:
                    ch[c.name] = Channel(vi.astype(np.float32)[:, None], units, ("time", "channel"), desc)
                else:
                    ch[c.name] = Channel(vi.astype(np.float32), units, ("time",), desc)
                if not same:
                    ch[f"{c.name}_native"] = Channel(v.astype(np.float32), units, (f"{st.name}_sample",), f"{c.name} as logged")
                attrs[f"{c.name}_min"] = float(np.min(v))
                attrs[f"{c.name}_max"] = float(np.max(v))
            evs += [{"time_s": float(t[i] - t0), "label": lab} for i, lab in events]
        attrs["events"] = sorted(evs, key=lambda e: e["time_s"])
        attrs["calibrations"] = {n: c[2] for n, c in cals.items()}
        episodes[ep], ep_attrs[ep] = ch, attrs
        runs.append({"episode": ep, "files": [str(p) for p in paths]})
    rate0 = next(iter(ep_attrs.values()))["rate_hz"]
    cfg = {"import": {"spec": spec.model_dump(mode="json"), "runs": runs}}
    sattrs = {"family": spec.family, "sample_rate_hz": rate0, "n_channels": 1, "input": spec.input,
              "target": spec.target, **spec.sensor_attrs}
    sattrs.setdefault("units", "raw")
    return write_recording(out, episodes, source="real", config_json=json.dumps(cfg, sort_keys=True), root_seed=None,
                           shard_index=0, sensor_attrs=sattrs, episode_attrs=ep_attrs,
                           extra_attrs={"importer": "sensors.data.column_import", "layout": spec.name})
