"""N-type 6 x 6 three-dimensional force array (paper key `ntype`: Wang & Song 2021, sect. 2).

Pipeline over (episode x element), ground truth and measurement both kept:
  load field of the pad (pressure, shear on the taxel grid, simulate/)
  -> labels: the force applied on each element's cell (36 x 3: F_x, F_y, F_z with F_z compressive > 0)
  -> elastic cover (crosstalk): the force reaching each element's top electrode, the Boussinesq (normal)
     stress of every surface load at the cover depth (same shape for shear) integrated over the electrode
     and normalised to 1 for a load centred on the element (Johnson, Contact Mechanics, 1985, sect. 3.2)
  -> element chain (Warp kernel sensors/ntype/kernels.py, numpy reference sensors/ntype/reference.py):
     viscoelastic lag, u = K^-1 F with K = sum_j k_j n_j n_j^T (+ filler), e_j = n_j.u / l_j,
     R_j = rho(e_j) l_j^2 (1 + e_j)^2 / V_j (ntype eq. 1; Timoshenko & Goodier 1970 for the columns)
  -> scan of the resistor matrix (sensors/ntype/scan.py: upper x lower wires, sneak paths and their
     suppression; "ideal" = an ohmmeter per column), then relative noise + resolution (resistance_measured).
Column order everywhere: (R_x, R_y, R_z) = the paper's columns "3", "1", "2", so resistance[..., c]
pairs with force[..., c] as in the paper's 36 x 3 samples.
"""

from __future__ import annotations

import math

import numpy as np

from scenes.config import SceneConfig
from sensors.base import ChannelSpec, LoadBatch, resolve_backend
from sensors.ntype.reference import NtypeParams, ntype_chain_numpy
from sensors.ntype.scan import scan_apparent

COLUMNS = ("3: R_x (inclined)", "1: R_y (inclined)", "2: R_z (normal)")

OUTPUTS: dict[str, ChannelSpec] = {
    "force_element": ChannelSpec("N", ("time", "element", "xyz"), "force applied on each element's cell (label; z compressive)"),
    "force_electrode": ChannelSpec("N", ("time", "element", "xyz"), "force reaching each element's top electrode through the elastic cover (with crosstalk)"),
    "force": ChannelSpec("N", ("time", "xyz"), "total applied force (sum of the labels)"),
    "displacement": ChannelSpec("m", ("time", "element", "xyz"), "top-electrode displacement, world frame (z up)"),
    "strain": ChannelSpec("1", ("time", "element", "column"), "column strain (negative = compression); columns R_x, R_y, R_z"),
    "resistance": ChannelSpec("ohm", ("time", "element", "column"), "true column resistance; columns R_x, R_y, R_z"),
    "resistance_measured": ChannelSpec("ohm", ("time", "element", "column"), "apparent resistance read by scanning the wire matrix (sneak paths, noise, resolution)"),
}


def column_normals(cfg: SceneConfig) -> np.ndarray:
    """[3, 3] unit directions of columns (R_x, R_y, R_z) = ("3", "1", "2"), bottom to top electrode, for the
    element's `reading` of Figure 1 / eq. 8 (scenes/ntype_config.py NtypeElementConfig)."""
    el = cfg.sensor.element
    t = math.radians(el.inclination_deg)
    s, c = math.sin(t), math.cos(t)
    if el.reading == "crossed":
        n3, n1 = (-s, 0.0, c), (0.0, -s, c)
    elif el.reading == "coplanar":
        n3, n1 = (-s, 0.0, c), (s, 0.0, c)
    elif el.reading == "decoupled":  # sect. 2.3: Delta l_i ~ the electrode's displacement along axis i
        n3, n1 = (-1.0, 0.0, 0.0), (0.0, -1.0, 0.0)
    else:  # "eq8": projections at +-phi from the x axis
        a = math.radians(el.inclined_azimuth_deg)
        n3, n1 = (-s * math.cos(a), -s * math.sin(a), c), (-s * math.cos(a), s * math.sin(a), c)
    return np.array([n3, n1, (0.0, 0.0, 1.0)])


def cell_stiffness(cfg: SceneConfig) -> np.ndarray:
    """[3, 3] stiffness (N/m) of the filler block around one element: the element's cell (pitch x pitch, the
    array's thickness h) less the three columns, bonded top and bottom: shear G A / h in x and y,
    compression E A / h in z (Timoshenko & Goodier 1970; the bonded layer's shape-factor stiffening is
    left out, an estimate)."""
    el = cfg.sensor.element
    area = cfg.pad.size_x_m / el.elements_x * cfg.pad.size_y_m / el.elements_y - 3 * el.column_area_m2
    h = el.normal_length_m
    g, e = el.filler_shear_modulus_pa * area / h, el.filler_youngs_modulus_pa * area / h
    return np.diag([g, g, e])


def ntype_params(cfg: SceneConfig) -> NtypeParams:
    el, rs, dy = cfg.sensor.element, cfg.sensor.resistance, cfg.sensor.dynamics
    n = column_normals(cfg)
    lengths = np.array([el.inclined_length_m, el.inclined_length_m, el.normal_length_m])
    k = el.youngs_modulus_pa * el.column_area_m2 / lengths
    K = sum(k[j] * np.outer(n[j], n[j]) for j in range(3)) + cell_stiffness(cfg)
    if abs(np.linalg.det(K)) < 1e-12 * np.abs(K).max() ** 3:
        raise ValueError("sensor.element: columns and filler leave the element without stiffness in some direction "
                         "(allowed: filler moduli > 0 or a reading whose columns span x, y, z)")
    dt = 1.0 / cfg.sampling.sample_rate_hz
    return NtypeParams(
        normals=n,
        lengths_m=lengths,
        compliance=np.linalg.inv(K),
        rest_ohm=np.array([rs.rest_inclined_ohm, rs.rest_inclined_ohm, rs.rest_normal_ohm]),
        beta=rs.piezo_coefficient,
        min_strain=rs.min_strain,
        lag_decay=math.exp(-dt / dy.lag_time_s),
        lag_fraction=dy.lag_fraction,
    )


def element_centres_m(cfg: SceneConfig) -> np.ndarray:
    """[M, 2] element centres, flat index m = iy * elements_x + ix."""
    el = cfg.sensor.element
    xs = -cfg.pad.size_x_m / 2 + (np.arange(el.elements_x) + 0.5) * cfg.pad.size_x_m / el.elements_x
    ys = -cfg.pad.size_y_m / 2 + (np.arange(el.elements_y) + 0.5) * cfg.pad.size_y_m / el.elements_y
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


def cover_influence(cfg: SceneConfig, dxy_m: np.ndarray) -> np.ndarray:
    """[..., 3] share of a surface point load (x, y, z components) at offset dxy_m [..., 2] from an element's
    centre that reaches its top electrode, normalised to 1 at zero offset.

    Boussinesq sigma_z = 3 P h^3 / (2 pi r^5), r^2 = x^2 + y^2 + h^2 at cover depth h, integrated over the
    electrode square by Gauss-Legendre quadrature (Johnson, Contact Mechanics, 1985, eq. 3.21), for all three
    components. # estimate: Cerruti's tau_zx = 3 Q x^2 h / (2 pi r^5) vanishes under the load and peaks
    off-axis, so normalised to a centred point load it over-counts a distributed shear patch (a 10 mm patch
    read 1.4x its force); the Boussinesq shape keeps patch loads consistent across components.
    """
    ly = cfg.sensor.layer
    h, a, nq = ly.depth_m, ly.electrode_size_m / 2, ly.quadrature
    g, w = np.polynomial.legendre.leggauss(nq)
    gx, gy = np.meshgrid(g * a, g * a)
    ww = (np.outer(w, w) * a * a).ravel()
    pts = np.stack([gx.ravel(), gy.ravel()], -1)  # [Q, 2]

    def raw(d: np.ndarray) -> np.ndarray:
        x = pts[:, 0] - d[..., None, 0]
        y = pts[:, 1] - d[..., None, 1]
        r5 = (x * x + y * y + h * h) ** 2.5
        c = 3.0 / (2.0 * np.pi)
        kz = ((c * h**3 / r5) * ww).sum(-1)
        return np.stack([kz, kz, kz], -1)

    return raw(np.asarray(dxy_m, float)) / raw(np.zeros(2))


class NtypeSensor:
    """Batched N-type array. Shapes: E episodes, T samples, N load-field taxels, M = 36 elements, 3 columns."""

    family = "ntype"
    outputs = OUTPUTS
    device_load = True  # run_load takes taxel fields left on the device (LoadBatch, GPU path; warp backend)

    def __init__(self, cfg: SceneConfig, backend: str = "warp", device: str = "cpu"):
        device = resolve_backend(backend, device)
        self.cfg, self.backend, self.device = cfg, backend, device
        self.p = ntype_params(cfg)
        el = cfg.sensor.element
        self.n_elements = el.n_elements
        self.centres = element_centres_m(cfg)
        from sensors.taxels import taxel_xy_m  # geometry helper only (no MuJoCo)

        xy = taxel_xy_m(cfg)
        # labels: each taxel's load belongs to the element whose cell holds the taxel centre
        ix = np.clip(((xy[:, 0] + cfg.pad.size_x_m / 2) / cfg.pad.size_x_m * el.elements_x).astype(int), 0, el.elements_x - 1)
        iy = np.clip(((xy[:, 1] + cfg.pad.size_y_m / 2) / cfg.pad.size_y_m * el.elements_y).astype(int), 0, el.elements_y - 1)
        self.owner = iy * el.elements_x + ix
        self.label_matrix = np.zeros((self.n_elements, len(xy)))
        self.label_matrix[self.owner, np.arange(len(xy))] = 1.0
        # crosstalk: [3, M, N] influence of taxel loads on electrode forces
        w = cover_influence(cfg, xy[None, :, :] - self.centres[:, None, :])  # [M, N, 3]
        self.influence = np.moveaxis(w, -1, 0)

    def loads(self, load: LoadBatch) -> tuple[np.ndarray, np.ndarray]:
        """(labels [E,T,M,3] with z compressive, electrode forces [E,T,M,3] world frame z up)."""
        A = load.taxel_area_m2
        f = np.concatenate([load.shear_pa * A, load.pressure_pa[..., None] * A], axis=-1)  # [E,T,N,3]
        labels = np.einsum("mn,etnc->etmc", self.label_matrix, f, optimize=True)
        elec = np.stack([np.einsum("mn,etn->etm", self.influence[c], f[..., c], optimize=True) for c in range(3)], -1)
        elec[..., 2] *= -1.0  # a press pushes the electrode down
        return labels, elec

    def run_load(self, load: LoadBatch, seeds: list[int]) -> dict[str, np.ndarray]:
        if load.fields_on_device and self.backend == "warp":  # the element loads made there (`ntype_loads_warp`)
            from sensors.ntype.kernels import ntype_loads_warp

            labels, elec = ntype_loads_warp(load.shear_pa, load.pressure_pa, load.taxel_area_m2, self.owner,
                                            self.influence, load.target.shape)
            return self.run(labels, elec, seeds)
        labels, elec = self.loads(load.on_host())
        return self.run(labels, elec, seeds)

    def run(self, labels: np.ndarray, electrode_force: np.ndarray, seeds: list[int]) -> dict[str, np.ndarray]:
        E, T, M, _ = electrode_force.shape
        if M != self.n_elements:
            raise ValueError(f"load has {M} elements; the array has {self.n_elements}")
        if len(seeds) != E:
            raise ValueError(f"need one seed per episode ({E}); got {len(seeds)}")
        if self.backend == "numpy":
            disp, strain, res, _ = ntype_chain_numpy(electrode_force, self.p)
        else:
            from sensors.ntype.kernels import ntype_chain_warp

            disp, strain, res, _ = ntype_chain_warp(electrode_force, self.p, self.device)
        rd, el = self.cfg.sensor.readout, self.cfg.sensor.element
        seen = scan_apparent(res, el.elements_x, el.elements_y, rd.scan, rd.drive_v, rd.switch_on_ohm, rd.reference_ohm,
                             self.backend, self.device)
        meas = np.empty_like(res)
        for e, s in enumerate(seeds):
            rng = np.random.default_rng(np.random.SeedSequence(int(s), spawn_key=(1,)))
            meas[e] = seen[e] * (1.0 + rd.noise_fraction * rng.standard_normal(res[e].shape))
        if rd.resolution_ohm > 0:
            meas = np.round(meas / rd.resolution_ohm) * rd.resolution_ohm
        f32 = np.float32
        return {
            "force_element": labels.astype(f32),
            "force_electrode": (electrode_force * np.array([1.0, 1.0, -1.0])).astype(f32),
            "force": labels.sum(2).astype(f32),
            "displacement": disp.astype(f32),
            "strain": strain.astype(f32),
            "resistance": res.astype(f32),
            "resistance_measured": meas.astype(f32),
        }

    def attrs(self) -> dict:
        el, rs = self.cfg.sensor.element, self.cfg.sensor.resistance
        return {
            "family": self.family,
            "paper": "ntype",
            "sample_rate_hz": self.cfg.sampling.sample_rate_hz,
            "n_elements": self.n_elements,
            "elements_x": el.elements_x,
            "elements_y": el.elements_y,
            "element_xy_m": self.centres,
            "columns": list(COLUMNS),
            "column_normals": self.p.normals,
            "column_lengths_m": self.p.lengths_m,
            "rest_resistance_ohm": self.p.rest_ohm,
            "piezo_coefficient": rs.piezo_coefficient,
            "control": self.cfg.protocol.control,
            "reading": el.reading,
            "scan": self.cfg.sensor.readout.scan,
            "switch_on_ohm": self.cfg.sensor.readout.switch_on_ohm,
            "reference_ohm": self.cfg.sensor.readout.reference_ohm,
        }
