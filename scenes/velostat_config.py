"""Sensor config of the `velostat` family (paper key `velostat`): a 120 x 120 mm Velostat film between two
PET-ITO sheets, a constant-current force channel and 4-/5-wire ITO position decoding.

Values the paper gives are cited; the rest are marked `# estimate` (and are parameters).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from scenes.base import Between, Fraction, NonNeg, Pos, Strict


class VelostatFilmConfig(Strict):
    """Through-thickness conductance of the film: G = g_area * A * field_g(x, y) * ((p + c) / p_ref)^n.

    Dominated by the film/ITO interface contact resistance, whose a-spot count grows with load
    (Holm, Electric Contacts, 1967): conductance ~ pressure^n with n ~ 1 (velostat sect. 2, Fig. 19).
    """

    resistance_at_ref_ohm: Pos(1e12) = 20_000.0  # estimate: 1 cm^2 of film at p_ref (1 N on a 1 cm^2 tip)
    reference_pressure_pa: Pos(1e9) = 10_000.0  # estimate: 1 N on 1 cm^2
    exponent: Annotated[float, Field(gt=0.2, le=3.0)] = 1.05  # estimate: power law n ~ 1 (velostat Fig. 13b)
    field_seed: Annotated[int, Field(ge=0)] | None = None  # None: the part follows generation.root_seed
    correlation_length_m: Pos(1.0) = 0.030  # estimate: 20-40 mm patches (velostat Figs. 18, 19)
    conductance_spread: NonNeg(5.0) = 0.35  # estimate: std of log conductance over the film
    creep_spread: NonNeg(5.0) = 0.35  # estimate: std of log creep amplitude over the film
    field_resolution_m: Between(1e-4, 0.1) = 0.002  # grid on which the random field is drawn


class VelostatCreepConfig(Strict):
    """Log-time creep of the contact (contact-area aging, Dieterich & Kilgore, PAGEOPH 143, 1994) as a
    Schapery-type nonlinear creep (Schapery, Polym. Eng. Sci. 9, 1969): a bank of first-order terms with
    log-spaced times (equal weights per term -> log-time growth) relaxing toward
    Phi(p) = amplitude * p_c * ln(1 + p / p_c), so the relative creep Phi/p falls with force and a faster
    ramp leaves more creep for the hold (velostat sect. 3.1, Figs. 3, 5)."""

    amplitude: NonNeg(100.0) = 6.0  # estimate: 3-6 N error in a 30 s hold at 7 N (velostat sect. 5.4: up to 5 N)
    saturation_pressure_pa: Pos(1e9) = 30_000.0  # estimate: p_c, relative creep halves by ~7 N on 1 cm^2
    times_s: list[Pos(1e6)] = Field(default_factory=lambda: [0.5, 1.5, 5.0, 15.0, 50.0, 150.0])  # estimate: half-decade spacing over the 1-100 s of the paper's holds

    @model_validator(mode="after")
    def _check(self) -> "VelostatCreepConfig":
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
    noise_v: NonNeg(100.0) = 1.0e-3  # estimate: white noise rms per channel at the ADC
    adc_bits: Annotated[int, Field(ge=4, le=24)] = 12  # estimate: STM32 ADC (velostat Fig. 20)
    adc_range_v: Pos(100.0) = 3.3  # estimate: unipolar 0-3.3 V

    @model_validator(mode="after")
    def _check(self) -> "VelostatReadoutConfig":
        if self.compliance_v > self.adc_range_v:
            raise ValueError(
                f"'compliance_v' ({self.compliance_v} V) must be <= adc_range_v ({self.adc_range_v} V)"
            )
        if self.drive_v > self.adc_range_v:
            raise ValueError(f"'drive_v' ({self.drive_v} V) must be <= adc_range_v ({self.adc_range_v} V)")
        return self


class VelostatSensorConfig(Strict):
    family: Literal["velostat"] = "velostat"
    units_x: Annotated[int, Field(ge=1, le=64)] = 6  # velostat sect. 4.1: 36 units
    units_y: Annotated[int, Field(ge=1, le=64)] = 6
    film: VelostatFilmConfig = Field(default_factory=VelostatFilmConfig)
    creep: VelostatCreepConfig = Field(default_factory=VelostatCreepConfig)
    readout: VelostatReadoutConfig = Field(default_factory=VelostatReadoutConfig)


__all__ = ["VelostatSensorConfig", "VelostatFilmConfig", "VelostatCreepConfig", "VelostatReadoutConfig", "Fraction"]
