"""Flat numeric parameters of the CNT-PDMS transduction chain, derived once from a SceneConfig.

The kernels (Warp and the numpy reference) read only these arrays, never the pydantic config.
Prony and play banks hold only the active terms; the Warp kernel is specialised (compiled once) for
each pair of term counts so that the whole state stays in registers and no work goes to padding.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scenes.config import SceneConfig
from sensors.percolation import NetworkParams, network_params, wt_to_volume_fraction

MODE_DISPLACEMENT = 0  # drive = compressive strain (-)
MODE_FORCE = 1  # drive = compressive stress (Pa)


@dataclass(frozen=True)
class TaxelParams:
    """Per-taxel mechanics, hysteresis and conduction constants (SI). Shapes in brackets."""

    dt_s: float
    youngs_modulus_pa: float  # relaxed (long-time) modulus E_inf
    lock_strain: float  # nonlinear law sigma_eq = E_inf e / (1 - e/e_lock)
    prony_decay: np.ndarray  # [P] a_i = exp(-dt/tau_i)
    prony_gain: np.ndarray  # [P] b_i = tau_i/dt (1 - a_i): exact for piecewise-linear strain
    prony_modulus_pa: np.ndarray  # [P] E_i = g_i E_inf
    net: NetworkParams  # percolation / tunneling network, its kinetics and damage (sensors/percolation.py)
    softening: float  # Mullins stress softening per unit damage: sigma x (1 - softening D)
    play_threshold: np.ndarray  # [K] r_k (strain)
    play_weight: np.ndarray  # [K] w_k
    recovery_decay: float  # exp(-dt/T_recovery) pulling play states toward the input
    taxel_area_m2: float
    rest_resistance_ohm: float  # one taxel's through-thickness resistance at rest: h / (sigma0 A)

    @property
    def n_prony(self) -> int:
        return len(self.prony_decay)

    @property
    def n_play(self) -> int:
        return len(self.play_threshold)


@dataclass(frozen=True)
class ElectronicsParams:
    """Bridge, amplifier, ADC and digital filter constants (SI)."""

    excitation_v: float
    bridge_resistance_ohm: float
    amp_gain: float
    amp_offset_v: float
    adc_bits: int
    adc_range_v: float
    sos: np.ndarray = field(repr=False)  # [n_sections, 6] Butterworth second-order sections (b0 b1 b2 a0 a1 a2)
    sos_zi: np.ndarray = field(repr=False)  # [n_sections, 2] steady-state filter state for a unit input
    # filter_mode "zero_phase": the readout kernel passes the ADC voltage through (sos = identity) and the
    # Butterworth runs forward-backward over the recorded episode afterwards (sensors.electronics.zero_phase)
    filter_mode: str = "causal"
    offline_sos: np.ndarray | None = field(default=None, repr=False)

    @property
    def lsb_v(self) -> float:
        return 2.0 * self.adc_range_v / float(2**self.adc_bits)

    @property
    def code_min(self) -> int:
        return -(2 ** (self.adc_bits - 1))

    @property
    def code_max(self) -> int:
        return 2 ** (self.adc_bits - 1) - 1


def taxel_params(cfg: SceneConfig) -> TaxelParams:
    dt = 1.0 / cfg.sampling.sample_rate_hz
    mech, hyst, tun = cfg.sensor.mechanics, cfg.sensor.hysteresis, cfg.sensor.tunneling
    # an empty bank becomes one inert term (zero modulus / zero weight) so kernels need no special case
    tau = np.asarray(mech.prony_times_s or [1.0], dtype=np.float64)
    g = np.asarray(mech.prony_fractions or [0.0], dtype=np.float64)
    a = np.exp(-dt / tau)
    b = tau / dt * (1.0 - a)
    r = np.asarray(hyst.play_thresholds or [0.0], dtype=np.float64)
    w = np.asarray(hyst.play_weights or [0.0], dtype=np.float64)
    perc, mul = cfg.sensor.percolation, cfg.sensor.mullins
    vol = lambda w: wt_to_volume_fraction(w, perc.filler_density_kg_per_m3, perc.matrix_density_kg_per_m3)
    net = network_params(
        dt, phi=vol(perc.filler_wt_fraction), phi_c=vol(perc.threshold_wt_fraction), exponent=perc.exponent,
        strain_gain=perc.strain_gain, gamma_s0=tun.gamma_s0, floor=perc.floor, formation_time_s=perc.formation_time_s,
        breakdown_time_s=perc.breakdown_time_s, damage_max=mul.damage_max, damage_strain=mul.damage_strain,
        damage_time_s=mul.damage_time_s, recovery_time_s=mul.recovery_time_s,
    )
    area = cfg.pad.size_x_m * cfg.pad.size_y_m / cfg.pad.n_taxels
    return TaxelParams(
        dt_s=dt,
        youngs_modulus_pa=cfg.pad.youngs_modulus_pa,
        lock_strain=mech.lock_strain,
        prony_decay=a,
        prony_gain=b,
        prony_modulus_pa=g * cfg.pad.youngs_modulus_pa,
        net=net,
        softening=mul.softening / mul.damage_max if mul.damage_max > 0 else 0.0,
        play_threshold=r,
        play_weight=w,
        recovery_decay=float(np.exp(-dt / hyst.recovery_time_s)),
        taxel_area_m2=area,
        rest_resistance_ohm=cfg.pad.thickness_m / (tun.conductivity_s_per_m * area),
    )


def rest_sensor_resistance_ohm(cfg: SceneConfig) -> float:
    """Resistance of one readout channel at rest, h / (sigma0 A): the whole pad (all taxel columns in
    parallel) or, with sensor.readout = "taxel", one taxel's column."""
    area = cfg.pad.size_x_m * cfg.pad.size_y_m
    if getattr(cfg.sensor, "readout", "pad") == "taxel":
        area /= cfg.pad.n_taxels
    return cfg.pad.thickness_m / (cfg.sensor.tunneling.conductivity_s_per_m * area)


def electronics_params(cfg: SceneConfig) -> ElectronicsParams:
    from scipy import signal

    el = cfg.sensor.electronics
    fs = cfg.sampling.sample_rate_hz
    mode = el.filter_mode if el.filter_order else "off"
    offline = None
    if mode == "causal":
        sos = signal.butter(el.filter_order, el.filter_cutoff_hz, btype="low", fs=fs, output="sos")
        zi = signal.sosfilt_zi(sos)
    else:
        if mode == "zero_phase":
            offline = np.ascontiguousarray(signal.butter(el.filter_order, el.filter_cutoff_hz, btype="low", fs=fs, output="sos"))
        sos = np.array([[1.0, 0.0, 0.0, 1.0, 0.0, 0.0]])
        zi = np.zeros((1, 2))
    rb = el.bridge_resistance_ohm or rest_sensor_resistance_ohm(cfg)
    return ElectronicsParams(
        excitation_v=el.excitation_v,
        bridge_resistance_ohm=rb,
        amp_gain=el.amp_gain,
        amp_offset_v=el.amp_offset_v,
        adc_bits=el.adc_bits,
        adc_range_v=el.adc_range_v,
        sos=np.ascontiguousarray(sos, dtype=np.float64),
        sos_zi=np.ascontiguousarray(zi, dtype=np.float64),
        filter_mode=mode,
        offline_sos=offline,
    )
