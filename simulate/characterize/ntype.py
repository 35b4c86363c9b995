"""Characterization of the ntype preset, next to the paper (Wang & Song 2021, sect. 2.2-3.3).

1. Pure loads on the centre-left element (a 10 x 10 mm patch, 0 -> 4.8 N of F_z, F_x, F_y alone): each
   column's resistance at 4.8 N and its relative change (signs and magnitudes; paper ranges 16-25 kOhm
   normal, 32-50 kOhm inclined over 0-4.8 N).
2. Crosstalk: a 4.8 N press moved 0, 1, 2, 3, 4 cm away from the element; the element's normal-column
   change relative to the centred press (paper: significant within 1-2 cm, sect. 3.3).
3. MuJoCo: a batch of default press_stroke episodes (our harder task); the shear the stick-slip contact delivers
   against the protocol's target, and the ranges of labels and resistances in that data; the same ranges on the
   paper's experiment (protocol kind element_loads, scenes/ntype_config.py PAPER_PROTOCOL), side by side.
4. Column readings of Figure 1 / eq. 8 (crossed, coplanar, eq8) and sect. 2.3 (decoupled, with its element: no
   filler, rho constant): each column's change under 4.8 N of each component alone, i.e. which component each
   column can observe.
5. Scanned readout: mean deviation of the scanned from the true resistances on the paper-protocol data, and an
   unloaded element's reading change when all others load, per scan scheme (ideal, floating, grounded, feedback).
"""

from __future__ import annotations

import json

import numpy as np

from scenes import SceneConfig
from sensors.base import LoadBatch
from sensors.registry import make_sensor
from sensors.taxels import taxel_area_m2, taxel_xy_m
from simulate.characterize.report import Report, fmt

PAPER = {"normal_kohm": (16.0, 25.0), "inclined_kohm": (32.0, 50.0), "force_range_n": (0.0, 4.8),
         "crosstalk": "significant within 1-2 cm", "rbfnn_err_pct": (2.62, 3.44, 1.82)}


def patch_load(cfg: SceneConfig, centre_xy: np.ndarray, force_n: np.ndarray, n_steps: int = 12) -> LoadBatch:
    """E episodes of a force ramped linearly 0 -> force_n[e] (F_x, F_y, F_z compressive) over n_steps - 2
    samples, spread uniformly over the taxels within 5 mm of centre_xy[e]."""
    xy = taxel_xy_m(cfg)
    A = taxel_area_m2(cfg)
    E = len(force_n)
    ramp = np.clip(np.arange(n_steps) / (n_steps - 2), 0.0, 1.0)
    pressure = np.zeros((E, n_steps, len(xy)))
    shear = np.zeros((E, n_steps, len(xy), 2))
    for e in range(E):
        w = (np.abs(xy - centre_xy[e]).max(1) < 0.005).astype(float)
        w /= w.sum() * A
        pressure[e] = ramp[:, None] * w * force_n[e][2]
        shear[e] = ramp[:, None, None] * w[:, None] * force_n[e][:2]
    fsum = np.stack([shear[..., 0].sum(-1) * A, shear[..., 1].sum(-1) * A, pressure.sum(-1) * A], -1)
    return LoadBatch(
        time_s=np.arange(n_steps) / cfg.sampling.sample_rate_hz, target=fsum[..., 2],
        indenter_pos_m=np.zeros((E, n_steps, 3)), contact_force_n=fsum, contact_points=np.ones((E, n_steps), np.int64),
        deformation_m=np.zeros_like(pressure), pressure_pa=pressure, shear_pa=shear, taxel_xy_m=xy,
        taxel_area_m2=A, control="force",
    )


def pure_and_crosstalk(cfg: SceneConfig, backend: str = "warp", device: str = "cpu") -> dict:
    sensor = make_sensor(cfg, backend, device)
    el = cfg.sensor.element
    m = (el.elements_y // 2) * el.elements_x + el.elements_x // 2 - 1  # an inner element, room on its +x side
    c = sensor.centres[m]
    fmax = PAPER["force_range_n"][1]
    loads = np.array([[0, 0, fmax], [fmax, 0, 0], [0, fmax, 0], [-fmax, 0, 0]], float)
    out = sensor.run_load(patch_load(cfg, np.repeat(c[None], 4, 0), loads), list(range(4)))
    r = out["resistance"][:, -1, m].astype(float)  # [load, column]
    r0 = sensor.p.rest_ohm
    pure = {name: {"r_kohm": (r[i] / 1e3).tolist(), "rel_pct": ((r[i] / r0 - 1) * 100).tolist()}
            for i, name in enumerate(["Fz", "Fx", "Fy", "-Fx"])}
    dists = np.array([0.0, 0.01, 0.02, 0.03, 0.04])
    centres = c[None] + np.stack([dists, np.zeros_like(dists)], 1)
    out = sensor.run_load(patch_load(cfg, centres, np.tile([0.0, 0.0, fmax], (len(dists), 1))), list(range(len(dists))))
    dz = out["resistance"][:, -1, m, 2].astype(float) - r0[2]
    cross = {f"{d * 100:g}cm": float(100 * dz[i] / dz[0]) for i, d in enumerate(dists)}
    return {"element": int(m), "pure": pure, "crosstalk_pct": cross}


def mujoco_dataset_stats(cfg: SceneConfig, episodes: int = 24, backend: str = "warp", device: str = "cpu") -> dict:
    from sensors.data.manifest import episode_seed
    from simulate.contact.load_field import run_episodes
    from simulate.protocols.indenter import make_episode_protocol

    seeds = [episode_seed(cfg.generation.root_seed, k) for k in range(episodes)]
    protos = [make_episode_protocol(cfg, s) for s in seeds]
    batch = run_episodes(cfg, protos, threads=cfg.generation.threads)
    out = make_sensor(cfg, backend, device).run_load(batch, seeds)
    # shear delivered during the hold after the stroke vs the target (min(ratio, 1) mu N per indenter)
    t_hold = np.array([max(i["t_stroke_s"][1] for i in p.params["indenters"]) + 0.1 for p in protos])
    k = np.minimum(np.ceil(t_hold * cfg.sampling.sample_rate_hz).astype(int), batch.time_s.size - 1)
    got = batch.contact_force_n[np.arange(episodes), k, :2]
    want = np.array([np.sum([i["shear_target_n"] for i in p.params["indenters"] if i["active"]], axis=0) for p in protos])
    err = np.abs(got - want).max()
    lab = out["force_element"].reshape(-1, 3)
    res_all = out["resistance"].reshape(-1, 3) / 1e3
    loaded = np.abs(lab).max(1) > 0.5  # element-samples carrying a load (most of the 36 are idle at any time)
    res = res_all[loaded]
    pct = lambda a: (float(np.percentile(a, 1)), float(np.percentile(a, 99)))
    return {
        "episodes": episodes, "samples": int(lab.shape[0] // cfg.sensor.element.n_elements),
        "shear_max_abs_error_n": float(err), "shear_target_max_n": float(np.abs(want).max()),
        "label_range_n": {ax: (float(lab[:, i].min()), float(lab[:, i].max())) for i, ax in enumerate("xyz")},
        "label_corr_loaded": np.corrcoef(lab[loaded].T).round(3).tolist(),
        "r_normal_kohm_p1_p99": pct(res[:, 2]), "r_inclined_kohm_p1_p99": pct(res[:, :2].ravel()),
        "loaded_element_samples": int(loaded.sum()),
        "fraction_inclined_in_paper_range": float(np.mean((res[:, :2] >= 32) & (res[:, :2] <= 50))),
        "fraction_normal_in_paper_range": float(np.mean((res[:, 2] >= 16) & (res[:, 2] <= 25))),
    }


def paper_protocol_stats(cfg: SceneConfig, episodes: int = 10, backend: str = "warp", device: str = "cpu") -> dict:
    """Labels and resistances on the paper's experiment (element_loads), and the scan schemes on the same loads."""
    from scenes.ntype_config import PAPER_PROTOCOL
    from sensors.data.manifest import episode_seed
    from simulate.contact.load_field import run_episodes
    from simulate.protocols.indenter import make_episode_protocol
    c = load_scene_from(cfg, PAPER_PROTOCOL)
    seeds = [episode_seed(c.generation.root_seed, k) for k in range(episodes)]
    batch = run_episodes(c, [make_episode_protocol(c, s) for s in seeds])
    out = make_sensor(c, backend, device).run_load(batch, seeds)
    lab = out["force_element"].reshape(-1, 3)
    res = out["resistance"].reshape(-1, 3) / 1e3
    pct = lambda a: (float(np.percentile(a, 1)), float(np.percentile(a, 99)))
    scans = {}
    from sensors.ntype.scan import scan_apparent

    el, rd = c.sensor.element, c.sensor.readout
    R = out["resistance"].astype(np.float64)
    R0 = np.ones((1, el.n_elements, 3)) * make_sensor(c, "numpy").p.rest_ohm
    R1 = R0 * 0.7
    R1[0, el.n_elements // 2] = R0[0, el.n_elements // 2]
    for sch in ("ideal", "floating", "grounded", "feedback"):
        a = scan_apparent(R, el.elements_x, el.elements_y, sch, rd.drive_v, rd.switch_on_ohm, rd.reference_ohm)
        q0, q1 = (scan_apparent(x, el.elements_x, el.elements_y, sch, rd.drive_v, rd.switch_on_ohm, rd.reference_ohm)[0, el.n_elements // 2]
                  for x in (R0, R1))
        scans[sch] = {"mean_abs_dev_pct": float(100 * np.abs(a / R - 1).mean()),
                      "sneak_pct": float(100 * np.abs(q1 / q0 - 1).max())}
    return {"episodes": episodes, "samples": int(lab.shape[0] // el.n_elements),
            "label_range_n": {ax: (float(lab[:, i].min()), float(lab[:, i].max())) for i, ax in enumerate("xyz")},
            "label_corr": np.corrcoef(lab.T).round(3).tolist(),
            "r_normal_kohm_p1_p99": pct(res[:, 2]), "r_inclined_kohm_p1_p99": pct(res[:, :2].ravel()),
            "scan": scans, "scan_default": rd.scan}


def load_scene_from(cfg: SceneConfig, overrides: list[str]) -> SceneConfig:
    """cfg with dotted overrides applied (the loader's syntax)."""
    from scenes.loader import apply_overrides

    return SceneConfig.model_validate(apply_overrides(json.loads(cfg.model_dump_json()), overrides))


def readings(cfg: SceneConfig) -> dict:
    """Per column reading: each column's relative change (%) under 4.8 N of F_x, F_y, F_z alone (element chain
    without lag or crosstalk: u = K^-1 F, e = N u / l, R = R0 (1 + e)^2 exp(beta e))."""
    from scenes.ntype_config import DECOUPLED_ELEMENT
    from sensors.ntype.model import ntype_params

    out = {}
    for r in ("crossed", "coplanar", "eq8", "decoupled"):  # "decoupled": sect. 2.3's element (DECOUPLED_ELEMENT)
        p = ntype_params(load_scene_from(cfg, DECOUPLED_ELEMENT if r == "decoupled" else [f"sensor.element.reading={r}"]))
        d = {}
        for name, F in (("Fx", [4.8, 0, 0]), ("Fy", [0, 4.8, 0]), ("Fz", [0, 0, -4.8])):
            e = p.normals @ (p.compliance @ np.array(F, float)) / p.lengths_m
            d[name] = (100 * ((1 + e) ** 2 * np.exp(p.beta * e) - 1)).tolist()
        out[r] = d
    return out


def characterize_ntype(cfg: SceneConfig, backend: str = "warp", device: str = "cpu") -> Report:
    pc = pure_and_crosstalk(cfg, backend, device)
    ds = mujoco_dataset_stats(cfg, backend=backend, device=device)
    pp = paper_protocol_stats(cfg, backend=backend, device=device)
    rd = readings(cfg)
    rows = []
    for name in ("Fz", "Fx", "-Fx", "Fy"):
        r, d = pc["pure"][name]["r_kohm"], pc["pure"][name]["rel_pct"]
        rows.append([f"pure {name} 4.8 N", f"{r[0]:.1f} ({d[0]:+.0f}%)", f"{r[1]:.1f} ({d[1]:+.0f}%)",
                     f"{r[2]:.1f} ({d[2]:+.0f}%)", "incl 50->32, normal 25->16"])
    rows.append(["crosstalk 1 / 2 / 3 cm (% of centred ΔR_z)", "", "",
                 " / ".join(fmt(pc["crosstalk_pct"][k]) for k in ("1cm", "2cm", "3cm")), PAPER["crosstalk"]])
    rn, ri = ds["r_normal_kohm_p1_p99"], ds["r_inclined_kohm_p1_p99"]
    rows.append([f"MuJoCo press_stroke data, loaded elements, 1-99 % (kOhm; {ds['samples']} samples)", f"{ri[0]:.1f}-{ri[1]:.1f}",
                 f"{ri[0]:.1f}-{ri[1]:.1f}", f"{rn[0]:.1f}-{rn[1]:.1f}", "32-50 / 32-50 / 16-25"])
    lr = ds["label_range_n"]
    rows.append(["labels F_x / F_y / F_z range (N)", f"{lr['x'][0]:.1f}..{lr['x'][1]:.1f}",
                 f"{lr['y'][0]:.1f}..{lr['y'][1]:.1f}", f"{lr['z'][0]:.1f}..{lr['z'][1]:.1f}", "0..4.8 each"])
    rows.append(["stroke shear |delivered - target| max (N)", "", "", fmt(ds["shear_max_abs_error_n"], 3),
                 f"(targets up to {ds['shear_target_max_n']:.2f} N)"])
    rn, ri = pp["r_normal_kohm_p1_p99"], pp["r_inclined_kohm_p1_p99"]
    rows.append([f"paper's experiment (element_loads), all elements, 1-99 % (kOhm; {pp['samples']} samples)",
                 f"{ri[0]:.1f}-{ri[1]:.1f}", f"{ri[0]:.1f}-{ri[1]:.1f}", f"{rn[0]:.1f}-{rn[1]:.1f}", "32-50 / 32-50 / 16-25"])
    lr = pp["label_range_n"]
    rows.append(["paper's experiment: labels F_x / F_y / F_z range (N)", f"{lr['x'][0]:.1f}..{lr['x'][1]:.1f}",
                 f"{lr['y'][0]:.1f}..{lr['y'][1]:.1f}", f"{lr['z'][0]:.1f}..{lr['z'][1]:.1f}", "0..4.8 each"])
    for r, d in rd.items():
        what = ("sect. 2.3's element: no filler, rho constant" if r == "decoupled"
                else "default" if r == cfg.sensor.element.reading else "alternative")
        rows.append([f"reading '{r}' ({what}): ΔR/R0 (%) under 4.8 N of F_x / F_y / F_z"]
                    + [" / ".join(f"{d[k][j]:+.1f}" for k in ("Fx", "Fy", "Fz")) for j in range(3)]
                    + ["col 3 ~ F_x, col 1 ~ F_y, col 2 ~ F_z; F_z weakly coupled"])
    for sch, v in pp["scan"].items():
        rows.append([f"scan '{sch}'{' (default)' if sch == pp['scan_default'] else ''}: |R_read/R - 1| mean on the paper's "
                     "experiment; an idle element's reading change when all others fall 30 % (%)", "", "",
                     f"{fmt(v['mean_abs_dev_pct'], 2)}; {fmt(v['sneak_pct'], 2)}", "paper: \"scanning the circuit\""])
    return Report(
        title=f"{cfg.name}: N-type element columns, crosstalk and MuJoCo 3-D loads (element {pc['element']})",
        columns=["case", "R_x col 3 (kOhm)", "R_y col 1 (kOhm)", "R_z col 2 (kOhm)", "paper"],
        rows=rows,
        notes=[
            "Column strains from u = K^-1 F (K = sum k_j n_j n_j^T + filler); R = R0 (1+e)^2 exp(beta e). "
            "Shear from a Coulomb stick-slip spring on the MuJoCo indenter path (MuJoCo's soft-contact "
            "friction is a weak drag). The paper's RBFNN errors (E_Fx 2.62 %, E_Fy 3.44 %, E_Fz 1.82 %, "
            "spread 7) belong to the learn/ stage, not reproduced here.",
            f"fraction of samples in the paper's ranges: normal {ds['fraction_normal_in_paper_range']:.2f}, "
            f"inclined {ds['fraction_inclined_in_paper_range']:.2f}; label correlation (loaded elements, x,y,z): "
            f"{ds['label_corr_loaded']}",
        ],
        metrics={"pure_crosstalk": pc, "mujoco": ds, "paper_protocol": pp, "readings": rd, "paper": PAPER},
        plot=lambda path: _plot(cfg, pc, path),
    )


def _plot(cfg: SceneConfig, pc: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(8, 3.2))
    names = ["Fz", "Fx", "-Fx", "Fy"]
    x = np.arange(len(names))
    for j, (lab, col) in enumerate(zip(["R_x (3)", "R_y (1)", "R_z (2)"], ["tab:red", "tab:blue", "tab:green"])):
        a.bar(x + (j - 1) * 0.27, [pc["pure"][n]["rel_pct"][j] for n in names], 0.27, label=lab, color=col)
    a.set_xticks(x, [f"{n} 4.8 N" for n in names])
    a.set_ylabel("ΔR / R0 (%)")
    a.legend(fontsize=8)
    ks = list(pc["crosstalk_pct"])
    b.plot([float(k[:-2]) for k in ks], [pc["crosstalk_pct"][k] for k in ks], "o-")
    b.set_xlabel("load distance from element (cm)")
    b.set_ylabel("ΔR_z / ΔR_z(centred) (%)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
