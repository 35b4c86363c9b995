"""Protocol kind "element_loads": the paper's ntype experiment (Wang & Song 2021, sect. 3.2).

Every sample, each of the 36 elements carries its own static 3-D force with F_x, F_y, F_z in
[amplitude_min, amplitude_max] (the paper: [0, 4.8] N, "36-dimensional force vector" per sample, eq. 14 averages
the relative error over all 36 elements of each sample, so all are loaded). What the paper does not say is an
estimate: the components are drawn independently and uniformly (no friction limit: a bonded probe per element
transmits shear without a normal force); a new load is applied at every frame (one frame per sample, held a
sample period before the reading); the probes are flat squares of indenter.size_x_m x size_y_m centred on the
elements (simulate/contact/element_loads.py turns them into the load field).
"""

from __future__ import annotations

import dataclasses

import numpy as np

KINDS = ("element_loads",)


def draw(proto, cfg, rng: np.random.Generator):
    """params["forces_n"] [T, M, 3]: the frames' element forces (F_x, F_y, F_z compressive), N."""
    p, el = cfg.protocol, cfg.sensor.element
    n_el = el.n_elements if hasattr(el, "n_elements") else 1
    f = rng.uniform(p.amplitude_min, p.amplitude_max, size=(proto.n_samples, n_el, 3))
    return dataclasses.replace(proto, params={"forces_n": f})


def waveform(proto, cfg, tau: np.ndarray) -> np.ndarray:
    """Mean normal force per element (N) of the frame shown at t = tau + settle."""
    f = np.asarray(proto.params["forces_n"])[..., 2].mean(-1)
    k = np.clip(np.floor((np.asarray(tau, float) + cfg.protocol.settle_s) * cfg.sampling.sample_rate_hz + 1e-9), 0,
                len(f) - 1).astype(int)
    return f[k]


def register(waveforms: dict, drawers: dict) -> None:
    for k in KINDS:
        waveforms[k] = waveform
        drawers[k] = draw
