"""Characterization of the `velostat` preset next to the paper (paper key `velostat`).

Experiments (force control, compression tester protocols of simulate/protocols/compression_tester.py):
  creep vs force   presses of 1-15 N at the centre E, 3 mm/min, 30 s hold (Fig. 3a); the resistance at the
                   end of each ramp is the static calibration R(F) (the paper: creep during loading negligible)
  creep vs speed   3 N at E at 1-6 mm/min, 30 s hold (Fig. 5)
  creep error      a 7 N press held 30 s and a 1-7 N staircase (5 s per step, then 30 s at 7 N; Fig. 22a),
                   read through the static calibration: the uncompensated force error (paper: up to 5 N)
  clustering       the 36-unit grid, 1-15 N on each unit; Ward linkage (scipy) of the units' R(F) curves
                   (eqs. 10-13); elbow of the merge distance vs number of groups (paper: about 5, Fig. 12)
  position         4-wire and 5-wire decoding error vs force at the 36 unit centres (paper: max 3 mm)
  two contacts     decoded position of two simultaneous presses vs the conductance-weighted mean
load="mujoco" runs every episode through MuJoCo (simulate.contact.load_field.run_episodes); load="ideal" uses the
commanded force with the same load-field distribution (fast; for tests).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from scenes import SceneConfig
from sensors.base import LoadBatch
from sensors.calibration import root_in_bracket
from sensors.registry import make_sensor
from simulate.characterize.report import Report, fmt
from simulate.protocols.compression_tester import (
    knots_staircase,
    knots_steps,
    ramp_s,
    site_xy_m,
    unit_centres_m,
)
from simulate.protocols.indenter import EpisodeProtocol, target_waveform

if TYPE_CHECKING:
    from sensors.calibration import CalibrationResult

PAPER = {
    "creep_error_7n_n": 5.0,  # sect. 5.4: "the maximum error is up to 5 N after loading to 7 N"
    "groups": 5,  # sect. 4.1, Fig. 12
    "position_error_max_mm": 3.0,  # sect. 4.1
    "silhouette": 0.931,  # sect. 3.2 (creep-stage clustering; not reproduced here)
}
MM_PER_MIN = 1e-3 / 60.0


def _proto(cfg: SceneConfig, t, f, xy, duration_s: float) -> EpisodeProtocol:
    n = int(round((cfg.protocol.settle_s + duration_s) * cfg.sampling.sample_rate_hz))
    return EpisodeProtocol(
        frequency_hz=0.1, amplitude=float(max(f)), offset_xy_m=np.asarray(xy, float), n_samples=n, control="force",
        kind="velostat_steps", params={"knots_t_s": list(map(float, t)), "knots_f_n": list(map(float, f))},
    )


def ideal_load(cfg: SceneConfig, protos: list[EpisodeProtocol]) -> LoadBatch:
    """The commanded force at the commanded position, spread by simulate.contact.load_field (no MuJoCo)."""
    from sensors.taxels import taxel_area_m2, taxel_xy_m
    from simulate.contact.load_field import load_field
    from simulate.contact.mjcf import contact_design

    n = protos[0].n_samples
    t = np.arange(n) / cfg.sampling.sample_rate_hz
    F = np.stack([target_waveform(p, cfg, t) for p in protos])
    k = contact_design(cfg).pad_stiffness_n_per_m
    pos = np.zeros((len(protos), n, 3))
    pos[..., :2] = np.stack([p.offset_xy_m for p in protos])[:, None, :]
    pos[..., 2] = -F / k
    force = np.zeros_like(pos)
    force[..., 2] = F
    deform, pressure, shear = load_field(cfg, pos, force)
    return LoadBatch(t, F, pos, force, (F > 0).astype(np.int64), deform, pressure, shear, taxel_xy_m(cfg),
                     taxel_area_m2(cfg), "force")


def run(cfg: SceneConfig, sensor, protos: list[EpisodeProtocol], load: str, seed: int = 0):
    if load == "ideal":
        batch = ideal_load(cfg, protos)
    else:
        from simulate.contact.load_field import run_episodes

        batch = run_episodes(cfg, protos, threads=cfg.generation.threads)
    return batch, sensor.run_load(batch, [seed + i for i in range(len(protos))])


def _idx(cfg, t_s: float) -> int:
    return int(round((cfg.protocol.settle_s + t_s) * cfg.sampling.sample_rate_hz))


def elbow(heights: np.ndarray, kmax: int = 15) -> int:
    """Number of groups at the elbow of the merge distance D(k) (distance of the merge that leaves k groups),
    k = 1..kmax: the point farthest below the chord from (1, D(1)) to (kmax, D(kmax)) (kneedle)."""
    h = np.sort(np.asarray(heights))[::-1]  # h[0] merges 2 -> 1 group
    k = np.arange(1, kmax + 1)
    d = h[: kmax]
    x = (k - 1) / (kmax - 1)
    y = (d - d[-1]) / max(d[0] - d[-1], 1e-12)
    return int(k[np.argmax((1 - x) - y)])


def smooth(r: np.ndarray, cfg: SceneConfig, window_s: float = 1.0) -> np.ndarray:
    """Moving average over window_s (valid part): the error is read on the signal, not on one noise spike."""
    w = max(1, int(round(window_s * cfg.sampling.sample_rate_hz)))
    return np.convolve(r, np.ones(w) / w, mode="valid") if len(r) >= w else r


def calibration(levels: np.ndarray, r_levels: np.ndarray):
    """Static calibration F(R) by log-log interpolation of the resistance at the end of each ramp."""
    lr, lf = np.log(r_levels[::-1]), np.log(levels[::-1])

    def f_of_r(r):
        return np.exp(np.interp(np.log(np.asarray(r, float)), lr, lf, left=lf[0], right=lf[-1]))

    return f_of_r


def creep_series(cfg: SceneConfig, sensor, load: str, speeds: bool = True) -> dict:
    """The creep experiments at the centre E: presses of 1-15 N at 3 mm/min held 30 s (Fig. 3a; the R at the end
    of each ramp is the static calibration), 3 N at 1-6 mm/min held 30 s (Fig. 5; speeds=False skips it), and a
    1-7 N staircase, 5 s per step, then 30 s at 7 N (Fig. 22a), read through the static calibration."""
    v3 = 3 * MM_PER_MIN
    E = site_xy_m(cfg, "E")
    hold = 30.0
    # --- creep vs force + static calibration (presses at E, 3 mm/min, 30 s hold)
    levels = np.arange(1.0, 16.0)
    dur = ramp_s(cfg, 15.0, v3) + hold + 1.0
    protos = [_proto(cfg, *knots_steps(cfg, [lv], [hold], [v3], [0.0])[:2], E, dur) for lv in levels]
    _, out = run(cfg, sensor, protos, load)
    r = out["resistance_measured"].astype(float)
    i0 = np.array([_idx(cfg, ramp_s(cfg, lv, v3)) for lv in levels])
    i1 = np.array([_idx(cfg, ramp_s(cfg, lv, v3) + hold) - 1 for lv in levels])
    r_load = r[np.arange(len(levels)), i0]
    r_end = r[np.arange(len(levels)), i1]
    creep_rel = (r_load - r_end) / r_load
    f_of_r = calibration(levels, r_load)
    j7 = 6
    err_hold = float(np.max(f_of_r(smooth(r[j7, i0[j7]: i1[j7] + 1], cfg)) - 7.0))

    speed_rel = r_full = np.full(6, np.nan)
    # --- creep vs loading speed (3 N at E, 1-6 mm/min, 30 s hold)
    if speeds:
        vs = np.arange(1, 7) * MM_PER_MIN
        dur_s = ramp_s(cfg, 3.0, vs[0]) + hold + 1.0
        protos = [_proto(cfg, *knots_steps(cfg, [3.0], [hold], [v], [0.0])[:2], E, dur_s) for v in vs]
        _, out = run(cfg, sensor, protos, load)
        rs = out["resistance_measured"].astype(float)
        a0 = np.array([_idx(cfg, ramp_s(cfg, 3.0, v)) for v in vs])
        a1 = a0 + int(round(hold * cfg.sampling.sample_rate_hz)) - 1
        r_full = rs[np.arange(6), a0]
        speed_rel = (r_full - rs[np.arange(6), a1]) / r_full

    # --- staircase 1-7 N, 5 s per step, then 30 s at 7 N (Fig. 22a)
    t, f = knots_staircase(cfg, np.arange(1.0, 8.0), 5.0, v3, release=False)
    t[-1] += hold - 5.0
    _, out = run(cfg, sensor, [_proto(cfg, t, f, E, t[-1] + 1.0)], load)
    at7 = np.where(out["force"][0] > 6.95)[0]
    err_stair = float(np.max(f_of_r(smooth(out["resistance_measured"][0, at7].astype(float), cfg)) - 7.0))
    return {"levels": levels, "r_load": r_load, "r_end": r_end, "creep_rel": creep_rel, "err_hold": err_hold,
            "err_stair": err_stair, "speed_rel": speed_rel, "r_full": r_full}


def unit_grid(cfg: SceneConfig, sensor, load: str):
    """The 36-unit calibration grid: a 1-15 N staircase (6 mm/min, 2 s per level) on each unit centre, R at the
    end of each ramp [units, 15]; Ward linkage (eqs. 10-13) and its elbow. Returns (R, Z, k_elbow, groups)."""
    from scipy.cluster.hierarchy import fcluster, linkage

    levels = np.arange(1.0, 16.0)
    t, f = knots_staircase(cfg, levels, 2.0, 6 * MM_PER_MIN)
    protos = [_proto(cfg, t, f, xy, t[-1] + 1.0) for xy in unit_centres_m(cfg)]
    _, out = run(cfg, sensor, protos, load)
    ends = [_idx(cfg, t[1 + 2 * i]) for i in range(len(levels))]
    R = out["resistance_measured"][:, ends].astype(float)  # (36, 15)
    Z = linkage(R, method="ward")
    k = elbow(Z[:, 2])
    return R, Z, k, fcluster(Z, k, criterion="maxclust")


def characterize_velostat(cfg: SceneConfig, backend: str = "warp", device: str = "cpu", load: str = "mujoco") -> Report:
    cfg = cfg.model_copy(deep=True)
    sensor = make_sensor(cfg, backend, device)

    cr = creep_series(cfg, sensor, load)
    levels, r_load, r_end, creep_rel = cr["levels"], cr["r_load"], cr["r_end"], cr["creep_rel"]
    err_hold, err_stair, speed_rel, r_full = cr["err_hold"], cr["err_stair"], cr["speed_rel"], cr["r_full"]
    vcal = 6 * MM_PER_MIN

    centres = unit_centres_m(cfg)
    R, Z, k_elbow, groups = unit_grid(cfg, sensor, load)
    spread = float(np.std(np.log(R[:, 6])))

    # --- position error vs force, 4-wire and 5-wire, at the 36 unit centres
    forces = np.array([0.5, 1.0, 2.0, 3.0, 5.0, 7.0, 10.0, 15.0])
    pos_err, pos_decoded = {}, {}
    for wiring in ("4-wire", "5-wire"):
        c2 = cfg.model_copy(deep=True)
        c2.sensor.readout.position_wiring = wiring
        s2 = make_sensor(c2, backend, device)
        protos, truth = [], []
        dur_p = ramp_s(c2, 15.0, vcal) + 2.0
        for F in forces:
            for xy in centres:
                tt, ff = knots_steps(c2, [F], [dur_p], [vcal], [0.0])[:2]
                protos.append(_proto(c2, tt, ff, xy, dur_p))
                truth.append(xy)
        _, out = run(c2, s2, protos, load)
        dec = out["position_measured"][:, -1].astype(float)
        pos_decoded[wiring] = dec.reshape(len(forces), len(centres), 2)
        e = np.linalg.norm(dec - np.asarray(truth), axis=-1) * 1e3
        e = e.reshape(len(forces), len(centres))
        pos_err[wiring] = (np.nanmean(e, axis=1), np.nanmax(e, axis=1))

    # --- two simultaneous contacts (2 N at x = -30 mm, 6 N at x = +30 mm), ideal load fields added
    xa, xb = np.array([-0.03, 0.0]), np.array([0.03, 0.0])
    tt, fa = knots_steps(cfg, [2.0], [5.0], [vcal], [0.0])[:2]
    pa = _proto(cfg, tt, fa, xa, 6.0)
    tt, fb = knots_steps(cfg, [6.0], [5.0], [vcal], [0.0])[:2]
    pb = _proto(cfg, tt, fb, xb, 6.0)
    la, lb = ideal_load(cfg, [pa]), ideal_load(cfg, [pb])
    pr = la.pressure_pa + lb.pressure_pa
    both = sensor.run(pr, [0])
    k = _idx(cfg, ramp_s(cfg, 2.0, vcal) + 2.0)
    g = sensor.conductance(pr)[0, k]
    x_meas = float(both["position_measured"][0, k, 0])
    x_g = float((g * sensor.xy[:, 0]).sum() / g.sum())
    x_f = float((pr[0, k] * sensor.xy[:, 0]).sum() / pr[0, k].sum())

    m = {
        "creep_rel_by_force": {f"{lv:g}N": float(c) for lv, c in zip(levels, creep_rel)},
        "creep_rel_by_speed": {f"{i + 1}mm/min": float(c) for i, c in enumerate(speed_rel)},
        "r_full_load_by_speed_ohm": {f"{i + 1}mm/min": float(c) for i, c in enumerate(r_full)},
        "creep_error_7n_hold_n": err_hold,
        "creep_error_7n_staircase_n": err_stair,
        "cluster_elbow": k_elbow,
        "cluster_sizes": sorted(np.bincount(groups)[1:].tolist(), reverse=True),
        "merge_heights": sorted(Z[:, 2].tolist(), reverse=True)[:12],
        "unit_log_r_std_7n": spread,
        "position_error_mm": {w: {f"{F:g}N": [float(a), float(b)] for F, a, b in zip(forces, *pos_err[w])} for w in pos_err},
        "two_contacts_x_mm": {"measured": x_meas * 1e3, "conductance_weighted": x_g * 1e3, "force_weighted": x_f * 1e3},
        "paper": PAPER,
    }
    rows = [
        ["creep error, 7 N held 30 s (static calibration)", fmt(err_hold, 2) + " N", "up to 5 N (sect. 5.4)"],
        ["creep error, 1-7 N staircase 5 s/step + 30 s", fmt(err_stair, 2) + " N", "up to 5 N (Fig. 22a)"],
        ["relative creep in 30 s: 1 / 3 / 5 / 7 / 15 N",
         " / ".join(f"{100 * creep_rel[i]:.0f}%" for i in (0, 2, 4, 6, 14)), "falls with force (Fig. 3a)"],
        ["relative creep in 30 s at 3 N, 1 / 3 / 6 mm/min",
         " / ".join(f"{100 * speed_rel[i]:.0f}%" for i in (0, 2, 5)), "grows with speed (Fig. 5)"],
        ["R at full load, 3 N, 1 / 6 mm/min", f"{r_full[0]:.0f} / {r_full[5]:.0f} ohm", "about equal (Fig. 5)"],
        ["Ward clustering of 36 units: elbow", f"{k_elbow} groups {m['cluster_sizes']}", "about 5 (Fig. 12)"],
        ["unit-to-unit spread of R at 7 N (std log R)", fmt(spread, 2), "inconsistent (Fig. 19)"],
    ]
    for w in pos_err:
        mean, mx = pos_err[w]
        rows.append([f"position error {w}, mean/max at 0.5 / 1 / 5 / 15 N",
                     " | ".join(f"{mean[i]:.1f}/{mx[i]:.1f}" for i in (0, 1, 4, 7)) + " mm", "max 3 mm (sect. 4.1)"])
    rows.append(["two contacts 2 N @ -30 mm + 6 N @ +30 mm: x", f"{x_meas * 1e3:.1f} mm (G-weighted {x_g * 1e3:.1f})",
                 "conductance-weighted mean"])

    def plot(path: str) -> None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from simulate.pictures.plots import position_error_maps, unit_dendrogram

        fig, ax = plt.subplots(2, 3, figsize=(13, 7.4))
        unit_dendrogram(ax[1, 0], R, Z=Z, n_groups=k_elbow, title=f"36 units, Ward on R(F): {k_elbow} groups")
        sel = [0, len(forces) - 1]
        position_error_maps(ax[1, 1:], centres, pos_decoded["4-wire"][sel], forces[sel],
                            size_m=(cfg.pad.size_x_m, cfg.pad.size_y_m), label="4-wire")
        ax = ax[0]
        ax[0].semilogy(levels, r_load, "o-", label="end of ramp")
        ax[0].semilogy(levels, r_end, "s--", label="after 30 s hold")
        ax[0].set_xlabel("force (N)"), ax[0].set_ylabel("R measured (ohm)"), ax[0].legend()
        for u in range(R.shape[0]):
            ax[1].semilogy(levels, R[u], color=f"C{groups[u] % 10}", lw=0.8)
        ax[1].set_title(f"36 units, Ward: {k_elbow} groups"), ax[1].set_xlabel("force (N)")
        for w, st in zip(pos_err, ("o-", "s--")):
            ax[2].plot(forces, pos_err[w][0], st, label=f"{w} mean")
            ax[2].plot(forces, pos_err[w][1], st, alpha=0.5, label=f"{w} max")
        ax[2].set_xlabel("force (N)"), ax[2].set_ylabel("position error (mm)"), ax[2].legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)

    return Report(
        title=f"{cfg.name}: creep, unit inconsistency and position decoding (load: {load})",
        columns=["quantity", "piezotwin", "paper"],
        rows=rows,
        notes=["static calibration = R at the end of each loading ramp (1-15 N at the centre E, 3 mm/min); "
               "clustering on R at the end of each ramp of a 1-15 N staircase (6 mm/min, 2 s per level) per unit."],
        metrics=m,
        plot=plot,
    )


# ------------------------------------------------------------------------------------------------- calibration
# `piezotwin calibrate velostat [--write]`: the creep runs of the characterization at the centre E with the ideal
# load field (the commanded force through simulate.contact.load_field, no MuJoCo: ~0.3 s per evaluation), numpy
# sensor chain, on the preset's part (film field of root seed 0, the part the experiment calibrates and tests).
# Fitted (1-D root find): sensor.creep.amplitude (aging creep per e-fold of contact age) -> the uncompensated
#   creep error of the 1-7 N staircase, 5 s per step, then 30 s at 7 N, read through the static calibration:
#   PAPER_CREEP_ERROR_N (velostat sect. 5.4, Fig. 22a: "the maximum error is up to 5 N after loading to 7 N").
# Checked, not fitted (the aging law carries them, velostat Fig. 5 and Fig. 3a): R at full load 3 N about equal at
#   1 and 6 mm/min (within FULL_LOAD_TOL); relative creep in a 30 s hold rising with the loading speed 1-6 mm/min
#   and falling with the force 1-15 N (Spearman rank correlation beyond +/- TREND_RANK); the Ward elbow of the 36
#   units on the preset's part and over PARTS film parts (the part field: film.domains Voronoi zones of
#   resistivity 1 -/+ film.domain_spread; an estimate, velostat Fig. 12 finds about 5 groups on its one part).
PAPER_CREEP_ERROR_N = 5.0  # velostat sect. 5.4, Fig. 22a
CREEP_ERROR_BAND_N = (4.5, 5.5)  # our acceptance band around the paper's 5 N ("up to": one reading of one part)
FULL_LOAD_TOL = 0.15  # issue 14: R at full load within 15 % between 1 and 6 mm/min ("approximately equal", Fig. 5)
TREND_RANK = 0.8  # estimate: a trend is "monotone" when its Spearman rank correlation is beyond 0.8
ELBOW_BAND = (4, 6)  # issue 14: the paper's "about 5" groups (Fig. 12)
PARTS = list(range(8))  # film parts (sensor.film.field_seed) over which the Ward elbow is reported


def _spearman(x: np.ndarray, y: np.ndarray) -> float:
    rx, ry = np.argsort(np.argsort(x)), np.argsort(np.argsort(y))
    return float(np.corrcoef(rx, ry)[0, 1])


def _with_amplitude(cfg: SceneConfig, a: float) -> SceneConfig:
    c = cfg.model_copy(deep=True)
    c.sensor.creep.amplitude = float(a)
    return c


def staircase_error(cfg: SceneConfig) -> float:
    """Uncompensated creep error at 7 N of the Fig. 22a staircase (N) through the numpy chain, ideal load."""
    return creep_series(cfg, make_sensor(cfg, "numpy", "cpu"), "ideal", speeds=False)["err_stair"]


def fit_creep_amplitude(cfg: SceneConfig, target_n: float = PAPER_CREEP_ERROR_N) -> float:
    """sensor.creep.amplitude that puts the staircase creep error at target_n (brentq; the error rises with it)."""
    def g(a):
        return staircase_error(_with_amplitude(cfg, a)) - target_n

    return root_in_bracket(g, 0.02, 3.0, xtol=1e-3)


def calibrate(cfg: SceneConfig | None = None, parts: list[int] = PARTS) -> CalibrationResult:
    """Fit sensor.creep.amplitude to the paper's creep error (Fig. 22a) and check the creep trends and the unit
    grouping; rows: targets beside results (see the block comment above)."""
    from scenes import load_scene
    from scenes.loader import PRESET_DIR
    from sensors.calibration import CalibrationResult, TargetRow

    path = f"{PRESET_DIR}/velostat.yaml"
    cfg = load_scene("velostat") if cfg is None else cfg
    before = float(cfg.sensor.creep.amplitude)
    err0 = staircase_error(cfg)
    amp = fit_creep_amplitude(cfg)
    c = _with_amplitude(cfg, amp)
    sensor = make_sensor(c, "numpy", "cpu")
    cr = creep_series(c, sensor, "ideal")
    res = CalibrationResult("velostat")
    lo, hi = CREEP_ERROR_BAND_N
    e = cr["err_stair"]
    res.rows.append(TargetRow("creep error at 7 N, 1-7 N staircase 5 s/step + 30 s (Fig. 22a, paper 'up to 5 N'); "
                              "fits creep.amplitude", f"{lo:g}-{hi:g}", e, "N", bool(lo <= e <= hi)))
    res.rows.append(TargetRow("  creep error at 7 N held 30 s after one ramp (3 mm/min)", "-", cr["err_hold"], "N", None))
    dev = float(abs(cr["r_full"][0] / cr["r_full"][5] - 1.0))
    res.rows.append(TargetRow("R at full load 3 N, |R(1 mm/min) / R(6 mm/min) - 1| (Fig. 5: about equal)",
                              f"<= {100 * FULL_LOAD_TOL:g}", 100 * dev, "%", bool(dev <= FULL_LOAD_TOL)))
    rs = _spearman(np.arange(6), cr["speed_rel"])
    res.rows.append(TargetRow("relative creep in 30 s at 3 N vs speed 1-6 mm/min, rank corr. (Fig. 5: grows)",
                              f">= {TREND_RANK:g}", rs, "", bool(rs >= TREND_RANK)))
    res.rows.append(TargetRow("  relative creep in 30 s at 3 N, 1 mm/min -> 6 mm/min", "-",
                              100 * (cr["speed_rel"][5] - cr["speed_rel"][0]), "% points", None))
    rf = _spearman(cr["levels"], cr["creep_rel"])
    res.rows.append(TargetRow("relative creep in 30 s vs force 1-15 N, rank corr. (Fig. 3a: falls)",
                              f"<= -{TREND_RANK:g}", rf, "", bool(rf <= -TREND_RANK)))
    res.rows.append(TargetRow("  relative creep in 30 s, 1 N -> 15 N", "-",
                              100 * (cr["creep_rel"][-1] - cr["creep_rel"][0]), "% points", None))
    _, _, k0, _ = unit_grid(c, sensor, "ideal")
    elo, ehi = ELBOW_BAND
    res.rows.append(TargetRow("Ward elbow of the 36 units, the preset's part (Fig. 12: about 5)", f"{elo}-{ehi}",
                              float(k0), "groups", bool(elo <= k0 <= ehi)))
    ks = []
    for seed in parts:
        cp = c.model_copy(deep=True)
        cp.sensor.film.field_seed = int(seed)
        ks.append(unit_grid(cp, make_sensor(cp, "numpy", "cpu"), "ideal")[2])
    share = float(np.mean([elo <= k <= ehi for k in ks]))
    res.rows.append(TargetRow(f"  Ward elbow over {len(ks)} film parts (field seeds {parts[0]}-{parts[-1]}), median",
                              f"{elo}-{ehi}", float(np.median(ks)), "groups", bool(elo <= np.median(ks) <= ehi)))
    res.rows.append(TargetRow("  share of those parts with the elbow in the band", "-", 100 * share, "%", None))
    res.notes.append(f"creep.amplitude {before:.4g} -> {amp:.4g} (staircase creep error {err0:.2f} -> {e:.2f} N); "
                     "ideal load field (no MuJoCo), numpy chain, the preset's part (root seed 0)")
    res.notes.append("elbows per part: " + ", ".join(f"{s}: {k}" for s, k in zip(parts, ks))
                     + f"; film.domains {c.sensor.film.domains}, domain_spread {c.sensor.film.domain_spread:g} "
                     "(estimates, not fitted: the elbow follows each part's Voronoi layout more than the contrast)")
    res.preset_fields[path] = {"sensor.creep.amplitude": float(f"{amp:.4g}")}
    return res
