"""CNT-PDMS soft tactile sensor (paper key cnt_pdms): the whole transduction chain over (episode x taxel).

Pipeline (ground truth and measurement both kept, as in Genesis' sensors):
  drive [E,T,N] (strain from the deformation field, or pressure)  -> taxel chain (sensors/taxel_*.py):
  strain, stress, conductance per taxel -> columns in parallel per channel + total force (label, from the
  viscoelastic stress) -> bridge, in-amp, noise, ADC, Butterworth (sensors/electronics.py): causal in the readout kernel, or
  zero-phase over the recorded episode (sensor.electronics.filter_mode, default "zero_phase": cnt_pdms sect. 2.2).
Every episode starts from a fresh sample (network damage D = 0, all states at rest): a recording session after
the sample has rested for many Mullins recovery times (sensor.mullins.recovery_time_s).
backend "warp" runs the Warp kernels on `device` ("cpu" or "cuda:0"); backend "numpy" runs the reference.
"""

from __future__ import annotations

import numpy as np

from scenes.config import SceneConfig
from sensors import electronics as el
from sensors.base import ChannelSpec, LoadBatch, resolve_backend
from sensors.cnt_pdms.params import MODE_DISPLACEMENT, MODE_FORCE, electronics_params, taxel_params
from sensors.cnt_pdms.reference import TaxelState, taxel_chain_numpy


OUTPUTS: dict[str, ChannelSpec] = {
    "strain": ChannelSpec("1", ("time", "taxel"), "compressive strain per taxel (ground truth)"),
    "force_taxel": ChannelSpec("N", ("time", "taxel"), "viscoelastic stress x taxel area (ground truth)"),
    "force": ChannelSpec("N", ("time",), "total normal force from the viscoelastic stress (reference label)"),
    "resistance": ChannelSpec("ohm", ("time", "channel"), "true sensor resistance (taxel columns in parallel)"),
    "bridge_v": ChannelSpec("V", ("time", "channel"), "noise-free Wheatstone bridge output"),
    "adc": ChannelSpec("counts", ("time", "channel"), "ADC codes of the amplified, noisy bridge voltage"),
    "voltage": ChannelSpec("V", ("time", "channel"), "ADC voltage after the digital Butterworth filter"),
    "resistance_measured": ChannelSpec("ohm", ("time", "channel"), "resistance inferred from the filtered voltage"),
}


# The pad's channel sum fused into the taxel kernel on CUDA (sensors/cnt_pdms/kernels.py: taxel_sum_kernel), also
# where the record keeps per-taxel fields: with its outputs in reused buffers (sensors.warp_setup.scratch) the
# fused chain ran 11.1 ms against 14.2 ms for the plain kernel + tiled sum (H100, 256 x 4096 x 1000,
# bench/results/logs/transduction-h100-s7-fifth.log). False: only records without per-taxel fields.
FUSED_WITH_PER_TAXEL = True


class CntPdmsSensor:
    """Batched CNT-PDMS sensor. Shapes: E episodes, T samples, N taxels, C channels: 1 (whole pad,
    sensor.readout = "pad") or N (one per taxel, "taxel")."""

    family = "cnt_pdms"
    outputs = OUTPUTS
    device_load = True  # run_load takes taxel fields left on the device (LoadBatch, GPU path)

    def __init__(self, cfg: SceneConfig, backend: str = "warp", device: str = "cpu"):
        device = resolve_backend(backend, device)
        self.cfg, self.backend, self.device = cfg, backend, device
        self.tp = taxel_params(cfg)
        self.ep = electronics_params(cfg)
        self.n_taxels = cfg.pad.n_taxels
        per_taxel = cfg.sensor.readout == "taxel"
        self.n_channels = self.n_taxels if per_taxel else 1
        self.taxel_channel = np.arange(self.n_taxels, dtype=np.int32) if per_taxel else np.zeros(self.n_taxels, np.int32)
        self.mode = MODE_FORCE if cfg.protocol.control == "force" else MODE_DISPLACEMENT

    def drive_from_load(self, deformation_m: np.ndarray, pressure_pa: np.ndarray) -> np.ndarray:
        """The chain's input [E,T,N]: strain = deformation / thickness (displacement control) or pressure (force control)."""
        if self.mode == MODE_FORCE:
            return np.ascontiguousarray(pressure_pa, np.float32)
        return np.ascontiguousarray(deformation_m / self.cfg.pad.thickness_m, np.float32)

    def run_load(self, load: LoadBatch, seeds: list[int]) -> dict[str, np.ndarray]:
        if load.fields_on_device and self.backend == "warp":
            from sensors.cnt_pdms.kernels import drive_on_device

            E, T = load.target.shape
            if self.mode == MODE_FORCE:
                drive = drive_on_device(load.pressure_pa, 1.0)
            else:
                drive = drive_on_device(load.deformation_m, self.cfg.pad.thickness_m)
            return self.run(drive, seeds, shape=(E, T, self.n_taxels))
        load = load.on_host()
        return self.run(self.drive_from_load(load.deformation_m, load.pressure_pa), seeds)

    def noise(self, seeds: list[int], n_steps: int) -> np.ndarray:
        """Readout noise [E, T, C] (V): the numpy mirror of what the warp backend draws in its readout kernel."""
        e = self.cfg.sensor.electronics
        return el.readout_noise_batch(seeds, n_steps, self.n_channels, e.white_noise_v, e.pink_noise_v)

    def run(self, drive, seeds: list[int], shape: tuple[int, int, int] | None = None) -> dict[str, np.ndarray]:
        """drive [E,T,N] float32 (numpy, or a flat Warp array on this device with shape=(E, T, N)) -> dict of
        outputs (see OUTPUTS; with generation.record, only those), each [E, T, ...] numpy."""
        E, T, N = shape or drive.shape
        if N != self.n_taxels:
            raise ValueError(f"drive has {N} taxels; the pad has {self.n_taxels}")
        if len(seeds) != E:
            raise ValueError(f"need one seed per episode ({E}); got {len(seeds)}")
        want = set(self.cfg.generation.record or OUTPUTS)  # outputs to return (and copy off the device)
        adc_dtype = np.int16 if self.ep.adc_bits <= 16 else np.int32
        ro_names = {"resistance": "resistance", "bridge_v": "bridge_v", "adc": "adc", "voltage": "filtered_v",
                    "resistance_measured": "resistance_measured"}
        if self.backend == "numpy":
            strain, stress, cond, _ = taxel_chain_numpy(drive, self.mode, self.tp, TaxelState.zeros(E * N, self.tp))
            g, force = el.sum_channels_numpy(cond, stress, self.taxel_channel, self.n_channels, self.tp.taxel_area_m2)
            ro, _ = el.readout_numpy(g, self.noise(seeds, T), self.ep)
            ro = el.zero_phase(ro, self.ep)
        else:
            import warp as wp

            from sensors.cnt_pdms.kernels import WARP_LANES, TaxelChainWarp, scaled_on_device
            from sensors.warp_setup import scratch, to_host

            chain = TaxelChainWarp(self.tp, E, N, self.device)
            d = drive if isinstance(drive, wp.array) else wp.array(np.ascontiguousarray(drive, np.float32).reshape(-1), dtype=wp.float32, device=self.device)
            per_taxel = bool(want & {"strain", "force_taxel"})
            dev = self.device
            size = E * T * N
            if self.n_channels == 1 and wp.get_device(dev).is_cuda and (FUSED_WITH_PER_TAXEL or not per_taxel):
                # whole pad on CUDA: the channel sum fused into the taxel kernel (warp partial sums), and only
                # the per-taxel fields the record keeps are written (issue 16)
                n_parts = -(-N // WARP_LANES) * E * T
                bufs = [scratch("cnt_pdms strain", size, wp.float32, dev), scratch("cnt_pdms stress", size, wp.float32, dev),
                        scratch("cnt_pdms part_g", n_parts, wp.float64, dev), scratch("cnt_pdms part_f", n_parts, wp.float64, dev)]
                s_d, st_d, g_d, f_d = chain.run_pad_device(d, T, self.mode, self.tp.taxel_area_m2,
                                                           write_strain="strain" in want, write_stress="force_taxel" in want,
                                                           outs=bufs)
            else:
                bufs = [scratch(f"cnt_pdms {n}", size, wp.float32, dev) for n in ("strain", "stress", "cond")]
                s_d, st_d, c_d = chain.run_device(d, T, self.mode, bufs)
                g_d, f_d = el.sum_channels_warp(
                    c_d, st_d, self.taxel_channel, self.n_channels, self.tp.taxel_area_m2, (E, T, N), self.device
                )
            keep_ro = {ro_names[k] for k in want if k in ro_names}
            if self.ep.offline_sos is not None and keep_ro & {"filtered_v", "resistance_measured"}:
                keep_ro |= {"filtered_v"}  # the zero-phase pass filters the ADC voltage on the host
            e = self.cfg.sensor.electronics
            noise = el.NoiseSeeds(seeds, e.white_noise_v, e.pink_noise_v)  # drawn in the readout kernel
            ro, _ = el.readout_warp(g_d, (E, T, self.n_channels), noise, self.ep, None, self.device, keep=keep_ro,
                                    adc_dtype=adc_dtype, return_state=False)
            ro = el.zero_phase(ro, self.ep)
            force = to_host(f_d, "cnt_pdms force").reshape(E, T) if "force" in want else None
            strain = to_host(s_d, "cnt_pdms strain").reshape(E, T, N) if "strain" in want else None
            stress = None
            if "force_taxel" in want:  # stress x area on the device: one float32 multiply, as in numpy
                ft = scaled_on_device(st_d, self.tp.taxel_area_m2, scratch("cnt_pdms force_taxel", size, wp.float32, self.device))
                force_taxel = to_host(ft, "cnt_pdms force_taxel").reshape(E, T, N)
        make = {
            "strain": lambda: strain,
            "force_taxel": lambda: force_taxel if stress is None else (stress * np.float32(self.tp.taxel_area_m2)).astype(np.float32),
            "force": lambda: force.astype(np.float32),
            "adc": lambda: ro["adc"].astype(adc_dtype, copy=False),
            **{k: (lambda r=r: ro[r].astype(np.float32)) for k, r in ro_names.items() if k != "adc"},
        }
        return {k: make[k]() for k in OUTPUTS if k in want}

    def attrs(self) -> dict:
        """/sensor attrs for recordings."""
        e = self.cfg.sensor.electronics
        return {
            "family": self.family,
            "paper": "cnt_pdms",
            "sample_rate_hz": self.cfg.sampling.sample_rate_hz,
            "adc_bits": e.adc_bits,
            "adc_range_v": e.adc_range_v,
            "n_taxels": self.n_taxels,
            "n_channels": self.n_channels,
            "taxel_channel": self.taxel_channel,
            "taxel_area_m2": self.tp.taxel_area_m2,
            "bridge_resistance_ohm": self.ep.bridge_resistance_ohm,
            "rest_resistance_ohm": 1.0 / ((self.n_taxels // self.n_channels) / self.tp.rest_resistance_ohm),
            "control": self.cfg.protocol.control,
            "filter_mode": self.ep.filter_mode,  # how voltage / resistance_measured were filtered (zero_phase, causal, off)
        }
