"""Protocol kind "element_loads": the paper's ntype experiment (Wang & Song 2021, sect. 3.2).

Every sample, each of the 36 elements carries its own static 3-D force with F_x, F_y, F_z in
[amplitude_min, amplitude_max] (the paper: [0, 4.8] N, "36-dimensional force vector" per sample, eq. 14 averages
the relative error over all 36 elements of each sample, so all are loaded). What the paper does not say is an
estimate: the components are drawn independently (no friction limit: a bonded probe per element transmits shear
without a normal force); a new load is applied at every frame (one frame per sample, held a sample period before
the reading); the probes are flat squares of indenter.size_x_m x size_y_m centred on the elements
(simulate/contact/element_loads.py turns them into the load field).

How each component is drawn on the range (protocol.force_distribution):
  "uniform"  U[amplitude_min, amplitude_max]: the paper's task default. Estimate: the paper states only the
             range. Its own numbers fit it (ntype eq. 14, Table 2, Figs. 6-8): eq. 14 divides each component's
             error by its true F (not by the range) over all s x 36 components, so the MAE / E ratio (0.60 /
             1.11 / 0.55 N for F_x / F_y / F_z) is a harmonic-type mean of F, not its arithmetic mean, whenever
             the absolute error does not scale with F - and it does not: Table 2's absolute errors spread
             0.8x their mean (0.0171 / 0.0203 N F_x) while Figs. 6-8's relative errors spread 2-10x theirs
             (0.2247 / 0.034), the heavy tail of a few near-zero F. Over 180 components of U[0, 4.8] N with
             Table 2's absolute errors the ratio falls in 0.16-1.21 N (5-95 %, median 0.72 N), the paper's
             three inside; a draw whose arithmetic mean is 0.6 N (Beta(1, 7) x 4.8 N) gives 0.02-0.20 N, none
             inside (learn/experiments/ntype.py implied_force_band, in the experiment's findings).
  "beta"     amplitude_min + (amplitude_max - amplitude_min) x Beta(force_beta_alpha, force_beta_beta): components
             skewed to small forces (mean alpha / (alpha + beta) of the range; the defaults alpha = 1, beta = 7 put it at 0.6 N on
             [0, 4.8] N, the paper's ratio read as an arithmetic mean). Kept available, not the default.
"""

from __future__ import annotations

import dataclasses

import numpy as np

KINDS = ("element_loads",)


def draw_components(p, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Force components (N) on [p.amplitude_min, p.amplitude_max] per p.force_distribution (module docstring)."""
    lo, hi = float(p.amplitude_min), float(p.amplitude_max)
    kind = getattr(p, "force_distribution", "uniform")
    if kind == "uniform":
        return rng.uniform(lo, hi, size=shape)
    if kind == "beta":
        return lo + (hi - lo) * rng.beta(float(p.force_beta_alpha), float(p.force_beta_beta), size=shape)
    raise ValueError(f"protocol.force_distribution: unknown {kind!r} (uniform, beta)")


def component_mean_n(p) -> float:
    """Expected value (N) of one drawn component under p.force_distribution."""
    lo, hi = float(p.amplitude_min), float(p.amplitude_max)
    if getattr(p, "force_distribution", "uniform") == "beta":
        a, b = float(p.force_beta_alpha), float(p.force_beta_beta)
        return lo + (hi - lo) * a / (a + b)
    return 0.5 * (lo + hi)


def draw(proto, cfg, rng: np.random.Generator):
    """params["forces_n"] [T, M, 3]: the frames' element forces (F_x, F_y, F_z compressive), N."""
    p, el = cfg.protocol, cfg.sensor.element
    n_el = el.n_elements if hasattr(el, "n_elements") else 1
    f = draw_components(p, rng, (proto.n_samples, n_el, 3))
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
