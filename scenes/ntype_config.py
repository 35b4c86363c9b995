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
    """One N-type element: a normal column (0 deg) and two inclined columns (+-45 deg from the normal).

    Column directions (unit vectors from the bottom to the top electrode):
      normal   n_z  = (0, 0, 1)
      R_x col  n_+  = ( sin(t) cos(a), sin(t) sin(a), cos(t))   (paper's column "3")
      R_y col  n_-  = (-sin(t) cos(a), sin(t) sin(a), cos(t))   (paper's column "1")
    t = inclination_deg (45 in the paper), a = inclined_azimuth_deg: the azimuth of the inclined columns'
    projections off the x axis (the paper's phi in eq. 8, value not given). At a = 0 the three columns are
    coplanar (an "N" in the x-z plane) and no column strains under F_y to first order.
    """

    elements_x: Annotated[int, Field(ge=1, le=64)] = 6  # ntype: 6 x 6 array
    elements_y: Annotated[int, Field(ge=1, le=64)] = 6  # ntype
    youngs_modulus_pa: Pos(1e10) = 6.1e6  # ntype sect. 2.1 (conductive rubber)
    poisson_ratio: Annotated[float, Field(ge=0.0, lt=0.5)] = 0.49  # ntype sect. 2.1
    column_area_m2: Pos(0.01) = 4e-6  # ntype sect. 2.2: 4 mm^2 cross-section
    normal_length_m: Pos(0.1) = 0.010  # ntype sect. 2.2: 1 cm
    inclined_length_m: Pos(0.1) = 0.014142135623730951  # ntype sect. 2.2: sqrt(2) cm
    inclination_deg: Annotated[float, Field(gt=0, lt=90)] = 45.0  # ntype sect. 2.2
    inclined_azimuth_deg: Annotated[float, Field(ge=0, le=90)] = 60.0  # estimate: F_y observable, normal column still most sensitive to F_z
    filler_stiffness_n_per_m: NonNeg(1e9) = 300.0  # estimate: insulating GD-401 filler around the element, isotropic

    @property
    def n_elements(self) -> int:
        return self.elements_x * self.elements_y


class NtypeResistanceConfig(Strict):
    """R_j = rho(e_j) l_j^2 (1 + e_j)^2 / V_j with rho(e) = rho0 exp(beta e) (e < 0 in compression).

    The rest resistances are set directly (they fix V_j = rho0 l_j^2 / R_j0): the paper's ranges
    (ntype sect. 3.2: normal column 16-25 kOhm, inclined 32-50 kOhm) are honoured rather than equal volumes.
    """

    rest_normal_ohm: Pos(1e9) = 25e3  # ntype sect. 3.2: top of the 16-25 kOhm range (unloaded)
    rest_inclined_ohm: Pos(1e9) = 50e3  # ntype sect. 3.2: top of the 32-50 kOhm range (unloaded)
    piezo_coefficient: Between(-100.0, 100.0) = 0.7  # estimate: beta of rho(e) = rho0 exp(beta e); places 4.8 N of F_z near 16 kOhm
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
    """Scanning ohmmeter over the 6 x 6 x 3 columns (upper wire x lower wire, ntype sect. 2.2)."""

    noise_fraction: NonNeg(1.0) = 0.002  # estimate: relative rms noise per reading
    resolution_ohm: NonNeg(1e6) = 1.0  # estimate: readout quantum (0 disables)


class NtypeSensorConfig(Strict):
    family: Literal["ntype"] = "ntype"
    element: NtypeElementConfig = Field(default_factory=NtypeElementConfig)
    resistance: NtypeResistanceConfig = Field(default_factory=NtypeResistanceConfig)
    layer: NtypeLayerConfig = Field(default_factory=NtypeLayerConfig)
    dynamics: NtypeDynamicsConfig = Field(default_factory=NtypeDynamicsConfig)
    readout: NtypeReadoutConfig = Field(default_factory=NtypeReadoutConfig)

    @model_validator(mode="after")
    def _check(self) -> "NtypeSensorConfig":
        e = self.element
        if e.inclined_azimuth_deg == 0.0 and e.filler_stiffness_n_per_m == 0.0:
            raise ValueError(
                "sensor.element.inclined_azimuth_deg: 0 with filler_stiffness_n_per_m=0 leaves F_y without stiffness "
                "(allowed: azimuth > 0 or filler stiffness > 0)"
            )
        return self
