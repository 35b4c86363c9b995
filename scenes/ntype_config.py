"""Sensor config of the N-type 6 x 6 three-dimensional force array (paper key `ntype`).

Source: Wang & Song, "Three-Dimensional Force Prediction of a Flexible Tactile Sensor Based on RBFNN"
(ntype), sect. 2.1-2.3 and 3.2. Numbers from the paper carry `# ntype`; the rest are `# estimate`.
Elasticity of the columns and the elastic cover: Timoshenko & Goodier, Theory of Elasticity (1970);
Johnson, Contact Mechanics (1985), sect. 3.2 (Boussinesq-Cerruti point loads).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from scenes.base import Between, NonNeg, Pos, Strict


class NtypeElementConfig(Strict):
    """One N-type element: a normal column "2" (1 cm) and two inclined columns "3" and "1" (sqrt2 cm, 45 deg
    from column 2; ntype sect. 2.2), read as R_x, R_y, R_z = columns 3, 1, 2 (ntype eq. 1-3).

    Column directions (unit vectors from the bottom to the top electrode; t = inclination_deg, s = sin t,
    c = cos t), by `reading` of Figure 1 / eq. 8 (the paper gives no drawing with coordinates):
      "crossed" (default): each element has two upper electrodes ("4", "5") and two lower ones ("6", "7")
                 and every column joins one upper to one lower wire, the upper wires perpendicular to the lower
                 ones (Figure 1). A three-stroke "N" over 2 + 2 electrodes (1: 6 -> 4, 2: 4 -> 7, 3: 7 -> 5)
                 that is not flat: column 3 leans in the x-z plane, column 1 in the y-z plane,
                 n_3 = (-s, 0, c), n_1 = (0, -s, c). A positive F_x (F_y) shortens column 3 (1), the paper's
                 R_x (R_y) in [32, 50] kOhm falling under F in [0, 4.8] N. Column 3 observes F_x and F_z,
                 column 1 F_y and F_z, column 2 F_z only (to first order; see sensors/ntype/model.py).
      "coplanar": a flat "N" in the x-z plane, n_3 = (-s, 0, c), n_1 = (s, 0, c): F_x moves columns 3 and 1
                 in opposite directions and no column observes F_y (only through the crosstalk of the cover).
      "eq8":     eq. 8 taken literally: the inclined columns' projections at +-phi from the x axis
                 (phi = inclined_azimuth_deg), n_{3,1} = (-s cos phi, -+s sin phi, c): each inclined column
                 observes F_x and F_y together (the paper's "strong coupling between F_x and F_y").
      "decoupled": sect. 2.3's own model (eqs. 4-5 and "Delta l_i ~ Delta i"): column i shortens by the top
                 electrode's displacement along axis i (columns 3, 1, 2 along x, y, z), each axis as stiff as its
                 column, E S / l_i, so each column observes one component. With no filler and rho constant
                 (filler moduli 0, piezo_coefficient 0: eq. 1) it gives the paper's ranges exactly: 4.8 N strains a
                 column by 4.8 / (E S) = 19.7 % ("does not exceed 20 %"), R' / R = (1 - 0.197)^2 = 0.645, 50 ->
                 32.3 and 25 -> 16.1 kOhm (`DECOUPLED_ELEMENT`). An idealisation: an inclined column also moves
                 with the normal displacement in any real N.
    The element's top moves as one (Delta l_i ~ the electrode displacement, ntype sect. 2.3), resisted by the
    three columns and the insulating GD-401 rubber that fills the rest of its cell (the filler, a bonded
    elastic block: shear G A / h, compression E A / h; Timoshenko & Goodier 1970), so the shear coupling of
    the normal column is that of the column geometry against the block.
    """

    elements_x: Annotated[int, Field(ge=1, le=64)] = 6  # ntype: 6 x 6 array
    elements_y: Annotated[int, Field(ge=1, le=64)] = 6  # ntype
    youngs_modulus_pa: Pos(1e10) = 6.1e6  # ntype sect. 2.1 (conductive rubber)
    poisson_ratio: Annotated[float, Field(ge=0.0, lt=0.5)] = 0.49  # ntype sect. 2.1
    column_area_m2: Pos(0.01) = 4e-6  # ntype sect. 2.2: 4 mm^2 cross-section
    normal_length_m: Pos(0.1) = 0.010  # ntype sect. 2.2: 1 cm
    inclined_length_m: Pos(0.1) = 0.014142135623730951  # ntype sect. 2.2: sqrt(2) cm
    inclination_deg: Annotated[float, Field(gt=0, lt=90)] = 45.0  # ntype sect. 2.2
    reading: Literal["crossed", "coplanar", "eq8", "decoupled"] = "crossed"  # estimate: Figure 1 read as above (crossed wires)
    inclined_azimuth_deg: Annotated[float, Field(ge=0, le=90)] = 45.0  # "eq8" only: eq. 8's phi, not given; estimate: 45 puts the two projections at right angles like the wires
    filler_youngs_modulus_pa: NonNeg(1e10) = 6.1e6  # estimate: GD-401 filler as stiff as the conductive rubber (ntype sect. 2.1 gives only the latter)
    filler_shear_modulus_pa: NonNeg(1e10) = 2.05e6  # estimate: likewise, the paper's 2.05 MPa

    @property
    def n_elements(self) -> int:
        return self.elements_x * self.elements_y


class NtypeResistanceConfig(Strict):
    """R_j = rho(e_j) l_j^2 (1 + e_j)^2 / V_j with rho(e) = rho0 exp(beta e) (e < 0 in compression).

    The rest resistances are set directly (they fix V_j = rho0 l_j^2 / R_j0): the paper's ranges
    (ntype sect. 3.2: normal column 16-25 kOhm, inclined 32-50 kOhm) are honoured rather than equal volumes.
    """

    rest_normal_ohm: Pos(1e12) = 25e3  # ntype sect. 3.2: top of the 16-25 kOhm range (unloaded)
    rest_inclined_ohm: Pos(1e12) = 50e3  # ntype sect. 3.2: top of the 32-50 kOhm range (unloaded)
    piezo_coefficient: Between(-1e4, 1e4) = 215.0  # estimate: beta of rho(e) = rho0 exp(beta e); places 4.8 N of F_z (0.2 % strain of the stiff cell) at 16 kOhm
    min_strain: Annotated[float, Field(gt=-0.9, lt=0)] = -0.6  # estimate: strain clamp (column fully squeezed)


class NtypeLayerConfig(Strict):
    """Elastic cover that couples neighbours (crosstalk): the load reaching an element's top electrode
    is the Boussinesq stress of every surface load at depth `depth_m` (same shape for the shear components),
    integrated over the electrode square and normalised so that a load centred on the element counts fully.
    Source: Johnson, Contact Mechanics (1985), eq. 3.21 (sigma_z under a point load).
    """

    depth_m: Pos(0.1) = 0.010  # estimate: the array's 1 cm thickness (ntype sect. 2.2); gives ~1/3 at 1 cm, a few % at 2 cm (sect. 3.3: 1-2 cm)
    electrode_size_m: Pos(0.1) = 0.010  # ntype sect. 2.2: the element spans 1 cm
    quadrature: Annotated[int, Field(ge=2, le=32)] = 8  # points per electrode side


class NtypeDynamicsConfig(Strict):
    """Small viscoelastic lag of the rubber: u = K^-1 ((1 - g) F + g q), q' = a q + (1 - a) F (creep to K^-1 F).
    Source: Ferry, Viscoelastic Properties of Polymers (1980) (standard linear solid)."""

    lag_fraction: Annotated[float, Field(ge=0, lt=1)] = 0.05  # estimate
    lag_time_s: Pos(1e4) = 0.3  # estimate


class NtypeReadoutConfig(Strict):
    """Scan of the 6 x 6 x 3 columns through the upper and lower wires that cross at right angles (ntype
    sect. 2.2, Figure 1): a passive resistor matrix of 2 x 6 upper and 2 x 6 lower wires (sensors/ntype/scan.py).
    One column at a time: its upper wire is driven at `drive_v`, its lower wire read; the others are

      "ideal"     not there (an ohmmeter per column, no matrix: the former readout, for comparison)
      "floating"  left open: sneak paths through every other column (reference resistor divider)
      "grounded"  grounded through the multiplexer: sneak currents into the read wire partly drain away
                  (reference resistor divider on the read wire)
      "feedback"  grounded, and the read wire held at virtual ground by an op-amp (zero-potential method):
                  only the multiplexer on-resistance leaves a residue
    Source: D'Alessio, "Measurement errors in the scanning of piezoresistive sensors arrays", Sens. Actuators A
    72 (1999) 71-76; the paper says only "by scanning the circuit" (sect. 3.2), so the scheme is an estimate.
    Then relative noise + resolution on the apparent resistance.
    """

    scan: Literal["ideal", "floating", "grounded", "feedback"] = "feedback"  # estimate: the usual suppression for a resistive matrix
    drive_v: Pos(1000.0) = 5.0  # estimate: scan voltage (only ratios matter without noise in volts)
    switch_on_ohm: NonNeg(1e9) = 100.0  # estimate: analog multiplexer on-resistance (CD4067-class, ~100 ohm at 5 V)
    reference_ohm: Pos(1e12) = 1e3  # estimate: a low sense resistor keeps the read wire near ground (what grounding needs to suppress; ~1/30 of a column)
    noise_fraction: NonNeg(1.0) = 0.002  # estimate: relative rms noise per reading
    resolution_ohm: NonNeg(1e9) = 1.0  # estimate: readout quantum (0 disables)


class NtypeSensorConfig(Strict):
    family: Literal["ntype"] = "ntype"
    element: NtypeElementConfig = Field(default_factory=NtypeElementConfig)
    resistance: NtypeResistanceConfig = Field(default_factory=NtypeResistanceConfig)
    layer: NtypeLayerConfig = Field(default_factory=NtypeLayerConfig)
    dynamics: NtypeDynamicsConfig = Field(default_factory=NtypeDynamicsConfig)
    readout: NtypeReadoutConfig = Field(default_factory=NtypeReadoutConfig)

    @model_validator(mode="after")
    def _check(self) -> NtypeSensorConfig:
        e = self.element
        flat = e.reading == "coplanar" or (e.reading == "eq8" and e.inclined_azimuth_deg in (0.0, 90.0))
        if flat and e.filler_shear_modulus_pa == 0.0:
            raise ValueError(
                f"sensor.element.reading: '{e.reading}' puts the columns in one plane; with filler_shear_modulus_pa=0 "
                "one shear direction has no stiffness (allowed: filler_shear_modulus_pa > 0 or reading 'crossed')"
            )
        return self


# The paper's experiment (protocol kind "element_loads", ntype sect. 3.2): every element carries its own static
# 3-D force, each component in [0, 4.8] N, drawn uniformly (estimate: the paper gives the range only; its eq. 14,
# Table 2 and Figs. 6-8 fit a uniform draw and not one skewed to ~0.6 N, simulate/protocols/element_loads.py);
# 150 episodes x 20 frames = 3000 samples. One frame a second:
# estimate, long beside the 0.3 s lag so that each sample is a settled reading (the paper's are static).
# (frequencies_hz is unused by this kind; set below the 1 Hz rate's limit.)
# sect. 2.3's element as the paper models it (reading "decoupled"): no filler in the load path, rho constant (eq. 1)
DECOUPLED_ELEMENT = [
    "sensor.element.reading=decoupled", "sensor.element.filler_youngs_modulus_pa=0",
    "sensor.element.filler_shear_modulus_pa=0", "sensor.resistance.piezo_coefficient=0",
]
PAPER_PROTOCOL = [
    "protocol.kind=element_loads", "protocol.amplitude_min=0", "protocol.amplitude_max=4.8",
    "protocol.force_distribution=uniform",
    "protocol.settle_s=0", "protocol.duration_s=20", "sampling.sample_rate_hz=1", "protocol.frequencies_hz=[0.05]",
]
