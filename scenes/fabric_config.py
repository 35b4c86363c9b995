"""Config of the `fabric` family: EeonTex knitted conductive fabric stacks (paper key `fabric`).

A stack of `layers` fabric layers (1 x 1 cm) between two silver-thread electrodes, read by a 2-wire
multimeter. Every value is SI with the unit in the field name; defaults without a source are marked
`# estimate`. The stack-curve defaults are the 1-layer calibration (fit to the paper's eq. 6 through the
whole chain, see sensors/fabric/calibrate.py); the presets fabric_3/6/12 carry their own fitted values.
The paper does not print the unit of its resistance axis; we read it as kOhm (EeonTex is sold at
~20 kOhm/sq), so eq. 6's R(0) = 3.17 becomes 3170 ohm.  # estimate
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from scenes.base import NonNeg, Pos, Strict


class FabricStackConfig(Strict):
    """Kirchhoff series stack: n layers of in-layer resistance + (n + 1) Holm contacts (n - 1 between layers,
    2 fabric-to-thread electrodes), all carrying the same force.

    in-layer (knit compaction):  R_layer(x) = layer_r_inf_ohm + layer_r_amp_ohm * exp(-(x / layer_force_n)^layer_beta)
                                 (the monotone form of the paper's reading note)
    contact (Holm, Electric Contacts, 1967, sect. 1-4): R_c = rho / (2 a), a-spot radius a ~ (x + F0)^m,
                                 R_c(x) = contact_r0_ohm * (1 + x / contact_force_n)^(-contact_exponent),
                                 m = 1/3 (elastic a-spots) .. 1/2 (plastic a-spots).
    x is the effective compaction load (N) after creep and hysteresis.
    """

    layer_thickness_m: Pos(0.01) = 0.38e-3  # fabric sect. 3.1 (EeonTex, 0.38 mm)
    layer_r_inf_ohm: NonNeg(1e9) = 242.368  # fit to fabric eq. 6 (sensors/fabric/calibrate.py)
    layer_r_amp_ohm: NonNeg(1e9) = 855.664  # fit to fabric eq. 6
    layer_force_n: Pos(1000.0) = 0.758332  # fit to fabric eq. 6
    layer_beta: Annotated[float, Field(gt=0, le=4)] = 1.39721  # fit to fabric eq. 6
    contact_r0_ohm: NonNeg(1e9) = 1021.62  # fit to fabric eq. 6
    contact_force_n: Pos(1000.0) = 0.225262  # fit to fabric eq. 6: preload of the sewn stack
    contact_exponent: Annotated[float, Field(ge=0.33, le=0.5)] = 0.5  # Holm: 1/3 elastic .. 1/2 plastic
    lead_resistance_ohm: NonNeg(1e6) = 30.0  # fabric sect. 3.2: silver thread < 300 ohm/m, 2 x 5 cm leads  # estimate


class FabricCreepConfig(Strict):
    """Prony creep of the fabric's compaction under force: u = F + sum q_i, q_i -> g_i F with time constant tau_i.
    Source: Ferry, Viscoelastic Properties of Polymers (1980) (generalized Kelvin-Voigt creep compliance)."""

    prony_fractions: list[NonNeg(1.0)] = Field(default_factory=lambda: [0.04, 0.06])  # estimate
    prony_times_s: list[Pos(1e6)] = Field(default_factory=lambda: [1.0, 30.0])  # estimate

    @model_validator(mode="after")
    def _check(self) -> FabricCreepConfig:
        if len(self.prony_fractions) != len(self.prony_times_s):
            raise ValueError("sensor.creep.prony_fractions and prony_times_s must have the same length")
        if len(self.prony_fractions) > 8:
            raise ValueError("sensor.creep allows at most 8 Prony terms")
        return self


class FabricHysteresisConfig(Strict):
    """Prandtl-Ishlinskii play bank on the creep-compaction load (N), with return-point memory; the stack law
    R(x) that follows is nonlinear, so minor loops are not congruent, and the residual compaction at zero
    force depends on the last peak (minor loops return at different points). Slow recovery at rest.
    Source: Brokate & Sprekels, Hysteresis and Phase Transitions (1996); Al Janaideh et al. (generalized PI)."""

    play_thresholds_n: list[NonNeg(1000.0)] = Field(default_factory=lambda: [0.05, 0.15, 0.3, 0.5])  # estimate, tuned to 24.2 % FSO
    play_weights: list[NonNeg(1.0)] = Field(default_factory=lambda: [0.1, 0.1, 0.1, 0.1])  # estimate, tuned to 24.2 % FSO
    recovery_time_s: Pos(1e6) = 120.0  # estimate: slow release of the compaction at rest

    @model_validator(mode="after")
    def _check(self) -> FabricHysteresisConfig:
        if len(self.play_thresholds_n) != len(self.play_weights):
            raise ValueError("sensor.hysteresis.play_thresholds_n and play_weights must have the same length")
        if len(self.play_weights) > 16:
            raise ValueError("sensor.hysteresis allows at most 16 play operators")
        if sum(self.play_weights) >= 1.0:
            raise ValueError("sensor.hysteresis.play_weights must sum to < 1 (the rest is the direct path)")
        return self


class FabricPressConfig(Strict):
    """Repeat-to-repeat variation of a hand-loaded knitted stack: every press (the load rising through
    onset_force_n after it fell below release_force_n) seats the plate differently and the knit keeps a different
    part of its compaction on release, so a repeated cycle does not retrace itself.

    - engaged contact area: the stack's conductance scales with the area a press engages (Holm, Electric
      Contacts 1967: conductance of n parallel a-spots ~ n a); per press kappa = exp(area_sigma N(0, 1)).
    - knit set: on release the loops do not slide back (inter-fibre friction; the compression resilience RC of
      knits is 40-60 %, Kawabata, The Standardization and Analysis of Hand Evaluation, 1980: 40-60 % of the
      compression work is not returned); the compaction seen by the stack is x + psi (x_peak - x), with psi per
      press a fraction of the peak compaction, so bounded in [0, 1]: psi ~ Beta of mean set_fraction_mean and
      coefficient of variation set_fraction_cv (a press cannot keep more than it was given). The spread is an
      estimate: a hand press differs in seat, dwell and the set the previous press left; with cv 0.75 and mean
      ~0.16 the Beta(~1.3, ~7) keeps < 0.4 of the peak in 95 % of presses and < 0.65 in all but ~1 in 1000,
      inside the work loss that RC allows. The peak relaxes toward x with set_recovery_time_s (fibre stress
      relaxation), so the set carries into the next press.
    Draws come from the episode seed (stream 2), press by press; without seeds every press is the mean one.
    """

    onset_force_n: NonNeg(100.0) = 0.05  # estimate: half the paper's 0.1 N step, a touch of the hand on the sample
    release_force_n: NonNeg(100.0) = 0.02  # estimate: below it the plate has left the sample
    area_sigma: Annotated[float, Field(ge=0, le=1)] = 0.05  # estimate: a hand-placed plate engages a few % more or less of a 1 x 1 cm knit
    set_fraction_mean: Annotated[float, Field(ge=0, le=1)] = 0.3  # estimate, fit: piezotwin calibrate fabric (1-layer hysteresis 24.2 %)
    set_fraction_cv: Annotated[float, Field(ge=0, lt=2)] = 0.75  # estimate: see the class docstring (sd 0.75 x mean between hand presses)
    set_recovery_time_s: Pos(1e5) = 60.0  # estimate: fibre stress relaxation of polyamide/spandex knits, ~1 min
    max_presses: Annotated[int, Field(ge=1, le=4096)] = 256  # draws per episode; press k uses draw k mod max_presses

    @model_validator(mode="after")
    def _check(self) -> FabricPressConfig:
        if self.release_force_n > self.onset_force_n:
            raise ValueError("sensor.press.release_force_n must not exceed onset_force_n")
        m, cv = self.set_fraction_mean, self.set_fraction_cv
        if 0 < m < 1 and cv > 0 and cv * cv >= (1 - m) / m:  # Beta(a, b) needs a + b = (1 - m) / (m cv^2) - 1 > 0
            raise ValueError(f"sensor.press.set_fraction_cv must be < sqrt((1 - mean) / mean) = {((1 - m) / m) ** 0.5:.3g} "
                             f"for a Beta of mean {m:g}")
        return self


class MultimeterConfig(Strict):
    """2-wire handheld multimeter (fabric sect. 3.3): autoranging, finite counts, a few readings per second,
    sample-and-hold between readings. Reading = round(R (1 + gain_error) / resolution + noise) counts."""

    ranges_ohm: list[Pos(1e12)] = Field(default_factory=lambda: [600.0, 6e3, 60e3, 600e3, 6e6])  # estimate: 6000-count meter
    counts: Annotated[int, Field(ge=100, le=1_000_000)] = 6000  # estimate
    readings_per_s: Pos(1e4) = 2.5  # estimate: "a few readings per second"
    noise_counts: NonNeg(1000.0) = 0.5  # estimate: rms, in least-significant counts
    gain_error: Annotated[float, Field(ge=-0.1, le=0.1)] = 0.0  # estimate: calibration error (fraction)

    @model_validator(mode="after")
    def _check(self) -> MultimeterConfig:
        if not self.ranges_ohm or sorted(self.ranges_ohm) != list(self.ranges_ohm):
            raise ValueError("sensor.multimeter.ranges_ohm must list at least one range, ascending")
        return self


class FabricSensorConfig(Strict):
    family: Literal["fabric"] = "fabric"
    layers: Annotated[int, Field(ge=1, le=64)] = 1  # fabric sect. 3.3: 1, 3, 6, 12
    stack: FabricStackConfig = Field(default_factory=FabricStackConfig)
    creep: FabricCreepConfig = Field(default_factory=FabricCreepConfig)
    hysteresis: FabricHysteresisConfig = Field(default_factory=FabricHysteresisConfig)
    press: FabricPressConfig = Field(default_factory=FabricPressConfig)
    multimeter: MultimeterConfig = Field(default_factory=MultimeterConfig)
