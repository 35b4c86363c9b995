"""Contact stage of protocol kind "element_loads" (the paper's ntype experiment, simulate/protocols/element_loads.py):
every element pressed by its own flat probe centred on it, each probe's force spread uniformly over its footprint
on the taxel grid (a flat punch on a Winkler layer, as simulate/contact/press_stroke.py). Static loads: no
MuJoCo rollout is needed (the frames are settled readings), so the field is written directly.
"""

from __future__ import annotations

import numpy as np

from scenes.config import SceneConfig
from sensors.base import LoadBatch
from sensors.taxels import interval_coverage, taxel_area_m2, taxel_xy_m


def run_element_loads(cfg: SceneConfig, protocols: list, threads: int = 1) -> LoadBatch:
    from sensors.ntype.model import element_centres_m

    n = protocols[0].n_samples
    if any(p.n_samples != n for p in protocols):
        raise ValueError("run_element_loads: all protocols need the same n_samples")
    pad, ind = cfg.pad, cfg.indenter
    F = np.stack([np.asarray(p.params["forces_n"], float) for p in protocols])  # [E, T, M, 3]
    c = element_centres_m(cfg)  # [M, 2]
    cx = interval_coverage(c[:, 0], ind.size_x_m / 2, pad.size_x_m, pad.taxels_x)  # [M, nx]
    cy = interval_coverage(c[:, 1], ind.size_y_m / 2, pad.size_y_m, pad.taxels_y)  # [M, ny]
    cover = (cy[:, :, None] * cx[:, None, :]).reshape(len(c), -1)  # [M, N]
    area = taxel_area_m2(cfg)
    share = cover / (area * cover.sum(1, keepdims=True))  # [M, N] 1/m^2, each row integrates to 1
    pressure = np.einsum("mn,etm->etn", share, F[..., 2], optimize=True)
    shear = np.einsum("mn,etmc->etnc", share, F[..., :2], optimize=True)
    E, T = F.shape[:2]
    t = np.arange(T) / cfg.sampling.sample_rate_hz
    return LoadBatch(
        time_s=t,
        target=F[..., 2].mean(-1),
        indenter_pos_m=np.zeros((E, T, 3)),
        contact_force_n=F.sum(2),
        contact_points=np.full((E, T), F.shape[2], np.int64),
        deformation_m=np.zeros_like(pressure),
        pressure_pa=pressure,
        shear_pa=shear,
        taxel_xy_m=taxel_xy_m(cfg),
        taxel_area_m2=area,
        control=cfg.protocol.control,
    )
