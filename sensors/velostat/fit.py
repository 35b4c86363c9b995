"""Real-to-sim: fit the `velostat` film model's physical parameters to a real recording (force + reading).

Fast forward model (numpy/scipy, no MuJoCo): the recorded force F(t) drives one contact of the
preset's indenter area A (pressure p = F / A, spread uniformly), through the same equations as
sensors/velostat/reference.py:
  creep   c_k[t] = d_k c_k[t-1] + (1 - d_k) w_k Phi(p[t]),  Phi(p) = a p_c ln(1 + p / p_c),
          d_k = exp(-dt / tau_k), tau_k log-spaced from tau_min to tau_max, w_k = 1 / K
          (a first-order IIR filter per term: scipy.signal.lfilter, O(T) in C)
  film    R_film = R_ref (A_ref / A) ((p + sum_k c_k) / p_ref)^-n     (R_ref = film.resistance_at_ref_ohm)
  board   reading = k (R_film + R_ITO)            k: the board's gain (reading per ohm), a nuisance
                                                  parameter: not a preset field; R_ITO: the preset's
                                                  ITO + lead resistance at the film centre
Only k R_ref is identifiable from a board that reads in raw units, so R_ref stays at the preset's value
and k is fitted (closed form: the mean log ratio). Residual: ln(reading_sim) - ln(reading_real) on loaded samples (F > min_force_n; unloaded,
the simulated film is an open circuit and the real board reads its own rest level), so every force decade
weighs alike. By default (per_press) each press's mean log residual is removed before the least squares:
the Lupasic logs read a level that varies by up to x6 between presses at equal force (tip placement; not
in the model), which would otherwise swamp the force law and the creep within a press; the gain is then
set on the full residual. scipy.optimize.least_squares (trust region reflective, bounded) over
  theta = [ln k, n, ln a, ln p_c, ln tau_min, ln tau_max].
Noise: the readout noise is not a least-squares parameter; it is estimated from the real reading's
sample-to-sample scatter on loaded samples (median absolute successive difference / (0.6745 sqrt 2)) and
converted to volts at the ADC (noise_v = I sigma_reading / k).
"fit error before": the preset's physical parameters with only k fitted (the preset has no gain).
The velostat model has no hysteresis (play) bank, so there are no hysteresis weights to fit.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Sequence as Seq
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "FitParams",
    "VelostatFit",
    "fit_recording",
    "forward_reading",
    "load_runs",
    "noise_estimate",
    "params_from_config",
    "write_fitted_preset",
]


@dataclass
class FitParams:
    gain: float  # reading per ohm
    exponent: float
    amplitude: float
    p_c_pa: float
    tau_min_s: float
    tau_max_s: float
    n_creep: int = 6

    NAMES = ("ln_gain", "exponent", "ln_amplitude", "ln_p_c", "ln_tau_min", "ln_tau_max")

    def to_theta(self) -> np.ndarray:
        return np.array([np.log(self.gain), self.exponent, np.log(max(self.amplitude, 1e-6)), np.log(self.p_c_pa),
                         np.log(self.tau_min_s), np.log(self.tau_max_s)])

    @classmethod
    def from_theta(cls, th: Seq[float], n_creep: int) -> FitParams:
        return cls(float(np.exp(th[0])), float(th[1]), float(np.exp(th[2])), float(np.exp(th[3])),
                   float(np.exp(th[4])), float(np.exp(th[5])), n_creep)

    @property
    def times_s(self) -> list[float]:
        if self.n_creep == 1:
            return [self.tau_min_s]
        return [float(v) for v in np.geomspace(self.tau_min_s, self.tau_max_s, self.n_creep)]

    def to_json(self) -> dict[str, Any]:
        return {"gain_reading_per_ohm": self.gain, "exponent": self.exponent, "creep_amplitude": self.amplitude,
                "saturation_pressure_pa": self.p_c_pa, "times_s": self.times_s}


@dataclass
class Model:
    """Fixed (not fitted) constants of the forward model, from the preset."""

    area_m2: float
    r_ref_ohm: float  # resistance of the contact area at p_ref: R_ref * (1 cm^2 / A)
    p_ref_pa: float
    r_series_ohm: float
    current_a: float


def params_from_config(cfg, gain: float = 1.0) -> tuple[FitParams, Model]:
    s = cfg.sensor
    taus = list(s.creep.times_s)
    area = cfg.indenter.size_x_m * cfg.indenter.size_y_m
    r = s.readout
    r_series = r.sheet_resistance_ohm * 0.5 + r.sheet_resistance_ohm * 0.5 + r.lead_resistance_ohm  # film centre
    fp = FitParams(gain, s.film.exponent, s.creep.amplitude, s.creep.saturation_pressure_pa, min(taus), max(taus), len(taus))
    return fp, Model(area, s.film.resistance_at_ref_ohm * 1e-4 / area, s.film.reference_pressure_pa, r_series, r.current_a)


def forward_reading(force_n: np.ndarray, dt: float, fp: FitParams, m: Model) -> np.ndarray:
    """Recorded force [T] (N) at step dt -> simulated board reading [T] (inf where unloaded)."""
    from scipy.signal import lfilter

    p = np.maximum(np.asarray(force_n, np.float64), 0.0) / m.area_m2
    phi = fp.amplitude * fp.p_c_pa * np.log1p(p / fp.p_c_pa)
    taus = np.asarray(fp.times_s)
    d = np.exp(-dt / taus)
    w = 1.0 / len(taus)
    c = np.zeros_like(p)
    for dk in d:
        c += lfilter([(1.0 - dk) * w], [1.0, -dk], phi)
    with np.errstate(divide="ignore"):
        r_film = np.where(p > 0, m.r_ref_ohm * ((p + c) / m.p_ref_pa) ** (-fp.exponent), np.inf)
    return fp.gain * (r_film + m.r_series_ohm)


@dataclass
class Run:
    key: str
    force: np.ndarray  # [T] N at the fit rate
    reading: np.ndarray  # [T]
    dt: float
    noise_sigma: float  # reading units, at the recording's own rate


def noise_estimate(reading: np.ndarray, loaded: np.ndarray) -> float:
    d = np.diff(np.asarray(reading, np.float64))[loaded[1:] & loaded[:-1]]
    d = d[np.isfinite(d)]  # a dropped sample (NaN) leaves its two differences out
    if len(d) < 10:
        return float("nan")
    return float(np.median(np.abs(d - np.median(d))) / 0.6745 / np.sqrt(2))


def load_runs(recording: str | Path, *, input_channel: str = "sensor", target: str = "force", rate_hz: float = 20.0,
              episodes: str | None = None, min_force_n: float = 0.5) -> list[Run]:
    from sensors.data.column_import import to_newtons
    from sensors.data.recording import Recording, split_column
    from sensors.data.resample import PART_SEP, resample_parts

    runs = []
    with Recording(recording) as rec:
        for ep in rec.episode_ids:
            if episodes and not fnmatch.fnmatch(ep, episodes):
                continue
            try:
                s = np.asarray(rec.read_column(ep, input_channel), np.float64).reshape(-1)
                f = to_newtons(np.asarray(rec.read_column(ep, target), np.float64).reshape(-1),
                               rec.units(ep, split_column(target)[0]), f"{recording}: episode {ep}: the target '{target}'")
                t = np.asarray(rec.read(ep, "time"), np.float64)
            except KeyError as exc:
                raise ValueError(str(exc.args[0])) from None
            if len(s) != len(f):
                raise ValueError(f"{recording}: episode {ep}: '{input_channel}' is not one value per sample")
            sig = noise_estimate(s, f > min_force_n)
            try:  # dropped samples (NaN) bridged up to MAX_GAP_S; cut at a longer stall into parts EP@k
                parts = resample_parts(t, [s, f], rate_hz)
            except ValueError as exc:
                raise ValueError(f"{recording}: episode {ep}: {exc}") from None
            for k, (_, (sr, fr)) in enumerate(parts):
                runs.append(Run(ep if len(parts) == 1 else f"{ep}{PART_SEP}{k + 1}", fr[:, 0], sr[:, 0], 1.0 / rate_hz, sig))
    if not runs:
        raise ValueError(f"{recording}: no episode" + (f" matches '{episodes}'" if episodes else ""))
    return runs


@dataclass
class VelostatFit:
    before: FitParams
    after: FitParams
    model: Model
    err_before: dict[str, float]
    err_after: dict[str, float]
    per_run_before: dict[str, float]
    per_run_after: dict[str, float]
    noise_v: float
    noise_reading: float
    result: dict[str, Any] = field(default_factory=dict)


def _press_ids(on: np.ndarray) -> np.ndarray:
    """Index of the contiguous loaded stretch (press) of each sample of ``on``."""
    start = on & ~np.concatenate([[False], on[:-1]])
    return np.cumsum(start)[on]


def _residuals(fp: FitParams, m: Model, runs: Seq[Run], min_force_n: float, per_press: bool = False) -> list[np.ndarray]:
    """ln(sim) - ln(real) on loaded samples; per_press: minus its mean over each press (shape only)."""
    out = []
    for r in runs:
        on = (r.force > min_force_n) & (r.reading > 0)
        sim = forward_reading(r.force, r.dt, fp, m)
        e = np.log(sim[on]) - np.log(r.reading[on])
        if per_press and len(e):
            ids = _press_ids(on)
            e = e - (np.bincount(ids, e) / np.maximum(np.bincount(ids), 1))[ids]
        out.append(e)
    return out


def fit_errors(fp: FitParams, m: Model, runs: Seq[Run], min_force_n: float) -> tuple[dict[str, float], dict[str, float]]:
    res = _residuals(fp, m, runs, min_force_n)
    shape = np.concatenate(_residuals(fp, m, runs, min_force_n, per_press=True))
    allr = np.concatenate(res)
    per = {r.key: float(np.sqrt(np.mean(e ** 2))) for r, e in zip(runs, res)}
    return ({"rms_log": float(np.sqrt(np.mean(allr ** 2))),
             "rms_log_within_press": float(np.sqrt(np.mean(shape ** 2))),
             "median_abs_rel": float(np.median(np.abs(np.expm1(allr)))),
             "n_samples": len(allr)}, per)


BOUNDS = (np.array([-40.0, 0.3, np.log(1e-3), np.log(1e2), np.log(0.05), np.log(1.0)]),
          np.array([40.0, 3.0, np.log(1e2), np.log(1e8), np.log(20.0), np.log(3000.0)]))


def fit_recording(cfg, runs: Seq[Run], *, min_force_n: float = 0.5, max_nfev: int = 200,
                  per_press: bool = True) -> VelostatFit:
    from scipy.optimize import least_squares

    p0, m = params_from_config(cfg)
    # before: preset physics, only the gain (closed form in log space: mean log ratio)
    r0 = np.concatenate(_residuals(p0, m, runs, min_force_n))
    before = FitParams(float(np.exp(-np.mean(r0))), p0.exponent, p0.amplitude, p0.p_c_pa, p0.tau_min_s, p0.tau_max_s, p0.n_creep)
    eb, pb = fit_errors(before, m, runs, min_force_n)
    th0 = np.clip(before.to_theta(), BOUNDS[0] + 1e-6, BOUNDS[1] - 1e-6)

    def fun(th):
        return np.concatenate(_residuals(FitParams.from_theta(th, p0.n_creep), m, runs, min_force_n, per_press=per_press))

    res = least_squares(fun, th0, bounds=BOUNDS, x_scale="jac", max_nfev=max_nfev, method="trf")
    after = FitParams.from_theta(res.x, p0.n_creep)
    r1 = np.concatenate(_residuals(after, m, runs, min_force_n))  # the gain: closed form on the full residual
    after.gain = float(after.gain * np.exp(-np.mean(r1)))
    ea, pa = fit_errors(after, m, runs, min_force_n)
    sig = float(np.nanmedian([r.noise_sigma for r in runs]))
    # the board's noise per reported sample (whatever it averages): written with oversampling 1 (save_preset)
    noise_v = float(m.current_a * sig / after.gain) if np.isfinite(sig) else float(cfg.sensor.readout.sample_noise_v)
    return VelostatFit(before, after, m, eb, ea, pb, pa, noise_v, sig,
                       {"nfev": int(res.nfev), "status": int(res.status), "message": str(res.message),
                        "cost": float(res.cost), "theta": res.x.tolist(), "names": list(FitParams.NAMES)})


def write_fitted_preset(preset: str, fit: VelostatFit, out: str | Path, source: str) -> Path:
    """The preset's YAML with the fitted sensor fields set (loadable by scenes.load_scene)."""
    import yaml

    from scenes.loader import PRESET_DIR

    src = Path(preset) if Path(preset).is_file() else PRESET_DIR / f"{preset}.yaml"
    data = yaml.safe_load(src.read_text()) or {}
    sensor = data.setdefault("sensor", {})
    a = fit.after
    sensor.setdefault("film", {})["exponent"] = round(a.exponent, 5)
    creep = sensor.setdefault("creep", {})
    creep["amplitude"] = float(f"{a.amplitude:.5g}")
    creep["saturation_pressure_pa"] = float(f"{a.p_c_pa:.5g}")
    creep["times_s"] = [float(f"{t:.4g}") for t in a.times_s]
    readout = sensor.setdefault("readout", {})
    readout["noise_v"] = float(f"{fit.noise_v:.4g}")
    readout["oversampling"] = 1  # the fitted noise is the reported sample's: no averaging on top of it
    data["name"] = f"{data.get('name', 'velostat')}_fitted"
    head = (f"# Fitted by `piezotwin fit {preset} {source}` (sensors/velostat/fit.py).\n"
            f"# Fit error (rms of ln reading, loaded samples): before {fit.err_before['rms_log']:.4f}, after {fit.err_after['rms_log']:.4f}.\n"
            f"# Board gain (not a preset field): reading = {a.gain:.6g} x (R_film + R_ITO) / ohm.\n")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(head + yaml.safe_dump(data, sort_keys=False))
    return out


def plot_fit(cfg, fit: VelostatFit, runs: Seq[Run], out_png: str | Path, min_force_n: float = 0.5) -> None:
    """Loops (reading vs force, real / preset / fitted) for up to 3 runs, and creep curves: the reading
    over each press plateau relative to its value at the plateau's start, mean over presses."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pick = sorted(runs, key=lambda r: r.force.max())
    pick = [pick[0], pick[len(pick) // 2], pick[-1]] if len(pick) >= 3 else pick
    fig, axes = plt.subplots(2, len(pick), figsize=(4.2 * len(pick), 7), squeeze=False)
    for j, r in enumerate(pick):
        ax = axes[0, j]
        on = r.force > min_force_n
        sb = forward_reading(r.force, r.dt, fit.before, fit.model)
        sa = forward_reading(r.force, r.dt, fit.after, fit.model)
        ax.plot(r.force[on], r.reading[on], "k.", ms=1.5, alpha=0.5, label="real")
        ax.plot(r.force[on], sb[on], ".", ms=1.2, alpha=0.4, color="tab:orange", label="preset (gain fitted)")
        ax.plot(r.force[on], sa[on], ".", ms=1.2, alpha=0.5, color="tab:blue", label="fitted")
        ax.set_yscale("log")
        ax.set_xlabel("force (N)")
        ax.set_ylabel("reading")
        ax.set_title(r.key, fontsize=9)
        if j == 0:
            ax.legend(fontsize=7, markerscale=6)
        ax = axes[1, j]
        for sig, lab, col in ((r.reading, "real", "k"), (sb, "preset", "tab:orange"), (sa, "fitted", "tab:blue")):
            tt, cc = creep_curve(r.force, sig, r.dt, min_force_n)
            if len(cc):
                ax.plot(tt, cc, color=col, label=lab)
        ax.set_xlabel("time in press (s)")
        ax.set_ylabel("reading / reading at press start")
        ax.grid(alpha=0.3)
        if j == 0:
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    plt.close(fig)


def creep_curve(force: np.ndarray, sig: np.ndarray, dt: float, min_force_n: float, rel_plateau: float = 0.9):
    """Mean over presses of sig(t) / sig(t0) from the first sample where the force reaches rel_plateau of
    the press's peak, for as long as the shortest such plateau lasts."""
    on = force > min_force_n
    edges = np.flatnonzero(np.diff(on.astype(int)))
    starts = [e + 1 for e in edges if not on[e]]
    ends = [e + 1 for e in edges if on[e]]
    if on[0]:
        starts = [0] + starts
    curves = []
    for a in starts:
        b = next((e for e in ends if e > a), len(force))
        seg = slice(a, b)
        f = force[seg]
        if len(f) < 3:
            continue
        i0 = a + int(np.argmax(f >= rel_plateau * f.max()))
        i1 = a + len(f) - 1 - int(np.argmax(f[::-1] >= rel_plateau * f.max()))
        if i1 - i0 >= 3:
            curves.append(sig[i0:i1 + 1] / sig[i0])
    if not curves:
        return np.array([]), np.array([])
    n = int(np.median([len(c) for c in curves]))
    curves = [c[:n] for c in curves if len(c) >= n]
    return np.arange(n) * dt, np.mean(curves, axis=0)
