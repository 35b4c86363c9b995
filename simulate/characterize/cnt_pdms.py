"""Characterization of a sensor preset: hysteresis loops per loading frequency, next to the paper.

For each frequency of the preset's protocol, one centred press at the full-scale amplitude runs through
MuJoCo and the sensor chain; the last cycle is analysed (sensors.analysis) twice: on the resistance the
instrument reports (after bridge, ADC and the causal Butterworth filter) and on the true resistance of
the material (no electronics), so the filter's share of the apparent hysteresis is visible.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes import SceneConfig
from sensors.analysis import LoopMetrics, loop_metrics
from simulate.contact.load_field import run_episodes
from simulate.protocols.indenter import EpisodeProtocol, n_samples_for
from simulate.characterize.report import Report, fmt
from sensors.registry import make_sensor

# cnt_pdms sect. 3.1: max hysteresis error of the uncompensated sensor, % FSO (reported without a frequency;
# the LSTM results of Table 3 are quoted at 0.5 Hz, so we compare at 0.5 Hz).
PAPER_HYSTERESIS_FSO_PCT = {0.5: 12.4}


@dataclass
class CharacterizationRow:
    frequency_hz: float
    measured: LoopMetrics  # on resistance_measured (what the instrument reports)
    material: LoopMetrics  # on the true resistance (no electronics)
    paper_hysteresis_fso_pct: float | None
    cycle: dict[str, np.ndarray]  # last cycle: time_s, displacement_m, force_n, resistance_ohm, resistance_measured_ohm


def characterize_loops(cfg: SceneConfig, seed: int = 0, backend: str = "warp", device: str = "cpu") -> list[CharacterizationRow]:
    if cfg.protocol.kind != "sinusoid":
        raise ValueError("characterize needs protocol.kind=sinusoid (allowed: sinusoid)")
    sensor = make_sensor(cfg, backend, device)
    fs = cfg.sampling.sample_rate_hz
    cycles = max(cfg.protocol.cycles, 2)
    cfg = cfg.model_copy(deep=True)
    cfg.protocol.cycles = cycles
    rows = []
    for f in cfg.protocol.frequencies_hz:
        proto = EpisodeProtocol(
            frequency_hz=f,
            amplitude=cfg.protocol.amplitude_max,
            offset_xy_m=np.zeros(2),
            n_samples=n_samples_for(cfg, f),
            control=cfg.protocol.control,
            kind="sinusoid",
        )
        batch = run_episodes(cfg, [proto], threads=1)
        out = sensor.run_load(batch, [seed])
        n = int(round(fs / f))
        sl = slice(proto.n_samples - n, proto.n_samples)
        drive = batch.target[0, sl]
        force = out["force"][0, sl].astype(np.float64)
        r_meas = out["resistance_measured"][0, sl, 0].astype(np.float64)
        r_true = out["resistance"][0, sl, 0].astype(np.float64)
        rows.append(
            CharacterizationRow(
                frequency_hz=f,
                measured=loop_metrics(force, r_meas, drive, f, fs),
                material=loop_metrics(force, r_true, drive, f, fs),
                paper_hysteresis_fso_pct=PAPER_HYSTERESIS_FSO_PCT.get(f),
                cycle={
                    "time_s": batch.time_s[sl],
                    "displacement_m": drive,
                    "force_n": force,
                    "resistance_ohm": r_true,
                    "resistance_measured_ohm": r_meas,
                },
            )
        )
    return rows


def plot_loops(rows: list[CharacterizationRow], path: str) -> None:
    """Force-resistance loops per frequency, loading and unloading coloured apart (matplotlib, PNG)."""
    from simulate.pictures import plots

    fig, axes = plots.figure(1, len(rows), size=(3.2 * len(rows), 3.2), sharey=True)
    for i, (ax, row) in enumerate(zip(axes[0], rows)):
        c = row.cycle
        dr = c["resistance_measured_ohm"] - c["resistance_measured_ohm"][0]
        plots.hysteresis_loop(
            ax, dr, c["force_n"], c["displacement_m"], xlabel="ΔR measured (Ω)", ylabel="force (N)" if i == 0 else "",
            title=f"{row.frequency_hz:g} Hz: {row.measured.hysteresis_fso_pct:.1f} % FSO", legend=i == 0,
        )
    plots.save(fig, path)


def characterize_cnt_pdms(cfg: SceneConfig, backend: str = "warp", device: str = "cpu") -> Report:
    """cnt_pdms sect. 3.1: hysteresis error, loop area and phase lag per loading frequency."""
    rows = characterize_loops(cfg, backend=backend, device=device)
    cols = ["f (Hz)", "F max (N)", "hysteresis % FSO", "paper % FSO", "loop area", "phase lag (deg)",
            "material only % FSO", "material lag (deg)"]
    table = [
        [f"{r.frequency_hz:g}", fmt(r.measured.force_max_n, 2), fmt(r.measured.hysteresis_fso_pct),
         fmt(r.paper_hysteresis_fso_pct), fmt(r.measured.loop_area_norm, 3), fmt(r.measured.phase_lag_deg),
         fmt(r.material.hysteresis_fso_pct), fmt(r.material.phase_lag_deg)]
        for r in rows
    ]
    return Report(
        title=f"{cfg.name}: uncompensated hysteresis (last of {max(cfg.protocol.cycles, 2)} cycles, full-scale press)",
        columns=cols,
        rows=table,
        notes=[
            "measured = resistance after bridge, 14-bit ADC and the causal 4th-order 10 Hz Butterworth (about 40 ms "
            "delay); material only = the true resistance of the pad. Loop area is normalised to the loop's spans."
        ],
        metrics={
            f"{r.frequency_hz:g}Hz": {
                "hysteresis_fso_pct": r.measured.hysteresis_fso_pct, "loop_area": r.measured.loop_area_norm,
                "phase_lag_deg": r.measured.phase_lag_deg, "material_hysteresis_fso_pct": r.material.hysteresis_fso_pct,
                "paper_hysteresis_fso_pct": r.paper_hysteresis_fso_pct,
            }
            for r in rows
        },
        plot=lambda path: plot_loops(rows, path),
    )
