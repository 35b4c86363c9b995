"""Real-to-sim fit of the velostat film model (sensors/velostat/fit.py, `piezotwin fit`)."""

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from piezotwin.cli import app
from scenes import load_scene
from sensors.data.recording import Channel, write_recording
from sensors.velostat import fit as VF
from sensors.velostat.reference import FilmParams, film_chain_numpy

runner = CliRunner()
RATE = 20.0
# known parameters, away from the preset's (exponent 1.05, amplitude 6, p_c 30 kPa, taus 0.5-150 s)
TRUE = dict(gain=0.05, exponent=1.3, amplitude=2.0, p_c_pa=8e4, tau_min_s=1.0, tau_max_s=60.0)


def _presses(seed, T=3000):
    rng = np.random.default_rng(seed)
    f, t = np.zeros(T), 20
    while t < T - 40:
        up, hold, down = rng.integers(4, 40), rng.integers(20, 400), rng.integers(4, 40)
        peak = rng.uniform(1.0, 40.0)
        seg = np.concatenate([np.linspace(0.0, peak, up), np.full(hold, peak), np.linspace(peak, 0.0, down)])[: T - t]
        f[t : t + len(seg)] = seg
        t += len(seg) + int(rng.integers(40, 200))
    return f


def test_fast_forward_matches_numpy_reference():
    cfg = load_scene("velostat")
    fp, m = VF.params_from_config(cfg, gain=1.0)
    f = _presses(0, 600)
    dt = 0.1
    s = VF.forward_reading(f, dt, fp, m)
    film = FilmParams(g_ref_s=np.array([1.0 / m.r_ref_ohm]), creep_drive=np.array([fp.amplitude * fp.p_c_pa]),
                      p_ref_pa=m.p_ref_pa, p_c_pa=fp.p_c_pa, exponent=fp.exponent,
                      decay=np.exp(-dt / np.asarray(fp.times_s)), weight=np.full(fp.n_creep, 1.0 / fp.n_creep))
    g, _ = film_chain_numpy((f / m.area_m2)[None, :, None].astype(np.float32), film)
    on = f > 0
    ref = 1.0 / g[0, on, 0].astype(np.float64) + m.r_series_ohm
    assert np.allclose(s[on], ref, rtol=2e-4)
    assert np.all(np.isinf(s[~on]))


def _recording(tmp: Path, noise: float = 0.005) -> Path:
    cfg = load_scene("velostat")
    _, m = VF.params_from_config(cfg)
    p = VF.FitParams(n_creep=len(cfg.sensor.creep.times_s), **TRUE)
    eps = {}
    for i in range(3):
        f = _presses(i)
        s = VF.forward_reading(f, 1 / RATE, p, m)
        s = np.where(np.isfinite(s), s, 800.0) * np.exp(noise * np.random.default_rng(10 + i).standard_normal(len(f)))
        eps[f"run{i}"] = {"time": Channel(np.arange(len(f)) / RATE, "s", ("time",)),
                          "sensor": Channel(s[:, None], "raw", ("time", "channel")),
                          "force": Channel(f.astype(np.float32), "N", ("time",))}
    return write_recording(tmp / "syn.h5", eps, source="real", config_json="{}", root_seed=None, shard_index=0,
                           sensor_attrs={"family": "velostat", "sample_rate_hz": RATE})


def test_fit_recovers_known_parameters(tmp_path):
    rec = _recording(tmp_path)
    cfg = load_scene("velostat")
    runs = VF.load_runs(rec, rate_hz=RATE)
    fit = VF.fit_recording(cfg, runs)
    a = fit.after
    # stated tolerances: exponent +-0.03, gain +-10 %, creep amplitude +-25 %, p_c and the tau span within x1.5
    assert a.exponent == pytest.approx(TRUE["exponent"], abs=0.03)
    assert a.gain == pytest.approx(TRUE["gain"], rel=0.10)
    assert a.amplitude == pytest.approx(TRUE["amplitude"], rel=0.25)
    for k, v in (("p_c_pa", a.p_c_pa), ("tau_min_s", a.tau_min_s), ("tau_max_s", a.tau_max_s)):
        assert 1 / 1.5 < v / TRUE[k] < 1.5, (k, v)
    assert fit.err_after["rms_log"] < 0.01 < fit.err_before["rms_log"]


def test_fit_cli_writes_loadable_preset_and_rejects_bad_input(tmp_path):
    rec = _recording(tmp_path)
    out = tmp_path / "fit"
    res = runner.invoke(app, ["fit", "velostat", str(rec), "-o", str(out)])
    assert res.exit_code == 0, res.output
    cfg = load_scene(str(out / "velostat_fitted.yaml"))
    assert cfg.sensor.film.exponent == pytest.approx(TRUE["exponent"], abs=0.03)
    assert (out / "fit.png").is_file() and (out / "fit.json").is_file()
    res = runner.invoke(app, ["fit", "cnt_pdms", str(rec), "-o", str(out)])
    assert res.exit_code == 2 and "velostat family only" in res.output
    res = runner.invoke(app, ["fit", "velostat", str(rec), "-o", str(out), "--input", "nope"])
    assert res.exit_code == 2 and "no channel" in res.output
    res = runner.invoke(app, ["fit", "velostat", str(tmp_path / "missing.h5")])
    assert res.exit_code == 2 and "does not exist" in res.output


# ------------------------------------------------------------------ the whole chain (sensors/chain_fit.py)
from dataclasses import replace as _replace

from scenes.randomize import Dist, Randomization, draw
from sensors import chain_fit as CF


def _synthetic_runs(p, n_runs=4, seed=1, fs=1000.0, rate=20.0, low_n=2.0, high_n=30.0):
    """Runs made with known parameters: press sequences through simulate_reading, one level per press."""
    from simulate.generation.chain_gen import press_protocol

    rand = Randomization(press={"peak_force_n": Dist(kind="loguniform", low=low_n, high=high_n),
                                "rise_s": Dist(kind="uniform", low=0.3, high=0.8), "hold_s": Dist(kind="uniform", low=1.0, high=1.5),
                                "fall_s": Dist(kind="fixed", value=0.1), "gap_s": Dist(kind="uniform", low=1.0, high=2.0)})
    rng = np.random.default_rng(seed)
    runs = []
    for k in range(n_runs):
        f, pid = press_protocol(rand, rng, 40.0, 1 / rate)
        lev = rng.normal(0, p.level_log_sd, pid.max() + 1)
        y = CF.simulate_reading(f, 1 / rate, p, level=np.where(pid >= 0, lev[np.maximum(pid, 0)], 0.0), fs=fs, rng=rng)
        runs.append(CF.RealRun(f"run{k}", f, y, 1 / rate, fs, p.noise_sd))
    return runs


def test_chain_fit_recovers_known_parameters():
    true = CF.ChainParams(exponent=1.2, r0_ohm=3000.0, creep_amplitude=2.0, creep_force_n=4.0, tau_min_s=0.1,
                          tau_max_s=5.0, n_creep=4, level_log_sd=0.4, r_ref_ohm=1e4, full_scale=1000.0, noise_sd=0.0)
    runs = _synthetic_runs(true)
    p0 = CF.ChainParams(r_ref_ohm=1e4, full_scale=1000.0, n_creep=4)
    fit = CF.fit_chain(runs, p0, n_boot=3)
    q = fit.params
    assert abs(q.exponent - 1.2) < 0.05
    assert fit.error["rms_log_reading_within_press"] < 0.03
    assert abs(q.level_log_sd - 0.4) < 0.15  # the spread of the presses' levels, from ~50 presses
    # the creep: the simulated plateau drop of the fit equals the true chain's
    ev = CF.evaluate(fit, _synthetic_runs(true, n_runs=4, seed=7))
    d = ev["plateau_drop"]
    assert abs(d["sim_median"] - d["real_median"]) < 0.03
    # a calibrated predictive band: near 90 % of new presses inside, not all of them (an inflated band)
    assert 0.75 <= ev["level_in_band90"] <= 0.97, ev["level_in_band90"]  # 39 presses fit the spread: +-0.05 of it
    half = fit.level_band90[1]
    assert half < 1.645 * 0.4 * 1.3
    # the randomization draws r0 jointly with each replicate, per press the within-run spread, per episode the
    # between-run one (runs of one chain here: small)
    rand = CF.randomization_from_fit(fit, runs)
    assert all("r0_ohm" in b for b in rand.boot)
    assert rand.episode["gain_log"].sd < 0.2
    assert set(fit.ranges) >= {"exponent", "r0_ohm", "level_log_sd"}


def test_divider_taxel_predicts_other_reference_resistor():
    """A fitted ADC divider taxel, told only the new reference resistor, predicts the reading through it."""
    true = CF.ChainParams(exponent=1.5, r0_ohm=2000.0, creep_amplitude=0.3, creep_force_n=1.0, tau_min_s=0.2, tau_max_s=5.0,
                          n_creep=3, r_series_ohm=200.0, r_leak_ohm=4e5, r_ref_ohm=1e4, full_scale=5115.0, level_log_sd=0.05)
    runs = _synthetic_runs(true, n_runs=3)
    for r in runs:
        r.attrs["adc_full_scale"] = 5115.0
    fit = CF.fit_chain(runs, CF.ChainParams(r_ref_ohm=1e4, full_scale=5115.0, n_creep=3, r_series_ohm=50.0), n_boot=0)
    new_true = _replace(true, r_ref_ohm=2.2e3, level_log_sd=0.0)
    new_fit = _replace(fit.params, r_ref_ohm=2.2e3)
    f = runs[0].force
    y_true = CF.simulate_reading(f, runs[0].dt, new_true)
    y_pred = CF.simulate_reading(f, runs[0].dt, new_fit)
    on = f > 1.0
    assert np.sqrt(np.mean(np.log(y_pred[on] / y_true[on]) ** 2)) < 0.1


def test_randomization_draw_is_seeded_and_recorded(tmp_path):
    from sensors.data.recording import Recording
    from simulate.generation.chain_gen import generate_chain

    rand = Randomization(episode={"gain_log": Dist(kind="normal", mean=0, sd=0.3), "tip_area_scale": Dist(kind="uniform", low=0.5, high=2)})
    a, _ = draw(rand, 123)
    b, _ = draw(rand, 123)
    c, _ = draw(rand, 124)
    assert a == b and a != c
    p = CF.ChainParams(r_ref_ohm=1e4, full_scale=1000.0, level_log_sd=0.3)
    f1 = generate_chain(p, rand, tmp_path / "a.h5", n_episodes=2, root_seed=5, duration_s=10)
    f2 = generate_chain(p, rand, tmp_path / "b.h5", n_episodes=2, root_seed=5, duration_s=10)
    with Recording(f1) as r1, Recording(f2) as r2:
        for ep in r1.episode_ids:
            at = r1.episode_attrs(ep)
            assert "seed" in at and "tip_area_scale" in at["randomized"]
            np.testing.assert_array_equal(np.asarray(r1.read(ep, "sensor")), np.asarray(r2.read(ep, "sensor")))


def test_bad_distribution_rejected():
    with pytest.raises(ValueError):
        Dist(kind="uniform", low=2, high=1)


def test_chain_fit_aging_creep_recovers_known_parameters():
    """creep_law "aging" (load-independent ln-conductance creep): the exponent is the across-press force law."""
    true = CF.ChainParams(exponent=0.95, r0_ohm=3000.0, creep_amplitude=0.25, creep_force_n=0.5, tau_min_s=0.1,
                          tau_max_s=3.0, n_creep=4, creep_law="aging", level_log_sd=0.4, r_ref_ohm=1e4,
                          full_scale=1000.0, noise_sd=0.0)
    runs = _synthetic_runs(true, n_runs=3)
    fit = CF.fit_chain(runs, CF.ChainParams(r_ref_ohm=1e4, full_scale=1000.0, n_creep=4, creep_law="aging"), n_boot=0)
    q = fit.params
    assert abs(q.exponent - 0.95) < 0.05, q.exponent
    assert fit.error["rms_log_reading_within_press"] < 0.03
    # the creep over the observed holds (amplitude and tau_max trade off beyond the longest hold)
    d = CF.evaluate(fit, _synthetic_runs(true, n_runs=2, seed=7))["plateau_drop"]
    assert abs(d["sim_median"] - d["real_median"]) < 0.03


def test_chain_fit_level_prior_recovers_known_parameters():
    """Random-effects levels (level_prior): the known chain is still recovered, force law and creep."""
    true = CF.ChainParams(exponent=1.2, r0_ohm=3000.0, creep_amplitude=2.0, creep_force_n=4.0, tau_min_s=0.1,
                          tau_max_s=5.0, n_creep=4, level_log_sd=0.4, r_ref_ohm=1e4, full_scale=1000.0, noise_sd=0.0)
    runs = _synthetic_runs(true, n_runs=3)
    fit = CF.fit_chain(runs, CF.ChainParams(r_ref_ohm=1e4, full_scale=1000.0, n_creep=4), n_boot=0, level_prior=True)
    q = fit.params
    assert abs(q.exponent - 1.2) < 0.05, q.exponent
    assert fit.error["rms_log_reading_within_press"] < 0.03
    assert abs(q.level_log_sd - 0.4) < 0.15
    d = CF.evaluate(fit, _synthetic_runs(true, n_runs=2, seed=7))["plateau_drop"]
    assert abs(d["sim_median"] - d["real_median"]) < 0.03


def _sloped_runs(p, coef, sd, n_runs=4, seed=3, fs=1000.0, rate=20.0):
    """Runs whose presses each have their own sensitivity (chain_gen.press_slopes) as well as their own level."""
    from simulate.generation.chain_gen import press_protocol, press_slopes

    rand = Randomization(press={"peak_force_n": Dist(kind="loguniform", low=2.0, high=30.0),
                                "rise_s": Dist(kind="uniform", low=0.8, high=1.5), "hold_s": Dist(kind="uniform", low=1.0, high=1.5),
                                "fall_s": Dist(kind="fixed", value=0.1), "gap_s": Dist(kind="uniform", low=1.0, high=2.0)})
    rng = np.random.default_rng(seed)
    runs, offsets = [], []
    for k in range(n_runs):
        f, pid = press_protocol(rand, rng, 60.0, 1 / rate)
        lev = rng.normal(0, p.level_log_sd, pid.max() + 1)
        level = np.where(pid >= 0, lev[np.maximum(pid, 0)], 0.0)
        s = press_slopes(f, pid, lev, p, {"slope_level_coef": coef, "slope_press_sd": sd}, rng)
        if s is not None:
            level = level + s[1]
            offsets.append(s[0])
        y = CF.simulate_reading(f, 1 / rate, p, level=level, fs=fs, rng=rng)
        runs.append(CF.RealRun(f"run{k}", f, y, 1 / rate, fs, p.noise_sd))
    return runs, offsets


def test_press_slope_spread_recovers_known_sensitivity_variation():
    """Contact variation: each press's own d ln R / d ln F, correlated with its level; measured on the runs as the
    chain's identification would see them (chain_fit.press_slope_spread), the chain's own spread removed."""
    from simulate.generation.chain_gen import press_slopes

    true = CF.ChainParams(exponent=1.0, r0_ohm=3000.0, creep_amplitude=0.5, creep_force_n=4.0, tau_min_s=0.1,
                          tau_max_s=5.0, n_creep=4, level_log_sd=0.5, r_ref_ohm=1e4, full_scale=1000.0, noise_sd=0.5)
    runs, offs = _sloped_runs(true, coef=0.15, sd=0.12)
    fit = CF.ChainFit(true, {}, [0.0, 0.0], [], {}, [])  # the known chain: this test is about the press statistic
    sp = CF.press_slope_spread(fit, runs)
    assert sp["n_presses"] >= 40
    assert abs(sp["slope_level_coef"] - 0.15) < 0.06, sp
    assert abs(sp["slope_press_sd"] - 0.12) < 0.04, sp
    flat, _ = _sloped_runs(true, coef=0.0, sd=0.0)
    sp0 = CF.press_slope_spread(fit, flat)
    assert sp0["slope_press_sd"] < 0.04 and abs(sp0["slope_level_coef"]) < 0.05, sp0
    # the offsets pivot at each press's peak: its plateau level is unchanged, its ramp is not
    f = np.r_[np.zeros(5), np.linspace(0.5, 10, 20), np.full(10, 10.0), np.zeros(5)]
    pid = np.where(f > 0, 0, -1)
    ds, add = press_slopes(f, pid, np.array([0.0]), true, {"slope_press_sd": 0.2}, np.random.default_rng(0))
    assert np.all(add[f == 10.0] == 0.0) and add[5] == pytest.approx(ds[0] * np.log(0.05))
    assert press_slopes(f, pid, np.array([0.0]), true, {}, np.random.default_rng(0)) is None
    # the randomization records them (fixed per episode) only when asked
    r1 = CF.randomization_from_fit(fit, runs, press_slope=True)
    assert r1.episode["slope_press_sd"].value == pytest.approx(sp["slope_press_sd"])
    assert "slope_press_sd" not in CF.randomization_from_fit(fit, runs).episode


def test_rated_force_widens_the_simulated_presses_to_the_rating_only():
    """The simulated peak forces span the sensor's rated force when the user gives it (the presses the real
    training runs lack), keep the training range where it already covers the rating, and are drawn inside it."""
    from scenes.randomize import Randomization, draw_one
    from simulate.generation.chain_gen import press_protocol

    peaks = [20.6, 21.0, 22.5]  # pike2-like training presses (N)
    d0 = CF.peak_force_dist(peaks)
    assert (d0.low, d0.high) == pytest.approx((10.3, 27.0))
    d = CF.peak_force_dist(peaks, rated_force_n=40.0)
    assert (d.low, d.high) == pytest.approx((CF.RATED_LOW_FRAC * 40.0, 40.0))
    wide = CF.peak_force_dist([0.25, 10.0, 44.5], rated_force_n=40.0)  # pike1-like: already spans the rating
    assert (wide.low, wide.high) == pytest.approx((0.125, 53.4))
    assert CF.peak_force_dist(peaks, rated_force_n=float("nan")).high == pytest.approx(27.0)
    rng = np.random.default_rng(3)
    x = np.log([draw_one(d, rng) for _ in range(4000)])
    # log-uniform: the share above every training press is ln(40 / 22.5) / ln(40 / 2) = 0.19 (none before)
    assert np.mean(x > np.log(max(peaks))) == pytest.approx(np.log(40 / 22.5) / np.log(20), abs=0.02)
    assert x.min() >= np.log(d.low) and x.max() <= np.log(d.high)
    f, pid = press_protocol(Randomization(press={"peak_force_n": d}), np.random.default_rng(0), 600.0, 0.05)
    assert f.max() > 1.2 * max(peaks) and f.max() < 40.0 * 1.1  # the rig's small hold drift on top


def _hier_levels(rng, n_runs, n_press, sd_run, sd_w):
    u = rng.normal(0.0, sd_run, n_runs)
    run_of = np.repeat(np.arange(n_runs), n_press)
    return u[run_of] + rng.normal(0.0, sd_w, len(run_of)), run_of


def test_run_level_sd_recovers_a_known_run_spread_and_falls_back_to_the_prior():
    """Hierarchical press levels l = mu + u_run + e: the run-level sd is recovered from the runs' presses (not the
    std of the run means, which also holds sd_w / sqrt(n)); one run gives the stated prior."""
    rng = np.random.default_rng(11)
    est, means_sd, within = [], [], []
    for _ in range(20):
        lev, run_of = _hier_levels(rng, 14, 15, 0.3, 0.55)  # pike1-like: 14 runs of ~15 presses
        h = CF.run_level_sd(lev, run_of, prior_dof=0.0)
        est.append(h["level_run_sd"])
        means_sd.append(np.std([lev[run_of == r].mean() for r in range(14)], ddof=1))
        within.append(h["level_within_run_sd"])
    assert abs(np.mean(within) - 0.55) < 0.02
    assert abs(np.mean(est) - 0.3) < 0.04, np.mean(est)
    # the variance of the run means holds the within-run part too: 0.3^2 + 0.55^2 / 15 = 0.110
    assert np.mean(np.square(means_sd)) - np.mean(np.square(est)) > 0.01
    lev, run_of = _hier_levels(rng, 14, 15, 0.0, 0.55)
    assert CF.run_level_sd(lev, run_of, prior_dof=0.0)["level_run_sd"] < 0.1
    # with the prior: 13 degrees of freedom outweigh it, one run is the prior, two runs lie between
    one = CF.run_level_sd(rng.normal(0, 0.5, 16), np.zeros(16, int))
    assert one["level_run_sd"] == pytest.approx(CF.RUN_LEVEL_PRIOR_SD) and one["n_runs"] == 1
    two = CF.run_level_sd(np.r_[np.full(8, -1.0), np.full(8, 1.0)] + rng.normal(0, 0.01, 16), np.repeat([0, 1], 8))
    assert CF.RUN_LEVEL_PRIOR_SD < two["level_run_sd"] < two["level_run_sd_anova"]


def test_new_run_band_covers_presses_of_new_runs():
    """The band of a press of a NEW run holds ~90 % of new runs' presses when runs differ; without its run term
    (a press of a run already seen) it holds far fewer. Fitted on 14 runs, scored on 400 new runs."""
    rng = np.random.default_rng(5)
    cov_new, cov_same = [], []
    for _ in range(10):
        lev, run_of = _hier_levels(rng, 14, 15, 0.5, 0.3)
        h = CF.run_level_sd(lev, run_of, prior_dof=0.0)
        half = CF.new_run_band90(h["level_within_run_sd"], h["level_run_sd"], 14, len(lev))
        half_same = CF.new_run_band90(h["level_within_run_sd"], 0.0, 14, len(lev))
        new, _ = _hier_levels(rng, 400, 15, 0.5, 0.3)
        new = new - lev.mean()
        cov_new.append(np.mean(np.abs(new) <= half))
        cov_same.append(np.mean(np.abs(new) <= half_same))
    assert 0.84 <= np.mean(cov_new) <= 0.95, np.mean(cov_new)
    assert np.mean(cov_same) < 0.7, np.mean(cov_same)


def test_chain_fit_records_the_run_level_and_draws_it_per_simulated_run():
    """fit_chain on runs made with a known run-level spread: the fitted preset records sd_run (and its run
    bootstrap range), the band is the new-run band, and run_level=True draws each episode's gain with it."""
    true = CF.ChainParams(exponent=1.2, r0_ohm=3000.0, creep_amplitude=2.0, creep_force_n=4.0, tau_min_s=0.1,
                          tau_max_s=5.0, n_creep=4, level_log_sd=0.2, r_ref_ohm=1e4, full_scale=1000.0, noise_sd=0.0)
    rng = np.random.default_rng(2)
    runs = _synthetic_runs(true, n_runs=8, seed=4)
    u = rng.normal(0.0, 0.6, len(runs))
    for r, uk in zip(runs, u):  # the run's own level: the reading of its film resistance scaled by e^u
        R = CF.resistance_from_reading(r.reading, true, r.fs)
        r.reading = np.where(np.isfinite(R), CF.reading_from_resistance(R * np.exp(uk), true, r.fs), r.reading)
    fit = CF.fit_chain(runs, CF.ChainParams(r_ref_ohm=1e4, full_scale=1000.0, n_creep=4), n_boot=0)
    h = fit.error["level_run_sd"]
    assert abs(fit.params.exponent - 1.2) < 0.05
    assert abs(h["anova"] - np.std(u, ddof=1)) < 0.15, (h, np.std(u, ddof=1))
    assert abs(h["within_run_sd"] - 0.2) < 0.06
    assert fit.params.level_run_log_sd == pytest.approx(h["point"])
    lo, mid, hi = fit.ranges["level_run_sd_run_bootstrap"]
    assert lo <= h["point"] * 1.01 and lo < mid < hi
    assert fit.level_band90[1] == pytest.approx(CF.new_run_band90(h["within_run_sd"], h["point"], 8, fit.error["n_presses"]))
    assert CF.randomization_from_fit(fit, runs, run_level=True).episode["gain_log"].sd == pytest.approx(h["point"])


def test_chain_fit_threshold_and_linear_creep_recover_known_parameters():
    """fit_threshold (F_0 without a series resistance) and creep_linear (Phi = a F): a chain made with a 0.5 N
    threshold and linear creep is recovered (exponent, threshold, hold drop); on a chain without a threshold the
    fitted F_0 stays near 0."""
    true = CF.ChainParams(exponent=1.0, r0_ohm=3000.0, creep_amplitude=1.5, creep_force_n=1e4, tau_min_s=0.1,
                          tau_max_s=3.0, n_creep=4, level_log_sd=0.4, r_ref_ohm=1e4, full_scale=1000.0, noise_sd=0.0,
                          threshold_force_n=0.5)
    runs = _synthetic_runs(true, n_runs=3)
    p0 = CF.ChainParams(r_ref_ohm=1e4, full_scale=1000.0, n_creep=4)
    fit = CF.fit_chain(runs, p0, n_boot=0, level_prior=True, fit_threshold=True, creep_linear=True)
    q = fit.params
    assert abs(q.exponent - 1.0) < 0.05, q.exponent
    assert abs(q.threshold_force_n - 0.5) < 0.1, q.threshold_force_n
    assert q.creep_force_n == pytest.approx(1e4) and q.r_series_ohm == 0.0
    assert fit.error["rms_log_reading_within_press"] < 0.03
    assert "threshold_force_n" in fit.result["names"] and "ln_creep_force_n" not in fit.result["names"]
    d = CF.evaluate(fit, _synthetic_runs(true, n_runs=2, seed=7))["plateau_drop"]
    assert abs(d["sim_median"] - d["real_median"]) < 0.03
    # the default fit holds F_0 at 0 and moves F_c (rounds 1-6)
    assert CF._free(False) == [0, 1, 2, 3, 4] and CF._free(True) == [0, 1, 2, 3, 4, 5, 6]
    none = CF.fit_chain(_synthetic_runs(_replace(true, threshold_force_n=0.0), n_runs=3), p0, n_boot=0, level_prior=True,
                        fit_threshold=True, creep_linear=True)
    assert none.params.threshold_force_n < 0.1, none.params.threshold_force_n


def test_contact_area_term_steepens_the_law_below_its_force_and_is_off_by_default():
    """contact_fraction: R_film / s, s = (F / (F + F_a))^beta; without creep the local law is -(n + beta F_a / (F +
    F_a)): -n - beta / 2 at F = F_a, -> -n far above it; F_a = 0 gives the rounds 1-8 chain bit for bit."""
    p = CF.ChainParams(exponent=0.8, r0_ohm=1000.0, creep_amplitude=1e-3, creep_force_n=1.0, contact_force_n=3.0)
    f = np.array([3.0 / 1.01, 3.0 * 1.01, 300.0 / 1.01, 300.0 * 1.01])
    lr = np.log(CF.film_resistance(f, 0.05, p))
    slope = np.diff(lr)[[0, 2]] / np.log(1.01 ** 2)
    assert slope[0] == pytest.approx(-(0.8 + (2.0 / 3.0) / 2.0), abs=2e-3)
    assert slope[1] == pytest.approx(-(0.8 + (2.0 / 3.0) * 3.0 / 303.0), abs=2e-3)
    off = _replace(p, contact_force_n=0.0)
    g = np.linspace(0.0, 40.0, 801)
    r_off = CF.film_resistance(g, 0.05, off)
    with np.errstate(divide="ignore"):
        ref = np.where(g > 0, off.r0_ohm * ((g + CF.creep_force(g, 0.05, off)) / 1.0) ** (-off.exponent), np.inf)
    assert np.array_equal(r_off, ref) and CF.contact_fraction(g, off) == 1.0
    assert np.isinf(CF.film_resistance(g, 0.05, p)[0])


def _fit_with_term(term: str, value: float, high_n: float, exponent_tol: float):
    """A chain made with one optional term (`term` = value), fitted with that term free on 3 runs of 0.5-high_n N:
    the term and the exponent recovered, a small within-press error, the term's bootstrap range and its draw in
    the randomization. Returns (true chain, prior, runs, fit)."""
    true = CF.ChainParams(exponent=0.8, r0_ohm=3000.0, creep_amplitude=1.0, creep_force_n=10.0, tau_min_s=0.1,
                          tau_max_s=3.0, n_creep=4, level_log_sd=0.3, r_ref_ohm=1e4, full_scale=1000.0, noise_sd=0.0,
                          **{term: value})
    p0 = CF.ChainParams(r_ref_ohm=1e4, full_scale=1000.0, n_creep=4)
    runs = _synthetic_runs(true, n_runs=3, low_n=0.5, high_n=high_n)
    flag = {"contact_force_n": "fit_contact", "tunnel_force_n": "fit_tunnel"}[term]
    fit = CF.fit_chain(runs, p0, n_boot=2, level_prior=True, **{flag: True})
    q = fit.params
    assert abs(np.log(getattr(q, term) / value)) < 0.25, getattr(q, term)
    assert abs(q.exponent - 0.8) < exponent_tol, q.exponent
    assert fit.error["rms_log_reading_within_press"] < 0.03
    assert f"ln_{term}" in fit.result["names"] and term in fit.ranges
    assert all(term in b for b in CF.randomization_from_fit(fit, runs).boot)
    return true, p0, runs, fit


def test_chain_fit_contact_force_recovers_known_parameters():
    """fit_contact: a chain made with F_a = 3 N (runs pressed 0.5-40 N) is recovered (F_a, exponent, within-press
    error, a bootstrap range around it); on a chain without the term the fitted F_a stays small; off (the default)
    F_a is not fitted and stays 0."""
    true, p0, runs, fit = _fit_with_term("contact_force_n", 3.0, 40.0, 0.06)
    # the default fit of the same runs has no term and a flatter law (the exponent takes part of it)
    off = CF.fit_chain(runs, p0, n_boot=0, level_prior=True)
    assert off.params.contact_force_n == 0.0 and "ln_contact_force_n" not in off.result["names"]
    assert off.error["rms_log_reading_within_press"] > fit.error["rms_log_reading_within_press"]
    none = CF.fit_chain(_synthetic_runs(_replace(true, contact_force_n=0.0), n_runs=3, low_n=0.5, high_n=40.0), p0,
                        n_boot=0, level_prior=True, fit_contact=True)
    assert none.params.contact_force_n < 0.3, none.params.contact_force_n


def test_chain_fit_tunnel_force_recovers_known_parameters_and_steepens_the_law():
    """fit_tunnel: a chain made with F_t = 8 N (tunneling: d ln R / d ln F = -(n + F / F_t)) is recovered (F_t,
    exponent, within-press error, a bootstrap range); the default fit of the same runs leaves a larger error; on a
    power-law chain the fitted F_t runs off to large forces (the term switches itself off); F_t = 0 is the power law
    bit for bit."""
    true, p0, runs, fit = _fit_with_term("tunnel_force_n", 8.0, 30.0, 0.1)
    g = np.array([1.0, 10.0, 20.0])
    slope = np.diff(np.log(CF.film_resistance(g, 1e3, _replace(true, creep_amplitude=1e-9)))) / np.diff(np.log(g))
    assert slope[0] > -0.8 - 10.0 / 8.0 * 0.9 and slope[1] < -0.8 - 10.0 / 8.0  # steepens with force
    off = CF.fit_chain(runs, p0, n_boot=0, level_prior=True)
    assert off.params.tunnel_force_n == 0.0 and off.error["rms_log_reading_within_press"] > 2 * fit.error["rms_log_reading_within_press"]
    none = CF.fit_chain(_synthetic_runs(_replace(true, tunnel_force_n=0.0), n_runs=3, low_n=0.5, high_n=30.0), p0,
                        n_boot=0, level_prior=True, fit_tunnel=True)
    assert none.params.tunnel_force_n > 300.0, none.params.tunnel_force_n
    f = np.linspace(0.0, 30.0, 301)
    assert np.array_equal(CF.film_resistance(f, 0.05, _replace(true, tunnel_force_n=0.0)),
                          CF.film_resistance(f, 0.05, _replace(true, tunnel_force_n=0.0, contact_force_n=0.0)))


def test_generation_draws_the_tunnel_force_with_its_replicate_and_scales_it_with_the_tip_area():
    """chain_gen.episode: F_t comes with the bootstrap replicate and scales with the tip's area (F_t = A M /
    (gamma s0): the same strain at the same pressure)."""
    from simulate.generation.chain_gen import episode

    p0 = CF.ChainParams(exponent=0.8, r0_ohm=3000.0, r_ref_ohm=1e4, full_scale=1000.0, tunnel_force_n=1.0)
    rand = Randomization(press={"peak_force_n": Dist(kind="fixed", value=2.0)},
                         episode={"tip_area_scale": Dist(kind="fixed", value=2.0)},
                         boot=[{"exponent": 0.8, "tunnel_force_n": 5.0}])
    _, attrs = episode(p0, rand, 3, 10.0, 0.05)
    assert CF.ChainParams.from_json(attrs["chain"]).tunnel_force_n == 10.0


def test_generation_draws_the_contact_force_with_its_replicate_and_scales_it_with_the_tip_area():
    """chain_gen.episode: F_a comes with the bootstrap replicate (joint with the exponent) and scales with the tip's
    area like F_c (Hertz: the force that makes the contact span the face ~ E* b^3 / R, ~ the area for a scaled tip);
    the simulated reading is the chain's own at that F_a."""
    from simulate.generation.chain_gen import episode

    p0 = CF.ChainParams(exponent=0.8, r0_ohm=3000.0, creep_amplitude=1.0, creep_force_n=10.0, r_ref_ohm=1e4,
                        full_scale=1000.0, contact_force_n=1.0)
    rand = Randomization(press={"peak_force_n": Dist(kind="fixed", value=2.0)},
                         episode={"tip_area_scale": Dist(kind="fixed", value=2.0)},
                         boot=[{"exponent": 0.8, "contact_force_n": 5.0}])
    ch, attrs = episode(p0, rand, 3, 10.0, 0.05)
    q = CF.ChainParams.from_json(attrs["chain"])
    assert q.contact_force_n == pytest.approx(10.0) and q.creep_force_n == pytest.approx(20.0)
    assert attrs["randomized"]["contact_force_n"] == 5.0
    lev = np.zeros(len(ch["force"]))  # level_log_sd 0: every press at level 0
    assert np.allclose(ch["sensor"], np.maximum(CF.simulate_reading(ch["force"], 0.05, q, level=lev, fs=attrs["full_scale"]), 1e-6))
    off = episode(CF.ChainParams(**{**p0.__dict__, "contact_force_n": 0.0}), Randomization(
        press=rand.press, episode=rand.episode, boot=[{"exponent": 0.8}]), 3, 10.0, 0.05)[0]["sensor"]
    assert np.all(off <= ch["sensor"])  # the partial contact raises R (high divider: the reading) at 2 N
    assert np.any(off < ch["sensor"] - 1.0)


def test_press_spread_reads_the_level_spread_at_equal_force_and_counts_misses_apart():
    """press_spread: presses whose level spreads by 0.3 ln read spread by ~0.3 ln of reading at equal force (a
    reading that rises with resistance, R ~ e^l F^-n: ln reading ~ l - n ln F well below the reference); a chain
    drawn with 0.6 ln is ~2x as spread beside it (ratio ~2); presses at the rest level (misses) are counted as
    outliers, not in the sd."""
    base = CF.ChainParams(exponent=1.0, r0_ohm=300.0, creep_amplitude=1e-6, level_log_sd=0.3, r_ref_ohm=1e5,
                          full_scale=1000.0)
    real = [(r.force, r.reading) for r in _synthetic_runs(base, n_runs=6, seed=3)]
    wide = [(r.force, r.reading) for r in _synthetic_runs(_replace(base, level_log_sd=0.6), n_runs=6, seed=4)]
    same = CF.press_spread(real, real)
    assert same["ratio"] == 1.0 and abs(same["real_ln_reading_sd"] - 0.3) < 0.1, same
    sp = CF.press_spread(real, wide)
    assert 1.5 < sp["ratio"] < 2.7 and sp["sim_outlier_share"] == 0.0, sp
    f, y = wide[0]
    missed = [(f, np.where(f > 0.5, 1000.0 * 0.99, y))] + wide[1:]  # the first run's presses never load the film
    mp = CF.press_spread(real, missed)
    assert mp["sim_outlier_share"] > 0.05 and abs(mp["sim_ln_reading_sd"] - sp["sim_ln_reading_sd"]) < 0.15, mp


def _divider_capture(path, divider, adc=True, seed=7, drop=0.0, gap_s=0.0):
    """Four runs of presses of one divider taxel (sim2real's family "divider"), written as `piezotwin import` writes
    an ADC capture; divider "low" = the reference resistor on the ADC side: the reading rises with force."""
    from simulate.generation.chain_gen import press_protocol
    from sensors.data.recording import Channel, write_recording

    p = CF.ChainParams(exponent=1.3, r0_ohm=8000.0, creep_amplitude=0.3, creep_force_n=2.0, tau_min_s=0.2, tau_max_s=5.0,
                       level_log_sd=0.25, r_ref_ohm=1e4, full_scale=4095.0, r_series_ohm=150.0, divider=divider, noise_sd=2.0)
    rand = Randomization(press={"peak_force_n": Dist(kind="loguniform", low=0.3, high=8.0),
                                "rise_s": Dist(kind="uniform", low=0.3, high=0.8), "hold_s": Dist(kind="uniform", low=1.0, high=2.0),
                                "fall_s": Dist(kind="fixed", value=0.2), "gap_s": Dist(kind="uniform", low=1.0, high=2.0)})
    rng = np.random.default_rng(seed)
    eps, attrs = {}, {}
    for k in range(4):
        f, pid = press_protocol(rand, rng, 40.0, 0.01)
        lev = rng.normal(0, p.level_log_sd, pid.max() + 1)
        y = np.clip(np.round(CF.simulate_reading(f, 0.01, p, level=np.where(pid >= 0, lev[np.maximum(pid, 0)], 0.0), rng=rng)), 0, 4095)
        y[np.random.default_rng(seed + k).random(len(y)) < drop] = np.nan  # samples the capture had none of
        y[1000:1000 + int(gap_s / 0.01)] = np.nan
        eps[f"run{k}"] = {"time": Channel(np.arange(len(f)) * 0.01, "s", ("time",), "clock"),
                          "force": Channel(f.astype(np.float32), "N", ("time",), "load cell"),
                          "sensor": Channel(y.astype(np.float32)[:, None], "counts", ("time", "channel"), "ADC")}
        attrs[f"run{k}"] = {"reference_resistor_ohm": 1e4}
    write_recording(path, eps, source="real", config_json="{}", root_seed=0, shard_index=0,
                    sensor_attrs={"family": "divider", "units": "counts", **({"adc_full_scale": 4095} if adc else {})},
                    episode_attrs=attrs)
    return p


@pytest.mark.parametrize("divider", ["high", "low"])
def test_divider_fit_reads_the_reading_direction_from_the_capture(tmp_path, divider):
    """A taxel on either side of its divider (reading falling with force: "high", the Lupasic board and TAMS;
    rising: "low", the FSR's basic circuit) is fitted as sim2real fits it: the direction is read from the capture
    and the chain recovered (the exponent, a within-press error near the ADC's), the same for both wirings.
    Before, every capture was read as "high", and a rising reading gave a within-press error of 8 ln."""
    from learn.sim2real import _chain_prior

    true = _divider_capture(tmp_path / "c.h5", divider)
    runs = CF.load_real_runs(tmp_path / "c.h5", rate_hz=20.0)
    assert CF.reading_direction(runs) == divider
    fit = CF.fit_chain(runs[:3], _chain_prior("divider", runs), n_boot=0)
    assert fit.params.divider == divider and abs(fit.params.exponent - true.exponent) < 0.15, fit.params
    assert fit.error["rms_log_reading_within_press"] < 0.02
    assert CF.evaluate(fit, runs[3:])["rms_log_reading_within_press"] < 0.02


def test_a_rising_reading_without_its_full_scale_is_refused(tmp_path):
    """A reading that rises with force rests at 0, not at its full scale: without adc_full_scale the capture is
    refused with one message naming the attribute."""
    _divider_capture(tmp_path / "c.h5", "low", adc=False)
    with pytest.raises(ValueError, match="adc_full_scale"):
        CF.load_real_runs(tmp_path / "c.h5")


def test_a_channel_of_several_taxels_is_refused_in_one_line(tmp_path):
    """The chain is one taxel's: a reading channel with 3 columns is refused naming the channel and its width (it
    was an IndexError from the resampling)."""
    from sensors.data.recording import Channel, write_recording

    t = np.arange(500) * 0.01
    f = np.clip(5 * np.sin(t), 0, None)
    eps = {"run0": {"time": Channel(t, "s", ("time",), "c"), "force": Channel(f.astype(np.float32), "N", ("time",), "f"),
                    "sensor": Channel(np.stack([1000 / (1 + f)] * 3, 1).astype(np.float32), "counts", ("time", "channel"), "a")}}
    write_recording(tmp_path / "m.h5", eps, source="real", config_json="{}", root_seed=0, shard_index=0,
                    sensor_attrs={"family": "divider"}, episode_attrs={})
    with pytest.raises(ValueError, match=r"channel .sensor. holds 3 readings per sample; the chain is one taxel.s: name one as .sensor\[k\]."):
        CF.load_real_runs(tmp_path / "m.h5")


def test_dropped_samples_are_bridged_and_a_long_gap_cuts_the_episode(tmp_path):
    """A capture with 5 % of its readings missing (NaN, as `piezotwin capture` leaves a stream's dropped samples)
    fits as the whole one does (within-press error, exponent); an episode with a 3 s stretch without a sample is cut
    there and read as two runs (before: 24 % NaN after resampling, and sim2real stopped in its static curve)."""
    from learn.sim2real import _chain_prior

    _divider_capture(tmp_path / "whole.h5", "high")
    _divider_capture(tmp_path / "holed.h5", "high", drop=0.05)
    fits = []
    for name in ("whole", "holed"):
        runs = CF.load_real_runs(tmp_path / f"{name}.h5", rate_hz=20.0)
        assert all(np.isfinite(r.reading).all() and np.isfinite(r.force).all() for r in runs)
        fits.append(CF.fit_chain(runs[:3], _chain_prior("divider", runs), n_boot=0))
    assert fits[1].error["rms_log_reading_within_press"] < 0.02
    assert abs(fits[1].params.exponent - fits[0].params.exponent) < 0.05
    # a 3 s stall: the episode is read as its two parts, each a run, and a glob naming the episode takes both
    from learn.finetune import load_recording
    from sensors.data.resample import key_matches

    _divider_capture(tmp_path / "gap.h5", "high", gap_s=3.0)
    runs = CF.load_real_runs(tmp_path / "gap.h5", rate_hz=20.0)
    assert [r.key for r in runs] == [f"run{k}@{j}" for k in range(4) for j in (1, 2)]  # every run stalls at 10 s
    assert 9.5 < len(runs[0].force) / 20.0 < 10.5 and all(np.isfinite(r.reading).all() for r in runs)
    assert [s.key for s in load_recording(tmp_path / "gap.h5", ["sensor"], ["force"], rate_hz=20.0)] == [r.key for r in runs]
    assert key_matches("run0@2", "run0") and key_matches("run0@2", "run0@*") and not key_matches("run10@1", "run1")
    assert CF.fit_chain(runs[:6], _chain_prior("divider", runs), n_boot=0).error["rms_log_reading_within_press"] < 0.02
    from sensors.velostat.fit import load_runs  # `piezotwin fit velostat` reads the same parts

    assert [r.key for r in load_runs(tmp_path / "gap.h5")] == [r.key for r in runs]


def test_a_board_run_without_an_unloaded_moment_is_refused(tmp_path):
    """A board without a known full scale (the Lupasic kind) reads it from its rest level: a run that is never
    unloaded is refused in one line (it was a NaN full scale and NaN fits)."""
    from sensors.data.recording import Channel, write_recording

    t = np.arange(600) * 0.01
    f = 3.0 + np.sin(t)  # always pressed
    eps = {"run0": {"time": Channel(t, "s", ("time",), "c"), "force": Channel(f, "N", ("time",), "f"),
                    "sensor": Channel((1000 / (1 + f))[:, None], "raw", ("time", "channel"), "r")}}
    write_recording(tmp_path / "p.h5", eps, source="real", config_json="{}", root_seed=0, shard_index=0,
                    sensor_attrs={"family": "velostat"}, episode_attrs={})
    with pytest.raises(ValueError, match="episode run0: no unloaded sample"):
        CF.load_real_runs(tmp_path / "p.h5")


@pytest.mark.parametrize("units,scale", [("N", 1.0), ("g", 9.80665e-3), ("counts", None)])
def test_the_force_label_is_read_in_newtons(tmp_path, units, scale):
    """The chain is fitted in N: a label recorded in another force unit (or a scale's grams) is converted, one that
    is no force is refused naming it."""
    from sensors.data.recording import Channel, write_recording

    t = np.arange(400) * 0.01
    f = np.clip(5 * np.sin(t), 0, None)
    eps = {"run0": {"time": Channel(t, "s", ("time",), "c"), "force": Channel(f, units, ("time",), "f"),
                    "sensor": Channel((1000 / (1 + f))[:, None], "raw", ("time", "channel"), "r")}}
    write_recording(tmp_path / "u.h5", eps, source="real", config_json="{}", root_seed=0, shard_index=0,
                    sensor_attrs={"family": "velostat"}, episode_attrs={})
    if scale is None:
        with pytest.raises(ValueError, match="the target 'force' is in 'counts', not a force"):
            CF.load_real_runs(tmp_path / "u.h5", rate_hz=None)
    else:
        from learn.finetune import load_recording

        (r,) = CF.load_real_runs(tmp_path / "u.h5", rate_hz=None)
        np.testing.assert_allclose(r.force, f * scale)
        (s,) = load_recording(tmp_path / "u.h5", ["sensor"], ["force"])  # the learning side reads it in N too
        np.testing.assert_allclose(s.y[:, 0], f * scale)
        assert s.units["force"] == "N"


def test_one_column_of_a_board_stream_is_named_name_k(tmp_path):
    """`--input velostat[0]`: one column of a stream of several values per sample (a capture of our velostat board:
    R, x, y) is read as the reading; a column beyond the stream's is one error naming the range."""
    from learn.finetune import load_recording
    from sensors.data.recording import Channel, write_recording

    t = np.arange(500) * 0.01
    f = np.clip(5 * np.sin(t), 0, None)
    board = np.stack([1000 / (1 + f), np.full_like(f, 0.01), np.full_like(f, -0.02)], 1)
    eps = {"run0": {"time": Channel(t, "s", ("time",), "c"), "cell": Channel(f, "N", ("time",), "f"),
                    "velostat": Channel(board, "ohm", ("time", "channel"), "R, x, y")}}
    write_recording(tmp_path / "c.h5", eps, source="real", config_json="{}", root_seed=0, shard_index=0,
                    sensor_attrs={"family": "velostat"}, episode_attrs={})
    (r,) = CF.load_real_runs(tmp_path / "c.h5", input_channel="velostat[0]", target="cell", rate_hz=None)
    np.testing.assert_allclose(r.reading, board[:, 0])
    (s,) = load_recording(tmp_path / "c.h5", ["velostat[0]"], ["cell"])
    assert s.x.shape == (500, 1) and s.units["velostat[0]"] == "ohm"
    with pytest.raises(ValueError, match=r"channel 'velostat' has 3 column\(s\); 'velostat\[3\]' asks for column 3"):
        CF.load_real_runs(tmp_path / "c.h5", input_channel="velostat[3]", target="cell")


def test_a_run_read_through_another_reference_resistor_is_evaluated_through_it():
    """The fit and its held-out evaluation read each run through its own reference resistor (the run's
    reference_resistor_ohm, as the TAMS file names give it): a taxel fitted at 10 kOhm, held out at 2.2 kOhm, has a
    within-press error and a level as at 10 kOhm; read through the fit's 10 kOhm instead, its level is off by more
    than a press-to-press spread."""
    true = CF.ChainParams(exponent=1.5, r0_ohm=2000.0, creep_amplitude=0.3, creep_force_n=1.0, tau_min_s=0.2, tau_max_s=5.0,
                          n_creep=3, r_series_ohm=200.0, r_leak_ohm=4e5, r_ref_ohm=1e4, full_scale=5115.0, level_log_sd=0.05)
    runs = _synthetic_runs(true, n_runs=3)
    held = _synthetic_runs(_replace(true, r_ref_ohm=2.2e3), n_runs=1, seed=9)
    for r in runs:
        r.attrs.update(adc_full_scale=5115.0, reference_resistor_ohm=1e4)
    held[0].attrs.update(adc_full_scale=5115.0, reference_resistor_ohm=2.2e3)
    fit = CF.fit_chain(runs, CF.ChainParams(r_ref_ohm=1e4, full_scale=5115.0, n_creep=3, r_series_ohm=50.0), n_boot=0)
    ev = CF.evaluate(fit, held)
    assert ev["rms_log_reading_within_press"] < 0.05 and abs(ev["level_mean_log_vs_fit"]) < 0.15, ev
    assert CF.run_params(fit.params, held[0]).r_ref_ohm == 2.2e3 and CF.run_params(fit.params, runs[0]) is fit.params
    held[0].attrs.pop("reference_resistor_ohm")  # read as if through the fit's own 10 kOhm
    assert abs(CF.evaluate(fit, held)["level_mean_log_vs_fit"]) > 0.3


def test_label_latency_is_read_from_a_late_label_lined_up_and_recovers_the_chain():
    """A rig that records the force 0.15 s late (label_latency_s): `label_latency` reads it from the runs (the
    reading leads its label), `fit_chain(latency=True)` lines the labels up and fits the chain as well as on the
    true force; a chain whose reading follows its force (creep, no latency) reads no latency (causality)."""
    true = CF.ChainParams(exponent=1.2, r0_ohm=3000.0, creep_amplitude=2.0, creep_force_n=4.0, tau_min_s=0.1,
                          tau_max_s=5.0, n_creep=4, level_log_sd=0.4, r_ref_ohm=1e4, full_scale=1000.0, noise_sd=0.0)
    on_time = _synthetic_runs(true, rate=50.0)
    assert CF.label_latency(on_time)[0] == 0.0  # the creep makes the reading follow its force: no latency read
    late = [_replace(r, force=CF.shift_label(r.force, r.dt, -0.15)) for r in on_time]
    lat, lags = CF.label_latency(late)
    assert abs(lat - 0.15) < 0.03, (lat, lags)
    p0 = CF.ChainParams(r_ref_ohm=1e4, full_scale=1000.0, n_creep=4)
    fit_late = CF.fit_chain(late, p0, n_boot=0)
    fit = CF.fit_chain(late, p0, n_boot=0, latency=True)
    assert abs(fit.params.label_latency_s - lat) < 1e-12
    assert fit.error["rms_log_reading_within_press"] < 0.5 * fit_late.error["rms_log_reading_within_press"]
    assert abs(fit.params.exponent - 1.2) < 0.1
    # other runs of the rig are lined up by the fit's latency when evaluated
    held = [_replace(r, force=CF.shift_label(r.force, r.dt, -0.15)) for r in _synthetic_runs(true, n_runs=2, seed=7, rate=50.0)]
    assert CF.evaluate(fit, held)["rms_log_reading_within_press"] < 0.5 * CF.evaluate(fit_late, held)["rms_log_reading_within_press"]


def test_generated_labels_are_recorded_as_late_as_the_rig_records_them():
    from simulate.generation.chain_gen import episode

    p = CF.ChainParams(exponent=1.2, r0_ohm=3000.0, creep_amplitude=0.0, n_creep=1, tau_min_s=1.0, level_log_sd=0.0,
                       r_ref_ohm=1e4, full_scale=1000.0, label_latency_s=0.2)
    rand = Randomization(press={"peak_force_n": Dist(kind="loguniform", low=2.0, high=30.0)})
    ch, _ = episode(p, rand, 3, 60.0, 0.02)
    ch0, _ = episode(_replace(p, label_latency_s=0.0), rand, 3, 60.0, 0.02)
    assert np.array_equal(ch["sensor"], ch0["sensor"])  # the sensor sees the same force ...
    np.testing.assert_allclose(ch["force"][10:], ch0["force"][:-10], atol=1e-9)  # ... its label comes 0.2 s (10 samples) late
    run = CF.RealRun("ep", ch["force"], ch["sensor"], 0.02, 1000.0, 0.0)
    assert abs(CF.label_latency([run])[0] - 0.2) < 0.02
