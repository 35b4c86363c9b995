"""Real-to-sim fit of the velostat film model (sensors/velostat/fit.py, `piezotwin fit`)."""

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from piezotwin.cli import app
from scenes import load_scene
from sensors.velostat import fit as VF
from sensors.data.recording import Channel, write_recording
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
