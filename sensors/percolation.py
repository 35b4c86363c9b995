"""Percolating, tunneling conductive network of a filled elastomer: a shared stage (numpy reference + Warp funcs).

Sources: Kirkpatrick, Rev. Mod. Phys. 45, 574 (1973) and Stauffer & Aharony, Introduction to Percolation Theory
(1994) for sigma ~ (phi - phi_c)^t, t ~ 2 in 3-D; Simmons, J. Appl. Phys. 34, 1793 (1963) for tunneling across
the inter-particle gap; Hu et al., Acta Mater. 56, 2929 (2008) for the combined tunneling-percolation picture
of CNT composites (strain changes both the number of conducting paths and the gaps in them); Mullins,
Rubber Chem. Technol. 42, 339 (1969) for the progressive, slowly recovering damage of the first cycles.

Per element (a taxel's column of composite) and sample step, with e the compressive strain (>= 0):

  kinetics   s' = a s + (1 - a) e + (1 - b)(e' - e), a = exp(-dt/tau), b = tau/dt (1 - a)   (first order, exact
             for e linear in the step), tau = tau_form while the network compresses (e' > s: tubes approach,
             paths form) and tau_break while it relaxes (paths break as the matrix recoils): rate-dependent and
             asymmetric between loading and unloading
  damage     D_eq = D_max e' / (e' + e_D) (saturating); D' = D + (D_eq - D)(1 - a_D) while D < D_eq (paths lost for good,
             progressive over the first cycles: Mullins-type), else D' = D c_D (slow recovery at rest)
  fraction   phi_eff = phi (1 - D)(1 + k x)     (x: network strain after the rate-independent play bank;
             compression brings tubes into contact, raising the effective conducting fraction; estimate)
  conduction G / G_0 = [(phi_eff - phi_c)/(phi - phi_c)]^t exp(gamma s0 x) / (1 - x)
             (paths: percolation power law; gaps: Simmons tunneling, gap s0 (1 - x); path length: 1 - x).
             Below threshold the path term is held at `floor` x its rest value (matrix / hopping leakage).

The cnt_pdms taxel chain (sensors/cnt_pdms/) calls these; `velostat` may reuse `conductance_ratio`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp


def wt_to_volume_fraction(wt: float, filler_density_kg_m3: float, matrix_density_kg_m3: float) -> float:
    """Filler weight fraction -> volume fraction for a two-phase composite."""
    vf = wt / filler_density_kg_m3
    return vf / (vf + (1.0 - wt) / matrix_density_kg_m3)


def percolation_conductivity(phi, phi_c: float, exponent: float, sigma_filler_s_per_m: float) -> np.ndarray:
    """sigma = sigma_f (phi - phi_c)^t above threshold, 0 below (Kirkpatrick 1973; Stauffer & Aharony 1994)."""
    d = np.maximum(np.asarray(phi, np.float64) - phi_c, 0.0)
    return sigma_filler_s_per_m * d**exponent


@dataclass(frozen=True)
class NetworkParams:
    """Flat constants of the network stage (SI, dimensionless fractions)."""

    phi: float  # filler volume fraction
    phi_c: float  # percolation threshold (volume fraction)
    exponent: float  # t
    strain_gain: float  # k: d(phi_eff/phi)/dx
    gamma_s0: float  # tunneling decay constant x rest gap
    floor: float  # path term below threshold, fraction of its rest value
    form_decay: float  # exp(-dt/tau_form)
    form_gain: float  # tau_form/dt (1 - a)
    break_decay: float
    break_gain: float
    damage_max: float  # D_max
    damage_strain: float  # e_D
    damage_decay: float  # a_D = exp(-dt/tau_D)
    damage_recovery: float  # c_D = exp(-dt/T_recovery)

    @property
    def inv_span(self) -> float:
        return 1.0 / (self.phi - self.phi_c)


def network_params(dt_s: float, *, phi: float, phi_c: float, exponent: float, strain_gain: float, gamma_s0: float,
                   floor: float, formation_time_s: float, breakdown_time_s: float, damage_max: float,
                   damage_strain: float, damage_time_s: float, recovery_time_s: float) -> NetworkParams:
    if phi <= phi_c:
        raise ValueError(f"filler fraction {phi:.4g} must be above the percolation threshold {phi_c:.4g} (the sensor conducts at rest)")
    af, ab = math.exp(-dt_s / formation_time_s), math.exp(-dt_s / breakdown_time_s)
    return NetworkParams(
        phi=phi, phi_c=phi_c, exponent=exponent, strain_gain=strain_gain, gamma_s0=gamma_s0, floor=floor,
        form_decay=af, form_gain=formation_time_s / dt_s * (1.0 - af),
        break_decay=ab, break_gain=breakdown_time_s / dt_s * (1.0 - ab),
        damage_max=damage_max, damage_strain=damage_strain, damage_decay=math.exp(-dt_s / damage_time_s),
        damage_recovery=math.exp(-dt_s / recovery_time_s),
    )


# ---------------------------------------------------------------------------------------------- numpy reference
# float32 arithmetic, in the same order as the Warp funcs below


def kinetics_numpy(s, e, e_new, p: NetworkParams):
    f32 = np.float32
    form = e_new > s
    a = np.where(form, f32(p.form_decay), f32(p.break_decay))
    b = np.where(form, f32(p.form_gain), f32(p.break_gain))
    return (a * s + (f32(1.0) - a) * e + (f32(1.0) - b) * (e_new - e)).astype(f32)


def damage_numpy(dmg, e_new, p: NetworkParams):
    f32 = np.float32
    d_eq = f32(p.damage_max) * e_new / (e_new + f32(p.damage_strain))
    grow = dmg + (d_eq - dmg) * (f32(1.0) - f32(p.damage_decay))
    return np.where(d_eq > dmg, grow, dmg * f32(p.damage_recovery)).astype(f32)


def conductance_ratio_numpy(x, dmg, p: NetworkParams):
    """G / G_0 of the network at network strain x and damage D (float32)."""
    f32 = np.float32
    phi, phi_c, t = f32(p.phi), f32(p.phi_c), f32(p.exponent)
    phi_eff = phi * (f32(1.0) - dmg) * (f32(1.0) + f32(p.strain_gain) * x)
    rel = np.maximum((phi_eff - phi_c) * f32(p.inv_span), f32(p.floor))
    if p.exponent == 2.0:  # as the kernel: t = 2 as a product (no log in the hot loop)
        return (rel * rel * np.exp(f32(p.gamma_s0) * x) / (f32(1.0) - x)).astype(f32)
    # otherwise rel^t exp(gamma s0 x) as one exp (one log, one exp per step)
    return (np.exp(t * np.log(rel) + f32(p.gamma_s0) * x) / (f32(1.0) - x)).astype(f32)


# ------------------------------------------------------------------------------------------------- Warp funcs


@wp.struct
class NetworkWp:
    phi: float
    phi_c: float
    exponent: float
    strain_gain: float
    gamma_s0: float
    floor: float
    form_decay: float
    form_gain: float
    break_decay: float
    break_gain: float
    damage_max: float
    damage_strain: float
    damage_decay: float
    damage_recovery: float
    inv_span: float


def network_struct(p: NetworkParams) -> NetworkWp:
    s = NetworkWp()
    for k in NetworkParams.__dataclass_fields__:
        setattr(s, k, float(np.float32(getattr(p, k))))
    s.inv_span = float(np.float32(p.inv_span))
    return s


@wp.func
def kinetics_wp(q: NetworkWp, s: float, e: float, e_new: float):
    a = q.break_decay
    b = q.break_gain
    if e_new > s:
        a = q.form_decay
        b = q.form_gain
    return a * s + (1.0 - a) * e + (1.0 - b) * (e_new - e)


@wp.func
def damage_wp(q: NetworkWp, dmg: float, e_new: float):
    d_eq = q.damage_max * e_new / (e_new + q.damage_strain)
    out = dmg * q.damage_recovery
    if d_eq > dmg:
        out = dmg + (d_eq - dmg) * (1.0 - q.damage_decay)
    return out


@wp.func
def conductance_ratio_wp(q: NetworkWp, x: float, dmg: float):
    phi_eff = q.phi * (1.0 - dmg) * (1.0 + q.strain_gain * x)
    rel = wp.max((phi_eff - q.phi_c) * q.inv_span, q.floor)
    if q.exponent == 2.0:  # the 3-D universal value: a product instead of a log (same float32 result to an ulp)
        return rel * rel * wp.exp(q.gamma_s0 * x) / (1.0 - x)
    return wp.exp(q.exponent * wp.log(rel) + q.gamma_s0 * x) / (1.0 - x)


# CUDA's fast float32 exp (ex2.approx with the scaling by log2(e); CUDA C Programming Guide, "Intrinsic Functions":
# max error 2 + floor(|1.173 x|) ulp); on the CPU the same call as wp.exp, so the CPU's bits do not change.
_fast_exp_snippet = """
#if defined(__CUDA_ARCH__)
    return __expf(x);
#else
    return wp::exp(x);
#endif
"""


@wp.func_native(_fast_exp_snippet)
def fast_exp(x: wp.float32) -> wp.float32: ...


# CUDA's approximate float32 division (div.approx.f32, as __fdividef: 2 ulp for |b| in [2^-126, 2^126]); on the
# CPU the exact a / b, as Warp's own division there.
_fast_div_snippet = """
#if defined(__CUDA_ARCH__)
    return __fdividef(a, b);
#else
    return a / b;
#endif
"""


@wp.func_native(_fast_div_snippet)
def fast_div(a: wp.float32, b: wp.float32) -> wp.float32: ...


@wp.func
def damage_approx_wp(q: NetworkWp, dmg: float, e_new: float):
    """damage_wp with CUDA's approximate division (2 ulp; the exact one on the CPU)."""
    d_eq = fast_div(q.damage_max * e_new, e_new + q.damage_strain)
    out = dmg * q.damage_recovery
    if d_eq > dmg:
        out = dmg + (d_eq - dmg) * (1.0 - q.damage_decay)
    return out


@wp.func
def conductance_ratio_approx_wp(q: NetworkWp, x: float, dmg: float):
    """conductance_ratio_wp with CUDA's approximate division and exp (fast_exp; the exact ones on the CPU)."""
    phi_eff = q.phi * (1.0 - dmg) * (1.0 + q.strain_gain * x)
    rel = wp.max((phi_eff - q.phi_c) * q.inv_span, q.floor)
    if q.exponent == 2.0:
        return fast_div(rel * rel * fast_exp(q.gamma_s0 * x), 1.0 - x)
    return fast_div(fast_exp(q.exponent * wp.log(rel) + q.gamma_s0 * x), 1.0 - x)


@wp.kernel
def _ratio_kernel(q: NetworkWp, x: wp.array(dtype=float), dmg: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = conductance_ratio_wp(q, x[i], dmg[i])


def conductance_ratio_warp(x: np.ndarray, dmg: np.ndarray, p: NetworkParams, device: str = "cpu") -> np.ndarray:
    """Warp twin of conductance_ratio_numpy on flat float32 arrays (for tests and other families)."""
    from sensors.warp_setup import init_warp

    init_warp()
    xa = wp.array(np.ascontiguousarray(x, np.float32).ravel(), dtype=float, device=device)
    da = wp.array(np.ascontiguousarray(dmg, np.float32).ravel(), dtype=float, device=device)
    out = wp.empty_like(xa)
    wp.launch(_ratio_kernel, dim=xa.shape[0], inputs=[network_struct(p), xa, da, out], device=device)
    return out.numpy().reshape(np.shape(x))
