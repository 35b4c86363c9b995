"""Fine-tuning a simulated-data compensator on a (synthetic or Lupasic) real recording."""

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from learn import finetune as FT
from learn.checkpoint import load_checkpoint, save_checkpoint
from learn.data import Sequence
from learn.models.base import make_model
from learn.sim2real import run_finetune
from piezotwin.cli import app
from sensors import chain_fit as CF
from sensors.data.recording import Channel, write_recording
from sensors.velostat.fit import FitParams, Model, forward_reading

torch.set_num_threads(1)
runner = CliRunner()
REAL = Path(__file__).resolve().parents[1].parent / "shared" / "real" / "velostat-lupasic"
if not REAL.is_dir():
    REAL = Path("/work/shared/real/velostat-lupasic")
needs_real = pytest.mark.skipif(not (REAL / "velostat_data").is_dir(), reason="real Lupasic logs not present")

RATE = 20.0
MODEL = Model(area_m2=1e-4, r_ref_ohm=20_000.0, p_ref_pa=1e4, r_series_ohm=0.0, current_a=50e-6)
SIM = FitParams(gain=1.0, exponent=1.0, amplitude=0.5, p_c_pa=3e4, tau_min_s=0.5, tau_max_s=20.0, n_creep=4)
# the "real" sensor: another gain (raw counts, not ohms), a steeper conductance law, more creep
REALP = FitParams(gain=0.03, exponent=1.3, amplitude=1.0, p_c_pa=3e4, tau_min_s=0.5, tau_max_s=20.0, n_creep=4)


def presses(seed: int, T: int = 600, fmax: float = 30.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    f = np.zeros(T)
    t = 10
    while t < T - 20:
        up, hold, down = rng.integers(3, 12), rng.integers(5, 60), rng.integers(3, 12)
        peak = rng.uniform(1.0, fmax)
        seg = np.concatenate([np.linspace(0, peak, up), np.full(hold, peak), np.linspace(peak, 0, down)])
        seg = seg[: T - t]
        f[t : t + len(seg)] = seg
        t += len(seg) + int(rng.integers(10, 40))
    return f


def reading(f: np.ndarray, p: FitParams, seed: int, rest: float) -> np.ndarray:
    r = forward_reading(f, 1 / RATE, p, MODEL)
    r = np.where(np.isfinite(r), np.minimum(r, rest), rest)  # unloaded: the board's rest level
    return r * np.exp(0.01 * np.random.default_rng(seed + 99).standard_normal(len(f)))


def sim_seqs(n: int, p: FitParams = SIM, rest: float = 60_000.0) -> list[Sequence]:
    out = []
    for i in range(n):
        f = presses(i)
        x = np.log(reading(f, p, i, rest))[:, None]
        out.append(Sequence(x, f[:, None], ["resistance_measured"], ["force"], {"force": "N"}, {"key": f"ep-{i}"}))
    return out


def tiny_checkpoint(tmp: Path, epochs: int = 30) -> Path:
    seqs = sim_seqs(8)
    comp = make_model("tcn", channels=8, dilations=[1, 2, 4, 8], max_epochs=epochs, patience=10, chunk=64)
    comp.fit([s.x for s in seqs[:6]], [s.y for s in seqs[:6]], valid=([s.x for s in seqs[6:]], [s.y for s in seqs[6:]]),
             seed=0, inputs=["resistance_measured"], targets=["force"], units={"resistance_measured": "ohm", "force": "N"})
    d = tmp / "ckpt"
    save_checkpoint(comp, d, extra={"input_map": {"channel": "resistance_measured", "transform": "log", "rate_hz": RATE}})
    return d


def real_recording(tmp: Path, n: int = 6) -> Path:
    eps = {}
    for i in range(n):
        f = presses(100 + i)
        s = reading(f, REALP, 100 + i, rest=800.0)
        t = np.arange(len(f)) / RATE
        eps[f"run{i}"] = {"time": Channel(t, "s", ("time",)), "sensor": Channel(s[:, None].astype(np.float32), "raw", ("time", "channel")),
                          "force": Channel(f.astype(np.float32), "N", ("time",))}
    return write_recording(tmp / "real.h5", eps, source="real", config_json="{}", root_seed=None, shard_index=0,
                           sensor_attrs={"family": "velostat", "sample_rate_hz": RATE})


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory):
    return tiny_checkpoint(tmp_path_factory.mktemp("ft"))


def test_finetune_beats_zero_shot_on_a_different_sensor(ckpt, tmp_path):
    rec = real_recording(tmp_path)
    m = run_finetune(ckpt, rec, tmp_path / "out", train_fraction=0.67, max_epochs=40, patience=10, scratch_epochs=40,
                     curve=True, compare_policies=False)
    r = m["results"]
    assert r["finetuned"]["rmse"] < 0.7 * r["zero_shot_restandardised"]["rmse"]
    assert r["finetuned"]["rmse"] < 0.5 * r["zero_shot"]["rmse"]
    sp = m["split"]  # whole runs, disjoint
    assert not (set(sp["train"]) & set(sp["test"])) and not (set(sp["valid"]) & set(sp["test"]))
    assert sp["valid"] and sp["test"] and sp["train"]
    saved = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert saved["results"]["finetuned"]["rmse"] == pytest.approx(r["finetuned"]["rmse"])
    assert [c["n_runs"] for c in saved["learning_curve"]][-1] == len(sp["train"])
    for f in ("report.md", "learning_curve.png", "predictions.png", "checkpoints/finetuned/config.json",
              "checkpoints/scratch/model.safetensors"):
        assert (tmp_path / "out" / f).is_file(), f
    # the saved fine-tuned checkpoint reproduces its test score (input affine folded into the z-score)
    ft = load_checkpoint(tmp_path / "out" / "checkpoints" / "finetuned")
    test = FT.apply_map(FT.load_recording(rec, ["sensor"], ["force"], episodes=sp["test"]), "log")
    assert FT.rmse_on(ft, test) == pytest.approx(r["finetuned"]["rmse"], rel=1e-4)


def test_head_policy_freezes_feature_layers(ckpt):
    base = load_checkpoint(ckpt)
    real = FT.apply_map(sim_seqs(3, REALP, rest=800.0), "log")
    before = {k: v.clone() for k, v in base.net.state_dict().items()}
    ft, info = FT.finetune(base, real[:2], real[2:], policy="head", lr=1e-2, max_epochs=5, patience=5)
    after = ft.net.state_dict()
    head = set(FT.head_parameter_names(ft))
    assert head == {"out.weight", "out.bias", "skip.weight", "skip.bias"}
    assert set(info["frozen"]) == set(before) - head
    for k in info["frozen"]:
        assert torch.equal(before[k], after[k]), k
    assert any(not torch.equal(before[k], after[k]) for k in head)
    # the original checkpoint object is untouched, and 'none' moves the features too
    assert all(torch.equal(before[k], v) for k, v in base.net.state_dict().items())
    ft2, info2 = FT.finetune(base, real[:2], real[2:], policy="none", lr=1e-2, max_epochs=3, patience=3)
    assert info2["frozen"] == [] and not torch.equal(before["convs.0.weight"], ft2.net.state_dict()["convs.0.weight"])


def test_split_by_run_and_bad_input(tmp_path):
    seqs = [Sequence(np.zeros((5, 1)), np.zeros((5, 1)), ["s"], ["f"], {}, {"key": f"r{i}_exp{1 + i % 2}"}) for i in range(8)]
    sp = FT.split_runs(seqs, train_fraction=None, test_glob="*exp2", seed=0)
    assert [s.key for s in sp.test] == ["r1_exp2", "r3_exp2", "r5_exp2", "r7_exp2"]
    assert len(sp.valid) == 1 and len(sp.train) == 3
    with pytest.raises(ValueError, match="matches no episode"):
        FT.split_runs(seqs, train_fraction=None, test_glob="*exp9", seed=0)
    with pytest.raises(ValueError, match="at least 3"):
        FT.split_runs(seqs[:2], train_fraction=0.5, test_glob=None, seed=0)
    res = runner.invoke(app, ["finetune", str(tmp_path / "nope"), str(tmp_path / "x.h5"), "-o", str(tmp_path / "o")])
    assert res.exit_code == 2 and "does not exist" in res.output
    bad = tmp_path / "bad.h5"
    bad.write_text("not hdf5")
    (tmp_path / "ck").mkdir()
    (tmp_path / "ck" / "config.json").write_text("{}")
    res = runner.invoke(app, ["finetune", str(tmp_path / "ck"), str(bad), "-o", str(tmp_path / "o")])
    assert res.exit_code == 2 and "not an HDF5 recording" in res.output


@needs_real
def test_lupasic_import_and_tiny_finetune_end_to_end(ckpt, tmp_path):
    from sensors.data.real_import import import_runs, lupasic_pairs

    pairs = [p for p in lupasic_pairs(REAL) if p[0].parent.name in ("pike1", "pike1_force_10")]
    rec = import_runs(pairs, tmp_path / "lupasic.h5")
    res = runner.invoke(app, ["finetune", str(ckpt), str(rec), "-o", str(tmp_path / "out"), "--test-episodes", "*exp2",
                              "--max-epochs", "5", "--patience", "3", "--no-curve"])
    assert res.exit_code == 0, res.output
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert m["input_map"]["transform"] == "log" and m["input_map"]["rate_hz"] == RATE
    assert sorted(m["split"]["test"]) == ["exp_pike1_force_10_sensor1_exp2", "exp_pike1_sensor1_exp2"]
    for k in ("zero_shot", "zero_shot_restandardised", "finetuned", "scratch"):
        assert np.isfinite(m["results"][k]["rmse"])


def test_checkpoint_norm_and_rehearsal(ckpt):
    """norm='checkpoint' starts from the pre-trained input z-score (only the learned affine moves it);
    rehearsal adds simulated examples to the training set, not to the valid runs."""
    base = load_checkpoint(ckpt)
    real = FT.apply_map(sim_seqs(3, REALP, rest=800.0), "log")
    sim = FT.apply_map(sim_seqs(2), "log")
    ft, info = FT.finetune(base, real[:1], real[1:], policy="head", lr=1e-3, max_epochs=1, patience=1, norm="checkpoint")
    a, b = np.array(info["input_affine"]["a"]), np.array(info["input_affine"]["b"])
    np.testing.assert_allclose(ft.x_norm.std, base.x_norm.std / a, rtol=1e-6)
    np.testing.assert_allclose(ft.x_norm.mean, base.x_norm.mean - b * base.x_norm.std / a, rtol=1e-6)
    ft_r, _ = FT.finetune(base, real[:1], real[1:], policy="head", lr=1e-3, max_epochs=1, patience=1, norm="real")
    assert not np.allclose(ft_r.x_norm.mean, ft.x_norm.mean)  # the real runs' statistics differ from the simulator's
    _, info2 = FT.finetune(base, real[:1], real[1:], policy="head", lr=1e-3, max_epochs=1, patience=1, norm="checkpoint",
                           rehearsal=sim)
    assert info2["n_rehearsal_episodes"] == 2 and info2["valid_mse_z_before"] == pytest.approx(info["valid_mse_z_before"])
    with pytest.raises(ValueError, match="norm"):
        FT.finetune(base, real[:1], real[1:], norm="sim")


def test_finetune_returns_the_pretrained_net_when_no_step_helps(ckpt):
    """Early stopping counts the pre-trained weights as a candidate (epoch -1): a fine-tuning whose every step
    worsens the validation loss returns the pre-trained net, not the first epoch's weights (round 3: TAMS
    fine-tuning stopped at epoch 0 on another cover's run, and 'fine-tuned' was one Adam step off the net)."""
    base = load_checkpoint(ckpt)
    sim = FT.apply_map(sim_seqs(2), "log")
    # validation: the pre-trained net's own predictions, so no weight change can improve on it
    valid = [Sequence(s.x, base.predict(s.x), s.inputs, s.targets, s.units, s.meta) for s in sim]
    real = FT.apply_map(sim_seqs(2, REALP, rest=800.0), "log")
    ft, info = FT.finetune(base, real, valid, policy="none", lr=1e-2, max_epochs=4, patience=2, norm="checkpoint")
    assert info["best_epoch"] == -1
    assert info["best_loss"] == pytest.approx(info["valid_mse_z_before"])
    x = real[0].x
    np.testing.assert_allclose(ft.predict(x), base.predict(x), rtol=1e-6, atol=1e-6)


def test_split_tail_cuts_each_run_between_presses():
    f = presses(3, T=800)
    s = Sequence(np.log(1.0 + f)[:, None], f[:, None], ["x"], ["force"], {"force": "N"}, {"key": "run"},
                 {"time": np.arange(len(f)) / RATE})
    (h,), (t,) = FT.split_tail([s], 0.25, by="samples")
    assert len(h) + len(t) == len(s)
    np.testing.assert_array_equal(np.concatenate([h.y, t.y]), s.y)
    np.testing.assert_array_equal(t.extra["time"], s.extra["time"][len(h):])
    assert f[len(h)] < 0.1 * f.max() and f[len(h) - 1] < 0.1 * f.max()  # the cut lies in a release, no press split
    assert 0.1 < len(t) / len(s) < 0.45 and t.y.max() > 0.1 * f.max()  # the tail holds presses of its own
    assert h.key == "run[head]" and t.key == "run[tail]"
    with pytest.raises(ValueError):
        FT.split_tail([s], 1.0)
    with pytest.raises(ValueError, match="tail by"):
        FT.split_tail([s], 0.25, by="time")


def _run(peaks, key, gap=30, hold=25, lead=20):
    f = [np.zeros(lead)]
    for pk in peaks:
        f += [np.linspace(0, pk, 6), np.full(hold, pk), np.linspace(pk, 0, 6), np.zeros(gap)]
    f = np.concatenate(f)
    return Sequence(np.log(1.0 + f)[:, None], f[:, None], ["x"], ["force"], {"force": "N"}, {"key": key},
                    {"time": np.arange(len(f)) / RATE})


def test_split_tail_by_presses_holds_the_last_loaded_presses():
    """Round 11: a run whose presses lie early and whose last samples hold one tiny press (the 1 N Lupasic run) gets a
    tail of the last ceil(frac n) of its n loaded presses (peak >= 10 % of the full scale), not a long stretch of
    one touch; a run with fewer than two loaded presses gives no tail; the sample cut (rounds 4-10) gave it one."""
    early = _run([10.0, 12.0, 11.0, 9.0, 13.0, 2.0], "early")
    early = Sequence(np.concatenate([early.x, np.zeros((600, 1))]), np.concatenate([early.y, np.zeros((600, 1))]),
                     early.inputs, early.targets, early.units, early.meta, {})  # a long unloaded end
    even = _run([20.0, 22.0, 21.0, 19.0, 20.0, 21.0, 22.0, 20.0], "even")
    touches = _run([1.0, 0.9, 1.2, 0.8], "touches")  # below 10 % of the 22 N full scale
    heads, tails = FT.split_tail([early, even, touches], 0.25)
    assert [t.key for t in tails] == ["early[tail]", "even[tail]"] and len(heads) == 3
    assert heads[2].key == "touches[head]" and len(heads[2]) == len(touches)  # no tail: all of it trains

    def tail_peaks(t, fs=22.0):
        f = t.y[:, 0]
        return [round(float(f[sl].max()), 2) for sl in CF.presses_of(f, 0.1 * fs)]

    assert tail_peaks(tails[0]) == [9.0, 13.0]  # ceil(0.25 x 5) = 2 loaded presses (the 2 N touch follows them)
    assert tail_peaks(tails[1]) == [22.0, 20.0]  # ceil(0.25 x 8) = 2
    for s, h, t in ((early, heads[0], tails[0]), (even, heads[1], tails[1])):
        np.testing.assert_array_equal(np.concatenate([h.y, t.y]), s.y)
        assert s.y[len(h), 0] == 0.0 and s.y[len(h) - 1, 0] == 0.0  # cut in a release
    # the sample cut of rounds 4-10 cuts the early run after its loaded presses: a tail of the 2 N touch (a press at
    # 10 % of the run's own peak) and the unloaded rest, more than a quarter of the run
    _, (t_old,) = FT.split_tail([early], 0.25, by="samples")
    assert tail_peaks(t_old, 22.0) == [] and tail_peaks(t_old, 13.0) == [2.0] and len(t_old) > 0.25 * len(early)
    # a full scale given by the user (a rated force) sets the threshold: at 150 N (15 N) the early run has no loaded
    # press and gives no tail; at 300 N no run has two, so every detected press counts (validation never vanishes)
    assert [t.key for t in FT.split_tail([early, even], 0.25, full_scale_n=150.0)[1]] == ["even[tail]"]
    _, tails300 = FT.split_tail([early, even], 0.25, full_scale_n=300.0)
    assert [t.key for t in tails300] == ["early[tail]", "even[tail]"]
    assert tail_peaks(tails300[0], 1.0) == [13.0, 2.0]  # ceil(0.25 x 6) = 2 of its 6 presses
    with pytest.raises(ValueError, match="full scale"):
        FT.split_tail([early], 0.25, full_scale_n=float("nan"))


def test_l2sp_penalty_pulls_toward_the_pretrained_weights(ckpt):
    """L2-SP (Li et al. 2018): the penalty is alpha/2 ||w - w0||^2 (beta on the named new parameters), zero at the
    anchor; fine-tuning with it ends nearer the pre-trained weights than plain fine-tuning from the same start."""
    base = load_checkpoint(ckpt)
    lin = torch.nn.Linear(3, 2)
    pen = FT.l2sp_penalty(lin, alpha=0.5, beta=2.0, new=("bias",))
    assert float(pen().detach()) == 0.0
    w0, b0 = lin.weight.detach().clone(), lin.bias.detach().clone()
    with torch.no_grad():
        lin.weight.add_(0.1)
        lin.bias.sub_(0.2)
    assert float(pen().detach()) == pytest.approx(0.5 * 0.5 * 6 * 0.01 + 0.5 * 2.0 * 2 * 0.04, rel=1e-5)
    pen().backward()  # its gradient points back to the anchor: alpha (w - w0), beta (b - b0)
    np.testing.assert_allclose(lin.weight.grad.numpy(), 0.5 * (lin.weight - w0).detach().numpy(), rtol=1e-5)
    np.testing.assert_allclose(lin.bias.grad.numpy(), 2.0 * (lin.bias - b0).detach().numpy(), rtol=1e-5)

    real = FT.apply_map(sim_seqs(3, REALP, rest=800.0), "log")
    w_pre = torch.cat([p.detach().flatten() for p in base.net.parameters()])

    def moved(**kw):
        ft, info = FT.finetune(base, real[:2], real[2:], policy="none", lr=1e-2, max_epochs=4, patience=10,
                               norm="checkpoint", **kw)
        return float(torch.linalg.norm(torch.cat([p.detach().flatten() for p in ft.net.parameters()]) - w_pre)), info

    d_plain, info_p = moved()
    d_l2sp, info_l = moved(method="l2sp", l2sp_alpha=50.0)
    assert info_p["method"] == "plain" and info_l["method"] == "l2sp" and info_l["l2sp_alpha"] == 50.0
    assert info_p["best_epoch"] >= 0 and info_l["best_epoch"] >= 0
    assert d_l2sp < 0.8 * d_plain
    with pytest.raises(ValueError, match="method"):
        FT.finetune(base, real[:1], real[1:], method="sgd")


def test_lpft_probes_the_head_before_every_layer(ckpt):
    """LP-FT (Kumar et al. 2022): stage 1 trains only the head (policy 'head'), stage 2 every layer from there;
    the validation loss before stage 1 is the pre-trained net's, and stage 2 never ends above stage 1's best."""
    base = load_checkpoint(ckpt)
    real = FT.apply_map(sim_seqs(3, REALP, rest=800.0), "log")
    ft, info = FT.finetune(base, real[:2], real[2:], policy="none", lr=1e-2, max_epochs=4, patience=10,
                           norm="checkpoint", method="lpft")
    _, plain = FT.finetune(base, real[:2], real[2:], policy="none", lr=1e-2, max_epochs=1, patience=1, norm="checkpoint")
    lp = info["linear_probe"]
    assert info["method"] == "lpft" and info["frozen"] == []
    assert lp["n_trainable"] < info["n_trainable"]  # the probe: head + input affine only
    assert info["valid_mse_z_before"] == pytest.approx(plain["valid_mse_z_before"])
    assert info["best_loss"] <= lp["best_loss"] + 1e-9


def test_shrink_perturb_starts_from_shrunk_weights_plus_a_fresh_initialisation(ckpt):
    """Shrink-and-perturb (Ash & Adams 2020): w <- SP_SHRINK w + SP_NOISE w0, w0 the layer's own fresh initialisation
    drawn from the seed (the same seed, the same start); the fine-tuning then runs as plain and reports the factors."""
    lin = torch.nn.Linear(4, 3)
    w = [p.detach().clone() for p in lin.parameters()]
    fresh = torch.nn.Linear(4, 3)
    torch.manual_seed(7)
    fresh.reset_parameters()
    FT._shrink_perturb(lin, 0.5, 0.1, 7)
    for p, p0, q in zip(lin.parameters(), w, fresh.parameters()):
        torch.testing.assert_close(p.detach(), 0.5 * p0 + 0.1 * q.detach())
    base = load_checkpoint(ckpt)
    real = FT.apply_map(sim_seqs(3, REALP, rest=800.0), "log")
    runs = [FT.finetune(base, real[:2], real[2:], policy="none", lr=1e-2, max_epochs=2, patience=5, norm="checkpoint",
                        method="shrink_perturb", seed=3) for _ in range(2)]
    (a, info), (b, _) = runs
    assert info["method"] == "shrink_perturb" and info["sp_shrink"] == FT.SP_SHRINK and info["sp_noise"] == FT.SP_NOISE
    for p, q in zip(a.net.parameters(), b.net.parameters()):
        torch.testing.assert_close(p, q)  # deterministic
    _, plain = FT.finetune(base, real[:2], real[2:], policy="none", lr=1e-2, max_epochs=1, patience=1, norm="checkpoint")
    assert info["valid_mse_z_before"] != pytest.approx(plain["valid_mse_z_before"])  # it starts elsewhere
    assert "shrink_perturb" in FT.FINETUNE_METHODS


def test_finetune_with_the_checkpoint_scales_reaches_scratch_on_mismatched_ranges(ckpt):
    """Tenth round of issue 15: the real runs span other ranges than the simulated data (pike1 -> pike2: the real
    force sd 1.4-1.8 x the checkpoint's z-score, mean +0.4-1.0 sd; ln reading sd 1.4-1.6 x, mean -0.4 to -0.7 sd).
    Fine-tuning keeps the checkpoint's z-scores (norm 'checkpoint'); with the same data, lr and epochs it must reach
    the validation loss of a net trained from scratch on the real runs' own z-scores, or the kept scales would be a
    handicap of the fine-tuning (a toy sensor with that mismatch: a steeper law, forces to 48 N against 30 N)."""
    from learn.normalize import ZScore

    base = load_checkpoint(ckpt)
    steep = FitParams(gain=1.0, exponent=1.3, amplitude=1.0, p_c_pa=3e4, tau_min_s=0.5, tau_max_s=20.0, n_creep=4)

    def runs(idx):
        out = []
        for i in idx:
            f = presses(200 + i, fmax=48.0)
            out.append(Sequence(np.log(reading(f, steep, 200 + i, rest=60_000.0))[:, None], f[:, None],
                                ["resistance_measured"], ["force"], {"force": "N"}, {"key": f"r{i}"}))
        return out

    tr, va = runs(range(4)), runs(range(6, 8))
    zx, zy = ZScore.fit([s.x for s in tr]), ZScore.fit([s.y for s in tr])
    assert zy.std[0] / base.y_norm.std[0] > 1.3 and (zy.mean[0] - base.y_norm.mean[0]) / base.y_norm.std[0] > 0.2
    assert zx.std[0] / base.x_norm.std[0] > 1.2 and (zx.mean[0] - base.x_norm.mean[0]) / base.x_norm.std[0] < -0.2
    kw = dict(seed=0, max_epochs=30, patience=30)
    ft, _ = FT.finetune(base, tr, va, policy="none", lr=2e-3, norm="checkpoint", **kw)
    sc = FT.train_from_scratch("tcn", base.hparams, tr, va, **kw)
    assert FT.rmse_on(base, va) > 3 * FT.rmse_on(sc, va)  # the pre-trained net alone is far off: there is a gap to close
    assert FT.rmse_on(ft, va) <= FT.rmse_on(sc, va)


def test_patience_replayed_on_one_probed_run_gives_the_early_stopped_fit(ckpt):
    """Training does not depend on the patience, and the on_epoch probe does not change it: a fine-tuning run to
    the epoch cap, probed each epoch, holds the early-stopped run's epochs, and `stopping_epoch` replayed on its
    validation curve gives the epoch the early-stopped run restored (tenth round's bench_s2r_patience.py)."""
    from learn.train import stopping_epoch

    base = load_checkpoint(ckpt)
    real = FT.apply_map(sim_seqs(3, REALP, rest=800.0), "log")
    kw = dict(policy="none", lr=2e-3, norm="checkpoint", seed=1)
    seen: list[tuple[int, float]] = []
    full, fi = FT.finetune(base, real[:2], real[2:], max_epochs=12, patience=12,
                           on_epoch=lambda e, c: seen.append((e, FT.rmse_on(c, real[2:]))), **kw)
    short, si = FT.finetune(base, real[:2], real[2:], max_epochs=12, patience=2, **kw)
    assert [e for e, _ in seen] == list(range(-1, 12))
    assert si["epochs"] < 12 and fi["valid_loss"][: si["epochs"]] == si["valid_loss"]
    curve = [fi["valid_mse_z_before"], *fi["valid_loss"]]
    assert stopping_epoch(curve, 2) == si["best_epoch"] and stopping_epoch(curve, 12) == fi["best_epoch"]
    # the probe saw the weights the run restores: its RMSE at the best epoch is the returned net's
    assert dict(seen)[fi["best_epoch"]] == pytest.approx(FT.rmse_on(full, real[2:]), rel=1e-5)
    assert dict(seen)[-1] == pytest.approx(FT.rmse_on(base, real[2:]), rel=1e-5)
    with pytest.raises(ValueError, match="on_epoch"):
        FT.finetune(base, real[:2], real[2:], method="lpft", on_epoch=lambda e, c: None, max_epochs=2, **kw)
