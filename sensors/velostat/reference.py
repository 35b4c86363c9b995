"""Numpy reference of the `velostat` chain (paper key `velostat`); sensors/velostat/kernels.py must match it.

Film, per taxel and sample step (dt = 1 / sample rate), pressure p >= 0 (Pa):
  creep   Phi(p) = a f_c(x, y) p_c ln(1 + p / p_c)              (Schapery-type nonlinear creep drive;
          c_k' = d_k c_k + (1 - d_k) w_k Phi(p'),  d_k = exp(-dt / tau_k), w_k = 1 / K,
          tau_k log-spaced -> log-time growth of the contact (Dieterich & Kilgore 1994); unloaded, the
          states recover toward 0 with the same times
  conduct G = g_ref f_g(x, y) ((p + sum_k c_k) / p_ref)^n  for p > 0, else 0
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
    decay: np.ndarray  # [K] exp(-dt / tau_k)
    weight: np.ndarray  # [K] 1 / K

    @property
    def n_creep(self) -> int:
        return len(self.decay)


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
    """pressure [E, T, N] (Pa) -> conductance [E, T, N] (S), final creep state [E*N, K] (Pa)."""
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
