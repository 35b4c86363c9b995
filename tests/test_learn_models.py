"""learn models on a small synthetic hysteretic sensor: each beats the trivial mean on held-out
episodes, streaming equals batch, checkpoints round-trip, training is seeded, estimators are exact."""

import json

import numpy as np
import pytest
import torch

from learn.checkpoint import load_checkpoint, save_checkpoint
from learn.data import Sequence, stratified_split
from learn.models import MODELS, edge_windows, make_model
from learn.models.classical import PolynomialRegression
from learn.train import TrainConfig, train_model

torch.set_num_threads(1)

TINY = {
    "mean": {}, "linear": {}, "cubic": {},
    "mlp": {"max_epochs": 15, "patience": 5, "hidden": [16]},
    "gru": {"max_epochs": 15, "patience": 5, "hidden": [8], "window": 20, "train_stride": 3, "lr": 1e-2, "batch_size": 32},
    "lstm": {"max_epochs": 15, "patience": 5, "hidden": [16, 8], "window": 20, "train_stride": 3, "lr": 1e-2, "batch_size": 32},
    "tcn": {"max_epochs": 15, "patience": 5, "channels": 8, "dilations": [1, 2, 4, 8]},
    "ensemble": {"member": "tcn", "n_members": 2,
                 "member_hparams": {"max_epochs": 15, "patience": 5, "channels": 8, "dilations": [1, 2, 4, 8]}},
}


def synth(n=12, seed=0):
    """Force sinusoids at 0.5/1/2 Hz; the 'sensor' is a lagged (first-order, 60 ms), exponential reading."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        f = [0.5, 1.0, 2.0][k % 3]
        t = np.arange(220) / 100.0
        tau = np.clip(t - 0.2, 0, None)
        F = rng.uniform(1, 5) * 0.5 * (1 - np.cos(2 * np.pi * f * tau)) * (tau < 2 / f)
        lag = np.zeros_like(F)
        a = np.exp(-0.01 / 0.06)
        for i in range(1, len(F)):
            lag[i] = a * lag[i - 1] + (1 - a) * F[i]
        R = 40.0 * np.exp(-0.08 * lag) + rng.normal(0, 0.01, len(F))
        out.append(Sequence(R[:, None], F[:, None], ["r"], ["f"], {"r": "ohm", "f": "N"},
                            {"key": f"s/ep-{k}", "frequency_hz": f}, {"drive": F.copy()}))
    return out


@pytest.fixture(scope="module")
def fitted():
    sp = stratified_split(synth(), "frequency_hz", 0, (0.6, 0.1, 0.3))
    tr, va = sp["train"], sp["valid"]
    models = {}
    for kind, hp in TINY.items():
        m = make_model(kind, **hp)
        m.fit([s.x for s in tr], [s.y for s in tr], valid=([s.x for s in va], [s.y for s in va]), seed=3,
              inputs=["r"], targets=["f"], units={"r": "ohm", "f": "N"})
        models[kind] = m
    return models, sp["test"]


def _rmse(m, seqs):
    return float(np.sqrt(np.mean(np.concatenate([(m.predict(s.x) - s.y) ** 2 for s in seqs]))))


def test_registry_has_the_paper_models_and_ours():
    assert {"mean", "linear", "cubic", "mlp", "gru", "lstm", "tcn"} <= set(MODELS)
    with pytest.raises(ValueError, match="unknown hyper-parameters"):
        make_model("lstm", hiden=[3])


@pytest.mark.parametrize("kind", [k for k in TINY if k != "mean"])
def test_each_model_beats_the_mean_on_held_out(fitted, kind):
    models, test = fitted
    assert _rmse(models[kind], test) < 0.5 * _rmse(models["mean"], test)


@pytest.mark.parametrize("kind", list(TINY))
def test_streaming_equals_batch(fitted, kind):
    models, test = fitted
    m, x = models[kind], test[0].x
    st = m.stream()
    y_stream = st.run(x)
    np.testing.assert_allclose(y_stream, m.predict(x), rtol=1e-4, atol=1e-4)
    st.reset()  # reset starts over
    np.testing.assert_allclose(st.run(x[:30]), y_stream[:30], rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("kind", list(TINY))
def test_checkpoint_round_trip(fitted, kind, tmp_path):
    m = fitted[0][kind]
    x = fitted[1][0].x
    d = save_checkpoint(m, tmp_path / kind, dataset={"manifest_sha256": "abc"})
    cfg = json.loads((d / "config.json").read_text())
    assert cfg["model_class"] == kind and cfg["inputs"] == [{"name": "r", "units": "ohm"}]
    assert cfg["normalization"]["x"]["mean"] == pytest.approx(list(m.x_norm.mean))
    assert cfg["dataset"]["manifest_sha256"] == "abc" and cfg["seed"] == 3 and "version" in cfg
    assert (d / "model.safetensors").is_file() and not list(d.glob("*.pt")) and not list(d.glob("*.pkl"))
    m2 = load_checkpoint(d)
    np.testing.assert_array_equal(m2.predict(x), m.predict(x))
    np.testing.assert_allclose(m2.stream().run(x[:40]), m.predict(x[:40]), rtol=1e-4, atol=1e-4)


def test_ensemble_is_the_mean_of_its_seeded_members(fitted, tmp_path):
    models, test = fitted
    ens, tcn, x = models["ensemble"], models["tcn"], test[0].x
    assert [m.seed for m in ens.members] == [3, 4] and ens.history["member_seeds"] == [3, 4]
    # member 0 is the plain model fitted with the ensemble's seed; member 1 differs only by its seed
    np.testing.assert_array_equal(ens.members[0].predict(x), tcn.predict(x))
    p0, p1 = ens.predict_members(x)
    assert not np.array_equal(p0, p1)
    np.testing.assert_array_equal(ens.predict(x), np.mean([p0, p1], axis=0))
    assert ens.context == tcn.context and ens.temporal
    # streaming: every member stepped, averaged
    np.testing.assert_allclose(ens.stream().run(x), np.mean([m.stream().run(x) for m in ens.members], axis=0),
                               rtol=1e-12, atol=1e-12)
    # checkpoint: every member's tensors (and norms) under its prefix, nothing pickled
    d = save_checkpoint(ens, tmp_path / "ens")
    cfg = json.loads((d / "config.json").read_text())
    assert cfg["hyper_parameters"]["member"] == "tcn" and cfg["hyper_parameters"]["n_members"] == 2
    names = set(cfg["tensors"])
    assert {n.split(".", 1)[0] for n in names} == {"member0", "member1"}
    assert {f"member{k}.{n}" for k in (0, 1) for n in tcn.state_tensors()} <= names
    assert "member1.norm.y_std" in names
    back = load_checkpoint(d)
    for a, b in zip(back.members, ens.members):
        np.testing.assert_array_equal(a.predict(x), b.predict(x))
    assert [m.seed for m in back.members] == [3, 4]
    # the ensemble beats its trivial baseline and is no worse than its average member
    assert _rmse(ens, test) < 0.5 * _rmse(models["mean"], test)
    assert _rmse(ens, test) <= np.mean([_rmse(m, test) for m in ens.members]) + 1e-12


def test_ensemble_errors():
    with pytest.raises(ValueError, match="member must be"):
        make_model("ensemble", member="nope")
    with pytest.raises(ValueError, match="member must be"):
        make_model("ensemble", member="ensemble")
    with pytest.raises(ValueError, match="n_members"):
        make_model("ensemble", n_members=0)
    with pytest.raises(ValueError, match="unknown hyper-parameters"):
        make_model("ensemble", member_hparams={"chanels": 3})
    with pytest.raises(RuntimeError, match="not fitted"):
        make_model("ensemble").predict(np.zeros((5, 1)))


def test_training_is_seeded():
    seqs = synth(6)
    xs, ys = [s.x for s in seqs], [s.y for s in seqs]
    hp = {"max_epochs": 2, "patience": 2, "channels": 4, "dilations": [1, 2]}
    a = make_model("tcn", **hp).fit(xs, ys, seed=5).predict(xs[0])
    b = make_model("tcn", **hp).fit(xs, ys, seed=5).predict(xs[0])
    c = make_model("tcn", **hp).fit(xs, ys, seed=6).predict(xs[0])
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_early_stopping_stops_after_patience():
    net = torch.nn.Linear(1, 1)
    x = torch.randn(64, 1)
    h = train_model(net, (x, 2 * x), (x, 2 * x), TrainConfig(lr=0.0, max_epochs=50, patience=3), progress=False)
    assert h.stopped_early and h.epochs == 4 and h.best_epoch == 0


def test_polynomial_regression_exact_and_online():
    rng = np.random.default_rng(0)
    X = rng.uniform(-2, 2, (200, 1))
    y = 1.0 - 2.0 * X + 0.5 * X**3
    est = PolynomialRegression(3).fit(X, y)
    np.testing.assert_allclose(est.coef_, [[1.0, -2.0, 0.0, 0.5]], atol=1e-6)
    online = PolynomialRegression(3).partial_fit(X[:80], y[:80]).partial_fit(X[80:], y[80:])
    np.testing.assert_allclose(online.predict(X), est.predict(X), atol=1e-9)
    assert est.get_params() == {"degree": 3, "ridge": 1e-10}


def test_edge_windows_and_split():
    z = np.arange(5.0)[:, None]
    w = edge_windows(z, 3)
    assert w.shape == (5, 3, 1)
    np.testing.assert_array_equal(w[0, :, 0], [0, 0, 0])
    np.testing.assert_array_equal(w[4, :, 0], [2, 3, 4])
    sp = stratified_split(synth(), "frequency_hz", 1)
    assert {s.meta["frequency_hz"] for s in sp["test"]} == {0.5, 1.0, 2.0}
    keys = [s.key for v in sp.values() for s in v]
    assert len(keys) == len(set(keys)) == 12


def test_tcn_log_inputs_stream_checkpoint_and_errors(tmp_path):
    """log_inputs: ln R joins R (stats as net buffers): beats the mean, streams = batch, round-trips, and refuses
    a non-positive channel or an index outside the inputs."""
    sp = stratified_split(synth(), "frequency_hz", 0, (0.6, 0.1, 0.3))
    tr, va, te = sp["train"], sp["valid"], sp["test"]
    hp = {**TINY["tcn"], "log_inputs": [0]}
    m = make_model("tcn", **hp).fit([s.x for s in tr], [s.y for s in tr], valid=([s.x for s in va], [s.y for s in va]),
                                   seed=3, inputs=["r"], targets=["f"], units={"r": "ohm", "f": "N"})
    mean = make_model("mean").fit([s.x for s in tr], [s.y for s in tr])
    assert _rmse(m, te) < 0.5 * _rmse(mean, te)
    lr = np.log(np.concatenate([s.x[:, 0] for s in tr]))
    assert float(m.net.feat.l_mean[0]) == pytest.approx(lr.mean(), rel=1e-5)
    assert float(m.net.feat.l_std[0]) == pytest.approx(lr.std(), rel=1e-4)
    x = te[0].x
    np.testing.assert_allclose(m.stream().run(x), m.predict(x), rtol=1e-4, atol=1e-4)
    save_checkpoint(m, tmp_path / "ck")
    m2 = load_checkpoint(tmp_path / "ck")
    assert m2.hparams["log_inputs"] == [0]
    np.testing.assert_array_equal(m2.predict(x), m.predict(x))
    with pytest.raises(ValueError, match="positive"):
        make_model("tcn", **hp).fit([s.x - 100.0 for s in tr], [s.y for s in tr])
    with pytest.raises(ValueError, match="outside"):
        make_model("tcn", **{**hp, "log_inputs": [1]}).fit([s.x for s in tr], [s.y for s in tr])


def test_play_gaps_hand_computed_and_wiping_out():
    """Play (backlash) operator of width r: the state follows u only once u leaves [p - r, p + r]; the gap
    (p - u) / r is +-1 on a monotone branch, and a minor loop inside a major one leaves the state where the major
    branch put it (return-point memory)."""
    from learn.models.tcn import play_gaps

    u = np.array([0.0, 1.0, 2.0, 1.5, 1.0, 0.5, 1.0])
    g, p = play_gaps(u, np.array([0.5]))
    # states: 0, 0.5, 1.5, 1.5, 1.5, 1.0, 1.0
    np.testing.assert_allclose(g[:, 0], (np.array([0.0, 0.5, 1.5, 1.5, 1.5, 1.0, 1.0]) - u) / 0.5)
    assert p[0] == pytest.approx(1.0)
    # monotone rise: every gap reaches -1; stepping through the series in pieces gives the same gaps
    ur = np.linspace(0, 3, 31)
    r = np.array([0.1, 0.4, 1.0])
    gr, _ = play_gaps(ur, r)
    assert np.allclose(gr[-1], -1.0)
    g1, p1 = play_gaps(ur[:10], r)
    g2, _ = play_gaps(ur[10:], r, p1)
    np.testing.assert_allclose(np.concatenate([g1, g2]), gr)
    # wiping out: a minor loop smaller than the widest operator's width does not move that operator's state
    um = np.concatenate([ur, [2.8, 2.6, 2.8, 3.0]])
    _, pm = play_gaps(um, r)
    assert pm[2] == pytest.approx(2.0)


def test_tcn_play_bank_stream_checkpoint_and_errors(tmp_path):
    """play_widths: a play bank on ln R joins the inputs; widths scale with the training span, streaming equals
    batch, the checkpoint round-trips, and it refuses a bank without log_inputs or a width outside (0, 1]."""
    sp = stratified_split(synth(), "frequency_hz", 0, (0.6, 0.1, 0.3))
    tr, va, te = sp["train"], sp["valid"], sp["test"]
    hp = {**TINY["tcn"], "log_inputs": [0], "play_widths": [0.05, 0.3]}
    m = make_model("tcn", **hp).fit([s.x for s in tr], [s.y for s in tr], valid=([s.x for s in va], [s.y for s in va]),
                                   seed=3, inputs=["r"], targets=["f"], units={"r": "ohm", "f": "N"})
    mean = make_model("mean").fit([s.x for s in tr], [s.y for s in tr])
    assert _rmse(m, te) < 0.5 * _rmse(mean, te)
    lr = np.log(np.concatenate([s.x[:, 0] for s in tr]))
    span = (lr.max() - lr.min()) / lr.std()
    np.testing.assert_allclose(m.net.play_r.numpy(), [0.05 * span, 0.3 * span], rtol=1e-4)
    x = te[0].x
    np.testing.assert_allclose(m.stream().run(x), m.predict(x), rtol=1e-4, atol=1e-4)
    save_checkpoint(m, tmp_path / "ck")
    m2 = load_checkpoint(tmp_path / "ck")
    np.testing.assert_array_equal(m2.predict(x), m.predict(x))
    with pytest.raises(ValueError, match="log_inputs"):
        make_model("tcn", **{**hp, "log_inputs": None}).fit([s.x for s in tr], [s.y for s in tr])
    with pytest.raises(ValueError, match="play_widths"):
        make_model("tcn", **{**hp, "play_widths": [0.0, 0.3]}).fit([s.x for s in tr], [s.y for s in tr])


def test_batched_tcn_members_equal_sequential_training():
    """fit_ensembles trains every member of two ensembles (input sets of 1 and 2 channels) as one grouped network:
    each member equals the same member trained alone by train_model (same seed) up to float summation order:
    the same epochs and best epoch, validation losses within 1e-6 (z-scored MSE ~0.05-1), weights within 1e-5
    and estimates within 1e-5 N of a ~3 N force (measured: ~1e-7, 3e-8, 1e-6)."""
    from learn.models.ensemble import fit_ensembles
    from learn.models.tcn import train_tcn_group

    sp = stratified_split(synth(), "frequency_hz", 0, (0.6, 0.1, 0.3))
    tr, va, te = sp["train"], sp["valid"], sp["test"]
    hp = {"max_epochs": 10, "patience": 1, "channels": 8, "dilations": [1, 2, 4, 8], "lr": 2e-2}
    two = lambda x: np.column_stack([x, np.log(x)])
    sets = {"one": lambda x: x, "two": two}
    data = {k: ([f(s.x) for s in tr], [s.y for s in tr], ([f(s.x) for s in va], [s.y for s in va])) for k, f in sets.items()}
    seq = {k: make_model("ensemble", member="tcn", n_members=2, member_hparams=hp).fit(*d[:2], valid=d[2], seed=3)
           for k, d in data.items()}
    bat = {k: make_model("ensemble", member="tcn", n_members=2, member_hparams=hp, batched=True) for k in data}
    fit_ensembles([(bat[k], {"xs": d[0], "ys": d[1], "valid": d[2], "seed": 3}) for k, d in data.items()])
    stopped = 0
    for k, f in sets.items():
        for a, b in zip(seq[k].members, bat[k].members):
            assert a.seed == b.seed and b.history["batched_members"] == 4
            assert (a.history["epochs"], a.history["best_epoch"]) == (b.history["epochs"], b.history["best_epoch"])
            stopped += a.history["stopped_early"]
            np.testing.assert_allclose(a.history["valid_loss"], b.history["valid_loss"], rtol=0, atol=1e-6)
            for name, t in a.net.state_dict().items():
                np.testing.assert_allclose(t.numpy(), b.net.state_dict()[name].numpy(), rtol=0, atol=1e-5)
            x = f(te[0].x)
            np.testing.assert_allclose(a.predict(x), b.predict(x), rtol=0, atol=1e-5)
        x = f(te[0].x)
        np.testing.assert_allclose(seq[k].predict(x), bat[k].predict(x), rtol=0, atol=1e-5)
    assert stopped >= 1  # a member left the group early (the compaction path ran)
    # the one-ensemble path (Ensemble.fit with batched=True) is the same training
    one = make_model("ensemble", member="tcn", n_members=2, member_hparams=hp, batched=True).fit(*data["one"][:2],
                                                                                                 valid=data["one"][2], seed=3)
    np.testing.assert_allclose(one.predict(te[0].x), bat["one"].predict(te[0].x), rtol=0, atol=1e-5)
    with pytest.raises(ValueError, match="every training setting"):
        a, b = (make_model("tcn", **h) for h in (hp, {**hp, "lr": 1e-2}))
        for m in (a, b):
            m.fit_setup(*data["one"][:2])
            m.net = m._build()
        train_tcn_group([a.net, b.net], [m._examples(*m.fit_setup(*data["one"][:2])[:2], True) for m in (a, b)],
                        [None, None], [a.train_config(0), b.train_config(1)])


@pytest.mark.gpu
@pytest.mark.parametrize("diff_loss_weight", [0.0, 1.0])
def test_batched_tcn_members_on_cuda_match_sequential(diff_loss_weight):
    """On a CUDA device the batched members (grouped convolutions) follow the members trained alone there (same
    seeds): the same epoch count and estimates within 2e-3 N of a ~3 N force (TF32 convolutions sum differently);
    with the plain MSE and with derivative matching (velostat's default since session 13)."""
    if not torch.cuda.is_available():
        pytest.skip("no CUDA device")
    from learn.models.ensemble import fit_ensembles
    from learn.train import training_device

    sp = stratified_split(synth(), "frequency_hz", 0, (0.6, 0.1, 0.3))
    tr, va, te = sp["train"], sp["valid"], sp["test"]
    hp = {"max_epochs": 4, "patience": 10, "channels": 8, "dilations": [1, 2, 4, 8],
          "diff_loss_weight": diff_loss_weight, "diff_loss_lag": 5}
    d = ([s.x for s in tr], [s.y for s in tr], ([s.x for s in va], [s.y for s in va]))
    with training_device("cuda"):
        seq = make_model("ensemble", member="tcn", n_members=2, member_hparams=hp).fit(*d[:2], valid=d[2], seed=3)
        bat = make_model("ensemble", member="tcn", n_members=2, member_hparams=hp, batched=True)
        fit_ensembles([(bat, {"xs": d[0], "ys": d[1], "valid": d[2], "seed": 3})])
    for a, b in zip(seq.members, bat.members):
        assert a.history["epochs"] == b.history["epochs"] == 4 and b.history["device"].startswith("cuda")
        np.testing.assert_allclose(a.predict(te[0].x), b.predict(te[0].x), rtol=0, atol=2e-3)


def test_tcn_residual_input_corrects_a_static_calibration(tmp_path):
    """residual_input: the net trains on y - x[channel] and its estimate is x[channel] + its output. On the lagged
    exponential reading, the channel is the static inverse ln(40 ohm / R) / 0.08 (blind to the 60 ms lag): the
    residual net beats it on held-out episodes, predict = channel + the net's own output, streams = batch, the
    hyper-parameter round-trips through a checkpoint, the batched ensemble equals its members trained alone, and a
    channel that is not an input or two targets are refused."""
    from learn.models.ensemble import fit_ensembles

    sp = stratified_split(synth(), "frequency_hz", 0, (0.6, 0.1, 0.3))
    tr, va, te = sp["train"], sp["valid"], sp["test"]
    feats = lambda s: np.column_stack([s.x[:, 0], np.log(40.0 / s.x[:, 0]) / 0.08])
    xs, ys, vx, vy = [feats(s) for s in tr], [s.y for s in tr], [feats(s) for s in va], [s.y for s in va]
    hp = {**TINY["tcn"], "residual_input": "f_static_n"}
    names = ["r", "f_static_n"]
    m = make_model("tcn", **hp).fit(xs, ys, valid=(vx, vy), seed=3, inputs=names, targets=["f"])
    err = lambda p: float(np.sqrt(np.mean(np.concatenate([(pp - s.y) ** 2 for pp, s in zip(p, te)]))))
    static = err([feats(s)[:, 1:] for s in te])
    assert err([m.predict(feats(s)) for s in te]) < 0.7 * static
    y_res = np.concatenate([y - x[:, 1:] for x, y in zip(xs, ys)])
    assert m.y_norm.mean[0] == pytest.approx(y_res.mean(), rel=1e-9)  # the z-score is the residual's
    x = feats(te[0])
    own = m.y_norm.invert(m._predict_z(m.x_norm.apply(x)))
    np.testing.assert_allclose(m.predict(x), own + x[:, 1:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(m.stream().run(x), m.predict(x), rtol=1e-4, atol=1e-4)
    save_checkpoint(m, tmp_path / "ck")
    m2 = load_checkpoint(tmp_path / "ck")
    assert m2.hparams["residual_input"] == "f_static_n"
    np.testing.assert_array_equal(m2.predict(x), m.predict(x))
    seq = make_model("ensemble", member="tcn", n_members=2, member_hparams=hp).fit(xs, ys, valid=(vx, vy), seed=3,
                                                                                   inputs=names)
    bat = make_model("ensemble", member="tcn", n_members=2, member_hparams=hp, batched=True)
    fit_ensembles([(bat, {"xs": xs, "ys": ys, "valid": (vx, vy), "seed": 3, "inputs": names})])
    np.testing.assert_allclose(seq.predict(x), bat.predict(x), rtol=0, atol=1e-5)
    with pytest.raises(ValueError, match="not an input"):
        make_model("tcn", **hp).fit(xs, ys, inputs=["r", "f_other_n"])
    with pytest.raises(ValueError, match="one target"):
        make_model("tcn", **hp).fit(xs, [np.column_stack([y, y]) for y in ys], inputs=names)


def test_tcn_diff_loss_hand_computed():
    """diff_matched_mse on a hand-computable chunk: e = pred - y = -[0, 1, 3, 6] (one chunk of 4 outputs), lag 2:
    levels (0 + 1 + 9 + 36) / 4 = 11.5, differences e_2 - e_0 = -3, e_3 - e_1 = -5 -> (9 + 25) / 2 = 17; a level
    offset has no difference term, a ramp e_t = a t has (a k)^2; the sum form / numel is the mean form."""
    from learn.models.tcn import _diffs, diff_matched_mse

    y = torch.tensor([0.0, 1.0, 3.0, 6.0]).reshape(1, 4, 1)
    p = torch.zeros_like(y)
    assert float(diff_matched_mse(p, y, 1.0, 2)) == pytest.approx(11.5 + 17.0)
    assert float(diff_matched_mse(p, y, 0.5, 2)) == pytest.approx(11.5 + 8.5)
    assert float(diff_matched_mse(p, y, 0.5, 2, reduction="sum")) / 4 == pytest.approx(11.5 + 8.5)
    assert float(diff_matched_mse(y + 2.0, y, 1.0, 2)) == pytest.approx(4.0)  # offset: levels only
    t = torch.arange(8.0).reshape(1, 8, 1)
    assert float(diff_matched_mse(0.5 * t, 0 * t, 1.0, 3) - (0.25 * t * t).mean()) == pytest.approx(1.5**2)
    np.testing.assert_array_equal(_diffs(-y.transpose(1, 2), 2).numpy().ravel(), [-3.0, -5.0])  # [.., L] layout
    with pytest.raises(ValueError, match="diff_loss_lag"):
        diff_matched_mse(p, y, 1.0, 4)
    with pytest.raises(ValueError, match="diff_loss_weight"):
        make_model("tcn", diff_loss_weight=-1.0).diff_loss()


def test_tcn_diff_loss_trains_on_chunks_and_batches_equal():
    """Derivative matching in training: weight 0 is today's training bit for bit (losses and weights equal to
    train_model's plain MSE on the same net and examples, whatever the lag); at lr 0 the first epoch's training and
    validation losses equal mean(e^2) + w mean((D_k e)^2) computed by hand in numpy over every chunk's outputs
    (differences inside a chunk only); the batched group equals the members trained one after another with the
    new loss (same epochs and best epoch, training and validation losses within 1e-6, estimates within 1e-5;
    measured ~1e-7, 3e-7: float summation order, which grows with epochs at a larger learning rate)."""
    from learn.models.ensemble import fit_ensembles
    from learn.train import seeded

    sp = stratified_split(synth(), "frequency_hz", 0, (0.6, 0.1, 0.3))
    tr, va, te = sp["train"], sp["valid"], sp["test"]
    xs, ys, vx, vy = [s.x for s in tr], [s.y for s in tr], [s.x for s in va], [s.y for s in va]
    hp = {"max_epochs": 3, "patience": 5, "channels": 8, "dilations": [1, 2, 4, 8], "lr": 2e-2, "chunk": 32}
    # weight 0: the plain MSE loop, bit for bit
    m0 = make_model("tcn", **hp, diff_loss_weight=0.0, diff_loss_lag=7).fit(xs, ys, valid=(vx, vy), seed=3)
    ref = make_model("tcn", **hp)
    zx, zy, zv = ref.fit_setup(xs, ys, (vx, vy))
    with seeded(3):
        ref.net = ref._build()
    h = train_model(ref.net, ref._examples(zx, zy, True), ref._examples(*zv, False), ref.train_config(3), progress=False)
    assert m0.history["train_loss"] == h.train_loss and m0.history["valid_loss"] == h.valid_loss
    for name, t in ref.net.state_dict().items():
        assert torch.equal(t, m0.net.state_dict()[name])
    # lr 0: the losses of the initial net, by hand
    w, k = 0.7, 5
    hz = {**hp, "lr": 0.0, "max_epochs": 1, "diff_loss_weight": w, "diff_loss_lag": k}
    m = make_model("tcn", **hz).fit(xs, ys, valid=(vx, vy), seed=3)
    tx, ty = m._examples(*m.fit_setup(xs, ys)[:2], True)
    ex, ey = m._examples(*zv, False)
    with torch.no_grad():
        def by_hand(x, y):
            e = (m.net(x) - y).double().numpy()  # [chunks, L, 1]
            d = e[:, k:] - e[:, :-k]
            return float((e**2).mean() + w * (d**2).mean())
        assert m.history["valid_loss"][0] == pytest.approx(by_hand(ex, ey), rel=1e-5)
        assert m.history["train_loss"][0] == pytest.approx(by_hand(tx, ty), rel=1e-5)  # every batch 16 chunks
    # batched = one after another, with the new loss (two input sets: 1 and 2 channels)
    hd = {**hp, "max_epochs": 4, "patience": 1, "lr": 5e-3, "diff_loss_weight": 1.0, "diff_loss_lag": 10}
    two = lambda x: np.column_stack([x, np.log(x)])
    data = {"one": (xs, ys, (vx, vy)), "two": ([two(x) for x in xs], ys, ([two(x) for x in vx], vy))}
    seq = {k2: make_model("ensemble", member="tcn", n_members=2, member_hparams=hd).fit(*d[:2], valid=d[2], seed=3)
           for k2, d in data.items()}
    bat = {k2: make_model("ensemble", member="tcn", n_members=2, member_hparams=hd, batched=True) for k2 in data}
    fit_ensembles([(bat[k2], {"xs": d[0], "ys": d[1], "valid": d[2], "seed": 3}) for k2, d in data.items()])
    for k2, f in (("one", lambda x: x), ("two", two)):
        for a, b in zip(seq[k2].members, bat[k2].members):
            assert (a.history["epochs"], a.history["best_epoch"]) == (b.history["epochs"], b.history["best_epoch"])
            np.testing.assert_allclose(a.history["valid_loss"], b.history["valid_loss"], rtol=0, atol=1e-6)
            np.testing.assert_allclose(a.history["train_loss"], b.history["train_loss"], rtol=0, atol=1e-6)
        np.testing.assert_allclose(seq[k2].predict(f(te[0].x)), bat[k2].predict(f(te[0].x)), rtol=0, atol=1e-5)
    # the derivative term changed the training (not the MSE path under another name)
    plain = make_model("ensemble", member="tcn", n_members=2, member_hparams={**hd, "diff_loss_weight": 0.0}).fit(
        *data["one"][:2], valid=data["one"][2], seed=3)
    assert plain.members[0].history["valid_loss"][0] < seq["one"].members[0].history["valid_loss"][0]
    with pytest.raises(ValueError, match="share diff_loss"):
        mixed = [make_model("ensemble", member="tcn", n_members=1, member_hparams={**hd, "diff_loss_weight": v},
                            batched=True) for v in (0.0, 1.0)]
        fit_ensembles([(e, {"xs": xs, "ys": ys, "valid": (vx, vy), "seed": 3}) for e in mixed])
