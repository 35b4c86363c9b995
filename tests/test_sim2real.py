"""The sim2real loop's pieces (learn/sim2real.py): the two-point calibration of a new sensor, seed averaging."""

from dataclasses import replace

import numpy as np
import pytest

from learn.data import Sequence
from learn.sim2real import _mean_metrics, run_level_shrinkage, two_point_calibration
from sensors import chain_fit as CF

RATE = 20.0


def _press_run(p, fs, level, seed=0):
    rng = np.random.default_rng(seed)
    f = np.zeros(40)
    for pk in rng.uniform(2.0, 30.0, 8):
        f = np.concatenate([f, np.linspace(0, pk, 10), np.full(30, pk), np.linspace(pk, 0, 4), np.zeros(40)])
    y = CF.simulate_reading(f, 1 / RATE, p, level=np.where(f > 0, level, 0.0), fs=fs)
    return f, y


def test_two_point_calibration_maps_a_new_sensor_onto_the_chain():
    """A sensor whose board reads 1.3x the chain's rest level and whose film sits 0.5 (ln) more resistive:
    after the calibration on its first press, its later presses read as the identified chain's (level 0)."""
    p = CF.ChainParams(exponent=1.1, r0_ohm=7e4, creep_amplitude=2.0, creep_force_n=4.0, tau_min_s=0.1, tau_max_s=3.0,
                       n_creep=3, r_ref_ohm=1e4, full_scale=900.0)
    f, y = _press_run(p, fs=1.3 * 900.0, level=0.5)
    seq = Sequence(np.log(y)[:, None], f[:, None], ["sensor"], ["force"], {}, {"key": "new"}, {})
    cal, info = two_point_calibration(p, seq, RATE)
    assert abs(info["unloaded_reading"] - 1.3 * 900.0) < 1.0
    assert abs(info["level_ln"] - 0.5) < 0.02
    on = f > 1.0
    ref = np.log(CF.simulate_reading(f, 1 / RATE, p))
    err = cal.apply(seq.x)[:, 0] - ref
    assert np.sqrt(np.mean(err[on] ** 2)) < 0.02
    # uncalibrated, the same presses are off by about the level and the gain
    assert np.sqrt(np.mean((seq.x[:, 0] - ref)[on] ** 2)) > 0.3
    # the calibration press is left out of the score: it ends where the first press ends
    assert info["calibration_end_sample"] == 40 + 43  # linspace(pk, 0, 4) ends at 0 N
    # a different film level only: the gain point leaves the rest level alone
    f2, y2 = _press_run(replace(p), fs=900.0, level=-0.3, seed=1)
    cal2, info2 = two_point_calibration(p, Sequence(np.log(y2)[:, None], f2[:, None], ["sensor"], ["force"], {}, {"key": "b"}, {}), RATE)
    assert abs(info2["level_ln"] + 0.3) < 0.02 and abs(info2["unloaded_reading"] - 900.0) < 1.0


def test_two_point_keeps_a_known_adc_full_scale():
    """An ADC divider with a leak (TAMS-like) rests below its full scale: the unloaded point is not a gain."""
    p = CF.ChainParams(exponent=1.5, r0_ohm=2000.0, creep_amplitude=0.3, creep_force_n=1.0, tau_min_s=0.2, tau_max_s=5.0,
                       n_creep=3, r_series_ohm=200.0, r_leak_ohm=4e5, r_ref_ohm=1e4, full_scale=5115.0)
    f, y = _press_run(p, fs=5115.0, level=0.3)
    cal, info = two_point_calibration(p, Sequence(np.log(y)[:, None], f[:, None], ["sensor"], ["force"], {}, {"key": "t"}, {}), RATE)
    assert info["full_scale_used"] == 5115.0 and info["unloaded_reading"] < 5115.0 * 0.99
    assert abs(info["level_ln"] - 0.3) < 0.05


def test_shrunk_two_point_level_predicts_the_run_level_better():
    """Presses at l = u_run + e (s_run 0.1, s_w 0.5, sensors.chain_fit's levels model): one calibration press's level
    in full is off the run level by s_w; shrunk by k = s_run^2 / (s_run^2 + s_w^2) (run_level_shrinkage, from the
    fit's own sds) it is off by about s_run s_w / sqrt(s_run^2 + s_w^2), the posterior sd."""
    p = CF.ChainParams(exponent=1.1, r0_ohm=7e4, creep_amplitude=0.0, n_creep=1, r_ref_ohm=1e4, full_scale=900.0,
                       level_run_log_sd=0.1)
    fit_json = {"error": {"level_run_sd": {"within_run_sd": 0.5}}}
    k = run_level_shrinkage(p, fit_json)
    assert k == pytest.approx(0.01 / 0.26)
    assert run_level_shrinkage(p, None) == 1.0  # no within-run sd recorded: the press says all
    rng = np.random.default_rng(3)
    f = np.concatenate([np.zeros(20), np.linspace(0, 10.0, 10), np.full(30, 10.0), np.linspace(10.0, 0, 4), np.zeros(10)])
    err = {1.0: [], k: []}
    for _ in range(60):
        u = rng.normal(0, 0.1)
        y = CF.simulate_reading(f, 1 / RATE, p, level=np.where(f > 0, u + rng.normal(0, 0.5), 0.0))
        seq = Sequence(np.log(y)[:, None], f[:, None], ["sensor"], ["force"], {}, {"key": "s"}, {})
        for kk in err:
            cal, info = two_point_calibration(p, seq, RATE, level_shrink=kk)
            assert info["level_ln"] == pytest.approx(kk * info["level_ln_measured"])
            err[kk].append(info["level_ln"] - u)
    rms = {kk: float(np.sqrt(np.mean(np.square(v)))) for kk, v in err.items()}
    assert 0.4 < rms[1.0] < 0.6 and rms[k] < 0.14 and rms[k] < 0.3 * rms[1.0]
    with pytest.raises(ValueError, match="level_shrink"):
        two_point_calibration(p, seq, RATE, level_shrink=1.5)


def test_seed_mean_and_spread():
    runs = [{"rmse": 2.0, "mae": 1.0, "per_run_rmse": {"a": 1.0}}, {"rmse": 4.0, "mae": 3.0, "per_run_rmse": {"a": 3.0}}]
    m = _mean_metrics(runs)
    assert m["rmse"] == 3.0 and m["mae"] == 2.0 and m["per_run_rmse"]["a"] == 2.0
    assert m["rmse_seeds"] == [2.0, 4.0] and abs(m["rmse_sd"] - np.sqrt(2.0)) < 1e-12


def test_curve_order_keeps_the_earlier_budgets_and_adds_the_former_valid_runs():
    """Round 4 validates on each training run's tail, so the whole runs that used to stop early train too: they
    join the learning curve after the runs it had (budgets 1, 2, 4 unchanged; 'all' gains them)."""
    from learn import finetune as FT
    from learn.sim2real import curve_order

    seqs = [Sequence(np.zeros((5, 1)), np.zeros((5, 1)), ["x"], ["force"], {}, {"key": f"run{i}"}) for i in range(10)]
    seqs += [Sequence(np.zeros((5, 1)), np.zeros((5, 1)), ["x"], ["force"], {}, {"key": "test0"})]
    old = FT.split_runs(seqs, train_fraction=None, test_glob="test*", seed=0)
    order = curve_order(seqs, "test*", 0)
    assert order[: len(old.order)] == old.order and len(old.valid) >= 2
    assert sorted(order) == sorted(f"run{i}" for i in range(10))


def test_cli_refuses_a_rated_force_that_is_not_a_force(tmp_path):
    """`sim2real --rated-force-n` takes a positive finite force in N; anything else stops before any step runs."""
    import h5py
    from typer.testing import CliRunner

    from piezotwin.cli import app

    rec = tmp_path / "r.h5"
    h5py.File(rec, "w").close()
    for bad in ("0", "-5", "nan", "inf", "1e30"):
        res = CliRunner().invoke(app, ["sim2real", "velostat", str(rec), "--test-episodes", "*x*", "-o", str(tmp_path / "o"),
                                       "--rated-force-n", bad])
        assert res.exit_code != 0 and "rated-force-n" in res.output, (bad, res.output)
        assert not (tmp_path / "o" / "state.json").exists()


def test_paired_improvement_rule_and_pipeline_seed():
    """The eighth round's rule: adopt when the mean paired difference over pipeline seeds is below minus its
    standard error; the pipeline seed moves steps 2-3 only (0: the recorded runs) and keeps the fit's state key."""
    from learn.sim2real import _fit_key, paired_improvement, pipeline_seed

    r = paired_improvement([1.0, 2.0, 3.0], [0.8, 1.9, 2.7])  # d = -0.2, -0.1, -0.3: mean -0.2, se 0.0577
    assert r["diff_mean"] == pytest.approx(-0.2) and r["diff_se"] == pytest.approx(0.1 / 3 ** 0.5) and r["improves"]
    assert not paired_improvement([1.0, 2.0, 3.0], [1.2, 1.5, 3.1])["improves"]  # d = 0.2, -0.5, 0.1: mean -0.067, se 0.22
    with pytest.raises(ValueError):
        paired_improvement([1.0], [0.5])
    assert pipeline_seed(7, {"pipeline_seed": 0}) == 7 and pipeline_seed(7, {}) == 7 and pipeline_seed(7, {"pipeline_seed": 2}) == 207
    k0 = {"family": "velostat", "budget": {"n_boot": 16, "pipeline_seed": 0}, "seed": 0}
    assert _fit_key(k0) == _fit_key({**k0, "budget": {"n_boot": 16, "pipeline_seed": 3}})
    assert _fit_key(k0) != _fit_key({**k0, "budget": {"n_boot": 8, "pipeline_seed": 0}}) and _fit_key(None) is None


def test_static_blend_weight_recovers_the_mix_and_its_ends():
    """Round 11's candidate (learn.sim2real.StaticBlend): F = S + w (N - S). On data whose force is exactly
    0.3 N + 0.7 S the least-squares weight is 0.7; it is clipped to [0, 1]; w = 1 gives the net, w = 0 the curve; no
    data gives None."""
    from learn.sim2real import StaticBlend, StaticCurve, blend_weight

    rng = np.random.default_rng(3)
    x = np.sort(rng.uniform(0.0, 3.0, 400))[::-1][:, None]  # ln reading falls as the force rises
    f = 10.0 * (3.0 - x[:, 0])
    curve_data = Sequence(x, f[:, None], ["x"], ["force"], {}, {"key": "cal"}, {})
    S = StaticCurve([curve_data])

    class Net:
        def __init__(self, bias):
            self.bias = bias

        def predict(self, xx):
            return S.predict(xx) + self.bias * np.sin(7.0 * xx)

    net = Net(2.0)
    truth = S.predict(x)[:, 0] + 0.7 * 2.0 * np.sin(7.0 * x[:, 0])
    seq = Sequence(x, truth[:, None], ["x"], ["force"], {}, {"key": "tail"}, {})
    assert blend_weight(net, S, [seq]) == pytest.approx(0.7, abs=1e-9)
    over = Sequence(x, (S.predict(x)[:, 0] + 3.0 * np.sin(7.0 * x[:, 0]))[:, None], ["x"], ["force"], {}, {"key": "o"}, {})
    assert blend_weight(net, S, [over]) == 1.0  # 1.5 clipped: never extrapolates past the net
    assert blend_weight(Net(-2.0), S, [seq]) == 0.0  # a correction pointing the wrong way: the curve alone
    assert blend_weight(net, S, []) is None
    np.testing.assert_allclose(StaticBlend(net, S, 1.0).predict(x), net.predict(x))
    np.testing.assert_allclose(StaticBlend(net, S, 0.0).predict(x), S.predict(x))
    np.testing.assert_allclose(StaticBlend(net, S, 0.7).predict(x)[:, 0], truth, atol=1e-12)


class _Seen(Exception):
    """Raised by the probe once it has recorded torch's thread count inside an entry point."""


@pytest.mark.parametrize("entry", ["pretrain", "run_finetune", "run_sim2real"])
def test_sim2real_entry_points_train_on_one_thread(entry, monkeypatch, tmp_path):
    """pretrain, run_finetune and run_sim2real train with torch on one thread whatever the caller set (a float sum
    split over threads sums in another order: a 2-core user's pre-trained net, and all fine-tuned from it, differed
    from the records made on one thread, session 13), and the caller's setting comes back, on error too."""
    import torch

    import learn.sim2real as S

    seen = []

    def probe(*a, **k):
        seen.append(torch.get_num_threads())
        raise _Seen

    monkeypatch.setattr(S, "load_sequences", probe)  # pretrain's first step
    monkeypatch.setattr(S, "checkpoint_input_map", probe)  # run_finetune's, after reading the checkpoint's config
    monkeypatch.setattr("learn.checkpoint.read_config", lambda p: {})
    monkeypatch.setattr("learn.checkpoint.load_checkpoint", lambda p: None)
    monkeypatch.setattr(S.FT, "_torch_only", lambda c: None)
    monkeypatch.setattr(S, "_fit_key", probe)  # run_sim2real's, reading its (empty) state before the first step
    args = {"pretrain": (tmp_path / "data", tmp_path / "out"), "run_finetune": (tmp_path / "ck", tmp_path / "r.h5", tmp_path / "o"),
            "run_sim2real": ("velostat", tmp_path / "r.h5", tmp_path / "o")}[entry]
    kw = {"test_glob": "*"} if entry == "run_sim2real" else {}
    old = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        with pytest.raises(_Seen):
            getattr(S, entry)(*args, **kw)
        assert seen == [1]
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(old)


def test_generated_presses_read_as_spread_as_the_chain_draws_them(tmp_path):
    """Step 2's check (simulated_press_spread): episodes generated around a chain whose presses spread by 0.4 ln
    read at equal force about as spread as real runs made by the same chain (ratio ~1), the report says so; a
    randomization that draws twice the spread reads ~2x."""
    from scenes.randomize import Dist, Randomization
    from learn.sim2real import S2R_BUDGET, _spread_lines, generate_step, simulated_press_spread

    p = CF.ChainParams(exponent=1.0, r0_ohm=300.0, creep_amplitude=1e-6, level_log_sd=0.4, r_ref_ohm=1e5, full_scale=1000.0)
    press = {"peak_force_n": Dist(kind="loguniform", low=2.0, high=30.0), "rise_s": Dist(kind="fixed", value=0.5),
             "hold_s": Dist(kind="fixed", value=1.2), "fall_s": Dist(kind="fixed", value=0.1),
             "gap_s": Dist(kind="fixed", value=1.5)}
    rand = Randomization(episode={"gain_log": Dist(kind="fixed", value=0.0)}, press=press)
    real = []
    for k in range(6):
        f, y = [], []
        for pk, l in zip(np.random.default_rng(k).uniform(2.0, 30.0, 10), np.random.default_rng(k + 50).normal(0, 0.4, 10)):
            ff = np.concatenate([np.zeros(20), np.linspace(0, pk, 10), np.full(24, pk), np.zeros(6)])
            f.append(ff)
            y.append(CF.simulate_reading(ff, 1 / RATE, p, level=np.where(ff > 0, l, 0.0)))
        real.append(CF.RealRun(f"run{k}", np.concatenate(f), np.concatenate(y), 1 / RATE, 1000.0, 0.0))
    B = dict(S2R_BUDGET, n_episodes=8, episode_s=60.0)
    generate_step(p, rand, tmp_path / "sim.h5", B, 0)
    sp = simulated_press_spread(tmp_path / "sim.h5", real)
    assert 0.7 < sp["ratio"] < 1.4 and abs(sp["real_ln_reading_sd"] - 0.4) < 0.12, sp
    assert "x{:.2f}".format(sp["ratio"]) in "\n".join(_spread_lines(sp))
    generate_step(replace(p, level_log_sd=0.8), rand, tmp_path / "wide.h5", B, 0)
    assert 1.5 < simulated_press_spread(tmp_path / "wide.h5", real)["ratio"] < 2.7


def test_a_rising_reading_is_read_through_its_headroom_and_calibrates_the_same():
    """A "low" divider (reading rises with force toward its ADC's full scale): the model's input is ln(FS - reading)
    (learn.sim2real.input_transform, learn.finetune.HEADROOM; forward and inverse undo each other); its two-point
    calibration finds the film level as the "high" wiring's does, keeping the ADC's full scale; its static curve
    rises with the reading. A malformed headroom map is refused."""
    from learn import finetune as FT
    from learn.sim2real import StaticCurve, input_transform

    p = CF.ChainParams(exponent=1.5, r0_ohm=2000.0, creep_amplitude=0.3, creep_force_n=1.0, tau_min_s=0.2, tau_max_s=5.0,
                       n_creep=3, r_series_ohm=200.0, r_ref_ohm=1e4, full_scale=4095.0, divider="low")
    t = input_transform(p)
    assert t == "log_headroom:4095" and input_transform(replace(p, divider="high")) == "log"
    r = np.array([0.0, 10.0, 4000.0, 4094.0])
    np.testing.assert_allclose(FT.inverse_transform(FT.forward_transform(r, t), t), r, rtol=0, atol=1e-9)
    np.testing.assert_allclose(FT.forward_transform(np.array([4095.0, 5000.0]), t), np.log(0.4095))  # saturated: bounded
    assert "ln(4095 - reading)" in FT.InputMap(t).describe()
    with pytest.raises(ValueError, match="full scale"):
        FT.InputMap("log_headroom:-3")
    f, y = _press_run(p, fs=4095.0, level=0.3)
    assert y[f > 1.0].mean() > y[f == 0].mean()  # the reading rises with force
    seq = Sequence(FT.forward_transform(y, t)[:, None], f[:, None], ["sensor"], ["force"], {}, {"key": "t"}, {})
    cal, info = two_point_calibration(p, seq, RATE)
    assert info["full_scale_used"] == 4095.0 and abs(info["level_ln"] - 0.3) < 0.05
    on = f > 1.0
    ref = FT.forward_transform(CF.simulate_reading(f, 1 / RATE, p), t)
    assert np.sqrt(np.mean((cal.apply(seq.x)[:, 0] - ref)[on] ** 2)) < 0.05
    raw = Sequence(np.log(y)[:, None], f[:, None], ["sensor"], ["force"], {}, {"key": "t"}, {})
    S = StaticCurve([raw])
    assert not S.decreasing and np.all(np.diff(S.ky) >= 0)
    assert np.sqrt(np.mean((S.predict(raw.x)[:, 0] - f)[on] ** 2)) < 0.2 * f.max()


def test_cli_reads_the_channels_it_is_told(tmp_path, monkeypatch):
    """`sim2real --input NAME --target NAME`: a capture whose streams are named otherwise (`piezotwin capture`'s
    stream names) is read through those channels; a channel the recording lacks is one line naming what it has."""
    import h5py
    from typer.testing import CliRunner

    import learn.sim2real as S
    from piezotwin.cli import app

    rec = tmp_path / "r.h5"
    h5py.File(rec, "w").close()
    seen = {}

    def fake(family, recording, out, **kw):
        seen.update(kw)
        raise ValueError(f"{recording}: episode 'e' has no channel '{kw['input_channel']}' (has ['cell', 'time'])")

    monkeypatch.setattr(S, "run_sim2real", fake)
    res = CliRunner().invoke(app, ["sim2real", "divider", str(rec), "--test-episodes", "*x*", "-o", str(tmp_path / "o"),
                                   "--input", "board", "--target", "cell"])
    assert seen["input_channel"] == "board" and seen["target"] == "cell"
    assert res.exit_code == 2 and "has no channel 'board'" in res.output and len(res.output.strip().splitlines()) == 1


def test_two_point_needs_a_press_and_says_so():
    """A test run without any press (the force never above 0.05 N) cannot give the known load: one ValueError
    naming the run (it was an IndexError traceback)."""
    p = CF.ChainParams(r_ref_ohm=1e4, full_scale=900.0)
    seq = Sequence(np.zeros((100, 1)), np.full((100, 1), 0.01), ["sensor"], ["force"], {}, {"key": "idle"}, {})
    with pytest.raises(ValueError, match="test run idle: no press above 0.05 N"):
        two_point_calibration(p, seq, RATE)


def test_a_run_through_another_resistor_is_reread_through_the_chains():
    """sim2real's step 4 re-reads a real run recorded through another reference resistor (its episode attribute)
    as through the chain's own (reread_through): the reading it gives equals the same presses read through the
    chain's resistor; a run through the chain's resistor, or without the attribute, comes back as it is."""
    from learn.sim2real import reread_through

    p = CF.ChainParams(exponent=1.5, r0_ohm=2000.0, creep_amplitude=0.3, creep_force_n=1.0, tau_min_s=0.2, tau_max_s=5.0,
                       n_creep=3, r_series_ohm=200.0, r_ref_ohm=1e4, full_scale=5115.0)
    f, y_10k = _press_run(p, fs=5115.0, level=0.2)
    _, y_2k = _press_run(replace(p, r_ref_ohm=2.2e3), fs=5115.0, level=0.2)
    seq = Sequence(y_2k[:, None], f[:, None], ["sensor"], ["force"], {}, {"key": "b", "reference_resistor_ohm": 2.2e3}, {})
    out = reread_through(seq, p)
    on = f > 0.5
    np.testing.assert_allclose(out.x[on, 0], y_10k[on], rtol=1e-9)
    assert np.max(np.abs(np.log(y_2k[on] / y_10k[on]))) > 0.5  # the two resistors read far apart
    assert out.meta["reread_from_reference_resistor_ohm"] == 2.2e3
    same = Sequence(y_10k[:, None], f[:, None], ["sensor"], ["force"], {}, {"key": "a", "reference_resistor_ohm": 1e4}, {})
    assert reread_through(same, p) is same


def test_static_oracle_is_the_floor_of_any_static_reading():
    """learn.sim2real.static_oracle: the isotonic curve fitted on the test runs themselves; on a noiseless monotone
    sensor it is exact but for its quantile bins (< 1 % of full scale), and with press-to-press levels the static
    curve fitted on other runs reads those runs worse."""
    from learn.sim2real import StaticCurve, static_oracle

    rng = np.random.default_rng(3)

    def run(key, level):
        f = np.repeat(rng.uniform(0.5, 10.0, 12), 25)  # 12 presses held 25 samples
        lvl = np.repeat(rng.normal(0.0, level, 12), 25)
        return Sequence(x=(-np.log(f) + lvl)[:, None], y=f[:, None], inputs=["sensor"], targets=["force"],
                        units={}, meta={"key": key})

    exact = [run("a", 0.0), run("b", 0.0)]
    assert static_oracle(exact)["rmse"] < 0.01 * 10.0
    train, test = [run("t1", 0.3), run("t2", 0.3)], [run("x1", 0.3), run("x2", 0.3)]
    o = static_oracle(test)
    other = StaticCurve(train)
    ref = np.concatenate([s.y[:, 0] for s in test])
    est = np.concatenate([other.predict(s.x)[:, 0] for s in test])
    assert 0.1 < o["rmse"] < float(np.sqrt(np.mean((est - ref) ** 2)))
    assert set(o["per_run_rmse"]) == {"x1", "x2"}


def test_sim2real_cli_refuses_an_unknown_two_point_level(tmp_path):
    """`--two-point-level` takes measured or shrunk: anything else is one line, exit 2, nothing written."""
    import h5py
    from typer.testing import CliRunner

    from piezotwin.cli import app

    rec = tmp_path / "real.h5"
    with h5py.File(rec, "w"):
        pass
    out = tmp_path / "run"
    res = CliRunner().invoke(app, ["sim2real", "velostat", str(rec), "--test-episodes", "*b*", "-o", str(out),
                                   "--two-point-level", "median"])
    assert res.exit_code == 2, res.output
    assert "--two-point-level must be one of measured, shrunk" in res.output.replace("\n", " ")
    assert not out.exists()


def test_finetune_grid_keeps_the_lowest_validation_loss(monkeypatch):
    """The budget's methods x rehearsal shares are each fine-tuned and the one of the lowest validation loss on the
    tails is kept (best_finetune); a single method is a grid of one; an unknown method is refused."""
    import learn.sim2real as S

    loss = {("plain", 0.0): 0.30, ("shrink_perturb", 0.0): 0.20, ("plain", 1.0): 0.25, ("shrink_perturb", 1.0): 0.22}
    calls = []

    def fake(base, heads, tails, *, rehearsal, seed, method, **kw):
        r = 1.0 if rehearsal else 0.0
        calls.append((method, r, seed, kw.get("lr")))
        return f"{method}@{r}", {"best_loss": loss[(method, r)]}

    monkeypatch.setattr(S.FT, "finetune", fake)
    sim = [Sequence(np.zeros((10, 1)), np.zeros((10, 1)), ["sensor"], ["force"], {}, {"key": "s"}, {})]
    heads = [Sequence(np.zeros((10, 1)), np.zeros((10, 1)), ["sensor"], ["force"], {}, {"key": "h"}, {})]
    B = {"finetune_method": ["plain", "shrink_perturb"], "rehearsal": [0.0, 1.0]}
    net, info, r, m = S.best_finetune("base", heads, heads, 7, B, sim, {"lr": 1e-3})
    assert (net, r, m, info["best_loss"]) == ("shrink_perturb@0.0", 0.0, "shrink_perturb", 0.20)
    assert len(calls) == 4 and {c[2] for c in calls} == {7} and {c[3] for c in calls} == {1e-3}
    assert S.best_finetune("base", heads, heads, 0, {"finetune_method": "plain", "rehearsal": 0.0})[3] == "plain"
    with pytest.raises(ValueError, match="finetune_method must be one or more of"):
        S.finetune_methods({"finetune_method": ["plain", "nope"]})


def test_sim2real_cli_takes_a_method_grid(tmp_path, monkeypatch):
    """`--finetune-method plain,shrink_perturb` is a grid (a list in the budget), one name stays a name, and a
    name outside the methods is one line, exit 2."""
    import h5py
    from typer.testing import CliRunner

    import learn.sim2real as S
    from piezotwin.cli import app

    rec = tmp_path / "r.h5"
    h5py.File(rec, "w").close()
    seen = []

    def fake(family, recording, out, **kw):
        seen.append(kw["budget"]["finetune_method"])
        raise ValueError("stop here")

    monkeypatch.setattr(S, "run_sim2real", fake)
    base = ["sim2real", "velostat", str(rec), "--test-episodes", "*x*", "-o", str(tmp_path / "o"), "--finetune-method"]
    CliRunner().invoke(app, base + ["plain, shrink_perturb"])
    CliRunner().invoke(app, base + ["l2sp"])
    assert seen == [["plain", "shrink_perturb"], "l2sp"]
    res = CliRunner().invoke(app, base + ["plain,nope"])
    assert res.exit_code == 2 and "--finetune-method must be one or more of" in res.output.replace("\n", " ")
    assert S.S2R_BUDGET["finetune_method"] == ["plain", "shrink_perturb"]


def test_trainings_in_processes_give_the_same_nets():
    """Step 4's trainings in worker processes (`Trainings`) give the nets one after another gives: each seeds itself
    and runs on one torch thread (a fine-tuning and a net from scratch of the same tiny runs, compared weight by
    weight)."""
    import torch

    from learn import finetune as FT
    from learn.models.base import make_model
    from learn.sim2real import Trainings

    rng = np.random.default_rng(0)
    runs = []
    for k in range(3):
        f = np.abs(np.cumsum(rng.normal(0, 0.3, 200)))
        runs.append(Sequence(np.log1p(f)[:, None] + rng.normal(0, 0.01, (200, 1)), f[:, None], ["sensor"], ["force"],
                             {}, {"key": f"r{k}"}, {}))
    base = make_model("tcn", channels=4, dilations=[1, 2], chunk=32, max_epochs=2, patience=2)
    base.fit([s.x for s in runs], [s.y for s in runs], seed=0, inputs=["sensor"], targets=["force"], units={})
    jobs = [("finetune", (base, runs[:2], runs[2:]), {"seed": 3, "max_epochs": 3, "patience": 3, "method": "shrink_perturb",
                                                       "norm": "checkpoint", "policy": "none", "lr": 1e-3}),
            ("scratch", (base.kind, base.hparams, runs[:2], runs[2:]), {"seed": 3, "max_epochs": 3, "patience": 3})]
    with Trainings(2) as par:
        a = par.run(jobs)
    b = Trainings(1).run(jobs)
    nets = [(a[0][0], b[0][0]), (a[1], b[1])]
    for x, y in nets:
        for (n, p), (_, q) in zip(x.net.state_dict().items(), y.net.state_dict().items()):
            assert torch.equal(p, q), n
    assert a[0][1]["best_loss"] == b[0][1]["best_loss"]
