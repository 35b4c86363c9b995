"""Validated scene configuration (pydantic v2, extra="forbid", SI units in field names).

A scene = pad geometry + indenter + loading protocol + sampling + sensor physics + generation settings.
Every value is SI; strings with units ("5 mm", "1.85 MPa") are converted on load (scenes.units).
Defaults without a source in the papers are marked `# estimate`.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from scenes.base import (  # noqa: F401  (re-exported)
    Between,
    Fraction,
    NonNeg,
    NonNegFloat,
    Pos,
    PositiveFloat,
    Strict,
)
from scenes.fabric_config import FabricSensorConfig
from scenes.ntype_config import NtypeSensorConfig
from scenes.scene_randomize import RandomizeConfig
from scenes.velostat_config import VelostatSensorConfig


class PadConfig(Strict):
    """The sensing pad: a box of elastomer with a regular taxel grid on its top surface."""

    size_x_m: Pos(1.0) = 0.030  # cnt_pdms Table 1
    size_y_m: Pos(1.0) = 0.030  # cnt_pdms Table 1
    thickness_m: Pos(0.1) = 0.005  # cnt_pdms Table 1
    taxels_x: Annotated[int, Field(ge=1, le=1024)] = 15  # estimate: 2 mm pitch
    taxels_y: Annotated[int, Field(ge=1, le=1024)] = 15  # estimate
    youngs_modulus_pa: Pos(1e10) = 1.85e6  # cnt_pdms Table 1
    poisson_ratio: Annotated[float, Field(ge=0.0, lt=0.5)] = 0.49  # estimate: near-incompressible PDMS
    density_kg_per_m3: Pos(25_000.0) = 1030.0  # estimate: Sylgard 184
    spread_length_m: Pos(0.1) = 0.0015  # estimate: elastic-layer kernel width ~ 0.3 x thickness

    @property
    def n_taxels(self) -> int:
        return self.taxels_x * self.taxels_y


class IndenterConfig(Strict):
    """A rigid indenter on a vertical slide joint (with x/y set per episode)."""

    shape: Literal["box", "sphere"] = "box"
    size_x_m: Pos(1.0) = 0.010  # estimate: 10 x 10 mm flat punch
    size_y_m: Pos(1.0) = 0.010  # estimate
    radius_m: Pos(0.5) = 0.005  # used when shape == "sphere"
    mass_kg: Pos(100.0) = 0.05  # estimate
    friction: NonNeg(10.0) = 0.8  # estimate: PDMS on steel
    position_jitter_m: NonNeg(1.0) = 0.003  # estimate: random x/y offset of the press per episode
    start_gap_m: NonNeg(0.1) = 0.0  # gap between indenter and pad at t=0
    count: Annotated[int, Field(ge=1, le=8)] = 1  # indenters in the scene (protocol kind "press_stroke" uses > 1)


class ProtocolConfig(Strict):
    """Loading protocol.

    kind = "sinusoid": d(t) = d0 [1 - cos(2 pi f t)] / 2 (cnt_pdms sect. 3.2), displacement or force amplitude.
    kind = "hold": ramp to a level in `ramp_s`, hold for the rest of the episode (creep / relaxation).
    kind = "staircase" (force control, fabric sect. 3.3): loading-unloading cycles in `stair_step_n` steps held
    `stair_dwell_s` each, between turning points: `stair_return_points_n` (0 -> r1 -> 0 -> r2 -> ...) or, when
    empty, a full cycle to amplitude_max then random minor loops (peaks in [amplitude_min, amplitude_max]).
    kind = "press_stroke": each of indenter.count indenters (each active with `active_probability`) presses
    at a random position to a force U[amplitude_min, amplitude_max] (force control), then strokes tangentially
    in a random direction to a target shear force of U[0, shear_ratio_max] x friction x normal force
    (Coulomb stick-slip; above 1 it slips), holds, then releases (ntype).
    kind = "element_loads" (force control, the ntype paper's experiment, sect. 3.2): every frame, each array
    element carries its own static 3-D force, components on [amplitude_min, amplitude_max], drawn per
    `force_distribution`: "uniform" (the paper's task default) or "beta" (amplitude_min + (max - min) x
    Beta(force_beta_alpha, force_beta_beta), a draw skewed to small forces) (simulate/protocols/element_loads.py;
    scenes/ntype_config.py PAPER_PROTOCOL).
    """

    kind: Literal[
        "sinusoid", "hold", "staircase", "press_stroke", "element_loads",
        "velostat_steps", "velostat_staircase", "velostat_calibration", "velostat_calibration_sweep",
        "velostat_site_sweep", "velostat_mix",
    ] = "sinusoid"
    control: Literal["displacement", "force"] = "displacement"
    frequencies_hz: list[Pos(1000.0)] = Field(default_factory=lambda: [0.1, 0.5, 1.0, 2.0])  # cnt_pdms
    cycles: Annotated[int, Field(ge=1, le=1000)] = 3  # estimate
    amplitude_min: NonNeg(1000.0) = 4.0e-5  # m (displacement) or N (force); estimate: spans 0-Fmax
    amplitude_max: Pos(1000.0) = 1.6e-4  # m or N; estimate: Fmax ~ 5 N (cnt_pdms R^2/RMSE imply ~1.2 N std)
    ramp_s: Pos(3600.0) = 0.5  # for kind="hold"
    duration_s: Pos(3600.0) = 20.0  # for kind="hold"; sinusoids last cycles / f
    settle_s: NonNeg(3600.0) = 0.2  # rest before loading starts
    stair_step_n: Pos(1000.0) = 0.1  # fabric sect. 3.3: 0.1 N between force levels
    stair_dwell_s: Pos(3600.0) = 2.0  # fabric sect. 3.3: 2 s from a new force level to the reading
    stair_ramp_s: NonNeg(3600.0) = 0.1  # estimate: time to apply a new level by hand
    stair_cycles_min: Annotated[int, Field(ge=1, le=50)] = 4  # fabric sect. 3.3: four to six cycles
    stair_cycles_max: Annotated[int, Field(ge=1, le=50)] = 6  # fabric sect. 3.3
    stair_return_points_n: list[Pos(1000.0)] = Field(default_factory=list)  # fixed peaks; empty: random
    stroke_s: Pos(3600.0) = 0.5  # for kind="press_stroke": duration of the tangential stroke; estimate
    shear_ratio_max: NonNeg(10.0) = 1.2  # for kind="press_stroke": target shear / (friction x normal force); estimate
    active_probability: Fraction = 0.7  # for kind="press_stroke": chance that each extra indenter presses; estimate
    # for kind="element_loads": how each force component is drawn on [amplitude_min, amplitude_max]. "uniform":
    # estimate, the paper (ntype sect. 3.2) states only the range [0, 4.8] N; its eq. 14 (relative error over every
    # component, divided by the true F) and Table 2 / Figs. 6-8 fit it (simulate/protocols/element_loads.py).
    force_distribution: Literal["uniform", "beta"] = "uniform"  # element_loads: uniform (ntype eq. 14 / Table 2 fit it; estimate) or beta
    # "beta" shape: estimate, alpha = 1, beta = 7 gives a component mean of (max - min) / 8 = 0.6 N on [0, 4.8] N, the
    # ntype paper's Table 2 MAE / Figs. 6-8 relative error (0.0203 N / 3.40 % = 0.60 N F_x, 0.0108 / 1.96 % =
    # 0.55 N F_z) read as an arithmetic mean (a reading the paper's numbers do not support: element_loads.py)
    force_beta_alpha: Between(0.05, 100.0) = 1.0  # element_loads "beta": shape alpha; estimate, mean 0.6 N on [0, 4.8] N (ntype Table 2 / Figs. 6-8 as an arithmetic mean)
    force_beta_beta: Between(0.05, 100.0) = 7.0  # element_loads "beta": shape beta; estimate (with alpha = 1: mean = range / 8)
    # velostat kinds (compression testing machine, force control; velostat sects. 3.1, 4.1, 5.4):
    hold_min_s: Pos(3600.0) = 5.0  # velostat: holds of 5-30 s
    hold_max_s: Pos(3600.0) = 30.0
    loading_speeds_m_per_s: list[Pos(1.0)] = Field(default_factory=lambda: [k / 60000.0 for k in (1, 2, 3, 4, 5, 6)])  # velostat Fig. 5: 1-6 mm/min
    machine_stiffness_n_per_m: Pos(1e9) = 20_000.0  # estimate: crosshead travel -> force (tip + protective layers)
    step_force_n: Pos(1000.0) = 1.0  # velostat: staircases in 1 N steps
    step_hold_s: Pos(3600.0) = 10.0  # velostat Fig. 6: 10 s per step
    staircase_max_n: Pos(1000.0) = 10.0  # velostat Fig. 6: 1 N to 10 N

    @model_validator(mode="after")
    def _check(self) -> ProtocolConfig:
        if self.amplitude_min > self.amplitude_max:
            raise ValueError(
                f"protocol.amplitude_min ({self.amplitude_min}) must be <= protocol.amplitude_max ({self.amplitude_max})"
            )
        if not self.frequencies_hz:
            raise ValueError("protocol.frequencies_hz must list at least one frequency")
        if self.stair_cycles_min > self.stair_cycles_max:
            raise ValueError(
                f"protocol.stair_cycles_min ({self.stair_cycles_min}) must be <= protocol.stair_cycles_max ({self.stair_cycles_max})"
            )
        if self.kind == "staircase" and self.stair_ramp_s > self.stair_dwell_s:
            raise ValueError("protocol.stair_ramp_s must be <= protocol.stair_dwell_s")
        if self.hold_min_s > self.hold_max_s:
            raise ValueError(f"protocol.hold_min_s ({self.hold_min_s}) must be <= protocol.hold_max_s ({self.hold_max_s})")
        return self


class SamplingConfig(Strict):
    sample_rate_hz: Pos(1e6) = 100.0  # cnt_pdms Table 1
    physics_timestep_s: Between(1e-6, 1.0) = 0.001  # MuJoCo step; estimate

    @model_validator(mode="after")
    def _check(self) -> SamplingConfig:
        ratio = 1.0 / (self.sample_rate_hz * self.physics_timestep_s)
        if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
            raise ValueError(
                f"sampling.physics_timestep_s ({self.physics_timestep_s}) must divide the sample period "
                f"1/sample_rate_hz ({1.0 / self.sample_rate_hz}) a whole number of times"
            )
        return self

    @property
    def substeps(self) -> int:
        return int(round(1.0 / (self.sample_rate_hz * self.physics_timestep_s)))


class MechanicsConfig(Strict):
    """Nonlinear elastic law + generalized Maxwell (Prony) series. Source: Ferry, Viscoelastic Properties of Polymers (1980)."""

    lock_strain: Annotated[float, Field(gt=0, le=1)] = 0.5  # estimate: sigma = E e / (1 - e/e_lock)
    prony_fractions: list[NonNeg(1.0)] = Field(default_factory=lambda: [0.03, 0.03, 0.04])  # estimate: Sylgard 184 tan(delta) ~ 0.05 over 0.1-10 Hz
    prony_times_s: list[Pos(1e6)] = Field(default_factory=lambda: [0.05, 0.5, 5.0])  # estimate: one per decade over 0.1-2 Hz

    @model_validator(mode="after")
    def _check(self) -> MechanicsConfig:
        if len(self.prony_fractions) != len(self.prony_times_s):
            raise ValueError("sensor.mechanics.prony_fractions and prony_times_s must have the same length")
        if len(self.prony_fractions) > 8:
            raise ValueError("sensor.mechanics allows at most 8 Prony terms")
        return self


class HysteresisConfig(Strict):
    """Rate-independent part of the network strain: internal friction and sliding of nanotubes (cnt_pdms sect. 3.1) as
    a Prandtl-Ishlinskii play bank. Source: Brokate & Sprekels, Hysteresis and Phase Transitions (1996)."""

    play_thresholds: list[NonNeg(1.0)] = Field(default_factory=lambda: [0.001, 0.002, 0.004, 0.008])  # estimate, strain: one per octave up to ~1/4 of the press range
    play_weights: list[NonNeg(1.0)] = Field(default_factory=lambda: [0.067, 0.067, 0.067, 0.067])  # estimate; scale calibrated (piezotwin calibrate cnt_pdms)
    recovery_time_s: Pos(1e6) = 30.0  # estimate: slow relaxation of play states toward the input at rest

    @model_validator(mode="after")
    def _check(self) -> HysteresisConfig:
        if len(self.play_thresholds) != len(self.play_weights):
            raise ValueError("sensor.hysteresis.play_thresholds and play_weights must have the same length")
        if len(self.play_weights) > 16:
            raise ValueError("sensor.hysteresis allows at most 16 play operators")
        if sum(self.play_weights) >= 1.0:
            raise ValueError("sensor.hysteresis.play_weights must sum to < 1 (the rest is the direct path)")
        return self


class TunnelingConfig(Strict):
    """Tunneling across the inter-tube gap, G ~ exp(gamma s0 x) / (1 - x) at network strain x (gap s0 (1 - x)).
    Source: Simmons, J. Appl. Phys. 34, 1793 (1963)."""

    conductivity_s_per_m: Pos(1e8) = 0.12  # cnt_pdms Table 1 (unloaded sensor)
    gamma_s0: Pos(1000.0) = 20.0  # estimate: 4 pi s0 sqrt(2 m lambda)/h ~ 11-22 for s0 ~ 1.5-3 nm, lambda ~ 0.5 eV (Hu et al. 2008)


class PercolationConfig(Strict):
    """Percolating CNT network: G ~ (phi_eff - phi_c)^t, phi_eff = phi (1 - D)(1 + k x), with first-order kinetics
    of network formation / breakdown (sensors/percolation.py). Sources: Kirkpatrick 1973; Stauffer & Aharony 1994;
    Hu et al., Acta Mater. 56, 2929 (2008)."""

    filler_wt_fraction: Annotated[float, Field(gt=0, lt=1)] = 0.005  # cnt_pdms Table 1: 0.5 wt% MWCNT
    threshold_wt_fraction: Annotated[float, Field(gt=0, lt=1)] = 0.003  # estimate: MWCNT/PDMS thresholds 0.1-0.5 wt% (Bauhofer & Kovacs, Compos. Sci. Technol. 69, 1486, 2009)
    filler_density_kg_per_m3: Pos(1e5) = 1750.0  # estimate: MWCNT 1.6-2.1 g/cm3
    matrix_density_kg_per_m3: Pos(1e5) = 1030.0  # estimate: Sylgard 184
    exponent: Pos(10.0) = 2.0  # estimate: universal 3-D conductivity exponent (Stauffer & Aharony); Hu et al. 2008 fit 1.8-2
    strain_gain: NonNeg(1e5) = 180.0  # estimate: new tube contacts per unit strain, lumped as an effective fraction; fitted by piezotwin calibrate cnt_pdms (paper's linear R^2)
    floor: Annotated[float, Field(gt=0, le=1)] = 0.01  # estimate: leakage below threshold, of the rest path term
    formation_time_s: Pos(1e6) = 0.004  # estimate: paths form as tubes are pushed together (fast, below the 2 Hz period / 100)
    breakdown_time_s: Pos(1e6) = 0.02  # estimate: paths break as the matrix recoils (5x slower); loop area rising over 0.1-2 Hz

    @model_validator(mode="after")
    def _check(self) -> PercolationConfig:
        if self.threshold_wt_fraction >= self.filler_wt_fraction:
            raise ValueError("sensor.percolation.threshold_wt_fraction must be below filler_wt_fraction (the sensor conducts at rest)")
        return self


class MullinsConfig(Strict):
    """Mullins-type damage D of the filled network over the first cycles, with slow recovery: D grows toward
    D_eq = damage_max e / (e + damage_strain) with time constant damage_time_s while below it, else decays with
    recovery_time_s; it removes conducting paths (phi (1 - D)) and softens the matrix (stress x (1 - softening D / damage_max)).
    Source: Mullins, Rubber Chem. Technol. 42, 339 (1969); Diani et al., Eur. Polym. J. 45, 601 (2009)."""

    damage_max: Annotated[float, Field(ge=0, lt=1)] = 0.03  # estimate: fraction of paths lost at large strain; calibrated
    damage_strain: Pos(1.0) = 0.03  # estimate: strain scale of the damage (the press range)
    damage_time_s: Pos(1e6) = 3.0  # estimate: loading time to reach it: several cycles at 0.5-2 Hz
    recovery_time_s: Pos(1e6) = 600.0  # estimate: slow recovery at rest (minutes; Mullins 1969)
    softening: Annotated[float, Field(ge=0, lt=1)] = 0.05  # estimate: stress softening at D = damage_max


class ElectronicsConfig(Strict):
    """Wheatstone bridge + in-amp + ADC + digital Butterworth. Source: cnt_pdms sect. 2.2; NI USB-6009 datasheet."""

    excitation_v: Pos(100.0) = 1.0  # estimate
    bridge_resistance_ohm: Pos(1e12) | None = None  # None: balanced at the unloaded sensor resistance
    amp_gain: Pos(1e6) = 15.6  # estimate: ~75 % of the ADC range at F_max (piezotwin calibrate cnt_pdms)
    amp_offset_v: Between(-100.0, 100.0) = 0.0
    white_noise_v: NonNeg(100.0) = 5e-4  # estimate: rms at the ADC input
    pink_noise_v: NonNeg(100.0) = 5e-4  # estimate: rms of the 1/f component at the ADC input
    adc_bits: Annotated[int, Field(ge=4, le=24)] = 14  # cnt_pdms Table 1 (NI USB-6009)
    adc_range_v: Pos(100.0) = 10.0  # NI USB-6009 differential +-10 V
    filter_order: Annotated[int, Field(ge=0, le=8)] = 4  # cnt_pdms sect. 2.2 (0 disables)
    filter_cutoff_hz: Pos(1e6) = 10.0  # cnt_pdms sect. 2.2
    # how the recorded voltage is filtered: "zero_phase" = the Butterworth run forward and backward over the
    # recorded episode (offline, no phase lag: the paper chose its filter "to avoid the phase distortion",
    # sect. 2.2); "causal" = forward only, as a real-time filter (about 40 ms delay at 4th order, 10 Hz);
    # "off" = the raw ADC voltage
    filter_mode: Literal["zero_phase", "causal", "off"] = "zero_phase"  # cnt_pdms sect. 2.2

    @field_validator("filter_order")
    @classmethod
    def _even(cls, v: int) -> int:
        if v % 2:
            raise ValueError(f"sensor.electronics.filter_order must be even (0, 2, 4, 6, 8); got {v}")
        return v


TAXEL_AMP_GAIN = 15.0  # estimate: cnt_pdms taxel readout, a pressed taxel's R falls ~100x (percolation): bridge -> -0.5 V -> 7.5 V of 10 V


class CntPdmsSensorConfig(Strict):
    family: Literal["cnt_pdms"] = "cnt_pdms"
    mechanics: MechanicsConfig = Field(default_factory=MechanicsConfig)
    hysteresis: HysteresisConfig = Field(default_factory=HysteresisConfig)
    tunneling: TunnelingConfig = Field(default_factory=TunnelingConfig)
    percolation: PercolationConfig = Field(default_factory=PercolationConfig)
    mullins: MullinsConfig = Field(default_factory=MullinsConfig)
    electronics: ElectronicsConfig = Field(default_factory=ElectronicsConfig)
    # "pad": one bridge over the whole pad, all taxel columns in parallel (cnt_pdms sect. 2);
    # "taxel": a tactile array, one bridge + ADC channel per taxel (isolated rows/columns)  # estimate
    readout: Literal["pad", "taxel"] = "pad"

    @model_validator(mode="after")
    def _taxel_gain(self) -> CntPdmsSensorConfig:
        # one taxel under the indenter changes ~5x more (relatively) than the whole pad: the pad's default
        # gain would clip the ADC, so a taxel readout defaults to ~75 % of the range at F_max  # estimate
        if self.readout == "taxel" and "amp_gain" not in self.electronics.model_fields_set:
            self.electronics = self.electronics.model_copy(update={"amp_gain": TAXEL_AMP_GAIN})
        return self



# one member per sensor family, told apart by its `family` literal (SceneConfig fills in cnt_pdms when missing)
SensorConfig = Annotated[
    CntPdmsSensorConfig | FabricSensorConfig | NtypeSensorConfig | VelostatSensorConfig,
    Field(discriminator="family"),
]


class GenerationConfig(Strict):
    episodes: Annotated[int, Field(ge=1, le=10_000_000)] = 32
    episodes_per_shard: Annotated[int, Field(ge=1)] = 16
    root_seed: Annotated[int, Field(ge=0, lt=2**63)] = 0
    # lzf + shuffle (default); gzip level 1; zstd / lz4: Blosc2 level 1 + shuffle (hdf5plugin); none
    compression: Literal["lzf", "gzip", "none", "zstd", "lz4"] = "lzf"
    threads: Annotated[int, Field(ge=1, le=256)] = 2
    device: Literal["cpu", "cuda", "auto"] = "cpu"
    # contact stage: C MuJoCo rollout on CPU threads, or MuJoCo Warp batched worlds on `device`;
    # auto = MuJoCo Warp when a CUDA device and the mujoco_warp package are present
    physics: Literal["mujoco", "mujoco_warp", "auto"] = "mujoco"
    # channels written per episode (None = all): e.g. [time, adc, force_taxel, contact_force, position]
    # for compact datasets; names are checked against the load channels and the sensor's outputs
    record: list[str] | None = None


class SceneConfig(Strict):
    """The whole scene: what `piezotwin generate` reads."""

    name: str = "cnt_pdms"
    paper: str = "cnt_pdms"
    pad: PadConfig = Field(default_factory=PadConfig)
    indenter: IndenterConfig = Field(default_factory=IndenterConfig)
    protocol: ProtocolConfig = Field(default_factory=ProtocolConfig)
    sampling: SamplingConfig = Field(default_factory=SamplingConfig)
    sensor: SensorConfig = Field(default_factory=CntPdmsSensorConfig)
    generation: GenerationConfig = Field(default_factory=GenerationConfig)
    randomize: RandomizeConfig | None = None  # per-episode distributions (scenes/scene_randomize.py)

    @model_validator(mode="before")
    @classmethod
    def _default_family(cls, data: object) -> object:
        """A sensor section without `family` is cnt_pdms (the union needs its tag; older scenes omit it)."""
        if isinstance(data, dict) and isinstance(data.get("sensor"), dict) and "family" not in data["sensor"]:
            data = {**data, "sensor": {"family": "cnt_pdms", **data["sensor"]}}
        return data

    @model_validator(mode="after")
    def _cross(self) -> SceneConfig:
        nyq = self.sampling.sample_rate_hz / 2.0
        for f in self.protocol.frequencies_hz:
            if f >= nyq / 5.0:
                raise ValueError(
                    f"protocol.frequencies_hz: {f} Hz cannot be resolved at sampling.sample_rate_hz="
                    f"{self.sampling.sample_rate_hz} Hz (allowed: 0 < f < {nyq / 5.0:g} Hz, 10 samples per cycle)"
                )
        elec = getattr(self.sensor, "electronics", None)  # families without a filtered ADC skip this
        fc = elec.filter_cutoff_hz if elec is not None else 0.0
        if elec is not None and elec.filter_order and fc >= nyq:
            raise ValueError(
                f"sensor.electronics.filter_cutoff_hz: {fc} Hz must be below the Nyquist frequency {nyq:g} Hz"
            )
        if self.indenter.shape == "box" and (
            self.indenter.size_x_m > self.pad.size_x_m * 2 or self.indenter.size_y_m > self.pad.size_y_m * 2
        ):
            raise ValueError("indenter.size_x_m/size_y_m: a box indenter may be at most twice the pad size")
        if self.protocol.control == "displacement" and self.protocol.amplitude_max >= self.pad.thickness_m:
            raise ValueError(
                f"protocol.amplitude_max: {self.protocol.amplitude_max} m is a displacement >= pad.thickness_m "
                f"({self.pad.thickness_m} m); allowed: < pad thickness"
            )
        if self.randomize is not None and not self.randomize.empty():
            from scenes.scene_randomize import check

            check(self)
        return self

    def episode_duration_s(self, frequency_hz: float) -> float:
        p = self.protocol
        if p.kind == "sinusoid":
            return p.settle_s + p.cycles / frequency_hz
        if p.kind == "staircase":  # longest plan: every cycle a full 0 -> peak -> 0, plus a rest of duration_s
            peaks = p.stair_return_points_n or [p.amplitude_max] * p.stair_cycles_max
            levels = sum(2 * (math.ceil(r / p.stair_step_n - 1e-9) + 1) for r in peaks)
            return p.settle_s + levels * p.stair_dwell_s + p.duration_s
        return p.settle_s + p.duration_s
