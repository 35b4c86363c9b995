"""Numpy reference of the `velostat` chain (paper key `velostat`); sensors/velostat/kernels.py must match it.

Film, per taxel and sample step (dt = 1 / sample rate), pressure p >= 0 (Pa), creep pressure c (Pa):
  model "aging" (default; contact aging, Dieterich & Kilgore, PAGEOPH 143, 1994; aging law of rate-and-state
          friction, Ruina 1983): contact age theta' = 1 - theta r, r = max(p', 0) / dp_c (a rising load renews
          the contact population, as slip does in the aging law); a new contact is born at the steady-state age
          1 / r of its loading. The aging gain grows only while the age grows,
            a += ln((theta_new + theta_c) / (theta_old + theta_c))  when theta_new > theta_old,
          so a constant-rate ramp adds nothing (creep during loading negligible, velostat Fig. 5), a hold adds
          ln(1 + t / (theta_0 + theta_c)) with theta_0 = dp_c / p' of the preceding ramp (faster ramp, younger
          contact, more creep in the hold), and the gains of successive holds accumulate (eq. 2, Fig. 22a).
          c = D f_c(x, y) p_c ln(1 + p / p_c) a; unloaded, a recovers exp(-dt / tau_rec) per step.
          State per taxel: (theta, a, p_prev).
  model "spectrum" (the earlier one, kept for comparison and sensors/velostat/fit.py): Schapery-type drive
          Phi(p) = D f_c p_c ln(1 + p / p_c); c_k' = d_k c_k + (1 - d_k) w_k Phi(p'), d_k = exp(-dt / tau_k),
          w_k = 1 / K, tau_k log-spaced (creep builds from the first pascal of every ramp); c = sum_k c_k.
  conduct G = g_ref f_g(x, y) ((p + c) / p_ref)^n  for p > 0, else 0
          (interface contact conductance ~ load^n, n ~ 1: Holm, Electric Contacts, 1967; velostat eq. 1)
Readout, per sample (velostat eq. 1, Fig. 1d; 4-/5-wire ITO position layers, sect. 5.1):
  force   paths film + ITO in parallel: G_f = sum_n 1 / (1/G_n + R_ito,f(x_n, y_n)); V_f = min(I / G_f, V_c)
  position  probe node of a driven gradient sheet: V_p = sum_n G'_n V_n / (sum_n G'_n + 1 / R_in),
          G'_n = 1 / (1/G_n + R_src,n)  -> the conductance-weighted mean of the contacts' potentials, pulled
          toward 0 V by the probe load when the film resistance is high (low force)
  ADC     v + noise, clipped to [0, range], floor-quantised to `bits`, read back at the code centre
Arithmetic in float32 like the Warp kernels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

f32 = np.float32


@dataclass(frozen=True)
class FilmParams:
    """Flat film constants (SI). Per-taxel arrays are [N]; creep arrays [K]."""

    g_ref_s: np.ndarray  # [N] conductance of the taxel cell at p_ref (includes the random field f_g)
    creep_drive: np.ndarray  # [N] a * f_c * p_c (Pa)
    p_ref_pa: float
    p_c_pa: float
    exponent: float
    decay: np.ndarray  # [K] exp(-dt / tau_k) (spectrum)
    weight: np.ndarray  # [K] 1 / K (spectrum)
    model: str = "spectrum"  # "aging" | "spectrum"
    dt_s: float = 0.1  # sample step (aging)
    renewal_pa: float = 2500.0  # dp_c: pressure rise that renews the contact (aging)
    cutoff_s: float = 0.5  # theta_c: cutoff time of the aging law (aging)
    recovery_decay: float = 1.0  # exp(-dt / tau_rec): memory of an unloaded contact per step (aging)

    @property
    def n_creep(self) -> int:
        return 3 if self.model == "aging" else len(self.decay)


@dataclass(frozen=True)
class ReadoutParams:
    """Per-taxel readout geometry [N] and circuit constants."""

    r_force_ohm: np.ndarray  # [N] ITO (both sheets) + leads in series with taxel n on the force path
    v_x: np.ndarray  # [N] potential of the driven sheet at taxel n in the X phase (V)
    r_x_ohm: np.ndarray  # [N] source (Thevenin) + probe-sheet resistance in the X phase
    v_y: np.ndarray
    r_y_ohm: np.ndarray
    current_a: float
    compliance_v: float
    input_resistance_ohm: float
    drive_v: float
    adc_bits: int
    adc_range_v: float
    size_x_m: float
    size_y_m: float
    x_sign: float  # decoding: x = (v / drive - 0.5) * L * sign (5-wire keeps the same convention)


def film_chain_numpy(pressure: np.ndarray, p: FilmParams, state: np.ndarray | None = None):
    """pressure [E, T, N] (Pa) -> conductance [E, T, N] (S), final creep state [E*N, K] (spectrum: Pa;
    aging: K = 3, (theta s, a, p_prev Pa))."""
    if p.model == "aging":
        return _aging_numpy(pressure, p, state)
    E, T, N = pressure.shape
    K = p.n_creep
    c = np.zeros((E, N, K), f32) if state is None else state.reshape(E, N, K).astype(f32).copy()
    d = p.decay.astype(f32)
    w1 = ((1.0 - p.decay) * p.weight).astype(f32)
    drive = p.creep_drive.astype(f32)
    g_ref = p.g_ref_s.astype(f32)
    inv_pc, inv_pref = f32(1.0 / p.p_c_pa), f32(1.0 / p.p_ref_pa)
    n = f32(p.exponent)
    out = np.zeros((E, T, N), f32)
    for k in range(T):
        pk = np.maximum(pressure[:, k, :].astype(f32), f32(0.0))
        phi = drive * np.log1p(pk * inv_pc).astype(f32)
        c = d * c + w1 * phi[..., None]
        cs = c.sum(-1, dtype=f32)
        g = g_ref * np.power((pk + cs) * inv_pref, n, dtype=f32)
        out[:, k, :] = np.where(pk > 0, g, f32(0.0))
    return out, c.reshape(E * N, K)


def _aging_numpy(pressure: np.ndarray, p: FilmParams, state: np.ndarray | None):
    E, T, N = pressure.shape
    st = np.zeros((E, N, 3), f32) if state is None else state.reshape(E, N, 3).astype(f32).copy()
    th, a, pp = st[..., 0].copy(), st[..., 1].copy(), st[..., 2].copy()
    drive = p.creep_drive.astype(f32)
    g_ref = p.g_ref_s.astype(f32)
    inv_pc, inv_pref, n = f32(1.0 / p.p_c_pa), f32(1.0 / p.p_ref_pa), f32(p.exponent)
    inv_dt, dt = f32(1.0 / p.dt_s), f32(p.dt_s)
    inv_dpc, thc, rec = f32(1.0 / p.renewal_pa), f32(p.cutoff_s), f32(p.recovery_decay)
    one, zero = f32(1.0), f32(0.0)
    out = np.zeros((E, T, N), f32)
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(T):
            pk = np.maximum(pressure[:, k, :].astype(f32), zero)
            on = pk > zero
            r = (np.maximum((pk - pp) * inv_dt, zero) * inv_dpc).astype(f32)
            rising = r > zero
            th_ss = np.where(rising, one / np.where(rising, r, one), zero).astype(f32)
            relax = (th_ss + (th - th_ss) * np.exp(-r * dt).astype(f32)).astype(f32)
            th_new = np.where(pp > zero, np.where(rising, relax, th + dt), th_ss).astype(f32)
            gain = np.log((th_new + thc) / (th + thc)).astype(f32)
            a_on = np.where((pp > zero) & (th_new > th), a + gain, a).astype(f32)
            a = np.where(on, a_on, a * rec).astype(f32)
            th = np.where(on, th_new, zero).astype(f32)
            c = (drive * np.log1p(pk * inv_pc).astype(f32) * a).astype(f32)
            g = g_ref * np.power((pk + c) * inv_pref, n, dtype=f32)
            out[:, k, :] = np.where(on, g, zero)
            pp = pk
    return out, np.stack([th, a, pp], -1).reshape(E * N, 3)


def quantise(v: np.ndarray, bits: int, range_v: float) -> tuple[np.ndarray, np.ndarray]:
    """Unipolar ADC: codes (int32) and the voltage at the code centre (float32)."""
    full = 2**bits
    lsb = f32(range_v / full)
    vc = np.clip(v.astype(f32), f32(0.0), f32(range_v))
    code = np.minimum(np.floor(vc / lsb), full - 1).astype(np.int32)
    return code, ((code.astype(f32) + f32(0.5)) * lsb).astype(f32)


def readout_numpy(cond: np.ndarray, noise_v: np.ndarray, r: ReadoutParams) -> dict[str, np.ndarray]:
    """cond [E, T, N] (S), noise [E, T, 3] (V) -> true and measured channels (float32)."""
    on = cond > 0
    safe = np.where(on, cond, f32(1.0))

    def paths(r_series):
        return np.where(on, f32(1.0) / (f32(1.0) / safe + r_series.astype(f32)), f32(0.0)).astype(f32)

    g_f = paths(r.r_force_ohm).sum(-1, dtype=f32)
    g_film = cond.sum(-1, dtype=f32)
    big = f32(1e12)
    r_true = np.where(g_f > 0, f32(1.0) / np.where(g_f > 0, g_f, f32(1.0)), big).astype(f32)
    r_film = np.where(g_film > 0, f32(1.0) / np.where(g_film > 0, g_film, f32(1.0)), big).astype(f32)
    v_f = np.minimum(f32(r.current_a) * r_true, f32(r.compliance_v)).astype(f32)
    gin = f32(1.0 / r.input_resistance_ohm)
    gx = paths(r.r_x_ohm)
    gy = paths(r.r_y_ohm)
    v_x = ((gx * r.v_x.astype(f32)).sum(-1, dtype=f32) / (gx.sum(-1, dtype=f32) + gin)).astype(f32)
    v_y = ((gy * r.v_y.astype(f32)).sum(-1, dtype=f32) / (gy.sum(-1, dtype=f32) + gin)).astype(f32)
    volts = np.stack([v_f, v_x, v_y], axis=-1)
    code, v_adc = quantise(volts + noise_v.astype(f32), r.adc_bits, r.adc_range_v)
    return finish(r_film, r_true, volts, code, v_adc, r)


def force_centroid_numpy(pressure: np.ndarray, xy: np.ndarray, area: float) -> tuple[np.ndarray, np.ndarray]:
    """pressure [E, T, N] (Pa) -> normal force [E, T] (N) = sum of max(p, 0) x taxel area, and the
    pressure-weighted contact centroid [E, T, 2] (m; NaN unloaded), in float64 (the recorded labels)."""
    p = np.clip(np.asarray(pressure, np.float64), 0, None)
    fz = p.sum(-1) * area
    with np.errstate(invalid="ignore", divide="ignore"):
        cxy = np.einsum("etn,nk->etk", p, xy) * area / fz[..., None]
    cxy[fz <= 0] = np.nan
    return fz, cxy


def finish(r_film, r_true, volts, code, v_adc, r: ReadoutParams) -> dict[str, np.ndarray]:
    """Decode the ADC voltages: measured resistance, touch flag, decoded position (NaN without touch)."""
    r_film = np.minimum(r_film, f32(1e12)).astype(f32)  # a vanishing contact is an open circuit
    r_true = np.minimum(r_true, f32(1e12)).astype(f32)
    r_meas = (v_adc[..., 0] / f32(r.current_a)).astype(f32)
    touch = v_adc[..., 0] < f32(0.98 * r.compliance_v)
    x = (v_adc[..., 1] / f32(r.drive_v) - f32(0.5)) * f32(r.size_x_m)
    y = (v_adc[..., 2] / f32(r.drive_v) - f32(0.5)) * f32(r.size_y_m)
    pos = np.stack([x, y], axis=-1).astype(f32)
    pos[~touch] = np.nan
    return {
        "resistance_film": r_film,
        "resistance": r_true,
        "voltage_true": volts.astype(f32),
        "adc": code,
        "voltage": v_adc,
        "resistance_measured": r_meas,
        "touch": touch,
        "position_measured": pos,
    }
