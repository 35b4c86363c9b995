"""The fabric paper's numbers and the calibration of the stack law to its fitted curves (paper key `fabric`).

PAPER_CURVES: eqs. 6-9, R (kOhm in the paper, read as kOhm; see scenes/fabric_config.py) as polynomials of
F (N), with the fitted range and the monotone range inside it (the polynomials turn upward past it:
non-physical; eq. 8 past 9.09 N, eq. 9 past 7.54 N). They are calibration targets, not the model.
`fit_stack` fits the stack law's parameters so that the *simulated loading branch* (x at the readings,
after creep and hysteresis) lands on a paper curve; `fit_set_fraction` fits the knit set's mean fraction
(sensor.press.set_fraction_mean) so that the 1-layer max hysteresis error by the paper's definition (referenced
to the highest output value, sect. 3.3) of the mean loop over repeated cycles (the paper averages 5 repeats;
we average 32 for the expectation) is 24.2 %; the presets hold both. `piezotwin calibrate fabric` runs `run`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from sensors.calibration import root_in_bracket

if TYPE_CHECKING:
    from sensors.calibration import CalibrationResult

KOHM = 1e3  # the paper's resistance unit (not printed in the paper)  # estimate


@dataclass(frozen=True)
class PaperCurve:
    layers: int
    coeffs: tuple[float, ...]  # highest power first (numpy.poly1d order), R in kOhm
    fitted_range_n: float
    monotone_range_n: float
    samples: int
    equation: str

    def r_ohm(self, f_n) -> np.ndarray:
        return np.poly1d(self.coeffs)(np.asarray(f_n, float)) * KOHM


PAPER_CURVES: dict[int, PaperCurve] = {
    1: PaperCurve(1, (-0.2366, 1.3822, -2.9373, 3.1703), 2.0, 2.0, 41, "eq. 6"),
    3: PaperCurve(3, (0.0108, -0.259, 2.3599, -10.21, 19.765), 8.0, 8.0, 90, "eq. 7"),
    6: PaperCurve(6, (0.0125, -0.3329, 3.3176, -15.345, 30.41), 15.0, 9.09, 142, "eq. 8"),
    12: PaperCurve(12, (0.0056, -0.2296, 3.431, -22.182, 54.944), 20.0, 7.54, 240, "eq. 9"),
}
PAPER_HYSTERESIS_FSO_PCT = {1: 24.2}  # fabric abstract and sect. 3.3: max hysteresis error, 1 layer, "referenced to the highest output value"
HYSTERESIS_BAND_PCT = (20.5, 28.0)  # our acceptance band around the paper's 24.2 % (issue 13)
PAPER_REPEATS = 5  # fabric sect. 3.3: "the average output ... after repeating each cycle five times"
REPEAT_SEEDS = list(range(PAPER_REPEATS))  # episode seeds of the paper's 5 repeats (characterization)
# The per-press knit set is random, so the average of 5 repeats scatters (+- ~15 % of its value); the fit and
# the characterization's headline use the mean loop of many repeats (the expectation the paper's 5 estimate).
MEAN_REPEAT_SEEDS = list(range(32))
PAPER_COMPENSATED_FSO_PCT = {1: 13.5}  # after the BP network (not simulated here)
PAPER_FORCE_RANGES_N = {  # fabric sect. 3.3
    1: [2.0, 1.27, 1.0, 1.96, 0.5, 1.7],
    3: [2.8, 4.0, 6.0, 8.0],
}

STACK_FIELDS = ("layer_r_inf_ohm", "layer_r_amp_ohm", "layer_force_n", "layer_beta", "contact_r0_ohm",
                "contact_force_n", "contact_exponent")


def fit_stack(x_n: np.ndarray, target_ohm: np.ndarray, layers: int, lead_ohm: float, x0: dict | None = None) -> dict:
    """Least squares (relative to the target's span) of the stack law at effective loads x_n to target_ohm - lead.
    Returns {field: value} for scenes.fabric_config.FabricStackConfig."""
    from scipy.optimize import least_squares

    from sensors.fabric.reference import FabricParams, stack_resistance

    span = float(np.ptp(target_ohm))
    r0 = float(target_ohm[0])
    n_el = 2 * layers + 1
    start = x0 or {}
    p0 = np.array([
        start.get("layer_r_inf_ohm", 0.05 * r0 / n_el), start.get("layer_r_amp_ohm", 0.5 * r0 / layers),
        start.get("layer_force_n", 0.3 * float(x_n.max())), start.get("layer_beta", 1.0),
        start.get("contact_r0_ohm", 0.5 * r0 / (layers + 1)), start.get("contact_force_n", 0.1 * float(x_n.max())),
        start.get("contact_exponent", 0.45),
    ])
    lo = np.array([0.0, 0.0, 1e-3, 0.3, 0.0, 1e-4, 0.33])
    hi = np.array([np.inf, np.inf, 1e3, 4.0, np.inf, 1e3, 0.5])
    base = FabricParams(0.1, 1, layers, np.ones(1), np.zeros(1), np.zeros(1), np.zeros(1), 1.0, *p0)

    def resid(v):
        p = replace(base, **dict(zip(STACK_FIELDS, v)))
        return (stack_resistance(x_n, p) + lead_ohm - target_ohm) / span

    sol = least_squares(resid, np.clip(p0, lo + 1e-9, hi - 1e-9), bounds=(lo, hi), x_scale="jac", max_nfev=20000)
    return {k: float(v) for k, v in zip(STACK_FIELDS, sol.x)}


# characterization series per layer count: the paper's ranges (1 and 3 layers), the full range first so the
# loading branch starts from the virgin state; 6 and 12 layers: estimate (the paper gives only the full range)
CHARACTERIZATION_SERIES_N = {
    1: [2.0, 1.27, 1.0, 1.96, 0.5, 1.7],
    3: [8.0, 2.8, 4.0, 6.0],
    6: [15.0, 5.0, 9.0, 12.0],
    12: [20.0, 7.0, 12.0, 16.0],
}


def characterization_series(cfg) -> list[float]:
    p = cfg.protocol
    if p.stair_return_points_n:
        return list(p.stair_return_points_n)
    s = CHARACTERIZATION_SERIES_N.get(cfg.sensor.layers)
    if s and abs(max(s) - p.amplitude_max) < 1e-9:
        return s
    return [p.amplitude_max * k for k in (1.0, 0.35, 0.6, 0.85)]


def loading_levels(f_max: float, step: float) -> np.ndarray:
    """0, step, 2 step, ..., f_max (f_max last even off the grid)."""
    n = int(np.ceil(f_max / step - 1e-9))
    return np.append(np.arange(n) * step, f_max)


def loading_branch_x(cfg, f_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Force levels of a virgin 0 -> f_max staircase and the effective load x at each reading (end of its
    dwell), through the chain's creep and hysteresis (numpy reference; the stack law does not feed back)."""
    from sensors.fabric.reference import fabric_chain_numpy, fabric_params

    p = fabric_params(cfg)
    levels = loading_levels(f_max, cfg.protocol.stair_step_n)
    dwell = int(round(cfg.protocol.stair_dwell_s * cfg.sampling.sample_rate_hz))
    f = np.repeat(levels, dwell).astype(np.float32)[None, :, None]
    x, _, _ = fabric_chain_numpy(f, replace(p, n_taxels=1))
    return levels, x[0, dwell - 1 :: dwell, 0].astype(np.float64)


def cycle_gap(levels: np.ndarray, r: np.ndarray) -> dict:
    """One 0 -> peak -> 0 cycle of readings: max |R_up - R_down| at equal nominal force over the highest output
    (the paper's definition, sect. 3.3) and over the output span (%)."""
    k = int(np.argmax(levels))
    up = {round(float(f), 6): v for f, v in zip(levels[: k + 1], r[: k + 1])}
    gaps = [abs(up[round(float(f), 6)] - v) for f, v in zip(levels[k:], r[k:]) if round(float(f), 6) in up]
    g = max(gaps)
    return {"hysteresis_of_max_pct": 100 * g / float(r.max()), "hysteresis_fso_pct": 100 * g / float(np.ptp(r)),
            "gap_ohm": float(g)}


def repeat_readings(cfg, peaks: list[float], seeds: list[int] = REPEAT_SEEDS) -> tuple[np.ndarray, np.ndarray]:
    """The characterization series (0 -> p1 -> 0 -> p2 ...) repeated once per seed through the chain (numpy, no
    MuJoCo, true resistance): levels [L] and the readings at the end of each dwell [len(seeds), L] (ohm)."""
    from sensors.fabric.reference import fabric_chain_numpy, fabric_params, press_draws

    p = replace(fabric_params(cfg), n_taxels=1)
    levels = [0.0]
    for v in peaks:  # 0 -> peak -> 0 on the step grid, the peak itself even off the grid (as the protocol)
        up = list(loading_levels(float(v), cfg.protocol.stair_step_n)[1:])
        levels += up + up[::-1][1:] + [0.0]
    levels = np.round(np.asarray(levels), 9)
    dwell = int(round(cfg.protocol.stair_dwell_s * cfg.sampling.sample_rate_hz))
    f = np.repeat(levels, dwell).astype(np.float32)[None, :, None].repeat(len(seeds), 0)
    _, g, _ = fabric_chain_numpy(f, p, None, press_draws(seeds, p))
    r = 1.0 / g[:, dwell - 1 :: dwell, 0].astype(np.float64) + cfg.sensor.stack.lead_resistance_ohm
    return levels, r


def repeat_hysteresis(cfg, seeds: list[int] = MEAN_REPEAT_SEEDS) -> dict:
    """Max hysteresis error of the full-range cycle (the first) of the average over repeats (one per seed), as
    the paper reports it (it averages 5)."""
    peaks = characterization_series(cfg)
    levels, r = repeat_readings(cfg, peaks[:1], seeds)
    return cycle_gap(levels, r.mean(0))


def fit_set_fraction(cfg, target_pct: float) -> float:
    """sensor.press.set_fraction_mean that gives target_pct (paper's definition) on the mean loop of repeats."""
    def h(v):
        c = cfg.model_copy(deep=True)
        c.sensor.press.set_fraction_mean = float(v)
        return repeat_hysteresis(c)["hysteresis_of_max_pct"] - target_pct

    return root_in_bracket(h, 0.0, 1.0, xtol=1e-5)


def calibrate(cfg) -> dict:
    """Fitted stack-law fields for this preset's layer count, against the paper curve inside its monotone range."""
    curve = PAPER_CURVES[cfg.sensor.layers]
    levels, x = loading_branch_x(cfg, curve.monotone_range_n)
    return fit_stack(x, curve.r_ohm(levels), cfg.sensor.layers, cfg.sensor.stack.lead_resistance_ohm)


EQUATION = {1: 6, 3: 7, 6: 8, 12: 9}  # fabric eqs. 6-9, one per layer count


def _with(cfg, stack: dict | None = None, set_mean: float | None = None):
    c = cfg.model_copy(deep=True)
    for k, v in (stack or {}).items():
        setattr(c.sensor.stack, k, float(v))
    if set_mean is not None:
        c.sensor.press.set_fraction_mean = float(set_mean)
    return c


def run() -> CalibrationResult:
    """1 layer: alternate the stack-law fit (eq. 6) and the knit set's mean fraction (24.2 % by the paper's
    definition, 5-repeat average) until both hold; the set fraction is a property of the fabric, so 3, 6 and
    12 layers take the 1-layer value and fit their stack laws to eqs. 7-9. Rows: rms error of each fitted
    curve against the paper's inside its monotone range (% of its span), and the 1-layer hysteresis."""
    from scenes import load_scene
    from scenes.loader import PRESET_DIR
    from sensors.calibration import CalibrationResult, TargetRow
    from sensors.fabric.reference import fabric_params, stack_resistance

    res = CalibrationResult("fabric")
    cfg1 = load_scene(Path(PRESET_DIR) / "fabric_1.yaml")
    set_mean = cfg1.sensor.press.set_fraction_mean
    for _ in range(3):  # the stack law and the set fraction depend on each other a little
        fit1 = calibrate(_with(cfg1, set_mean=set_mean))
        set_mean = fit_set_fraction(_with(cfg1, fit1), PAPER_HYSTERESIS_FSO_PCT[1])
    h1 = repeat_hysteresis(_with(cfg1, fit1, set_mean))
    lo, hi = HYSTERESIS_BAND_PCT
    res.rows.append(TargetRow("1 layer: max hysteresis, % of highest output (paper's def.; mean loop of 32 repeats), paper 24.2",
                              f"{lo:g}-{hi:g}", h1["hysteresis_of_max_pct"], "%", bool(lo <= h1["hysteresis_of_max_pct"] <= hi)))
    res.rows.append(TargetRow("  same, % of output span (ours)", "-", h1["hysteresis_fso_pct"], "%", None))
    h5 = repeat_hysteresis(_with(cfg1, fit1, set_mean), REPEAT_SEEDS)
    res.rows.append(TargetRow("  same, % of highest output, average of the paper's 5 repeats (seeds 0-4)", "-",
                              h5["hysteresis_of_max_pct"], "%", None))
    res.notes.append(f"knit set fraction (mean of the per-press Beta) fitted on 1 layer: {set_mean:.4g}; "
                     "3, 6 and 12 layers take the same (same fabric)")
    for n in sorted(PAPER_CURVES):
        path = Path(PRESET_DIR) / f"fabric_{n}.yaml"
        cfg = _with(load_scene(path), set_mean=set_mean)
        fit = fit1 if n == 1 else calibrate(cfg)
        curve = PAPER_CURVES[n]
        levels, x = loading_branch_x(cfg, curve.monotone_range_n)
        target = curve.r_ohm(levels)
        model = stack_resistance(x, replace(fabric_params(cfg), **fit)) + cfg.sensor.stack.lead_resistance_ohm
        span = float(np.ptp(target)) or 1.0
        rms = float(np.sqrt(np.mean((model - target) ** 2)) / span * 100.0)
        res.rows.append(TargetRow(f"{n} layer(s): stack law vs eq. {EQUATION[n]} (rms, % of span)", "<= 2", rms, "%", rms <= 2.0))
        res.preset_fields[str(path)] = {f"sensor.stack.{k}": (v if v > 1e-6 else 0.0) for k, v in fit.items()}
        res.preset_fields[str(path)]["sensor.press.set_fraction_mean"] = float(set_mean)
    return res


def main() -> None:  # pragma: no cover - rewrites the presets' `stack:` lines
    import re

    for path, fields in run().preset_fields.items():
        fit = {k.rsplit(".", 1)[1]: v for k, v in fields.items() if k.startswith("sensor.stack.")}
        line = "  stack: {" + ", ".join(f"{k}: {v:.6g}" for k, v in fit.items()) + "}  # fit: piezotwin calibrate fabric --write"
        p = Path(path)
        p.write_text(re.sub(r"^  stack: .*$", line, p.read_text(), count=1, flags=re.MULTILINE))
        print(p.name, fit)


if __name__ == "__main__":  # pragma: no cover
    main()
