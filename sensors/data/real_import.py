"""Import two-column text logs (``value unix_time_s`` per line) of a sensor and a load cell into a recording.

Made for the Lupasic Velostat logs (../shared/real/velostat-lupasic): the sensor board's raw reading at
about 143 Hz and a Futek load cell at about 250 Hz, both stamped by the same host (unix seconds). The two
streams are resampled by linear interpolation onto one uniform clock over their common span (default
rate: the sensor stream's mean rate rounded to 1 Hz), and also kept as received.

Force units: the Lupasic force logs are already in newtons (the logging host converted them; values
reach 44.8 N for the 40 N target). ``force_units="counts"`` converts load-cell counts -> kg with a
least-squares line through the ``counts kg`` pairs of a calibration file (``futek_calibration.txt``),
then kg -> N with g = 9.80665; ``"kg"`` only multiplies by g.

A malformed line raises ImportLogError naming the file and the 1-based line number.
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

import numpy as np

G = 9.80665
FORCE_UNITS = ("N", "kg", "counts")
MAX_UPSAMPLE = 10.0  # the common clock may run at most this many times faster than the faster of the two logs
_NAME_BAD = re.compile(r"[^A-Za-z0-9_.\-]")

__all__ = ["ImportLogError", "import_logs", "import_runs", "lupasic_pairs", "read_calibration", "read_log"]


class ImportLogError(ValueError):
    """One line: file, line number and what is wrong."""


def read_log(path: str | os.PathLike, what: str = "value") -> tuple[np.ndarray, np.ndarray]:
    """``value time`` lines -> (values, unix times). Blank lines are skipped; anything else must parse."""
    path = Path(path)
    vals: list[float] = []
    times: list[float] = []
    try:
        fh = open(path, "r", encoding="ascii", errors="strict")
    except OSError as exc:
        raise ImportLogError(f"{path}: cannot read ({exc.strerror or exc})") from None
    with fh:
        lineno = 0
        try:
            for lineno, line in enumerate(fh, 1):
                s = line.strip()
                if not s:
                    continue
                toks = s.split()
                if len(toks) != 2:
                    raise ImportLogError(
                        f"{path}:{lineno}: malformed line (expected '{what} unix_time_s', got {len(toks)} fields): {s[:60]!r}"
                    )
                try:
                    v, t = float(toks[0]), float(toks[1])
                except ValueError:
                    raise ImportLogError(f"{path}:{lineno}: malformed line (not two numbers): {s[:60]!r}") from None
                if not (math.isfinite(v) and math.isfinite(t)):
                    raise ImportLogError(f"{path}:{lineno}: malformed line (non-finite number): {s[:60]!r}")
                if times and t < times[-1]:
                    raise ImportLogError(f"{path}:{lineno}: time goes backwards ({t} after {times[-1]})")
                vals.append(v)
                times.append(t)
        except UnicodeDecodeError:
            raise ImportLogError(f"{path}:{lineno + 1}: malformed line (not ASCII text)") from None
    if len(vals) < 2:
        raise ImportLogError(f"{path}: needs at least 2 samples, has {len(vals)}")
    return np.asarray(vals, np.float64), np.asarray(times, np.float64)


def read_calibration(path: str | os.PathLike) -> tuple[float, float, float]:
    """``counts kg`` pairs -> (kg per count, kg offset, rms residual in kg) of a least-squares line."""
    counts, kg = _read_pairs(Path(path))
    A = np.stack([counts, np.ones_like(counts)], 1)
    (slope, offset), *_ = np.linalg.lstsq(A, kg, rcond=None)
    resid = float(np.sqrt(np.mean((A @ [slope, offset] - kg) ** 2)))
    return float(slope), float(offset), resid


def _read_pairs(path: Path) -> tuple[np.ndarray, np.ndarray]:
    a, b = [], []
    try:
        lines = path.read_text(encoding="ascii").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ImportLogError(f"{path}: cannot read ({exc})") from None
    for i, line in enumerate(lines, 1):
        s = line.strip()
        if not s:
            continue
        try:
            x, y = (float(t) for t in s.split())
        except ValueError:
            raise ImportLogError(f"{path}:{i}: malformed line (expected 'counts kg'): {s[:60]!r}") from None
        a.append(x)
        b.append(y)
    if len(a) < 2:
        raise ImportLogError(f"{path}: a calibration needs at least 2 'counts kg' lines")
    return np.asarray(a), np.asarray(b)


def _rate(t: np.ndarray) -> float:
    return (len(t) - 1) / (t[-1] - t[0]) if t[-1] > t[0] else float("nan")


def lupasic_pairs(root: str | os.PathLike) -> list[tuple[Path, Path]]:
    """(sensor log, force log) pairs of a Lupasic data folder: velostat_data/<run>/F beside futek_data/<run>/F."""
    root = Path(root)
    pairs = []
    for s in sorted((root / "velostat_data").glob("*/*.txt"), key=lambda p: (p.parent.name, p.name)):
        f = root / "futek_data" / s.parent.name / s.name
        if f.is_file():
            pairs.append((s, f))
    if not pairs:
        raise ImportLogError(f"{root}: no velostat_data/<run>/*.txt with a matching futek_data/<run>/*.txt")
    return pairs


def import_logs(
    sensor_log: str | os.PathLike,
    force_log: str | os.PathLike,
    out: str | os.PathLike,
    **kw,
) -> Path:
    """One sensor log + one force log -> a recording with one episode (see ``import_runs``)."""
    return import_runs([(sensor_log, force_log)], out, **kw)


def import_runs(
    pairs,
    out: str | os.PathLike,
    *,
    rate_hz: float | None = None,
    force_units: str = "N",
    calibration: str | os.PathLike | None = None,
    sensor_units: str = "raw",
    family: str = "velostat",
) -> Path:
    """Write a recording (source="real") with one episode per (sensor log, force log) pair, named after
    the sensor log's file stem; see the module docstring. Each run is resampled on its own clock."""
    from sensors.data.recording import write_recording

    if force_units not in FORCE_UNITS:
        raise ImportLogError(f"force units must be one of {', '.join(FORCE_UNITS)}; got {force_units!r}")
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
        raise ImportLogError(f"rate must be a finite number > 0 Hz (got {rate_hz}; leave it out for the sensor's own rate)")
    cal = None
    if force_units == "counts":
        if calibration is None:
            raise ImportLogError("force units 'counts' need a calibration file (counts kg per line)")
        slope, offset, resid = read_calibration(calibration)
        cal = {"file": str(calibration), "kg_per_count": slope, "kg_offset": offset, "rms_residual_kg": resid, "g": G}
    episodes, ep_attrs, runs = {}, {}, []
    for sensor_log, force_log in pairs:
        ep = _NAME_BAD.sub("_", Path(sensor_log).stem)
        if ep in episodes:
            ep = f"{ep}-{len(episodes)}"
        episodes[ep], ep_attrs[ep] = _import_pair(Path(sensor_log), Path(force_log), rate_hz, force_units, cal,
                                                  sensor_units)
        runs.append({"episode": ep, "sensor_log": Path(sensor_log).name, "force_log": Path(force_log).name})
        if rate_hz is None:
            rate_hz = ep_attrs[ep]["rate_hz"]  # one clock rate for every run of the file
    rate = rate_hz
    cfg = {"import": {"runs": runs, "rate_hz": rate, "force_units": force_units, "calibration": cal,
                      "sensor_units": sensor_units}}
    return write_recording(
        out,
        episodes,
        source="real",
        config_json=json.dumps(cfg, sort_keys=True),
        root_seed=None,
        shard_index=0,
        sensor_attrs={"family": family, "sample_rate_hz": rate, "units": sensor_units, "n_channels": 1},
        episode_attrs=ep_attrs,
        extra_attrs={"importer": "sensors.real_import"},
    )


def _import_pair(sensor_log: Path, force_log: Path, rate_hz, force_units: str, cal: dict | None, sensor_units: str):
    from sensors.data.recording import Channel
    from sensors.data.resample import MAX_GAP_S
    from sensors.serial.capture import interp_onto

    sv, st = read_log(sensor_log, "value")
    fv, ft = read_log(force_log, "force")
    if cal is not None:
        fv = (fv * cal["kg_per_count"] + cal["kg_offset"]) * G
    elif force_units == "kg":
        fv = fv * G
    t0, t1 = max(st[0], ft[0]), min(st[-1], ft[-1])
    if not t1 > t0:
        raise ImportLogError(f"{sensor_log} and {force_log} do not overlap in time")
    rs, rf = _rate(st), _rate(ft)
    rate = float(rate_hz) if rate_hz is not None else float(round(rs))
    if not rate > 0:
        raise ImportLogError(f"rate must be > 0 Hz, got {rate}")
    top = MAX_UPSAMPLE * max(rs, rf)
    if not rate <= top:
        raise ImportLogError(f"rate {rate:g} Hz is more than {MAX_UPSAMPLE:g}x the logs' own rates (sensor {rs:.1f} Hz, "
                             f"force {rf:.1f} Hz): allowed 0 < rate <= {top:.0f} Hz")
    n = int(math.floor((t1 - t0) * rate)) + 1
    t_rel = np.arange(n) / rate  # exact; absolute unix times near 1.6e9 s carry only ~0.2 us resolution
    grid = t0 + t_rel
    s_i = interp_onto(grid, st, sv, MAX_GAP_S)[:, 0]
    f_i = interp_onto(grid, ft, fv, MAX_GAP_S)[:, 0]
    ch = {
        "time": Channel(t_rel, "s", ("time",), "common clock: seconds since the later of the two streams' starts"),
        "unix_time": Channel(grid, "s", ("time",), "host unix time of the common clock"),
        "sensor": Channel(s_i.astype(np.float32)[:, None], sensor_units, ("time", "channel"),
                          "sensor board reading, linearly interpolated onto the common clock"),
        "force": Channel(f_i.astype(np.float32), "N", ("time",), "load-cell force, linearly interpolated (reference label)"),
        "sensor_native": Channel(sv.astype(np.float32), sensor_units, ("sensor_sample",), "sensor readings as logged"),
        "sensor_unix_time": Channel(st, "s", ("sensor_sample",), "host unix time of each sensor reading"),
        "force_native": Channel(fv.astype(np.float32), "N", ("force_sample",), "load-cell force as logged (N)"),
        "force_unix_time": Channel(ft, "s", ("force_sample",), "host unix time of each load-cell reading"),
    }
    attrs = {
        "sensor_file": str(sensor_log),
        "force_file": str(force_log),
        "sensor_rate_hz": rs,
        "force_rate_hz": rf,
        "sensor_max_gap_s": float(np.max(np.diff(st))),
        "force_max_gap_s": float(np.max(np.diff(ft))),
        "start_offset_s": float(ft[0] - st[0]),
        "start_unix_s": float(t0),
        "duration_s": float(n / rate),
        "rate_hz": rate,
        "force_min_n": float(np.min(fv)),
        "force_max_n": float(np.max(fv)),
        "force_units_in_log": force_units,
        "calibration": cal,
        "n_samples": n,
    }
    return ch, attrs
