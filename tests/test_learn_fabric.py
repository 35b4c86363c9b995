"""fabric learn: the Levenberg-Marquardt step against closed forms, its damping adaptation, the BP network
(Jacobian, beats a trivial baseline on held-out data, streams and round-trips), the hysteresis metric on a
hand-computed staircase, and `piezotwin experiment fabric` end to end on a tiny config."""

import json

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from learn.checkpoint import load_checkpoint, save_checkpoint
from learn.lm import LevenbergMarquardt, LMConfig, lm_delta
from learn.models import make_model
from learn.models.bpnet import BPNet
from piezotwin.cli import app

torch.set_num_threads(1)
runner = CliRunner()


def _linear_problem(seed=0, n=40, p=4):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, p))
    y = A @ rng.normal(size=p) + 0.1 * rng.normal(size=n)
    return A, y


def test_lm_step_small_mu_is_gauss_newton_normal_equations():
    A, y = _linear_problem()
    th0 = np.array([0.3, -1.0, 2.0, 0.5])
    r = y - A @ th0
    step = th0 + lm_delta(A, r, 1e-12)
    normal = np.linalg.solve(A.T @ A, A.T @ y)  # the least-squares solution, in one step on a linear problem
    np.testing.assert_allclose(step, normal, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(step, np.linalg.lstsq(A, y, rcond=None)[0], rtol=1e-9, atol=1e-9)


def test_lm_step_large_mu_is_scaled_gradient_step():
    A, y = _linear_problem(1)
    th0 = np.zeros(4)
    r = y - A @ th0
    grad = -2.0 * A.T @ r  # gradient of E = |y - A theta|^2
    for mu in (1e6, 1e9):
        d = lm_delta(A, r, mu)
        np.testing.assert_allclose(d, -grad / (2 * mu), rtol=1e-3 * (1e6 / mu) * 10)
        assert np.dot(d, -grad) / (np.linalg.norm(d) * np.linalg.norm(grad)) > 1 - 1e-6


def test_lm_exact_formula_any_mu():
    A, y = _linear_problem(2)
    r = y - A @ np.ones(4)
    for mu in (0.0, 0.1, 10.0):
        np.testing.assert_allclose(lm_delta(A, r, mu), np.linalg.solve(A.T @ A + mu * np.eye(4), A.T @ r), rtol=1e-10)


def test_lm_damping_accept_decreases_mu():
    A, y = _linear_problem(3)
    lm = LevenbergMarquardt(lambda th: y - A @ th, lambda th: A, LMConfig(mu=1e-3))
    th, sse, ok, rej = lm.step(np.zeros(4))
    assert ok and rej == 0 and lm.mu == pytest.approx(1e-4)
    assert sse == pytest.approx(float(np.sum((y - A @ np.linalg.lstsq(A, y, rcond=None)[0]) ** 2)), rel=1e-6)


def test_lm_damping_reject_increases_mu_until_accepted():
    # a Jacobian 10x too small makes the Gauss-Newton step 10x too long: rejected until mu has shortened it
    A, y = _linear_problem(4)
    lm = LevenbergMarquardt(lambda th: y - A @ th, lambda th: 0.1 * A, LMConfig(mu=1e-3))
    e0 = float(np.sum(y**2))
    th, sse, ok, rej = lm.step(np.zeros(4))
    assert ok and rej >= 1 and sse < e0
    assert lm.mu == pytest.approx(1e-3 * 10.0**rej * 0.1)


def test_lm_damping_gives_up_past_mu_max():
    A, y = _linear_problem(5)
    th0 = np.zeros(4)
    lm = LevenbergMarquardt(lambda th: y - A @ th, lambda th: -A, LMConfig(mu=1e-3, mu_max=1e3))  # uphill for every mu
    th, sse, ok, rej = lm.step(th0)
    assert not ok and rej == 7 and lm.mu > 1e3  # 1e-3 * 10^7 = 1e4 > 1e3
    np.testing.assert_array_equal(th, th0)
    theta, h = LevenbergMarquardt(lambda th: y - A @ th, lambda th: -A, LMConfig(mu_max=1e3)).fit(th0)
    assert h.stop_reason == "mu_max"


def test_lm_fit_converges_to_least_squares_and_stops_on_validation_checks():
    A, y = _linear_problem(6)
    theta, h = LevenbergMarquardt(lambda th: y - A @ th, lambda th: A, LMConfig(min_grad=1e-9)).fit(np.zeros(4))
    np.testing.assert_allclose(theta, np.linalg.lstsq(A, y, rcond=None)[0], rtol=1e-8, atol=1e-10)
    assert h.stop_reason == "min_grad" and h.mu[0] < 1e-3
    # validation improves once, then never again: six more epochs, and the first epoch's weights come back
    calls = iter([5.0, 1.0] + [2.0] * 50)
    seen = []

    def valid(th):
        seen.append(th.copy())
        return next(calls)

    # (a 10x too small Jacobian: slow, steady progress, so training would go on for many epochs)
    theta, h = LevenbergMarquardt(lambda th: y - A @ th, lambda th: 0.1 * A, LMConfig(max_fail=6, min_grad=0)).fit(
        np.zeros(4), valid=valid)
    assert h.stop_reason == "validation_checks" and h.best_epoch == 0 and h.epochs == 7
    np.testing.assert_array_equal(theta, seen[1])


def test_bpnet_jacobian_matches_finite_differences():
    net = BPNet(2, [5, 5])
    assert net.n_params == 2 * 5 + 5 + 5 * 5 + 5 + 5 + 1
    rng = np.random.default_rng(0)
    th, X = net.init(rng), rng.normal(size=(9, 2))
    J = net.jacobian(th, X)
    eps = 1e-6
    Jn = np.stack([(net.forward(th + eps * e, X) - net.forward(th - eps * e, X)) / (2 * eps) for e in np.eye(net.n_params)], 1)
    np.testing.assert_allclose(J, Jn, atol=1e-8)


def _play_sensor(n, seed, width=0.25):
    """A random staircase force through a play operator (hysteresis with return-point memory); the reading is
    a falling function of the play output, the target that function of the force (the static curve)."""
    rng = np.random.default_rng(seed)
    F = np.abs(np.cumsum(rng.choice([-0.1, 0.1], n) * (1 + (rng.random(n) < 0.3))))
    u = np.zeros(n)
    for i in range(1, n):
        u[i] = min(max(u[i - 1], F[i] - width), F[i] + width)
    R = 3.0 / (1.0 + u) + rng.normal(0, 0.002, n)
    return R[:, None], (3.0 / (1.0 + F))[:, None]


def test_bp_lm_beats_trivial_and_static_baselines_on_held_out_data(tmp_path):
    tr = [_play_sensor(150, s) for s in range(4)]
    va = [_play_sensor(150, 50)]
    te = [_play_sensor(150, s) for s in (100, 101)]
    rmse = lambda m: float(np.sqrt(np.mean(np.concatenate([(m.predict(a) - b) ** 2 for a, b in te]))))
    fitted = {}
    for kind, hp in (("mean", {}), ("cubic", {}), ("bp_lm", {"restarts": 2, "max_epochs": 200})):
        m = make_model(kind, **hp)
        m.fit([a for a, _ in tr], [b for _, b in tr], valid=([a for a, _ in va], [b for _, b in va]), seed=1,
              inputs=["r"], targets=["r_static"], units={"r": "ohm", "r_static": "ohm"})
        fitted[kind] = m
    bp = fitted["bp_lm"]
    assert rmse(bp) < 0.5 * rmse(fitted["mean"])
    assert rmse(bp) < rmse(fitted["cubic"])  # the previous reading tells the branch: better than any static map
    assert bp.history["optimizer"] == "levenberg-marquardt" and bp.history["n_parameters"] == 51
    assert bp.context == 2
    # streaming equals batch; the checkpoint round-trips exactly; training is seeded
    x = te[0][0]
    np.testing.assert_allclose(bp.stream().run(x), bp.predict(x), atol=1e-12)
    save_checkpoint(bp, tmp_path / "bp")
    cfg = json.loads((tmp_path / "bp" / "config.json").read_text())
    assert cfg["model_class"] == "bp_lm" and cfg["hyper_parameters"]["hidden"] == [5, 5]
    np.testing.assert_array_equal(load_checkpoint(tmp_path / "bp").predict(x), bp.predict(x))
    again = make_model("bp_lm", restarts=2, max_epochs=200).fit([a for a, _ in tr], [b for _, b in tr],
                                                                valid=([a for a, _ in va], [b for _, b in va]), seed=1)
    np.testing.assert_array_equal(again.predict(x), bp.predict(x))


def test_bp_lm_observations_subset():
    tr = [_play_sensor(100, s) for s in range(2)]
    m = make_model("bp_lm", observations=11, restarts=1, max_epochs=50).fit([a for a, _ in tr], [b for _, b in tr], seed=0)
    assert m.history["n_train_examples"] == 11 and len(m.history["observation_index"]) == 11


def test_hysteresis_metric_hand_computed():
    from learn.experiments.fabric import hysteresis, loops

    level = np.array([0, 1, 2, 1, 0, 1, 2, 3, 2, 1, 0], float)
    assert loops(level) == [(0, 2, 4), (4, 7, 10)]
    y = np.array([10, 8, 6, 7, 9, 8, 6, 4, 5, 6, 9], float)
    h = hysteresis(level, y)
    # full-range loop 0-2-0: span 10 - 6 = 4; gaps at 1: |8 - 7| = 1, at 0: |10 - 9| = 1 -> 25 %
    assert h["fso"] == 4 and h["full_range"] == pytest.approx(25.0)
    # second loop 0-3-0: gaps at 2: |6 - 5| = 1, at 1: |8 - 6| = 2, at 0: |9 - 9| = 0 -> 2 / 4 = 50 %
    assert h["loops"][1] == pytest.approx(50.0)


def test_experiment_fabric_bad_input_exit_2(tmp_path):
    res = runner.invoke(app, ["experiment", "fabric", "--quick", "--models", "bp_lm,foo", "-o", str(tmp_path / "a")])
    assert res.exit_code == 2 and "foo" in res.output
    res = runner.invoke(app, ["experiment", "fabric", "--quick", "--set", "protocol.stair_step=1", "-o", str(tmp_path / "b")])
    assert res.exit_code == 2
    assert not any(tmp_path.iterdir())


def raw_hyst(L):
    return L["raw"]["hyst_full_mean"]


def test_experiment_fabric_tiny(tmp_path):
    out = tmp_path / "exp"
    res = runner.invoke(app, ["experiment", "fabric", "--mode", "tiny", "--models", "linear,bp_lm,tcn", "-o", str(out)])
    assert res.exit_code == 0, res.output
    m = json.loads((out / "metrics.json").read_text())
    assert {"experiment", "mode", "layers", "paper", "findings"} <= set(m)
    assert set(m["layers"]) == {"1", "3"}
    assert m["paper"]["hysteresis_fso"]["1"] == {"before": 24.2, "after": 13.5}
    for n, L in m["layers"].items():
        assert set(L["models"]) == {"mean", "linear", "bp_lm", "tcn"}
        tcn = L["models"]["tcn"]
        assert tcn["hparams"]["member"] == "tcn" and tcn["hparams"]["n_members"] == 2  # ours: a seed ensemble of TCNs
        assert tcn["hparams"]["member_hparams"]["log_inputs"] == [0]  # reading (R, ln R)
        assert [x["seed"] for x in tcn["members"]] == [0, 1] and all("valid" in x for x in tcn["members"])
        assert tcn["test"]["mse"] < min(L["models"][k]["test"]["mse"] for k in ("mean", "linear"))  # beats trivial baselines
        assert tcn["test"]["hyst_full_mean"] < raw_hyst(L) and tcn["latency"]["stream_vs_batch_max_abs"] < 1e-2
        assert {"dataset", "split", "target_poly", "raw", "table2"} <= set(L)
        assert not set(L["split"]["test"]) & set(L["split"]["train"] + L["split"]["valid"])
        assert not set(L["episode_seeds"]["test"]) & set(L["episode_seeds"]["train"])  # new random force sequences
        assert L["dataset"]["test"]["dataset_sha256"] != L["dataset"]["train"]["dataset_sha256"]
        bp, raw = L["models"]["bp_lm"]["test"], L["raw"]
        for k in ("mse", "r", "hyst_full_mean", "hyst_loops_max"):
            assert k in bp and k in raw
        assert bp["hyst_full_mean"] < raw["hyst_full_mean"]  # the BP net reduces the max hysteresis error
        assert bp["mse"] < L["models"]["mean"]["test"]["mse"]
        # the simulated sensor's loop, referenced to the highest output (paper, 1 layer: 24.2 %); every press draws
        # its own knit set, so single cycles scatter around the calibrated mean loop
        assert 12 < raw["hyst_paper_mean"] < 60 and raw["hyst_paper_mean"] < raw["hyst_full_mean"]
        if n == "1":  # the press-to-press variation is invisible to (R_t, R_t-1): the BP net cannot remove it all
            assert bp["hyst_paper_mean"] > 3.0
        assert {"6", "21", "46"} == set(L["table2"])
        assert L["models"]["bp_lm"]["latency"]["stream_vs_batch_max_abs"] < 1e-6
    assert all(m["findings"]["bp_reduces_full_range_hysteresis"].values())
    text = (out / "report.md").read_text()
    assert "24.2" in text and "13.5" in text and "9.41e-05" in text and "Where we differ" in text
    for p in ("loops.png", "hysteresis.png", "table2.png", "lm_training.png"):
        assert (out / p).stat().st_size > 1000
    comp = load_checkpoint(out / "checkpoints" / "fabric_1-bp_lm")
    assert comp.kind == "bp_lm"


@pytest.mark.slow
def test_experiment_fabric_quick(tmp_path):
    out = tmp_path / "quick"
    res = runner.invoke(app, ["experiment", "fabric", "--quick", "-o", str(out)])
    assert res.exit_code == 0, res.output
    m = json.loads((out / "metrics.json").read_text())
    assert set(m["layers"]) == {"1", "3", "6", "12"}
    assert all(m["findings"]["bp_reduces_full_range_hysteresis"].values())
    # ours (TCN on R, ln R) beats the paper's BP net on every layer count: test MSE, full cycle, worst loop
    assert set(m["findings"]["tcn_beats_bp_lm"]) == {"1", "3", "6", "12"}
    for n, d in m["findings"]["tcn_beats_bp_lm"].items():
        assert all(d.values()), (n, d)


def test_fabric_run_layers_subset_refuses_unknown_counts(tmp_path):
    """run(layers=...) reruns a subset of the mode's layer counts; a count the mode lacks is an error before
    anything is written; the full mode trains on the same number of episodes for every layer count."""
    from learn.experiments import fabric as F

    with pytest.raises(ValueError, match="layers"):
        F.run(tmp_path / "x", mode="tiny", layers=(6,))
    assert not (tmp_path / "x").exists()
    assert len(set(F.MODES["full"].train_episodes.values())) == 1
