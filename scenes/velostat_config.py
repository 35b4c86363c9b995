"""Sensor config of the `velostat` family (paper key `velostat`): a 120 x 120 mm Velostat film between two
PET-ITO sheets, a constant-current force channel and 4-/5-wire ITO position decoding.

Values the paper gives are cited; the rest are marked `# estimate` (and are parameters).
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from scenes.base import Between, Fraction, NonNeg, Pos, Strict


class VelostatFilmConfig(Strict):
    """Through-thickness conductance of the film: G = g_area * A * field_g(x, y) * ((p + c) / p_ref)^n, with
    ln field_g = -ln(1 + domain_spread * q(domain)) + conductance_spread * z(x, y): a few domains of distinct
    resistivity (Voronoi zones, q evenly spaced in [-1, 1]; an estimate of the structure behind the paper's ~5
    Ward groups) and a smooth field z.

    Dominated by the film/ITO interface contact resistance, whose a-spot count grows with load
    (Holm, Electric Contacts, 1967): conductance ~ pressure^n with n ~ 1 (velostat sect. 2, Fig. 19).
    """

    resistance_at_ref_ohm: Pos(1e12) = 20_000.0  # estimate: 1 cm^2 of film at p_ref (1 N on a 1 cm^2 tip)
    reference_pressure_pa: Pos(1e9) = 10_000.0  # estimate: 1 N on 1 cm^2
    exponent: Annotated[float, Field(gt=0.2, le=3.0)] = 1.05  # estimate: power law n ~ 1 (velostat Fig. 13b)
    field_seed: Annotated[int, Field(ge=0)] | None = None  # None: the part follows generation.root_seed
    correlation_length_m: Pos(1.0) = 0.030  # estimate: 20-40 mm patches (velostat Figs. 18, 19)
    conductance_spread: NonNeg(5.0) = 0.06  # estimate: std of log conductance within a domain (smooth field)
    domains: Annotated[int, Field(ge=1, le=64)] = 5  # estimate: zones of carbon-black loading; the paper's Ward elbow finds about 5 groups of units (Fig. 12)
    domain_spread: Annotated[float, Field(ge=0.0, lt=1.0)] = 0.65  # estimate: resistivity factors 1 -/+ domain_spread evenly over the domains (unit-to-unit inconsistency, Figs. 13, 19)
    creep_spread: NonNeg(5.0) = 0.35  # estimate: std of log creep amplitude over the film
    field_resolution_m: Between(1e-4, 0.1) = 0.002  # grid on which the random field is drawn


class VelostatCreepConfig(Strict):
    """Creep of the film/ITO contact. model "aging" (default): contact aging (Dieterich & Kilgore, PAGEOPH 143,
    1994) with the aging law of rate-and-state friction (Ruina, JGR 88, 1983): the contact age grows in holds and
    is renewed while the load rises (steady-state age renewal_pressure_pa / (dp/dt)); the contact grows by
    amplitude * p_c * ln(1 + p / p_c) per e-fold of age, only while the age grows, so creep lives in the holds
    (velostat Fig. 5: creep during loading negligible, R at full load about equal at 1-6 mm/min), grows with the
    speed of the preceding ramp (younger contact), falls relative to the load (Fig. 3a) and accumulates over the
    holds of a staircase (eq. 2, Fig. 22a). model "spectrum": the earlier Schapery-type bank of first-order terms
    with log-spaced times_s relaxing toward amplitude * p_c * ln(1 + p / p_c) (creep from the first pascal of
    every ramp; Schapery, Polym. Eng. Sci. 9, 1969), kept for comparison and for sensors/velostat/fit.py."""

    model: Literal["aging", "spectrum"] = "aging"
    amplitude: NonNeg(100.0) = 0.4  # estimate (aging: per e-fold of contact age): ~3 N error after a 30 s hold at 7 N, ~5 N after the 1-7 N staircase (velostat sect. 5.4, Fig. 22a: up to 5 N)
    saturation_pressure_pa: Pos(1e9) = 8_000.0  # estimate: p_c; relative creep falls over the 1-15 N of the paper (velostat Fig. 3a), p_c ~ 3 N on a 10 mm tip at a taxel corner
    renewal_pressure_pa: Pos(1e9) = 10_000.0  # estimate (aging): dp_c; contact age at the end of a ramp = dp_c / (dp/dt): 2 s at 6 mm/min, 12 s at 1 mm/min on a 10 mm tip at a taxel corner, so the creep rate at the start of a hold stays in the paper's creep band (eqs. 8-9)
    cutoff_time_s: Pos(3600.0) = 0.5  # estimate (aging): theta_c of ln(1 + t / theta_c), Dieterich & Kilgore 1994 report ~1 s
    recovery_time_s: Pos(1e5) = 20.0  # estimate (aging): an unloaded film forgets its contact history (re-expansion of the matrix)
    times_s: list[Pos(1e6)] = Field(default_factory=lambda: [0.5, 1.5, 5.0, 15.0, 50.0, 150.0])  # estimate (spectrum): half-decade spacing over the 1-100 s of the paper's holds

    @model_validator(mode="after")
    def _check(self) -> VelostatCreepConfig:
        if not 1 <= len(self.times_s) <= 8:
            raise ValueError(f"'times_s' must list 1 to 8 times (got {len(self.times_s)})")
        return self


class VelostatReadoutConfig(Strict):
    """Constant-current force channel V = I (R_film + R_ITO(x, y)) (velostat eq. 1, Fig. 1d) with the
    source's compliance limit, and ITO position decoding (velostat sect. 5.1: 4-wire [20], 5-wire [21])."""

    sheet_resistance_ohm: Annotated[float, Field(ge=100.0, le=500.0)] = 300.0  # velostat sect. 5.1: PET-ITO 100-500 ohm/sq
    lead_resistance_ohm: NonNeg(1e6) = 20.0  # estimate: silver busbars + leads
    current_a: Annotated[float, Field(gt=0, le=0.1)] = 50e-6  # estimate: constant-current source
    compliance_v: Pos(100.0) = 3.0  # estimate: 5 V battery minus source headroom
    position_wiring: Literal["4-wire", "5-wire"] = "4-wire"  # velostat sect. 5.1
    drive_v: Pos(100.0) = 3.3  # estimate: gradient excitation across the ITO sheet
    input_resistance_ohm: Pos(1e15) = 1.0e6  # estimate: probe load (switch leakage + ADC) -> 3 mm at 1 N (velostat sect. 4.1)
    five_wire_bow: Annotated[float, Field(ge=0.0, lt=0.5)] = 0.02  # estimate: residual pincushion of corner-driven field
    noise_v: NonNeg(100.0) = 1.0e-3  # estimate: white noise rms per channel at the ADC, per conversion
    adc_bits: Annotated[int, Field(ge=4, le=24)] = 12  # estimate: STM32 ADC (velostat Fig. 20)
    adc_range_v: Pos(100.0) = 3.3  # estimate: unipolar 0-3.3 V
    # conversions per reported sample (4^k; the paper names "amplification and filtering" and an A/D, sect. 5.3, but
    # no averaging). A firmware that oversamples sums them and shifts right by k (ST AN2668): the sample carries
    # noise_v / 2^k and adc_bits + k bits. 1: each sample one conversion (the preset). 16 was scored as the preset by
    # a rule written first and not adopted: it lifts the creep compensation and the silhouette but widens the
    # K-means band of eq. 3 as printed past 2x the paper's (bench/results/velostat-oversampling-rule.md)
    oversampling: Annotated[int, Field(ge=1, le=1024)] = 1

    @property
    def oversampling_bits(self) -> int:
        """k of oversampling = 4^k: the bits the averaging adds."""
        return int(round(np.log(self.oversampling) / np.log(4)))

    @property
    def sample_noise_v(self) -> float:
        """White noise rms of a reported sample (V): noise_v over sqrt(oversampling)."""
        return float(self.noise_v / np.sqrt(self.oversampling))

    @property
    def sample_bits(self) -> int:
        """Bits of a reported sample's code: adc_bits + k."""
        return self.adc_bits + self.oversampling_bits

    @model_validator(mode="after")
    def _check(self) -> VelostatReadoutConfig:
        if self.compliance_v > self.adc_range_v:
            raise ValueError(
                f"'compliance_v' ({self.compliance_v} V) must be <= adc_range_v ({self.adc_range_v} V)"
            )
        if self.drive_v > self.adc_range_v:
            raise ValueError(f"'drive_v' ({self.drive_v} V) must be <= adc_range_v ({self.adc_range_v} V)")
        if 4 ** self.oversampling_bits != self.oversampling:
            raise ValueError(f"'oversampling' must be a power of 4 (1, 4, 16, 64, 256, 1024), got {self.oversampling}")
        if self.sample_bits > 24:
            raise ValueError(f"'adc_bits' + the oversampling's bits must be <= 24 (got {self.adc_bits} + "
                             f"{self.oversampling_bits})")
        return self


class VelostatSensorConfig(Strict):
    family: Literal["velostat"] = "velostat"
    units_x: Annotated[int, Field(ge=1, le=64)] = 6  # velostat sect. 4.1: 36 units
    units_y: Annotated[int, Field(ge=1, le=64)] = 6
    film: VelostatFilmConfig = Field(default_factory=VelostatFilmConfig)
    creep: VelostatCreepConfig = Field(default_factory=VelostatCreepConfig)
    readout: VelostatReadoutConfig = Field(default_factory=VelostatReadoutConfig)


__all__ = ["Fraction", "VelostatCreepConfig", "VelostatFilmConfig", "VelostatReadoutConfig", "VelostatSensorConfig"]
