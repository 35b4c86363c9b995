"""Identify a whole piezoresistive sensing chain from a real capture (force + reading), with ranges.

Chain (one taxel or one film pressed by one tip; all SI):
  contact   p = F / A_tip; press j lands at a random place on a spatially varying film: its conductance
            level is multiplied by exp(-l_j), l_j ~ N(0, level_log_sd^2) (velostat: film random field,
            sensors/velostat/model.py film_field; curved mount: partial contact), and with probability
            miss_prob the press does not reach the active area (no response, as a third of a Lupasic
            series' low-force samples).
  film      R_film = r0_ohm * exp(l_j) * ((F + c) / F_ref)^-n, F_ref = 1 N (power law G ~ p^n: Holm,
            Electric Contacts 1967; velostat paper Fig. 13b); the tip area only rescales r0 and F_c (p = F / A),
            so from force and reading alone A is not identifiable: it is taken from the user (tip) and kept.
  tunneling (optional, tunnel_force_n = F_t > 0) R_film x exp(-F_e / F_t), F_e = F + c: the filler gaps close with
            the composite's strain, and the tunneling resistance across a gap s = s0 (1 - eps) falls as
            exp(-gamma s0 eps), eps ~ F / (A M) (Zhang, Pan, Zheng & Yi, J. Polym. Sci. B 38, 2739, 2000; Simmons,
            J. Appl. Phys. 34, 1793, 1963), so F_t = A M / (gamma s0): d ln R / d ln F = -(n + F / F_t), a law that
            steepens with force (the TAMS taxels: ~1 at 0.05 N, ~3.5 at 0.5 N); F_t = 0: off (rounds 1-11).
  creep     c = sum_k c_k, c_k[t] = d_k c_k[t-1] + (1 - d_k) w_k Phi(F), Phi = a F_c ln(1 + F / F_c),
            d_k = exp(-dt / tau_k), tau_k log-spaced in [tau_min, tau_max], w_k = 1 / K (Schapery-type
            log-time creep as sensors/velostat/reference.py, written in force units): creep_law "force".
            creep_law "aging" (contact aging, Dieterich & Kilgore 1994: the real contact area, so the
            conductance, grows by a load-independent fraction per log time of hold): R_film = r0 e^l (F / F_ref)^-n
            e^-c, c_k driven by Phi = a F / (F + F_c) (a: ln conductance gained at full aging; F_c: the force that
            establishes the contact). Its steady state is a constant in ln R above F_c, so it leaves the force law
            to the exponent; in force units it adds ~a F_c ln(1 + F / F_c) to F and flattens the law (measured on
            the Lupasic runs: the hold drop is ~0.17 ln at 1 to 40 N, bench/bench_s2r_diagnose.py).
  readout   R = R_film + r_series (traces, mux), in parallel with r_leak (unloaded: the leak alone);
            divider with reference resistor r_ref: reading = offset + FS * R / (R + r_ref)  ("high": the taxel
            on the ADC side, reading rises with resistance and falls with force: the Lupasic board, TAMS) or
            offset + FS * r_ref / (R + r_ref) ("low": the reference on the ADC side, reading rises with force:
            the FSR's basic circuit, Interlink FSR Integration Guide fig. 9); reading_direction tells them apart
            from the capture; FS = full scale (ADC counts x samples summed, or the board's rest
            level); noise: white, noise_sd in reading units; ADC step adc_step (0: none).
Fit (scipy least_squares, trust-region reflective, bounded; with level_prior, random-effects levels: fit_chain) of ln R on loaded samples (R from the reading
through the inverse divider), each press's level l_j profiled out (its mean log residual): theta =
[n, ln a, ln F_c, ln tau_min, ln tau_max] (+ ln r_series when the readout saturates). Then ln r0 = mean of
the press levels, level_log_sd = their std (the press-to-press spread is a parameter of the model, drawn
per press when generating, not subtracted), miss_prob = share of loaded presses that stay at the rest
level. Ranges: bootstrap over presses (resample presses with replacement, refit), 5-95 % per parameter;
the levels are hierarchical, l_{run,j} = mu + u_run + e_j (run_level_sd: within-run and run-level sd, the latter
with a prior where there are few runs), and the predictive 90 % band of a press of a new run is
mean +- 1.645 sqrt(sd_w^2 + sd_run^2 + se^2), se^2 = sd_run^2 / runs + sd_w^2 / presses (at the point fit's
shape; see fit_chain and new_run_band90).
Hysteresis: the creep bank is the chain's (rate-dependent) hysteresis; no rate-independent (play) bank is
fitted (the velostat model has none).
Label latency (label_latency_s, a property of the rig, not of the sensor): two streams stamped by one host clock on
receipt carry each instrument's own delay (serial buffering, a load-cell amplifier's filter), so the recorded force
may arrive late against the reading. A reading cannot respond before its load (causality), so where the reading
leads the force label (the peak of their correlation, `reading_lag_s`, at a negative lag) the label is late by at
least that much: the Lupasic load cell by 0.10-0.17 s (session 22). The fit then reads each force label that much
earlier (`align_labels`), and the generation records its labels that much late, as the rig does. A reading that
follows its force (a positive lag) may be the film's own creep, which the chain models: no latency is read then.
The premise holds where the label is the force on the film; a load cell under a mount that carries force past the
film breaks it. On the Lupasic runs (a curved leg) the lined-up fits were worse (bench/bench_s2r_latency.py), so it
is an option (`fit_chain(latency=True)`, `piezotwin sim2real --latency`), not the default.
"""

from __future__ import annotations

import fnmatch
import json
from collections.abc import Sequence as Seq
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "ChainFit",
    "ChainParams",
    "Press",
    "RealRun",
    "evaluate",
    "align_labels",
    "fit_chain",
    "label_latency",
    "load_real_runs",
    "reading_from_resistance",
    "resistance_from_reading",
    "simulate_reading",
]

F_REF_N = 1.0


@dataclass
class ChainParams:
    exponent: float = 1.0  # estimate
    r0_ohm: float = 1.0e3  # estimate: film resistance at 1 N, mean placement
    creep_amplitude: float = 0.5  # estimate
    creep_force_n: float = 5.0  # estimate: F_c = p_c A_tip
    tau_min_s: float = 0.3  # estimate
    tau_max_s: float = 30.0  # estimate
    n_creep: int = 4
    creep_law: str = "force"  # "force": c adds to F; "aging": c multiplies the conductance by e^c (see module doc)
    level_log_sd: float = 0.0  # press-to-press std of ln level (placement)
    level_run_log_sd: float = 0.0  # run-to-run std of ln level (mounting / conditioning of a run: run_level_sd)
    miss_prob: float = 0.0
    r_series_ohm: float = 0.0
    r_leak_ohm: float = 1.0e12
    # readout
    divider: str = "high"  # "high": reading ~ R / (R + r_ref); "low": reading ~ r_ref / (R + r_ref)
    r_ref_ohm: float = 1.0e4
    full_scale: float = 1023.0
    full_scale_log_sd: float = 0.0  # run-to-run std of ln FS (the Lupasic board's rest level drifts)
    offset: float = 0.0
    noise_sd: float = 0.0  # reading units
    adc_step: float = 0.0
    tip_area_m2: float = 1e-4
    threshold_force_n: float = 0.0  # force the cover / gap carries before the film is loaded (F_eff = F - F_0)
    # contact area (module doc, "contact"): the share of the tip's face in contact, s = (F / (F + F_a))^beta;
    # F_a = 0: full contact at any force (rounds 1-8, bit for bit)
    contact_force_n: float = 0.0
    # tunneling (module doc): R_film x exp(-F_e / F_t); 0: off
    tunnel_force_n: float = 0.0
    contact_area_exponent: float = 2.0 / 3.0  # estimate: Hertz, a rounded tip's contact area grows as F^(2/3)
    # (Johnson, Contact Mechanics 1985, eq. 4.22) before it spans the face; held, not fitted (one term: F_a)
    label_latency_s: float = 0.0  # how late the rig records the force label against the reading (module doc,
    # "Label latency"; label_latency); 0: none

    @property
    def times_s(self) -> list[float]:
        if self.n_creep == 1:
            return [self.tau_min_s]
        return [float(v) for v in np.geomspace(self.tau_min_s, self.tau_max_s, self.n_creep)]

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["times_s"] = self.times_s
        return d

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> ChainParams:
        return cls(**{k: v for k, v in d.items() if k in cls.__dataclass_fields__})


def creep_force(force: np.ndarray, dt: float, p: ChainParams) -> np.ndarray:
    from scipy.signal import lfilter

    f = np.maximum(np.asarray(force, np.float64), 0.0)
    if p.creep_law == "aging":  # ln conductance gained (dimensionless)
        phi = p.creep_amplitude * f / (f + p.creep_force_n)
    else:  # force units (N)
        phi = p.creep_amplitude * p.creep_force_n * np.log1p(f / p.creep_force_n)
    c = np.zeros_like(f)
    w = 1.0 / p.n_creep
    for tau in p.times_s:
        d = np.exp(-dt / tau)
        c += lfilter([(1.0 - d) * w], [1.0, -d], phi)
    return c


def contact_fraction(f: np.ndarray, p: ChainParams) -> np.ndarray | float:
    """Share of the tip's face in contact with the film at the (effective) force f (N): s = (f / (f + F_a))^beta,
    beta = contact_area_exponent; 1.0 when F_a = contact_force_n = 0 (off). Source: Johnson, Contact Mechanics
    1985, sect. 4.2 (Hertz: a rounded or compliant tip's contact area grows as F^(2/3) until it spans the face;
    Greenwood & Williamson 1966: the true contact of a rough film grows with the load); an FSR-type film conducts
    through the true contact area (Interlink Electronics, FSR Integration Guide: the conductance follows the
    contact area at low force), so R_film is divided by s. F >> F_a: s -> 1; F << F_a: s ~ (F / F_a)^beta, the
    law steepens by beta F_a / (F + F_a) in d ln R / d ln F."""
    if p.contact_force_n <= 0.0:
        return 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        return (f / (f + p.contact_force_n)) ** p.contact_area_exponent


def film_resistance(force: np.ndarray, dt: float, p: ChainParams, level: np.ndarray | float = 0.0) -> np.ndarray:
    """R_film (ohm, inf unloaded) of the recorded force; level: ln multiplier per sample (press placement)."""
    f = np.maximum(np.asarray(force, np.float64) - p.threshold_force_n, 0.0)
    c = creep_force(f, dt, p)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        if p.creep_law == "aging":
            r = np.where(f > 0, p.r0_ohm * np.exp(level - c) * (f / F_REF_N) ** (-p.exponent), np.inf)
        else:
            r = np.where(f > 0, p.r0_ohm * np.exp(level) * ((f + c) / F_REF_N) ** (-p.exponent), np.inf)
        if p.contact_force_n > 0.0:
            r = np.where(f > 0, r / contact_fraction(f, p), np.inf)
        if p.tunnel_force_n > 0.0:
            r = r * np.exp(-(f if p.creep_law == "aging" else f + c) / p.tunnel_force_n)
        return r


def total_resistance(r_film: np.ndarray, p: ChainParams) -> np.ndarray:
    r = r_film + p.r_series_ohm
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.isinf(r), p.r_leak_ohm, r * p.r_leak_ohm / (r + p.r_leak_ohm))


def reading_from_resistance(r: np.ndarray, p: ChainParams, fs: float | None = None) -> np.ndarray:
    fs = p.full_scale if fs is None else fs
    frac = r / (r + p.r_ref_ohm) if p.divider == "high" else p.r_ref_ohm / (r + p.r_ref_ohm)
    return p.offset + fs * frac


def resistance_from_reading(y: np.ndarray, p: ChainParams, fs: float | None = None) -> np.ndarray:
    """Inverse divider (nan outside (offset, offset + FS))."""
    fs = p.full_scale if fs is None else fs
    u = (np.asarray(y, np.float64) - p.offset) / fs
    u = np.where((u > 0) & (u < 1), u, np.nan)
    return p.r_ref_ohm * (u / (1 - u) if p.divider == "high" else (1 - u) / u)


def simulate_reading(force: np.ndarray, dt: float, p: ChainParams, level: np.ndarray | float = 0.0,
                     fs: float | None = None, rng: np.random.Generator | None = None) -> np.ndarray:
    """Force [T] (N) -> reading [T] (noise-free without rng)."""
    y = reading_from_resistance(total_resistance(film_resistance(force, dt, p, level), p), p, fs)
    if rng is not None and p.noise_sd > 0:
        y = y + rng.standard_normal(len(y)) * p.noise_sd
    if p.adc_step > 0:
        y = np.round((y - p.offset) / p.adc_step) * p.adc_step + p.offset
    return y


# ----------------------------------------------------------------------------------------------- real runs

@dataclass
class Press:
    run: int
    sl: slice  # samples of the press (loaded stretch)


@dataclass
class RealRun:
    key: str
    force: np.ndarray
    reading: np.ndarray
    dt: float
    fs: float  # full scale of this run (rest level for a board whose full scale is its rest)
    noise_sd: float
    attrs: dict = field(default_factory=dict)


MAX_LAG_S = 0.5  # estimate: the widest lag looked for between the reading and its force label (a serial link's
# buffering or a load-cell amplifier's filter: tens to hundreds of ms)


def reading_lag_s(run: RealRun, max_lag_s: float = MAX_LAG_S) -> float:
    """The lag (s) of the reading behind the force label that lines them up best: the peak, refined between samples
    (parabola through the best three), of the correlation of ln force with the log of the reading's headroom toward
    full load (ln reading where it falls with force, ln(FS - reading) where it rises) over the loaded samples (force
    >= 10 % of the run's peak), the reading shifted by -max_lag_s .. max_lag_s. Positive: the reading follows the
    force; negative: it leads it. nan where the run has too few loaded samples."""
    f, y = np.asarray(run.force, np.float64), np.asarray(run.reading, np.float64)
    x = np.where(f >= 0.1 * np.nanmax(f), np.log(np.maximum(f, 1e-12)), np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.log(run.fs - y) if run.attrs.get("reading_rises_with_force") else np.log(y)
    z = np.where(np.isfinite(z), z, np.nan)
    K = max(1, int(round(max_lag_s / run.dt)))
    score = np.full(2 * K + 1, np.nan)
    for i, k in enumerate(range(-K, K + 1)):  # z[t + k] against x[t]
        a, b = x[max(0, -k):len(x) - max(0, k)], z[max(0, k):len(z) - max(0, -k)]
        m = np.isfinite(a) & np.isfinite(b)
        if m.sum() >= 20 and np.std(a[m]) > 0 and np.std(b[m]) > 0:
            score[i] = -np.corrcoef(a[m], b[m])[0, 1]  # the headroom falls as the force rises
    if not np.isfinite(score).any():
        return float("nan")
    i = int(np.nanargmax(score))
    frac = 0.0
    if 0 < i < 2 * K and np.isfinite(score[i - 1]) and np.isfinite(score[i + 1]):
        den = score[i - 1] - 2 * score[i] + score[i + 1]
        frac = 0.5 * (score[i - 1] - score[i + 1]) / den if den < 0 else 0.0
    return float((i - K + frac) * run.dt)


def label_latency(runs: Seq[RealRun], max_lag_s: float = MAX_LAG_S) -> tuple[float, list[float]]:
    """The rig's label latency (s, >= 0) from its runs (module doc, "Label latency"): minus the median of the runs'
    `reading_lag_s` where the reading leads its force label, else 0; and the per-run lags."""
    lags = [reading_lag_s(r, max_lag_s) for r in runs]
    ok = [v for v in lags if np.isfinite(v)]
    return (max(0.0, -float(np.median(ok))) if ok else 0.0), lags


def shift_label(force: np.ndarray, dt: float, by_s: float) -> np.ndarray:
    """The force label read by_s later (by_s > 0: the value recorded by_s after each sample, the ends held):
    with by_s = the latency it lines the label up with its reading; with -latency it delays a true force as the rig
    records it."""
    f = np.asarray(force, np.float64)
    if by_s == 0.0 or len(f) < 2:
        return f
    t = np.arange(len(f)) * dt
    return np.interp(t + by_s, t, f)


def align_labels(runs: Seq[RealRun], latency_s: float) -> list[RealRun]:
    """The runs with each force label read latency_s later (`shift_label`), so that it is the force on the sensor
    at the reading's time; the runs themselves where latency_s is 0."""
    if latency_s <= 0.0:
        return list(runs)
    return [replace(r, force=shift_label(r.force, r.dt, latency_s)) for r in runs]


def presses_of(force: np.ndarray, min_force_n: float) -> list[slice]:
    on = force > min_force_n
    edges = np.flatnonzero(np.diff(np.concatenate([[0], on.astype(int), [0]])))
    return [slice(a, b) for a, b in zip(edges[::2], edges[1::2]) if b - a >= 3]


def noise_of(reading: np.ndarray, mask: np.ndarray) -> float:
    d = np.diff(np.asarray(reading, np.float64))[mask[1:] & mask[:-1]]
    d = d[np.isfinite(d)]  # a dropped sample (NaN) leaves its two differences out
    if len(d) < 10:
        return 0.0
    return float(np.median(np.abs(d - np.median(d))) / 0.6745 / np.sqrt(2))


def load_real_runs(recording: str | Path, *, input_channel: str = "sensor", target: str = "force",
                   rate_hz: float | None = 20.0, episodes: str | Seq[str] | None = None) -> list[RealRun]:
    from sensors.data.column_import import to_newtons
    from sensors.data.recording import Recording, split_column
    from sensors.data.resample import MAX_GAP_S, MIN_PART_S, PART_SEP, resample_parts

    out = []
    with Recording(recording) as rec:
        sattrs = dict(rec.sensor_attrs)
        for ep in rec.episode_ids:
            if isinstance(episodes, str) and not fnmatch.fnmatch(ep, episodes):
                continue
            if episodes is not None and not isinstance(episodes, str) and ep not in episodes:
                continue
            try:
                s = np.asarray(rec.read_column(ep, input_channel), np.float64)
                if s.ndim > 1 and int(np.prod(s.shape[1:])) != 1:
                    raise ValueError(f"{recording}: episode {ep}: channel '{input_channel}' holds {int(np.prod(s.shape[1:]))} "
                                     f"readings per sample; the chain is one taxel's: name one as '{input_channel}[k]' "
                                     "(k from 0), or import that taxel as its own channel")
                s = s.reshape(-1)
                f = to_newtons(np.asarray(rec.read_column(ep, target), np.float64).reshape(-1),
                               rec.units(ep, split_column(target)[0]), f"{recording}: episode {ep}: the target '{target}'")
                t = np.asarray(rec.read(ep, "time"), np.float64)
            except KeyError as exc:
                raise ValueError(str(exc.args[0])) from None
            top = np.nanmax(f) if np.isfinite(f).any() else 0.0
            rest = f < 0.02 * max(top, 1e-9)
            noise = noise_of(s, ~rest)
            if rate_hz:
                try:  # dropped samples (NaN, as `piezotwin capture` leaves them) bridged up to MAX_GAP_S; an episode
                    # is cut at a longer stretch without a sample and read as its parts EP@1, EP@2, ...
                    pp = resample_parts(t, [s, f], rate_hz)
                    parts = [(ep if len(pp) == 1 else f"{ep}{PART_SEP}{k + 1}", s2[:, 0], f2[:, 0])
                             for k, (_, (s2, f2)) in enumerate(pp)]
                except ValueError as exc:
                    raise ValueError(f"{recording}: episode {ep}: {exc}") from None
                if not parts:
                    raise ValueError(f"{recording}: episode {ep}: no stretch of {MIN_PART_S:g} s with both the reading "
                                     f"and the force between its gaps (> {MAX_GAP_S:g} s without a sample)")
                dt = 1.0 / rate_hz
            else:
                if not (np.isfinite(s).all() and np.isfinite(f).all()):
                    raise ValueError(f"{recording}: episode {ep}: has samples without a value (NaN); give a rate to "
                                     "resample it onto (they are bridged there)")
                parts, dt = [(ep, s, f)], float(np.median(np.diff(t)))
            a = {**sattrs, **dict(rec.episode_attrs(ep))}
            for key, s, f in parts:
                rises = reading_rises(f, s)
                if rises and not a.get("adc_full_scale"):
                    raise ValueError(f"{recording}: episode {key}: the reading rises with force (the reference resistor "
                                     "on the ADC side), so its rest level is not its full scale; give the ADC's full "
                                     "scale as the sensor attribute adc_full_scale (the import spec's sensor_attrs)")
                unloaded = s[f < 0.02 * max(f.max(), 1e-9)]
                if not a.get("adc_full_scale") and not len(unloaded):
                    raise ValueError(f"{recording}: episode {key}: no unloaded sample (force < 2 % of its peak), and "
                                     "the board's full scale is read from its rest level: give adc_full_scale, or "
                                     "capture a moment without load")
                fs = float(a.get("adc_full_scale") or np.median(unloaded))
                kept = {k: a[k] for k in ("reference_resistor_ohm", "adc_full_scale") if k in a}
                out.append(RealRun(key, f, s, dt, fs, noise, {**kept, "reading_rises_with_force": rises}))
    if not out:
        raise ValueError(f"{recording}: no episode" + (f" matches {episodes!r}" if episodes else ""))
    return out


def run_params(p: ChainParams, run: RealRun) -> ChainParams:
    """The chain ``p`` as the run ``run`` was read: its own reference resistor where it records one (a taxel read
    through another divider: the prediction needs only the new value)."""
    r_ref = run.attrs.get("reference_resistor_ohm")
    return p if not r_ref or float(r_ref) == p.r_ref_ohm else replace(p, r_ref_ohm=float(r_ref))


def reading_rises(force: np.ndarray, reading: np.ndarray) -> bool:
    """True where the run's reading is higher under load (force >= 50 % of its largest) than at rest (< 2 %)."""
    top = max(float(force.max()), 1e-9)
    rest, loaded = reading[force < 0.02 * top], reading[force >= 0.5 * top]
    return bool(len(rest) and len(loaded) and np.median(loaded) > np.median(rest))


def reading_direction(runs: Seq[RealRun]) -> str:
    """The divider a capture was read through (module doc, readout): "high" where the reading falls as force rises,
    "low" where it rises; the majority of the runs (load_real_runs measures each: its loaded vs rest median)."""
    rises = [bool(r.attrs.get("reading_rises_with_force", reading_rises(r.force, r.reading))) for r in runs]
    return "low" if 2 * sum(rises) > len(rises) else "high"


# ----------------------------------------------------------------------------------------------- fit

@dataclass
class ChainFit:
    params: ChainParams
    ranges: dict[str, list[float]]  # parameter -> [p5, p50, p95] over the bootstrap
    level_band90: list[float]  # predictive 90 % band of a new press's ln level (relative to ln r0)
    boot: list[dict[str, float]]
    error: dict[str, Any]
    press_levels: list[float]
    result: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {"params": self.params.to_json(), "ranges_p5_p50_p95": self.ranges, "level_band90_log": self.level_band90,
                "bootstrap": self.boot, "error": self.error, "press_levels_log": self.press_levels, "least_squares": self.result}


NAMES = ("exponent", "ln_creep_amplitude", "ln_creep_force_n", "ln_tau_min_s", "ln_tau_max_s", "ln_r_series_ohm",
         "threshold_force_n", "ln_contact_force_n", "ln_tunnel_force_n")
LB = np.array([0.2, np.log(1e-3), np.log(1e-3), np.log(0.02), np.log(0.5), np.log(1e-3), 0.0, np.log(1e-3), np.log(1e-3)])
UB = np.array([4.0, np.log(50.0), np.log(1e4), np.log(5.0), np.log(1e3), np.log(1e7), 1e3, np.log(1e3), np.log(1e4)])
CONTACT_START_N = 1.0  # estimate: starting F_a of the contact fit, inside the range where the Lupasic runs' law
# steepens (below ~5 N, seventh round); from F_a -> 0 the term's gradient vanishes


def _free(fit_series: bool, fit_threshold: bool = False, creep_linear: bool = False, fit_contact: bool = False,
          fit_tunnel: bool = False) -> list[int]:
    """Indices of theta the fit moves: the shape always (F_c not with creep_linear: held at its upper bound);
    r_series and the threshold where the readout saturates (fit_series); the threshold alone with fit_threshold
    (a mount that carries force before the film is loaded); the contact force F_a with fit_contact; the tunneling
    force F_t with fit_tunnel."""
    return sorted([0, 1, 3, 4] + ([] if creep_linear else [2]) + ([5, 6] if fit_series else [6] if fit_threshold else [])
                  + ([7] if fit_contact else []) + ([8] if fit_tunnel else []))


def _with(p: ChainParams, th: np.ndarray, free: list[int]) -> ChainParams:
    """p with the shape of theta (all nine entries); r_series, the threshold, F_a and F_t only where free (_free)."""
    q = replace(p, exponent=float(th[0]), creep_amplitude=float(np.exp(th[1])), creep_force_n=float(np.exp(th[2])),
                tau_min_s=float(np.exp(th[3])), tau_max_s=float(np.exp(max(th[4], th[3]))))
    if 5 in free:
        q.r_series_ohm = float(np.exp(th[5]))
    if 6 in free:
        q.threshold_force_n = float(th[6])
    if 7 in free:
        q.contact_force_n = float(np.exp(th[7]))
    if 8 in free:
        q.tunnel_force_n = float(np.exp(th[8]))
    return q


def _theta(p: ChainParams) -> np.ndarray:
    return np.array([p.exponent, np.log(p.creep_amplitude), np.log(p.creep_force_n), np.log(p.tau_min_s),
                     np.log(p.tau_max_s), np.log(max(p.r_series_ohm, 1e-3)), p.threshold_force_n,
                     np.log(max(p.contact_force_n, 1e-3)), np.log(max(p.tunnel_force_n, 1e-3))])


class _Data:
    """Loaded samples of the presses of the runs: per press its run, slice, and ln R from the reading."""

    def __init__(self, runs: Seq[RealRun], p: ChainParams, min_force_frac: float, min_force_n: float):
        # a press that stays at the rest level (within 15 % of the scale) missed the film: the reading near the full
        # scale for a "high" divider (unloaded R >> r_ref), near 0 for a "low" one
        self.runs = runs
        self.presses: list[Press] = []
        self.lnr: list[np.ndarray] = []
        self.missed: list[bool] = []
        for i, r in enumerate(runs):
            thr = max(min_force_frac * r.force.max(), min_force_n)
            R = resistance_from_reading(r.reading, run_params(p, r), r.fs)
            for sl in presses_of(r.force, thr):
                # the loading ramp above 30 % of the peak and the plateau, up to its last sample >= 90 % of the
                # peak; the release is left out: there the tip leaves the film within one or two samples and
                # the ~10 ms alignment of the two streams, not the film, sets the reading
                seg = np.arange(sl.start, sl.stop)
                fpk = r.force[seg].max()
                seg = seg[: int(np.flatnonzero(r.force[seg] >= 0.9 * fpk)[-1]) + 1]
                seg = seg[r.force[seg] > max(thr, 0.3 * fpk)]
                if len(seg) < 3:
                    continue
                lr = np.log(R[seg])
                u = np.nanmedian(np.abs(r.reading[seg] - p.offset) / r.fs)
                miss = u > 0.85 if p.divider == "high" else u < 0.15
                self.missed.append(bool(miss or not np.isfinite(lr).mean() > 0.8))
                if self.missed[-1]:
                    continue
                self.presses.append(Press(i, seg))
                self.lnr.append(lr)

    def residuals(self, p: ChainParams) -> tuple[list[np.ndarray], np.ndarray]:
        """Per press ln R_sim(level 0) - ln R_real, and each press's mean (its level)."""
        sims = {}
        out, lev = [], []
        for pr, lr in zip(self.presses, self.lnr):
            if pr.run not in sims:
                r = self.runs[pr.run]
                sims[pr.run] = np.log(film_resistance(r.force, r.dt, p) + p.r_series_ohm)
            e = sims[pr.run][pr.sl] - lr
            e = e[np.isfinite(e)]
            out.append(e)
            lev.append(-np.mean(e) if len(e) else 0.0)
        return out, np.asarray(lev)


def _fit_shape(data: _Data, p0: ChainParams, idx: np.ndarray, free: list[int], max_nfev: int,
               prior: tuple[float, float] | None = None):
    """Fit the free entries of theta (_free); prior = (within-press rms, level sd): fit with the level prior (see
    fit_chain's level_prior)."""
    from scipy.optimize import least_squares

    full0 = _theta(p0)

    def expand(th):
        full = full0.copy()
        full[free] = th
        return full

    def fun(th):
        q = _with(p0, expand(th), free)
        # series resistance enters inside the log: refit the level per press through ln(R_film e^l + r_s)
        out, lev = _profile(data, q, idx)
        if prior is None:
            return np.concatenate(out)
        sw, sl = prior
        return np.concatenate([np.concatenate([e / (np.sqrt(max(len(e), 1)) * sw) for e in out]), (lev - np.mean(lev)) / sl])

    th0 = np.clip(full0[free], LB[free] + 1e-6, UB[free] - 1e-6)
    res = least_squares(fun, th0, bounds=(LB[free], UB[free]), x_scale="jac", max_nfev=max_nfev, method="trf")
    q = _with(p0, expand(res.x), free)
    res.names = [NAMES[i] for i in free]
    return q, res


def _profile(data: _Data, q: ChainParams, idx: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """Residuals ln R_model - ln R_real with each press's level l fitted (Gauss-Newton, r0 = 1 ohm so the
    levels absorb r0): R_model = (R_f e^l + r_s) || r_leak."""
    out, lev = [], []
    cache = {}
    L = q.r_leak_ohm
    for j in idx:
        pr, lr = data.presses[j], data.lnr[j]
        if pr.run not in cache:
            r = data.runs[pr.run]
            cache[pr.run] = film_resistance(r.force, r.dt, replace(q, r0_ohm=1.0))
        rf = cache[pr.run][pr.sl]
        ok = np.isfinite(lr)
        rf, y = rf[ok], lr[ok]
        fin = np.isfinite(rf)
        if not fin.any():
            out.append(np.log(L) - y)
            lev.append(0.0)
            continue
        ry = np.exp(y)
        ry = ry * L / np.maximum(L - ry, 1e-3 * L)  # undo the leak
        target = np.log(np.maximum(ry - q.r_series_ohm, 1e-3 * ry))
        l = float(np.median(target[fin] - np.log(rf[fin])))
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            for _ in range(4):
                a = rf * np.exp(l) + q.r_series_ohm
                m = L / (1.0 + L / a)
                g = np.where(fin, m * rf * np.exp(l) / a ** 2, 0.0)
                e = np.log(m) - y
                l -= float(np.sum(e * g) / max(np.sum(g * g), 1e-12))
                l = float(np.clip(l, -50, 50))
            a = rf * np.exp(l) + q.r_series_ohm
            out.append(np.log(L / (1.0 + L / a)) - y)
        lev.append(l)
    return out, np.asarray(lev)


def leak_from_unloaded(runs: Seq[RealRun], p: ChainParams) -> float:
    """Unloaded resistance (ohm) through the divider: median over the runs' unloaded samples; 1e12 when
    the board's full scale is its own rest level (no leak visible)."""
    vals = []
    for r in runs:
        rest = r.force < 0.02 * max(r.force.max(), 1e-9)
        R = resistance_from_reading(r.reading[rest], run_params(p, r), r.fs)
        R = R[np.isfinite(R)]
        if len(R) > 10 and "adc_full_scale" in r.attrs:
            vals.append(np.median(R))
    return float(np.median(vals)) if vals else 1e12


RUN_LEVEL_PRIOR_SD = 0.15  # estimate: run-to-run (re-mount, conditioning) spread of a thin-film piezoresistor's
# ln level at one force: FSR makers quote +-5 to +-25 % force accuracy for one part, set by the consistency of the
# actuation and mounting (Interlink Electronics, FSR Integration Guide, p. 8) and condition each part before
# use because its response shifts over the first loadings (Tekscan, FlexiForce user manual rev. G,
# "Repeatability"); +-25 % as a 90 % range in force is ~0.15 ln at a force exponent near 1 (Lupasic fit 0.98)
RUN_LEVEL_PRIOR_DOF = 2.0  # estimate: the prior weighs as two runs' worth of between-run information (it decides
# the value only where the training runs give fewer than ~2 degrees of freedom: one or two runs)


def run_level_sd(levels: np.ndarray, run_of: np.ndarray, prior_sd: float = RUN_LEVEL_PRIOR_SD,
                 prior_dof: float = RUN_LEVEL_PRIOR_DOF) -> dict[str, float]:
    """Hierarchical press levels l_{r,j} = mu + u_r + e_{r,j}, u_r ~ N(0, sd_run^2) per run (its mounting and
    contact conditioning), e ~ N(0, sd_w^2) per press (placement). One-way random-effects ANOVA (moment estimates
    for unbalanced runs; Searle, Casella & McCulloch, Variance Components 1992, sect. 3.5): sd_w^2 = MSW,
    sd_run^2 = max(MSB - MSW, 0) / n0, n0 = (N - sum n_r^2 / N) / (k - 1); then the conjugate scaled-inverse-chi^2
    update with a prior of prior_dof runs at prior_sd (Gelman et al., Bayesian Data Analysis 3rd ed., sect. 3.3):
    sd_run^2 = ((k - 1) sd_anova^2 + prior_dof prior_sd^2) / (k - 1 + prior_dof); one run: the prior."""
    lev = np.asarray(levels, np.float64)
    run_of = np.asarray(run_of)
    runs, inv = np.unique(run_of, return_inverse=True)
    k, n = len(runs), len(lev)
    cnt = np.bincount(inv, minlength=k).astype(float)
    means = np.bincount(inv, lev, minlength=k) / np.maximum(cnt, 1)
    ssw = float(np.sum((lev - means[inv]) ** 2))
    msw = ssw / (n - k) if n > k else 0.0
    if k > 1:
        msb = float(np.sum(cnt * (means - lev.mean()) ** 2)) / (k - 1)
        n0 = (n - float(np.sum(cnt ** 2)) / n) / (k - 1)
        s2 = max(msb - msw, 0.0) / max(n0, 1e-12)
    else:
        s2 = 0.0
    post = ((k - 1) * s2 + prior_dof * prior_sd ** 2) / max(k - 1 + prior_dof, 1e-12)
    return {"level_within_run_sd": float(np.sqrt(msw)), "level_run_sd_anova": float(np.sqrt(s2)),
            "level_run_sd": float(np.sqrt(post)), "n_runs": int(k), "n_presses": int(n)}


def new_run_band90(within_sd: float, run_sd: float, n_runs: int, n_presses: int) -> float:
    """Half width of the predictive 90 % band of the ln level of a press of a NEW run (a held-out run or series:
    its own u_run) under the hierarchical levels (run_level_sd): 1.645 sqrt(sd_w^2 + sd_run^2 + se^2), se^2 =
    sd_run^2 / runs + sd_w^2 / presses (the fitted mean's uncertainty)."""
    var = within_sd ** 2 + run_sd ** 2 + run_sd ** 2 / max(n_runs, 1) + within_sd ** 2 / max(n_presses, 1)
    return float(1.645 * np.sqrt(var))


N_RUN_BOOT = 200  # replicates of the run bootstrap of level_run_sd (no refit: cheap)


def fit_chain(runs: Seq[RealRun], p0: ChainParams, *, fit_series: bool | None = None, n_boot: int = 16,
              min_force_frac: float = 0.1, min_force_n: float = 0.05, max_nfev: int = 60, seed: int = 0,
              progress=None, level_prior: bool = False, fit_threshold: bool = False,
              creep_linear: bool = False, fit_contact: bool = False, fit_tunnel: bool = False,
              latency: bool = False) -> ChainFit:
    """Fit the chain to real runs (see the module docstring); progress(k, n) is called after each fit.

    latency: read the rig's label latency from the runs (`label_latency`), fit on the runs with their labels
    lined up (`align_labels`) and keep it in the params (label_latency_s; `evaluate` lines up other runs of the
    rig by it, the generation delays its labels by it); off, p0's label_latency_s is used as given (0: none).

    level_prior: the press levels are draws l_j ~ N(mu, sd^2) of a placement chosen before the press, so
    independent of its force; free levels (the default) let them absorb a force law that is too flat. With the
    prior the shape is refit on [e_j / (sqrt(n_j) rms_w), (l_j - mean l) / sd]: each press's within-press
    residuals count as one observation (its samples are strongly correlated: the presses' own ln R-ln F slopes
    spread by sd 0.16 within a Lupasic run, bench/bench_s2r_identify.py) beside its level's prior term;
    rms_w and sd from the free-level fit (random-effects least squares, one step).

    fit_threshold: fit the threshold force F_0 (F_eff = F - F_0: the force a mount or cover carries before the
    film is loaded; the FSR's actuation force set by its mechanical preload, Interlink FSR Integration Guide) also
    where the readout does not saturate (fit_series off: the Lupasic board), without a series resistance.

    creep_linear: linear creep (Boltzmann superposition, Findley, Lai & Onaran, Creep and Relaxation of Nonlinear
    Viscoelastic Materials 1976, ch. 2): the creep force proportional to the load, Phi = a F (F_c held at its
    upper bound, 1e4 N, where a F_c ln(1 + F / F_c) = a F within 0.2 % up to 40 N), so the steady law stays
    the power law -n and the hold's relative drop is the same at every force.

    fit_contact: fit the contact force F_a of the tip's contact area (contact_fraction; its exponent held), started
    at CONTACT_START_N where p0 has none; off, F_a stays p0's (0: no contact term).

    fit_tunnel: fit the tunneling force F_t (module doc, "tunneling"), started where p0 has none at the median peak
    force of the runs' presses (there the term moves ln R by ~1 over a press, so its gradient is alive); off, F_t
    stays p0's (0: no tunneling term)."""
    if latency:
        p0 = replace(p0, label_latency_s=label_latency(runs)[0])
    runs = align_labels(runs, p0.label_latency_s)
    p0 = replace(p0, r_leak_ohm=leak_from_unloaded(runs, p0))
    if fit_contact and p0.contact_force_n <= 0.0:
        p0 = replace(p0, contact_force_n=CONTACT_START_N)
    if fit_tunnel and p0.tunnel_force_n <= 0.0:
        peaks = [float(r.force[sl].max()) for r in runs for sl in presses_of(r.force, max(min_force_frac * r.force.max(), min_force_n))]
        p0 = replace(p0, tunnel_force_n=float(np.median(peaks)) if peaks else 1.0)
    data = _Data(runs, p0, min_force_frac, min_force_n)
    if len(data.presses) < 3:
        raise ValueError(f"found {len(data.presses)} press(es) with a response; a fit needs at least 3")
    if fit_series is None:
        fit_series = any("adc_full_scale" in r.attrs for r in runs)  # an ADC of known full scale: a floor shows
    idx = np.arange(len(data.presses))
    free = _free(bool(fit_series), fit_threshold, creep_linear, fit_contact, fit_tunnel)
    if creep_linear:
        p0 = replace(p0, creep_force_n=float(np.exp(UB[2])))
    q, res = _fit_shape(data, p0, idx, free, max_nfev)
    prior = None
    if level_prior:
        out, lev = _profile(data, q, idx)
        prior = (float(np.sqrt(np.mean(np.concatenate(out) ** 2))), float(np.std(lev, ddof=1)))
        q, res = _fit_shape(data, q, idx, free, max_nfev, prior)
    if progress:
        progress(1, n_boot + 1)
    fin = _finish(q, data, idx, runs)
    rng = np.random.default_rng([seed, 0xB007])
    boot = []
    for b in range(n_boot):
        # resample presses with replacement (runs keep their own presses' force histories)
        bi = rng.integers(0, len(idx), len(idx))
        qb, _ = _fit_shape(data, q, bi, free, max(10, max_nfev // 3), prior)
        boot.append(_summary(_finish(qb, data, bi, runs)))
        if progress:
            progress(b + 2, n_boot + 1)
    ranges = {}
    if boot:
        for k in boot[0]:
            v = np.array([d[k] for d in boot])
            ranges[k] = [float(np.percentile(v, 5)), float(np.percentile(v, 50)), float(np.percentile(v, 95))]
    lev = np.asarray(fin["levels"])
    # predictive band of a new press's level under the point fit's shape (the held-out levels are profiled
    # with it): N(mean, sd^2 (1 + 1/n_eff)), the mean's uncertainty from the run means (presses of one run
    # share its mounting, so they are not independent draws of it). Not the bootstrap spread of ln r0: each
    # replicate refits the shape, and ln r0 trades off against the exponent, so that spread is the shape's
    # uncertainty, not the level's (it made the band 1.6x too wide: 100 % of held-out levels inside).
    n_runs = len({data.presses[j].run for j in idx})
    sd = fin["p"].level_log_sd
    se2 = fin["level_between_run_sd"] ** 2 / n_runs + fin["level_within_run_sd"] ** 2 / len(idx)
    half_pooled = 1.645 * float(np.sqrt(sd ** 2 + se2))  # rounds 2-5: one level distribution (recorded beside)
    # the band of a press of a NEW run (held-out runs and series are that case, fixed before scoring, sixth round):
    # its run's own level u_run as well as the press's placement (hierarchical levels, run_level_sd)
    half = new_run_band90(fin["level_within_run_sd"], fin["level_run_sd"], n_runs, len(idx))
    # the run-level sd's range: a bootstrap over runs (clusters) of the point fit's press levels, with the prior
    rb = np.random.default_rng([seed, 0x5D])
    run_of = fin["run_of"]
    ur = np.unique(run_of)
    rs = []
    for _ in range(N_RUN_BOOT):
        pick = rb.choice(ur, len(ur))
        sel = np.concatenate([np.flatnonzero(run_of == r) for r in pick])
        lab = np.concatenate([np.full(int(np.sum(run_of == r)), i) for i, r in enumerate(pick)])
        rs.append(run_level_sd(lev[sel], lab)["level_run_sd"])
    ranges["level_run_sd_run_bootstrap"] = [float(np.percentile(rs, q)) for q in (5, 50, 95)]
    err = within_press_error(fin["p"], data, idx)
    err["level_band90_pooled_log"] = [-half_pooled, half_pooled]
    err["level_run_sd"] = {"point": fin["level_run_sd"], "anova": fin["level_run_sd_anova"],
                           "within_run_sd": fin["level_within_run_sd"], "n_runs": int(n_runs),
                           "prior_sd": RUN_LEVEL_PRIOR_SD, "prior_dof": RUN_LEVEL_PRIOR_DOF}
    err["n_presses"] = len(idx)
    err["n_missed_presses"] = int(sum(data.missed))
    return ChainFit(fin["p"], ranges, [-half, half], boot, err, [float(x) for x in lev - np.log(fin["p"].r0_ohm)],
                    {"nfev": int(res.nfev), "status": int(res.status), "message": str(res.message), "names": list(res.names)})


def _finish(q: ChainParams, data: _Data, idx: np.ndarray, runs: Seq[RealRun]) -> dict[str, Any]:
    _, lev = _profile(data, q, idx)
    p = replace(q, r0_ohm=float(np.exp(np.mean(lev))), level_log_sd=float(np.std(lev, ddof=1)) if len(lev) > 1 else 0.0)
    p.miss_prob = float(np.mean(data.missed)) if data.missed else 0.0
    # the spread split by run: within-run (press to press, placement) and between-run (run means: mounting,
    # board gain); run = data.presses[j].run; a run with one press adds to the between part only
    run_of = np.array([data.presses[j].run for j in idx])
    within, means = [], []
    for r in np.unique(run_of):
        lr = lev[run_of == r]
        means.append(float(np.mean(lr)))
        within.extend(lr - np.mean(lr))
    dof = max(len(lev) - len(means), 1)
    w_sd = float(np.sqrt(np.sum(np.square(within)) / dof)) if len(lev) > len(means) else 0.0
    b_sd = float(np.std(means, ddof=1)) if len(means) > 1 else 0.0
    hier = run_level_sd(lev, run_of)
    p.level_run_log_sd = hier["level_run_sd"]
    sig = [r.noise_sd for r in runs if r.noise_sd > 0]
    p.noise_sd = float(np.median(sig)) if sig else 0.0
    fs = np.array([r.fs for r in runs])
    if p.divider == "high" and len(fs) > 1 and not any("adc_full_scale" in r.attrs for r in runs):
        p.full_scale = float(np.exp(np.mean(np.log(fs))))
        p.full_scale_log_sd = float(np.std(np.log(fs), ddof=1))
    return {"p": p, "levels": lev, "level_within_run_sd": w_sd, "level_between_run_sd": b_sd,
            "level_run_sd": hier["level_run_sd"], "level_run_sd_anova": hier["level_run_sd_anova"], "run_of": run_of}


def _summary(f: dict[str, Any]) -> dict[str, float]:
    p = f["p"]
    return {"exponent": p.exponent, "r0_ohm": p.r0_ohm, "threshold_force_n": p.threshold_force_n, "creep_amplitude": p.creep_amplitude,
            "creep_force_n": p.creep_force_n, "tau_min_s": p.tau_min_s, "tau_max_s": p.tau_max_s,
            "level_log_sd": p.level_log_sd, "r_series_ohm": p.r_series_ohm,
            "level_within_run_sd": f["level_within_run_sd"], "level_between_run_sd": f["level_between_run_sd"],
            "level_run_sd": f["level_run_sd"], "level_run_sd_anova": f["level_run_sd_anova"],
            **({"contact_force_n": p.contact_force_n} if p.contact_force_n > 0 else {}),
            **({"tunnel_force_n": p.tunnel_force_n} if p.tunnel_force_n > 0 else {})}


def within_press_error(p: ChainParams, data: _Data, idx: np.ndarray) -> dict[str, Any]:
    """rms of ln reading (sim - real) over the presses with each press's level fitted; and plateau drop."""
    errs = []
    per_run: dict[str, list[np.ndarray]] = {}
    _, lev = _profile(data, p, idx)
    for j, l in zip(idx, lev):
        pr = data.presses[j]
        r = data.runs[pr.run]
        y_sim = simulate_reading(r.force, r.dt, replace(run_params(p, r), r0_ohm=1.0), level=l, fs=r.fs)[pr.sl]
        y = r.reading[pr.sl]
        ok = (y > 0) & (y_sim > 0)
        e = np.log(y_sim[ok]) - np.log(y[ok])
        errs.append(e)
        per_run.setdefault(r.key, []).append(e)
    a = np.concatenate(errs) if errs else np.zeros(0)
    return {"rms_log_reading_within_press": float(np.sqrt(np.mean(a ** 2))) if len(a) else float("nan"),
            "per_run": {k: float(np.sqrt(np.mean(np.concatenate(v) ** 2))) for k, v in per_run.items()},
            "n_samples": len(a)}


def evaluate(fit: ChainFit, runs: Seq[RealRun], min_force_frac: float = 0.1, min_force_n: float = 0.05) -> dict[str, Any]:
    """On runs not used in the fit: within-press rms ln-reading error (levels removed), the share of the
    presses' levels inside the fitted 90 % band, and the plateau drop (reading at the end of the plateau /
    at its start, real vs simulated)."""
    p = fit.params
    data = _Data(align_labels(runs, p.label_latency_s), p, min_force_frac, min_force_n)
    idx = np.arange(len(data.presses))
    if not len(idx):
        return {"n_presses": 0}
    err = within_press_error(p, data, idx)
    _, lev = _profile(data, p, idx)
    rel = lev - np.log(p.r0_ohm)
    lo, hi = fit.level_band90
    err["level_in_band90"] = float(np.mean((rel >= lo) & (rel <= hi)))
    err["level_mean_log_vs_fit"] = float(np.mean(rel))
    err["level_sd_log"] = float(np.std(rel, ddof=1)) if len(rel) > 1 else 0.0
    err["n_presses"] = len(idx)
    err["plateau_drop"] = plateau_drops(p, data, idx, lev)
    return err


def plateau_drops(p: ChainParams, data: _Data, idx, lev) -> dict[str, float]:
    """Median over presses of reading(end of plateau) / reading(plateau start), plateau = force >= 90 % of peak."""
    real, sim = [], []
    for j, l in zip(idx, lev):
        pr = data.presses[j]
        r = data.runs[pr.run]
        f = r.force[pr.sl]
        hold = np.flatnonzero(f >= 0.9 * f.max())
        hold = hold[: np.argmax(np.diff(np.concatenate([hold, [hold[-1] + 2]])) > 1) + 1]  # first contiguous stretch
        if len(hold) < 4:
            continue
        a, b = int(pr.sl[hold[0]]), int(pr.sl[hold[-1]])
        ys = simulate_reading(r.force[: b + 1], r.dt, replace(run_params(p, r), r0_ohm=1.0), level=l, fs=r.fs)
        real.append(r.reading[b] / r.reading[a])
        sim.append(ys[b] / ys[a])
    if not real:
        return {}
    return {"real_median": float(np.median(real)), "sim_median": float(np.median(sim)),
            "real_p10_p90": [float(np.percentile(real, 10)), float(np.percentile(real, 90))],
            "sim_p10_p90": [float(np.percentile(sim, 10)), float(np.percentile(sim, 90))]}


def save_fit(fit: ChainFit, path: str | Path, extra: dict[str, Any] | None = None) -> Path:
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps({**(extra or {}), **fit.to_json()}, indent=2, default=float))
    tmp.replace(path)
    return path


def load_params(path: str | Path) -> tuple[ChainParams, dict[str, Any]]:
    d = json.loads(Path(path).read_text())
    return ChainParams.from_json(d["params"]), d


def press_stats(runs: Seq[RealRun], min_force_frac: float = 0.1, min_force_n: float = 0.05) -> dict[str, list[float]]:
    """Per press of the real runs: peak force (N), rise, hold (>= 90 % of peak), fall and gap times (s)."""
    out: dict[str, list[float]] = {k: [] for k in ("peak_force_n", "rise_s", "hold_s", "fall_s", "gap_s")}
    for r in runs:
        sls = presses_of(r.force, max(min_force_frac * r.force.max(), min_force_n))
        for i, sl in enumerate(sls):
            f = r.force[sl]
            hold = np.flatnonzero(f >= 0.9 * f.max())
            out["peak_force_n"].append(float(np.percentile(f, 95)))
            out["rise_s"].append(float(hold[0] * r.dt + r.dt))
            out["hold_s"].append(float((hold[-1] - hold[0]) * r.dt + r.dt))
            out["fall_s"].append(float((len(f) - hold[-1]) * r.dt))
            if i + 1 < len(sls):
                out["gap_s"].append(float((sls[i + 1].start - sl.stop) * r.dt))
    return out


def plateau_points(pairs: Seq[tuple[np.ndarray, np.ndarray]], min_force_frac: float = 0.1,
                   min_force_n: float = 0.05) -> np.ndarray:
    """[P, 2]: per press of the (force [T] N, reading [T]) pairs, ln of its plateau force (mean over the samples
    >= 90 % of its peak) and ln of its plateau reading (their median); presses with < 3 plateau samples or a
    reading <= 0 are left out."""
    out = []
    for f, y in pairs:
        f, y = np.asarray(f, np.float64), np.asarray(y, np.float64)
        for sl in presses_of(f, max(min_force_frac * f.max(), min_force_n)):
            ff, yy = f[sl], y[sl]
            h = ff >= 0.9 * ff.max()
            if h.sum() >= 3 and np.median(yy[h]) > 0:
                out.append((np.log(ff[h].mean()), np.log(np.median(yy[h]))))
    return np.asarray(out).reshape(-1, 2)


def _spread_at_equal_force(pts: np.ndarray) -> tuple[float, float]:
    """(robust sd, outlier share) of ln reading about a quadratic in ln force (a line or a constant where the
    presses are few or their forces close): least squares, then refit without the residuals beyond 4 robust sd
    (1.4826 x the median absolute residual); the sd is the robust one, outliers (presses that missed the film,
    chain_fit's miss_prob) are counted apart."""
    deg = 2 if len(pts) >= 6 and np.ptp(pts[:, 0]) > 0.2 else 1 if len(pts) >= 3 and np.ptp(pts[:, 0]) > 0.05 else 0
    A = np.vander(pts[:, 0], deg + 1)
    keep = np.ones(len(pts), bool)
    for _ in range(3):
        r = pts[:, 1] - A @ np.linalg.lstsq(A[keep], pts[keep, 1], rcond=None)[0]
        sd = 1.4826 * float(np.median(np.abs(r[keep] - np.median(r[keep]))))
        keep = np.abs(r - np.median(r[keep])) <= 4.0 * max(sd, 1e-9)
    return sd, float(1.0 - keep.mean())


def press_spread(real: Seq[tuple[np.ndarray, np.ndarray]], sim: Seq[tuple[np.ndarray, np.ndarray]]) -> dict[str, Any]:
    """How spread the simulated presses read at equal force beside the real ones (a check of the randomization
    on the training runs; no test data): per press (plateau_points) the robust sd of ln plateau reading about
    a quadratic in ln plateau force (_spread_at_equal_force; outliers, presses that missed the film, apart), for the real presses and for the simulated presses inside the real presses'
    force range. ratio > 1: the simulated presses are more spread at equal force (harder to read) than the real.
    Its parts are each press's placement level, the episode's gain and full scale, the replicate's law and the
    creep; see randomization_from_fit."""
    pr, ps = plateau_points(real), plateau_points(sim)
    if len(pr) < 3 or not len(ps):
        return {"n_real": len(pr), "n_sim": len(ps)}
    lo, hi = float(pr[:, 0].min()), float(pr[:, 0].max())
    ps = ps[(ps[:, 0] >= lo) & (ps[:, 0] <= hi)]
    if len(ps) < 3:
        return {"n_real": len(pr), "n_sim": len(ps)}
    (a, oa), (b, ob) = _spread_at_equal_force(pr), _spread_at_equal_force(ps)
    return {"real_ln_reading_sd": a, "sim_ln_reading_sd": b, "ratio": b / a if a > 0 else None,
            "real_outlier_share": oa, "sim_outlier_share": ob, "n_real": len(pr), "n_sim": len(ps),
            "force_range_n": [float(np.exp(lo)), float(np.exp(hi))]}


SLOPE_T0_S = 0.05  # estimate: one sample at 20 Hz, the earliest time a hold is resolved (bench_s2r_identify)


def _press_slopes(force_runs: Seq[tuple[np.ndarray, np.ndarray, float, float, float]], p: ChainParams) -> tuple[np.ndarray, np.ndarray]:
    """Per press (runs of >= 4 usable presses): the local slope d ln R / d ln F (ln R on [1, ln F, ln(1 + t / T0)]
    over the ramp above 30 % of the peak and the hold; R through the inverse divider) minus its run mean, and the
    press level (median ln R on the hold, >= 90 % of the peak) minus its run mean."""
    ds, dl = [], []
    for force, reading, dt, fs, r_ref in force_runs:  # r_ref: the run's reference resistor (run_params)
        with np.errstate(divide="ignore", invalid="ignore"):
            lnr = np.log(resistance_from_reading(reading, replace(p, r_ref_ohm=r_ref), fs))
        s_run, l_run = [], []
        for sl in presses_of(force, max(0.1 * float(force.max()), 0.05)):
            seg = np.arange(sl.start, sl.stop)
            f = force[seg]
            loc = seg[f > max(0.3 * f.max(), p.threshold_force_n + 1e-6)]
            if len(loc) < 8:
                continue
            loc = loc[: np.flatnonzero(force[loc] >= 0.9 * f.max())[-1] + 1]
            fe = force[loc] - p.threshold_force_n
            hold = loc[force[loc] >= 0.9 * f.max()]
            if len(loc) < 8 or len(hold) < 3 or not np.all(np.isfinite(lnr[loc])) or np.ptp(np.log(fe)) < 0.3:
                continue
            A = np.c_[np.ones(len(loc)), np.log(fe), np.log1p(np.arange(len(loc)) * dt / SLOPE_T0_S)]
            s_run.append(float(np.linalg.lstsq(A, lnr[loc], rcond=None)[0][1]))
            l_run.append(float(np.median(lnr[hold])))
        if len(s_run) >= 4:
            ds.extend(np.asarray(s_run) - np.mean(s_run))
            dl.extend(np.asarray(l_run) - np.mean(l_run))
    return np.asarray(ds), np.asarray(dl)


def press_slope_spread(fit: ChainFit, runs: Seq[RealRun], seed: int = 0) -> dict[str, float]:
    """Press-to-press sensitivity variation (contact variation: tip tilt and local film thickness change where
    and how the contact area grows with force, so each press has its own level AND slope; Holm, Electric
    Contacts 1967, sect. 1-5: constriction resistance of a multi-spot contact): measured model-free on the
    runs (the training runs) as the within-run spread of the presses' local slopes d ln R / d ln F and their
    regression on the press level; the chain's own spread of the same statistic (its creep and noise on the
    same forces at one level, seeded) is removed in quadrature. Returns slope_level_coef (per unit ln level),
    slope_press_sd (the rest, independent of the level) and the measured parts."""
    p = fit.params
    ds, dl = _press_slopes([(r.force, r.reading, r.dt, r.fs, run_params(p, r).r_ref_ohm) for r in runs], p)
    if len(ds) < 8:
        return {"slope_level_coef": 0.0, "slope_press_sd": 0.0, "n_presses": len(ds)}
    rng = np.random.default_rng([int(seed), 0x51])
    q = replace(p, miss_prob=0.0)
    sim = [(r.force, simulate_reading(r.force, r.dt, run_params(q, r), fs=r.fs, rng=rng), r.dt, r.fs,
            run_params(q, r).r_ref_ohm) for r in runs]
    cs, _ = _press_slopes(sim, p)
    var_dl = float(np.var(dl, ddof=1))
    corr = float(np.corrcoef(ds, dl)[0, 1]) if var_dl > 0 else 0.0
    # the level term only where the correlation is resolved (|r| > 2 / sqrt(n), about two standard errors)
    coef = float(np.cov(ds, dl)[0, 1] / var_dl) if var_dl > 0 and abs(corr) > 2.0 / np.sqrt(len(ds)) else 0.0
    resid = float(np.var(ds - coef * dl, ddof=1))
    out = {"slope_sd_real": float(np.std(ds, ddof=1)), "slope_level_corr": corr, "n_presses": len(ds),
           "n_presses_chain": len(cs)}
    if len(cs) < 8:  # the chain's own spread is not measurable on these forces (saturated readout): nothing added
        return {"slope_level_coef": 0.0, "slope_press_sd": 0.0, **out}
    chain = float(np.var(cs, ddof=1))
    return {"slope_level_coef": coef, "slope_press_sd": float(np.sqrt(max(resid - chain, 0.0))),
            "slope_sd_chain": float(np.sqrt(chain)), **out}


RATED_LOW_FRAC = 0.05  # estimate: a force sensor's rated range is quoted from ~5 % of its full scale up (below it
# the reading barely leaves its unloaded level); the shape over the range is not given, log-uniform kept


def peak_force_dist(peaks: Seq[float], rated_force_n: float | None = None):
    """Peak-force distribution of the simulated presses: log-uniform from half the smallest to 1.2 x the largest
    real training peak; with the sensor's rated force (what the user knows of the rig / sensor, never the test
    runs) it spans at least [RATED_LOW_FRAC, 1] x rated, so pre-training covers what the few real runs do not
    (the point of a simulator; Tobin et al. 2017, domain randomization over the deployment range)."""
    from scenes.randomize import Dist

    lo, hi = 0.5 * float(min(peaks)), 1.2 * float(max(peaks))
    if rated_force_n is not None and np.isfinite(rated_force_n) and rated_force_n > 0:
        lo, hi = min(lo, RATED_LOW_FRAC * float(rated_force_n)), max(hi, float(rated_force_n))
    return Dist(kind="loguniform", low=lo, high=hi)


def randomization_from_fit(fit: ChainFit, runs: Seq[RealRun], press_slope: bool = False,
                           rated_force_n: float | None = None, run_level: bool = False):
    """The Randomization `fit` writes: joint bootstrap replicates of the chain, the gain (bootstrap spread of
    ln r0), the board's full scale (run-to-run spread), the noise, and press protocols spanning the real
    presses (peak force log-uniform from half the smallest to 1.2 x the largest peak, widened to the rated
    range when given: peak_force_dist; times uniform over their 5-95 % range). run_level: the episode's (one
    simulated run's) ln gain u_run ~ N(0, level_run_log_sd^2), the hierarchical run-level sd (run_level_sd);
    off: the median over the replicates of the std of the run means (rounds 2-5; it holds the within-run spread
    over each run's few presses as well, and the run-level prior does not reach it)."""
    from scenes.randomize import Dist, Randomization

    p = fit.params
    st = press_stats(runs)
    press = {}
    for k, v in st.items():
        if len(v) < 2:
            continue
        if k == "peak_force_n":
            press[k] = peak_force_dist(v, rated_force_n)
        else:
            press[k] = Dist(kind="uniform", low=float(np.percentile(v, 5)), high=float(np.percentile(v, 95)))
    # joint replicates, r0 with them (it trades off against the exponent: drawing the exponent of one
    # replicate with the point fit's r0 and an independent gain of the bootstrap's ln r0 spread gave simulated
    # levels at equal force twice as spread as the real ones); per press the within-run spread, per episode
    # (one run: mounting, board) the between-run spread of the run means
    boot = []
    for b in fit.boot:
        d = {k: float(b[k]) for k in ("exponent", "creep_amplitude", "creep_force_n", "tau_min_s", "tau_max_s",
                                      "r0_ohm", "r_series_ohm", "threshold_force_n", "contact_force_n", "tunnel_force_n")
             if k in b}
        if "level_within_run_sd" in b:
            d["level_log_sd"] = float(b["level_within_run_sd"])
        boot.append(d)
    sd_gain = float(np.median([b["level_between_run_sd"] for b in fit.boot])) if fit.boot and "level_between_run_sd" in fit.boot[0] else 0.1
    if run_level:
        sd_gain = float(p.level_run_log_sd)
    episode = {"gain_log": Dist(kind="normal", mean=0.0, sd=max(sd_gain, 0.05)),  # estimate: floor 5 %
               "noise_scale": Dist(kind="loguniform", low=0.5, high=2.0)}  # estimate
    if p.full_scale_log_sd > 0:
        episode["full_scale"] = Dist(kind="lognormal", median=p.full_scale, log_sd=p.full_scale_log_sd)
    if press_slope:  # each press's own sensitivity (press_slope_spread), drawn per press by the generator
        sp = press_slope_spread(fit, runs)
        episode["slope_level_coef"] = Dist(kind="fixed", value=sp["slope_level_coef"])
        episode["slope_press_sd"] = Dist(kind="fixed", value=sp["slope_press_sd"])
    return Randomization(episode=episode, press=press, boot=boot)
