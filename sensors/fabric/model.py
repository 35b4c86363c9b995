"""Knitted conductive fabric stack (paper key `fabric`: Abdul-Hussain et al., "Modified Nonlinear Hysteresis
Approach of a Tactile Sensor"): EeonTex layers (1, 3, 6, 12) of 1 x 1 cm between silver-thread electrodes,
read by a 2-wire multimeter.

Pipeline (ground truth and measurement both kept):
  pressure field [E,T,N] -> whole-sample-equivalent force per taxel f = N p A_taxel (N) -> taxel chain
  (sensors/fabric/kernels.py, reference sensors/fabric/reference.py): Prony creep -> Prandtl-Ishlinskii play bank
  (return-point memory, slow recovery) -> knit set (per-press, from the episode seed; slow fibre relaxation)
  -> Kirchhoff stack of in-layer resistances and Holm contact
  resistances (Holm, Electric Contacts, 1967) -> taxel columns in parallel + lead resistance (2-wire)
  -> multimeter (autorange, finite counts, a reading every 1/readings_per_s, held between readings).
The multimeter runs in numpy for both backends (integer counts: identical by construction).
"""

from __future__ import annotations

import numpy as np

from sensors.base import ChannelSpec, LoadBatch, resolve_backend
from sensors.fabric.reference import (
    FabricState,
    fabric_chain_numpy,
    fabric_params,
    press_draws,
)

OUTPUTS: dict[str, ChannelSpec] = {
    "force_taxel": ChannelSpec("N", ("time", "taxel"), "applied normal force per taxel (ground truth)"),
    "force": ChannelSpec("N", ("time",), "applied normal force on the sample (reference label)"),
    "load_effective": ChannelSpec("N", ("time", "taxel"), "compaction load after creep, hysteresis and knit set (model state)"),
    "resistance": ChannelSpec("ohm", ("time", "channel"), "true 2-wire resistance: stack + leads"),
    "dmm_counts": ChannelSpec("counts", ("time", "channel"), "multimeter display counts (held between readings)"),
    "dmm_range_ohm": ChannelSpec("ohm", ("time", "channel"), "multimeter range (full scale) of the reading"),
    "resistance_measured": ChannelSpec("ohm", ("time", "channel"), "multimeter reading"),
}


def multimeter_numpy(r_ohm: np.ndarray, seeds: list[int], mm, sample_rate_hz: float) -> dict[str, np.ndarray]:
    """2-wire autoranging multimeter. r_ohm [E, T] (float64) -> counts, range, reading, each [E, T].

    A reading is taken at samples 0, h, 2h, ... (h = round(sample_rate / readings_per_s)) and held until the
    next; it uses the smallest range whose full scale exceeds R (1 + gain_error), resolution = range / counts,
    white noise of noise_counts rms (from the episode seed, stream 1), and clips at counts - 1 on the top range.
    """
    E, T = r_ohm.shape
    hold = max(1, int(round(sample_rate_hz / mm.readings_per_s)))
    ranges = np.asarray(mm.ranges_ohm, np.float64)
    idx = np.arange(0, T, hold)
    r = r_ohm[:, idx] * (1.0 + mm.gain_error)
    ri = np.minimum(np.searchsorted(ranges, r, side="right"), len(ranges) - 1)
    rng_fs = ranges[ri]
    res = rng_fs / mm.counts
    noise = np.stack([np.random.default_rng([s, 1]).standard_normal(len(idx)) for s in seeds]) * mm.noise_counts
    counts = np.clip(np.round(r / res + noise), 0, mm.counts - 1).astype(np.int32)
    k = np.minimum(np.arange(T) // hold, len(idx) - 1)
    return {"counts": counts[:, k], "range": rng_fs[:, k], "reading": (counts * res)[:, k]}


def force_of(load: LoadBatch) -> np.ndarray:
    """Force per taxel [E, T, N] float32 (N) of a load batch: max(pressure, 0) x taxel area."""
    return (np.clip(load.on_host().pressure_pa, 0.0, None) * load.taxel_area_m2).astype(np.float32)


class FabricStream:
    """The sensor chain of E episodes of T samples fed in time chunks, the chain's state carried from one chunk to
    the next (the GPU feed hands each chunk of a long batch of worlds on while the later samples still step);
    `finish` gives what `FabricSensor.run` gives for the whole episodes, bit for bit (run is this with one chunk):
    every output is per sample but the multimeter, which runs on the whole (E, T) resistance at the end."""

    def __init__(self, sensor: FabricSensor, seeds: list[int], n_samples: int):
        self.s, self.seeds, self.T = sensor, list(seeds), int(n_samples)
        E, N = len(seeds), sensor.n_taxels
        self.force_taxel = np.empty((E, self.T, N), np.float32)
        self.x = np.empty((E, self.T, N), np.float32)
        self.r = np.empty((E, self.T))
        draws = press_draws(self.seeds, sensor.p, E)
        if sensor.backend == "numpy":
            self.state, self.draws = None, draws
        else:
            from sensors.fabric.kernels import FabricChainWarp

            self.chain = FabricChainWarp(sensor.p, E, N, sensor.device)
            self.chain.set_draws(draws)

    def feed(self, load: LoadBatch, t0: int) -> None:
        """The load batch of samples t0 .. t0 + its length of the E episodes."""
        self.feed_force(force_of(load), t0)

    def feed_force(self, force_taxel_n: np.ndarray, t0: int) -> None:
        E, T, N = force_taxel_n.shape
        if N != self.s.n_taxels:
            raise ValueError(f"load has {N} taxels; the pad has {self.s.n_taxels}")
        if E != len(self.seeds):
            raise ValueError(f"need one seed per episode ({E}); got {len(self.seeds)}")
        t1 = t0 + T
        drive = np.ascontiguousarray(force_taxel_n * np.float32(N), np.float32)
        if self.s.backend == "numpy":
            x, g, self.state = fabric_chain_numpy(drive, self.s.p, self.state, self.draws)
        else:
            x, g = self.chain.run(drive)
        self.force_taxel[:, t0:t1] = force_taxel_n
        self.x[:, t0:t1] = x
        self.r[:, t0:t1] = 1.0 / g.astype(np.float64).sum(-1) + self.s.cfg.sensor.stack.lead_resistance_ohm

    def finish(self) -> dict[str, np.ndarray]:
        """The outputs (see OUTPUTS) of the whole episodes, each [E, T, ...]."""
        cfg, r, ft = self.s.cfg, self.r, self.force_taxel
        dmm = multimeter_numpy(r, self.seeds, cfg.sensor.multimeter, cfg.sampling.sample_rate_hz)
        return {
            "force_taxel": ft,
            "force": ft.astype(np.float64).sum(-1).astype(np.float32),
            "load_effective": self.x,
            "resistance": r[..., None].astype(np.float32),
            "dmm_counts": dmm["counts"][..., None],
            "dmm_range_ohm": dmm["range"][..., None].astype(np.float32),
            "resistance_measured": dmm["reading"][..., None].astype(np.float32),
        }


class FabricSensor:
    """Batched fabric stack. Shapes: E episodes, T samples, N taxels, C = 1 channel (whole sample)."""

    family = "fabric"
    outputs = OUTPUTS

    def __init__(self, cfg, backend: str = "warp", device: str = "cpu"):
        if cfg.sensor.family != "fabric":
            raise ValueError(f"FabricSensor needs sensor.family=fabric; got {cfg.sensor.family!r}")
        device = resolve_backend(backend, device)
        self.cfg, self.backend, self.device = cfg, backend, device
        self.p = fabric_params(cfg)
        self.n_taxels = cfg.pad.n_taxels
        self.taxel_area_m2 = cfg.pad.size_x_m * cfg.pad.size_y_m / self.n_taxels

    def run_load(self, load: LoadBatch, seeds: list[int]) -> dict[str, np.ndarray]:
        return self.run(force_of(load), seeds)

    def chain(self, load_n: np.ndarray, state: FabricState | None = None,
              seeds: list[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """[E,T,N] whole-sample-equivalent force -> effective load and taxel conductance (backend's kernel);
        seeds (one per episode) draw each press's contact area and knit set (None: the mean press)."""
        draws = press_draws(seeds, self.p, load_n.shape[0])
        if self.backend == "numpy":
            x, g, _ = fabric_chain_numpy(load_n, self.p, state, draws)
            return x, g
        from sensors.fabric.kernels import FabricChainWarp

        ch = FabricChainWarp(self.p, load_n.shape[0], load_n.shape[2], self.device)
        if state is not None:
            ch.reset(state)
        ch.set_draws(draws)
        return ch.run(load_n)

    def run(self, force_taxel_n: np.ndarray, seeds: list[int]) -> dict[str, np.ndarray]:
        """force_taxel_n [E,T,N] (N per taxel) -> outputs (see OUTPUTS), each [E, T, ...]."""
        E, T, N = force_taxel_n.shape
        st = self.stream(seeds, T)
        st.feed_force(force_taxel_n, 0)
        return st.finish()

    def stream(self, seeds: list[int], n_samples: int) -> FabricStream:
        """The chain over E = len(seeds) episodes of n_samples, fed in time chunks (`FabricStream`)."""
        return FabricStream(self, seeds, n_samples)

    def attrs(self) -> dict:
        s = self.cfg.sensor
        return {
            "family": self.family,
            "paper": "fabric",
            "layers": s.layers,
            "sample_rate_hz": self.cfg.sampling.sample_rate_hz,
            "n_taxels": self.n_taxels,
            "n_channels": 1,
            "taxel_area_m2": self.taxel_area_m2,
            "multimeter_counts": s.multimeter.counts,
            "multimeter_ranges_ohm": np.asarray(s.multimeter.ranges_ohm),
            "multimeter_readings_per_s": s.multimeter.readings_per_s,
            "lead_resistance_ohm": s.stack.lead_resistance_ohm,
            "control": self.cfg.protocol.control,
        }
