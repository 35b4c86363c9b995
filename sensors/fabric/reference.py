"""Numpy reference of the per-taxel fabric chain (paper key `fabric`); sensors/fabric/kernels.py must match it.

Per taxel and sample step (dt = 1 / sample rate), with f the taxel's load scaled to the whole sample
(f = n_taxels x taxel force, N, so a uniform press gives every taxel the sample's force):
  creep      q_i' = a_i q_i + g_i (1 - a_i) f,  u = f + sum_i q_i       (Prony creep of the compaction,
             exact for f held within a step; Ferry, Viscoelastic Properties of Polymers, 1980)
  hysteresis z_k' = max(u - r_k, min(u + r_k, z_k)), then z_k' -> u + (z_k' - u) c  (slow recovery at rest);
             x = max(0, (1 - sum w) u + sum w_k z_k')  (Prandtl-Ishlinskii play bank: return-point memory;
             Brokate & Sprekels 1996). x is the effective compaction load (N).
  press      a press starts when f rises through f_on after falling below f_off; it takes the episode's next
             draw (kappa, psi): engaged contact area and knit set fraction (scenes/fabric_config.py,
             FabricPressConfig; Holm 1967; Kawabata 1980)
  knit set   x_pk' = max(x, x + (x_pk - x) c_set),  x_s = x + psi (x_pk' - x)   (the loops keep part of the peak
             compaction on release; fibre stress relaxation with c_set = exp(-dt / T_set))
  stack      R_layer = r_inf + r_amp exp(-(x / F_l)^beta)                  (in-layer, knit compaction)
             R_c     = R_c0 (1 + x / F_c)^(-m),  m in [1/3, 1/2]          (Holm, Electric Contacts 1967:
             constriction resistance rho / 2a with the a-spot radius growing as F^m)
             R_stack = n_layers R_layer + (n_layers + 1) R_c              (Kirchhoff: layers and contacts in series)
             (laws at x_s)
  column     R_taxel = n_taxels R_stack / kappa   (taxel columns in parallel give R_stack under a uniform press;
             the press's engaged area scales the conduction)
Outputs: effective load x_s and conductance 1 / R_taxel per taxel, float32 like the Warp kernel.
Press draws: `press_draws(seeds, p)` [E, M, 2] (kappa, psi ~ Beta in [0, 1]) from each episode seed (stream 2); None = every
press the mean one (kappa 1, psi = set_fraction_mean).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FabricParams:
    """Flat constants of the fabric chain (SI). Shapes in brackets; empty banks become one inert term."""

    dt_s: float
    n_taxels: int
    layers: int
    prony_decay: np.ndarray  # [P] a_i = exp(-dt / tau_i)
    prony_fraction: np.ndarray  # [P] g_i
    play_threshold_n: np.ndarray  # [K] r_k
    play_weight: np.ndarray  # [K] w_k
    recovery_decay: float  # c = exp(-dt / T_recovery)
    layer_r_inf_ohm: float
    layer_r_amp_ohm: float
    layer_force_n: float
    layer_beta: float
    contact_r0_ohm: float
    contact_force_n: float
    contact_exponent: float
    press_on_n: float = 0.05
    press_off_n: float = 0.02
    area_sigma: float = 0.0
    set_mean: float = 0.0
    set_cv: float = 0.0
    set_decay: float = 1.0  # c_set = exp(-dt / T_set)
    max_presses: int = 1

    @property
    def n_prony(self) -> int:
        return len(self.prony_decay)

    @property
    def n_play(self) -> int:
        return len(self.play_threshold_n)


def fabric_params(cfg) -> FabricParams:
    """SceneConfig with a fabric sensor -> FabricParams."""
    s = cfg.sensor
    dt = 1.0 / cfg.sampling.sample_rate_hz
    tau = np.asarray(s.creep.prony_times_s or [1.0], np.float64)
    g = np.asarray(s.creep.prony_fractions or [0.0], np.float64)
    r = np.asarray(s.hysteresis.play_thresholds_n or [0.0], np.float64)
    w = np.asarray(s.hysteresis.play_weights or [0.0], np.float64)
    st = s.stack
    return FabricParams(
        dt_s=dt,
        n_taxels=cfg.pad.n_taxels,
        layers=s.layers,
        prony_decay=np.exp(-dt / tau),
        prony_fraction=g,
        play_threshold_n=r,
        play_weight=w,
        recovery_decay=float(np.exp(-dt / s.hysteresis.recovery_time_s)),
        layer_r_inf_ohm=st.layer_r_inf_ohm,
        layer_r_amp_ohm=st.layer_r_amp_ohm,
        layer_force_n=st.layer_force_n,
        layer_beta=st.layer_beta,
        contact_r0_ohm=st.contact_r0_ohm,
        contact_force_n=st.contact_force_n,
        contact_exponent=st.contact_exponent,
        press_on_n=s.press.onset_force_n,
        press_off_n=s.press.release_force_n,
        area_sigma=s.press.area_sigma,
        set_mean=s.press.set_fraction_mean,
        set_cv=s.press.set_fraction_cv,
        set_decay=float(np.exp(-dt / s.press.set_recovery_time_s)),
        max_presses=s.press.max_presses,
    )


def set_fraction_beta(mean: float, cv: float) -> tuple[float, float] | None:
    """Beta(a, b) of mean `mean` and coefficient of variation `cv` (sd / mean) for the knit set fraction psi in
    [0, 1]: a + b = (1 - mean) / (mean cv^2) - 1, a = mean (a + b). None where the draw is the constant mean
    (cv 0, mean 0 or 1). Raises ValueError if cv is too large for a Beta of that mean (a + b <= 0)."""
    if cv <= 0 or mean <= 0 or mean >= 1:
        return None
    k = (1.0 - mean) / (mean * cv * cv) - 1.0
    if k <= 0:
        raise ValueError(f"knit set: cv {cv:g} too large for a Beta of mean {mean:g} (need cv < {np.sqrt((1 - mean) / mean):.3g})")
    return mean * k, (1.0 - mean) * k


def press_draws(seeds: list[int] | None, p: FabricParams, n_episodes: int | None = None) -> np.ndarray:
    """[E, M, 2] float32 per-press draws (kappa, psi), M = p.max_presses: kappa = exp(area_sigma N(0,1)),
    psi ~ Beta of mean set_mean and coefficient of variation set_cv (set_fraction_beta: bounded in [0, 1], a
    press never keeps more than its peak compaction), from np.random.default_rng([seed, 2]). seeds None: the
    mean press (kappa 1, psi set_mean) for n_episodes episodes."""
    M = p.max_presses
    if seeds is None:
        out = np.empty((n_episodes or 1, M, 2), np.float32)
        out[..., 0], out[..., 1] = 1.0, p.set_mean
        return out
    ab = set_fraction_beta(p.set_mean, p.set_cv)
    out = np.empty((len(seeds), M, 2), np.float64)
    for e, s in enumerate(seeds):
        rng = np.random.default_rng([int(s), 2])
        out[e, :, 0] = np.exp(p.area_sigma * rng.standard_normal(M))
        out[e, :, 1] = p.set_mean if ab is None else rng.beta(ab[0], ab[1], M)
    return out.astype(np.float32)


def stack_resistance(x, p: FabricParams, layers: int | None = None):
    """Static stack law R_stack(x) (ohm) at effective load x (N); float64 for calibration and plots."""
    n = p.layers if layers is None else layers
    x = np.maximum(np.asarray(x, np.float64), 0.0)
    r_layer = p.layer_r_inf_ohm + p.layer_r_amp_ohm * np.exp(-np.power(x / p.layer_force_n, p.layer_beta))
    r_c = p.contact_r0_ohm * np.power(1.0 + x / p.contact_force_n, -p.contact_exponent)
    return n * r_layer + (n + 1) * r_c


@dataclass
class FabricState:
    """State carried across calls (float32): prony [B, P], play [B, K], press [B, 5] = (pressed 0/1, presses so
    far, kappa, psi, x_peak N); B = episodes x taxels. Virgin: no press yet, kappa 1, psi 0."""

    prony_n: np.ndarray
    play_n: np.ndarray
    press: np.ndarray

    @classmethod
    def zeros(cls, n: int, p: FabricParams) -> FabricState:
        press = np.zeros((n, 5), np.float32)
        press[:, 2] = 1.0
        return cls(np.zeros((n, p.n_prony), np.float32), np.zeros((n, p.n_play), np.float32), press)


def fabric_chain_numpy(
    load_n: np.ndarray, p: FabricParams, state: FabricState | None = None, draws: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, FabricState]:
    """load_n [E, T, N] float32 (whole-sample-equivalent force per taxel, N), draws [E, M, 2] (press_draws; None:
    the mean press) -> effective load x_s [E,T,N] (N), conductance [E,T,N] (S) per taxel column, final state."""
    f32 = np.float32
    E, T, N = load_n.shape
    st = state if state is not None else FabricState.zeros(E * N, p)
    q = st.prony_n.reshape(E, N, p.n_prony).astype(f32).copy()
    z = st.play_n.reshape(E, N, p.n_play).astype(f32).copy()
    ps = st.press.reshape(E, N, 5).astype(f32).copy()
    pressed, npress, kappa, psi, xpk = (ps[..., i].copy() for i in range(5))
    tab = press_draws(None, p, E) if draws is None else np.asarray(draws, f32)
    M = tab.shape[1]
    ep = np.arange(E)[:, None]
    f_on, f_off, c_set = f32(p.press_on_n), f32(p.press_off_n), f32(p.set_decay)
    a, g = p.prony_decay.astype(f32), p.prony_fraction.astype(f32)
    r, w = p.play_threshold_n.astype(f32), p.play_weight.astype(f32)
    w_direct = f32(1.0) - w.sum(dtype=f32)
    c = f32(p.recovery_decay)
    n_l = f32(p.layers)
    n_c = f32(p.layers + 1)
    n_t = f32(p.n_taxels)
    r_inf, r_amp = f32(p.layer_r_inf_ohm), f32(p.layer_r_amp_ohm)
    inv_fl, beta = f32(1.0 / p.layer_force_n), f32(p.layer_beta)
    rc0, inv_fc, m = f32(p.contact_r0_ohm), f32(1.0 / p.contact_force_n), f32(p.contact_exponent)
    xs = np.empty((E, T, N), f32)
    cond = np.empty((E, T, N), f32)
    for k in range(T):
        f = load_n[:, k, :].astype(f32)
        start = (pressed == 0) & (f > f_on)
        stop = (pressed == 1) & (f < f_off)
        j = np.mod(npress.astype(np.int64), M)
        kappa = np.where(start, tab[ep, j, 0], kappa)
        psi = np.where(start, tab[ep, j, 1], psi)
        npress = np.where(start, npress + f32(1.0), npress)
        pressed = np.where(start, f32(1.0), np.where(stop, f32(0.0), pressed))
        q = a * q + g * (f32(1.0) - a) * f[..., None]
        u = f + q.sum(-1, dtype=f32)
        z = np.maximum(u[..., None] - r, np.minimum(u[..., None] + r, z))
        z = u[..., None] + (z - u[..., None]) * c
        x = np.maximum(w_direct * u + (w * z).sum(-1, dtype=f32), f32(0.0))
        xpk = np.maximum(x, x + (xpk - x) * c_set)
        x = x + psi * (xpk - x)
        r_layer = r_inf + r_amp * np.exp(-np.power(x * inv_fl, beta))
        r_c = rc0 * np.power(f32(1.0) + x * inv_fc, -m)
        r_taxel = n_t * (n_l * r_layer + n_c * r_c) / kappa
        xs[:, k] = x
        cond[:, k] = f32(1.0) / r_taxel
    press = np.stack([pressed, npress, kappa, psi, xpk], -1).astype(f32).reshape(-1, 5)
    return xs, cond, FabricState(q.reshape(-1, p.n_prony), z.reshape(-1, p.n_play), press)
