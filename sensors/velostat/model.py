"""Large-scale Velostat tactile sensor (paper key `velostat`): film conductance with log-time creep over a
random field, constant-current force channel, 4-/5-wire ITO position decoding.

Pipeline (ground truth beside the measurement):
  pressure [E,T,N] (MuJoCo load field) -> film kernel: contact-aging creep states + conductance per taxel
  (sensors/velostat/kernels.py, reference sensors/velostat/reference.py) -> readout kernel: parallel contact paths
  through the ITO sheets, V = I (R_film + R_ITO(x, y)) clipped at the compliance voltage, probe voltages of
  the X and Y gradient phases, noise, 12-bit ADC -> decoded resistance and position.
The film is one physical part: its domains (carbon-loading zones, distinct conductance levels) and smooth
random fields (conductance and creep amplitude, correlation length 20-40 mm) are drawn from sensor.film.field_seed, or from generation.root_seed when that is None.
backend "warp" runs the Warp kernels on `device`; backend "numpy" runs the reference.
"""

from __future__ import annotations

import numpy as np

from scenes.config import SceneConfig
from sensors.base import ChannelSpec, LoadBatch, resolve_backend
from sensors.velostat.reference import (
    FilmParams,
    ReadoutParams,
    film_chain_numpy,
    force_centroid_numpy,
    readout_numpy,
)

OUTPUTS: dict[str, ChannelSpec] = {
    "force": ChannelSpec("N", ("time",), "applied normal force: sum of the contact pressure (reference label)"),
    "contact_xy": ChannelSpec("m", ("time", "xy"), "pressure-weighted contact centroid (ground truth; NaN unloaded)"),
    "unit": ChannelSpec("1", ("time",), "calibration unit under the contact centroid (-1 unloaded)"),
    "resistance_film": ChannelSpec("ohm", ("time",), "true film resistance, taxels in parallel (1e12 unloaded)"),
    "resistance": ChannelSpec("ohm", ("time",), "true R_film + R_ITO seen by the current source (1e12 unloaded)"),
    "voltage_true": ChannelSpec("V", ("time", "channel"), "noise-free force, X-probe, Y-probe voltages"),
    "adc": ChannelSpec("counts", ("time", "channel"), "ADC codes of force, X, Y channels"),
    "voltage": ChannelSpec("V", ("time", "channel"), "ADC voltages (code centres) of force, X, Y"),
    "resistance_measured": ChannelSpec("ohm", ("time",), "V_force / I as the instrument reports (clipped at compliance)"),
    "position_measured": ChannelSpec("m", ("time", "xy"), "decoded ITO position (NaN without touch)"),
}


def film_field(cfg: SceneConfig, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Standard-normal smooth random fields (z_g, z_c), each [N] (cell means over the taxel grid).

    White noise on a grid of pitch field_resolution_m, Gaussian-filtered with sigma = L / 2 so that the
    correlation exp(-r^2 / L^2) falls to 1/e at the correlation length L; normalised over the film."""
    from scipy.ndimage import gaussian_filter

    pad, f = cfg.pad, cfg.sensor.film
    res = f.field_resolution_m
    sig = f.correlation_length_m / 2 / res
    m = int(np.ceil(3 * sig))
    nx = max(int(round(pad.size_x_m / res)), pad.taxels_x)
    ny = max(int(round(pad.size_y_m / res)), pad.taxels_y)
    rng = np.random.default_rng([int(seed), 0x7E105])
    out = []
    ix = (np.arange(nx) * pad.taxels_x) // nx
    iy = (np.arange(ny) * pad.taxels_y) // ny
    flat = (iy[:, None] * pad.taxels_x + ix[None, :]).ravel()
    counts = np.bincount(flat, minlength=pad.n_taxels)
    for _ in range(2):
        z = gaussian_filter(rng.standard_normal((ny + 2 * m, nx + 2 * m)), sig, mode="wrap")[m:m + ny, m:m + nx]
        z = (z - z.mean()) / z.std()
        cell = np.bincount(flat, weights=z.ravel(), minlength=pad.n_taxels) / counts
        out.append(cell)
    return out[0], out[1]


def film_domains(cfg: SceneConfig, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Domains of the film (carbon-black loading zones of the calendered sheet; count and contrast are
    estimates): a Voronoi tessellation of `domains` seeds thrown uniformly over the film at a minimum distance
    of 0.6 sqrt(area / domains) from each other, each domain with a
    resistivity factor 1 + domain_spread * q, q evenly spaced over [-1, 1] (shuffled), so the levels are
    distinct and evenly spaced in ohm (the paper's Ward distance, eq. 11); per taxel the cell mean of the log
    conductance over the fine grid (a taxel on a border mixes). Returns (log-conductance level per taxel [N],
    domain of each taxel's centre [N])."""
    pad, f = cfg.pad, cfg.sensor.film
    M = f.domains
    n = pad.n_taxels
    if M <= 1:
        return np.zeros(n), np.zeros(n, int)
    rng = np.random.default_rng([int(seed), 0xD0A1])
    d_min = 0.6 * np.sqrt(pad.size_x_m * pad.size_y_m / M)  # estimate: zones of comparable size (no slivers)
    seeds = np.empty((0, 2))
    while len(seeds) < M:  # dart throwing with a minimum distance; relaxed if the film is crowded
        for _ in range(200):
            c = (rng.random(2) - 0.5) * [pad.size_x_m, pad.size_y_m]
            if not len(seeds) or np.min(np.linalg.norm(seeds - c, axis=1)) >= d_min:
                break
        else:
            d_min *= 0.8
        seeds = np.vstack([seeds, c])
    levels = -np.log1p(f.domain_spread * rng.permutation(np.linspace(-1.0, 1.0, M)))
    res = f.field_resolution_m
    nx = max(int(round(pad.size_x_m / res)), pad.taxels_x)
    ny = max(int(round(pad.size_y_m / res)), pad.taxels_y)
    gx = (np.arange(nx) + 0.5) / nx * pad.size_x_m - pad.size_x_m / 2
    gy = (np.arange(ny) + 0.5) / ny * pad.size_y_m - pad.size_y_m / 2
    X, Y = np.meshgrid(gx, gy)
    dom = np.argmin((X.ravel()[:, None] - seeds[None, :, 0]) ** 2 + (Y.ravel()[:, None] - seeds[None, :, 1]) ** 2, axis=1)
    ix = (np.arange(nx) * pad.taxels_x) // nx
    iy = (np.arange(ny) * pad.taxels_y) // ny
    flat = (iy[:, None] * pad.taxels_x + ix[None, :]).ravel()
    counts = np.bincount(flat, minlength=n)
    cell = np.bincount(flat, weights=levels[dom], minlength=n) / counts
    xy = taxel_xy(cfg)
    centre = np.argmin(((xy[:, None, :] - seeds[None]) ** 2).sum(-1), axis=1)
    return cell, centre


def unit_index(xy: np.ndarray, cfg: SceneConfig) -> np.ndarray:
    """Calibration unit (iy * units_x + ix, int16) of positions [..., 2] (m) on the sensor's unit grid; -1 where NaN.
    The GPU path makes the same in its frame-sums kernel (sensors/velostat/kernels.py velostat_frame_sums)."""
    s, pad = cfg.sensor, cfg.pad
    ok = np.isfinite(xy).all(-1)
    z = np.nan_to_num(xy)
    ix = np.clip(((z[..., 0] / pad.size_x_m + 0.5) * s.units_x).astype(int), 0, s.units_x - 1)
    iy = np.clip(((z[..., 1] / pad.size_y_m + 0.5) * s.units_y).astype(int), 0, s.units_y - 1)
    return np.where(ok, iy * s.units_x + ix, -1).astype(np.int16)


def taxel_xy(cfg: SceneConfig) -> np.ndarray:
    from sensors.taxels import taxel_xy_m  # geometry helper (numpy only)

    return taxel_xy_m(cfg)


def film_params(cfg: SceneConfig, z_g: np.ndarray, z_c: np.ndarray, level: np.ndarray | None = None) -> FilmParams:
    f, c = cfg.sensor.film, cfg.sensor.creep
    area = cfg.pad.size_x_m * cfg.pad.size_y_m / cfg.pad.n_taxels
    g_area = 1.0 / (f.resistance_at_ref_ohm * 1e-4)  # S/m^2 at p_ref
    dt = 1.0 / cfg.sampling.sample_rate_hz
    taus = np.asarray(c.times_s, float)
    aging = dict(model="aging", dt_s=dt, renewal_pa=c.renewal_pressure_pa, cutoff_s=c.cutoff_time_s,
                 recovery_decay=float(np.exp(-dt / c.recovery_time_s))) if c.model == "aging" else {}
    return FilmParams(
        g_ref_s=g_area * area * np.exp(f.conductance_spread * z_g + (0.0 if level is None else level)),
        creep_drive=c.amplitude * c.saturation_pressure_pa * np.exp(f.creep_spread * z_c),
        p_ref_pa=f.reference_pressure_pa,
        p_c_pa=c.saturation_pressure_pa,
        exponent=f.exponent,
        decay=np.exp(-dt / taus),
        weight=np.full(len(taus), 1.0 / len(taus)),
        **aging,
    )


def readout_params(cfg: SceneConfig, xy: np.ndarray) -> ReadoutParams:
    """Per-taxel ITO geometry. Top sheet: busbars X-/X+ at x = -/+ Lx/2; bottom sheet: Y-/Y+ at y = -/+ Ly/2.

    Force path: X- busbar, top sheet to x, film, bottom sheet to the Y- busbar: R_s (x + Lx/2) / Ly +
    R_s (y + Ly/2) / Lx + leads. 4-wire X phase: the top sheet carries V = V_d u (u = x / Lx + 1/2), Thevenin
    resistance R_s (Lx / Ly) u (1 - u), probed through the bottom sheet to Y-; Y phase likewise.
    5-wire: the bottom sheet is driven from its corners for both phases (residual pincushion `five_wire_bow`:
    V = V_d (1/2 + (x / Lx)(1 - bow (1 - (2 y / Ly)^2)))), the top sheet is the probe (R_s / 2 to its contact).
    """
    r = cfg.sensor.readout
    lx, ly = cfg.pad.size_x_m, cfg.pad.size_y_m
    x, y = xy[:, 0], xy[:, 1]
    rs, rl = r.sheet_resistance_ohm, r.lead_resistance_ohm
    u, v = x / lx + 0.5, y / ly + 0.5
    r_force = rs * u * lx / ly + rs * v * ly / lx + rl
    th_x = rs * (lx / ly) * u * (1 - u)
    th_y = rs * (ly / lx) * v * (1 - v)
    if r.position_wiring == "4-wire":
        v_x, v_y = r.drive_v * u, r.drive_v * v
        r_x = th_x + rs * v * ly / lx + rl
        r_y = th_y + rs * u * lx / ly + rl
    else:
        b = r.five_wire_bow
        v_x = r.drive_v * (0.5 + (x / lx) * (1 - b * (1 - (2 * y / ly) ** 2)))
        v_y = r.drive_v * (0.5 + (y / ly) * (1 - b * (1 - (2 * x / lx) ** 2)))
        r_x = th_x + 0.5 * rs + rl
        r_y = th_y + 0.5 * rs + rl
    return ReadoutParams(
        r_force_ohm=r_force, v_x=v_x, r_x_ohm=r_x, v_y=v_y, r_y_ohm=r_y, current_a=r.current_a,
        compliance_v=r.compliance_v, input_resistance_ohm=r.input_resistance_ohm, drive_v=r.drive_v,
        adc_bits=r.sample_bits, adc_range_v=r.adc_range_v, size_x_m=lx, size_y_m=ly, x_sign=1.0,
    )


class VelostatSensor:
    """Batched Velostat sensor. Shapes: E episodes, T samples, N taxels; 3 ADC channels (force, X, Y)."""

    family = "velostat"
    outputs = OUTPUTS
    device_load = True  # run_load takes taxel fields left on the device (LoadBatch, GPU path; warp backend)

    def __init__(self, cfg: SceneConfig, backend: str = "warp", device: str = "cpu"):
        device = resolve_backend(backend, device)
        self.cfg, self.backend, self.device = cfg, backend, device
        f = cfg.sensor.film
        self.film_seed = int(cfg.generation.root_seed if f.field_seed is None else f.field_seed)
        self.z_g, self.z_c = film_field(cfg, self.film_seed)
        self.domain_level, self.domain = film_domains(cfg, self.film_seed)
        self.xy = taxel_xy(cfg)
        self.area = cfg.pad.size_x_m * cfg.pad.size_y_m / cfg.pad.n_taxels
        self.fp = film_params(cfg, self.z_g, self.z_c, self.domain_level)
        self.rp = readout_params(cfg, self.xy)
        self.n_taxels = cfg.pad.n_taxels

    def noise(self, seeds: list[int], n_steps: int) -> np.ndarray:
        sd = self.cfg.sensor.readout.sample_noise_v  # per reported sample (the conversions averaged)
        return np.stack(
            [np.random.default_rng([int(s), 1]).standard_normal((n_steps, 3)) * sd for s in seeds]
        ).astype(np.float32)

    def run_load(self, load: LoadBatch, seeds: list[int]) -> dict[str, np.ndarray]:
        if load.fields_on_device and self.backend == "warp":
            return self.run_device(load.pressure_pa, seeds, load.target.shape)
        return self.run(load.on_host().pressure_pa, seeds)

    def run_device(self, pressure, seeds: list[int], frames: tuple[int, int]) -> dict[str, np.ndarray]:
        """The GPU path of `run`: pressure a float64 Warp array (E T, N) on this sensor's device (the load field
        left there); the film input, force and contact centroid are made there (`velostat_frame_sums`), the film
        and readout run on it, and only the (E, T, <= 3) outputs come back. Same outputs as `run` on the same
        field: bit for bit but force and contact_xy, whose float64 sums run in taxel order instead of numpy's
        pairwise order (float32 rounding of the same float64 values)."""
        import warp as wp

        from sensors.velostat.kernels import (
            frame_sums_device,
            run_film_device,
            run_readout_device,
        )
        from sensors.warp_setup import scratch, to_host

        E, T = frames
        N = pressure.shape[1]
        if N != self.n_taxels:
            raise ValueError(f"pressure has {N} taxels; the pad has {self.n_taxels}")
        if len(seeds) != E:
            raise ValueError(f"need one seed per episode ({E}); got {len(seeds)}")
        dev = self.device
        size = E * T * N
        p32, sums, unit = frame_sums_device(pressure, self.xy, self.area, scratch("velostat p32", size, wp.float32, dev),
                                            units=self.unit_grid())
        cond, _ = run_film_device(p32, (E, T, N), self.fp, dev, out=scratch("velostat cond", size, wp.float32, dev))
        ro = run_readout_device(cond, (E, T, N), self.noise(seeds, T), self.rp, dev)
        s = to_host(sums, "velostat sums").reshape(E, T, 3)
        # the unit index made on the device: the host's pass over the centroids ran ~10x slower in the GPU feed's
        # driver than alone (each numpy step waits for the interpreter its threads hold; bench/probe_unit_of.py)
        return self._outputs(s[..., 0], s[..., 1:], ro, to_host(unit, "velostat unit").reshape(E, T))

    def conductance(self, pressure: np.ndarray) -> np.ndarray:
        """pressure [E,T,N] -> film conductance [E,T,N] (S) by the selected backend."""
        if self.backend == "numpy":
            return film_chain_numpy(np.asarray(pressure, np.float32), self.fp)[0]
        from sensors.velostat.kernels import run_film_warp

        return run_film_warp(pressure, self.fp, self.device)[0]

    def run(self, pressure: np.ndarray, seeds: list[int]) -> dict[str, np.ndarray]:
        """pressure [E,T,N] (Pa) -> outputs (see OUTPUTS), each [E, T, ...]."""
        E, T, N = pressure.shape
        if N != self.n_taxels:
            raise ValueError(f"pressure has {N} taxels; the pad has {self.n_taxels}")
        if len(seeds) != E:
            raise ValueError(f"need one seed per episode ({E}); got {len(seeds)}")
        noise = self.noise(seeds, T)
        cond = self.conductance(pressure)
        if self.backend == "numpy":
            ro = readout_numpy(cond, noise, self.rp)
        else:
            from sensors.velostat.kernels import run_readout_warp

            ro = run_readout_warp(cond, noise, self.rp, self.device)
        fz, cxy = force_centroid_numpy(pressure, self.xy, self.area)
        return self._outputs(fz, cxy, ro)

    def _outputs(self, fz: np.ndarray, cxy: np.ndarray, ro: dict[str, np.ndarray],
                 unit: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """force [E,T] (N), contact centroid [E,T,2] (m) and the readout's arrays -> OUTPUTS, each [E, T, ...];
        unit: the calibration unit index [E,T] where made already (the device path), else unit_of(cxy)."""
        out = {
            "force": fz.astype(np.float32),
            "contact_xy": cxy.astype(np.float32),
            "unit": self.unit_of(cxy) if unit is None else np.array(unit, np.int16),
        }
        out.update(ro)
        out["adc"] = out["adc"].astype(np.int16 if self.rp.adc_bits <= 15 else np.int32)
        out.pop("touch")
        return out

    def unit_grid(self) -> tuple[float, float, int, int]:
        """(pad size x, y (m), calibration units along x, y): the grid `unit_of` reads positions on."""
        s, pad = self.cfg.sensor, self.cfg.pad
        return float(pad.size_x_m), float(pad.size_y_m), int(s.units_x), int(s.units_y)

    def unit_of(self, xy: np.ndarray) -> np.ndarray:
        """Calibration unit index (iy * units_x + ix) of positions [..., 2]; -1 for NaN (`unit_index`)."""
        return unit_index(xy, self.cfg)

    def attrs(self) -> dict:
        r = self.cfg.sensor.readout
        return {
            "family": self.family,
            "paper": "velostat",
            "sample_rate_hz": self.cfg.sampling.sample_rate_hz,
            "adc_bits": r.sample_bits,  # of a reported sample's code
            "adc_range_v": r.adc_range_v,
            "adc_oversampling": r.oversampling,
            "noise_v_per_sample": r.sample_noise_v,
            "adc_channels": "force,x,y",
            "n_taxels": self.n_taxels,
            "taxel_area_m2": self.area,
            "units_x": self.cfg.sensor.units_x,
            "units_y": self.cfg.sensor.units_y,
            "film_seed": self.film_seed,
            "current_a": r.current_a,
            "compliance_v": r.compliance_v,
            "position_wiring": r.position_wiring,
            "control": self.cfg.protocol.control,
            "field_conductance_log": self.z_g * self.cfg.sensor.film.conductance_spread + self.domain_level,
            "film_domain": self.domain,
            "field_creep_log": self.z_c * self.cfg.sensor.film.creep_spread,
        }
