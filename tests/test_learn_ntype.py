"""ntype learning: RLS against the closed-form least squares, k-means on hand-made clusters, the RBF network
against a trivial baseline on held-out data, sliding-window inputs at the borders, and a tiny experiment."""

import json

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from learn.experiments import EXPERIMENTS
from learn.experiments.ntype import (
    NEIGHBOURS,
    component_errors,
    kfold_episodes,
    minmax_fit,
    to_paper_scale,
    window_inputs,
)
from learn.models import MODELS, make_model
from learn.models.element_mlp import invert_strain, mirror_x
from learn.models.rbf import KMeans, RBFNetwork, RecursiveLeastSquares

torch.set_num_threads(1)


def _ridge(H, Y, delta):
    return np.linalg.solve(H.T @ H + delta * np.eye(H.shape[1]), H.T @ Y)


@pytest.mark.parametrize("block", [1, 3, 50])
def test_rls_equals_batch_least_squares(block):
    rng = np.random.default_rng(0)
    H, Y = rng.normal(size=(40, 6)), rng.normal(size=(40, 2))
    delta = 1e-2
    rls = RecursiveLeastSquares(delta=delta, block=block)
    for i in range(0, 40, 7):  # uneven partial_fit calls
        rls.partial_fit(H[i : i + 7], Y[i : i + 7])
    np.testing.assert_allclose(rls.W, _ridge(H, Y, delta), rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(rls.P, np.linalg.inv(H.T @ H + delta * np.eye(6)), rtol=1e-8, atol=1e-12)
    assert rls.n_samples_seen_ == 40
    # one call with more rows than a block takes the information form: the same solution
    big = RecursiveLeastSquares(delta=delta, block=4).fit(H, Y)
    np.testing.assert_allclose(big.W, _ridge(H, Y, delta), rtol=1e-9, atol=1e-10)


def test_sweep_closed_form_equals_sample_by_sample_rls_and_sq_dist_is_bit_exact():
    """The sweep's closed form (Haykin: RLS of forgetting factor 1 from P0 = I / delta is the ridge solution) against
    RBFNetwork's sample-by-sample RLS (block 1) and its block / information forms, on the same centres, every
    spread and both readings; eq. 12's Cholesky against LU; the in-place squared distances against the
    out-of-place expression bit for bit (k-means and the nearest-centre distances depend on them)."""
    from learn.models.rbf import exact_weights, kernel_phi, sq_dist, sweep_predict

    rng = np.random.default_rng(5)
    X, T = rng.uniform(16.0, 25.0, (90, 8)), rng.uniform(16.0, 25.0, (30, 8))
    Y = rng.uniform(0.0, 4.8, (90, 3))
    C = X[::3]
    ref = (X * X).sum(1)[:, None] - 2.0 * X @ C.T + (C * C).sum(1)[None, :]
    assert np.array_equal(sq_dist(X, C), np.maximum(ref, 0.0))
    for kern in ("eq9", "matlab"):
        spreads = (1.0, 4.0, 10.0)
        sp = sweep_predict(sq_dist(X, C), Y, sq_dist(T, C), kern, spreads)["rls"]
        for s in spreads:
            p = sp[s]
            for block in (1, 256):  # sample by sample; one call of 90 rows > 31 units + bias: the information form
                net = RBFNetwork(len(C), s, kern, block=block).fit(X, Y, centres=C)
                np.testing.assert_allclose(p, net.predict(T), rtol=1e-7, atol=1e-7 * np.abs(p).max())
        ex = sweep_predict(sq_dist(X, X), Y, sq_dist(T, X), kern, spreads, solvers=("exact", "rls"))
        for s in spreads:
            Phi = kernel_phi(kern, s, sq_dist(X, X))
            np.testing.assert_allclose(ex["exact"][s], kernel_phi(kern, s, sq_dist(T, X)) @ np.linalg.solve(Phi, Y),
                                       rtol=1e-6, atol=1e-8)
            np.testing.assert_allclose(Phi @ exact_weights(Phi, Y), Y, atol=1e-6)
    with pytest.raises(ValueError):
        sweep_predict(sq_dist(X, C), Y, sq_dist(T, C), "eq9", (1.0,), solvers=("exact",))


def test_rls_single_update_by_hand():
    # one scalar weight, P0 = 1/delta: after h=2, y=4: P = 1/(delta + 4), w = 2*4/(delta + 4)
    rls = RecursiveLeastSquares(delta=1.0, block=1).partial_fit(np.array([[2.0]]), np.array([[4.0]]))
    assert rls.P[0, 0] == pytest.approx(1 / 5) and rls.W[0, 0] == pytest.approx(8 / 5)


def test_rbf_partial_fit_is_rls_continuation():
    rng = np.random.default_rng(1)
    X = rng.uniform(0, 5, size=(120, 2))
    Y = np.sin(X[:, :1]) + X[:, 1:] ** 2 / 10
    full = RBFNetwork(n_centres=15, spread=2.0, seed=0).fit(X, Y)
    part = RBFNetwork(n_centres=15, spread=2.0, seed=0).fit(X[:50], Y[:50], centres=full.centres_)
    part.partial_fit(X[50:90], Y[50:90]).partial_fit(X[90:], Y[90:])
    np.testing.assert_allclose(part.predict(X), full.predict(X), rtol=1e-7, atol=1e-8)
    Hh = full.hidden(X)
    np.testing.assert_allclose(full.coef_, _ridge(Hh, Y, full.delta), rtol=1e-7, atol=1e-9)


def test_kmeans_finds_hand_made_clusters():
    rng = np.random.default_rng(2)
    true = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    X = np.concatenate([c + 0.3 * rng.normal(size=(30, 2)) for c in true])
    km = KMeans(4, seed=0).fit(X)
    C = km.cluster_centers_[np.argsort(km.cluster_centers_ @ [1.0, 100.0])]
    np.testing.assert_allclose(C, true, atol=0.2)
    # every hand-made cluster gets one label of its own
    labels = km.labels_.reshape(4, 30)
    assert all(len(set(r)) == 1 for r in labels) and len({r[0] for r in labels}) == 4
    np.testing.assert_array_equal(km.predict(true), km.predict(true + 0.1))
    # more clusters than distinct points: duplicates do not crash it
    assert KMeans(3, seed=0).fit(np.ones((5, 2))).cluster_centers_.shape == (3, 2)


def test_rbf_beats_trivial_baseline_on_held_out():
    rng = np.random.default_rng(3)
    X = rng.uniform(16, 25, size=(400, 3))
    Y = np.stack([np.exp(-(X[:, 0] - 20) ** 2 / 8), np.cos(X[:, 1] / 2) * X[:, 2] / 25], 1)
    tr, te = slice(0, 300), slice(300, None)
    net = RBFNetwork(n_centres=60, spread=3.0, seed=0).fit(X[tr], Y[tr])
    err = np.sqrt(np.mean((net.predict(X[te]) - Y[te]) ** 2))
    base = np.sqrt(np.mean((Y[tr].mean(0) - Y[te]) ** 2))
    assert err < 0.3 * base
    # the registered compensator (min-max scaling + z-scored targets) too, and its online update
    comp = make_model("rbf", n_centres=60, spread=3.0).fit([X[tr]], [Y[tr]], seed=0)
    assert np.sqrt(np.mean((comp.predict(X[te]) - Y[te]) ** 2)) < 0.3 * base
    comp.partial_fit(X[te][:50], Y[te][:50])
    np.testing.assert_allclose(comp.stream().run(X[te][:5]), comp.predict(X[te][:5]), rtol=1e-10)


def test_models_and_experiment_registered():
    assert {"rbf", "map_cnn"} <= set(MODELS) and "ntype" in EXPERIMENTS
    with pytest.raises(ValueError, match="kernel"):
        RBFNetwork(kernel="gauss")


def test_window_inputs_at_borders():
    # 2 frames, 6 x 6 elements, 3 columns: value = 100 * frame + 10 * element + column (unique)
    R = np.array([[[100 * n + 10 * m + c for c in range(3)] for m in range(36)] for n in range(2)], float)
    pad = np.array([-1.0, -2.0, -3.0])
    W1 = window_inputs(R, 1, pad)
    np.testing.assert_array_equal(W1, R.reshape(72, 3))
    W7 = window_inputs(R, 7, pad)
    assert W7.shape == (72, 21) and NEIGHBOURS[:5] == ((0, 0), (-1, 0), (1, 0), (0, -1), (0, 1))

    def elem(n, m):
        return W7[n * 36 + m].reshape(7, 3)

    # corner element 0 (ix = iy = 0): left, up (dy = -1) and the (-1,-1) diagonal are outside
    e = elem(1, 0)
    np.testing.assert_array_equal(e[0], R[1, 0])
    for k in (1, 3, 5):
        np.testing.assert_array_equal(e[k], pad)
    np.testing.assert_array_equal(e[2], R[1, 1])   # right neighbour (ix + 1)
    np.testing.assert_array_equal(e[4], R[1, 6])   # next row (iy + 1)
    np.testing.assert_array_equal(e[6], R[1, 7])   # (+1, +1) diagonal
    # right edge element 11 (ix = 5, iy = 1)
    e = elem(0, 11)
    np.testing.assert_array_equal(e[1], R[0, 10])
    np.testing.assert_array_equal(e[2], pad)
    np.testing.assert_array_equal(e[3], R[0, 5])
    np.testing.assert_array_equal(e[4], R[0, 17])
    np.testing.assert_array_equal(e[5], R[0, 4])
    np.testing.assert_array_equal(e[6], pad)
    # last corner element 35: right, down and (+1,+1) outside
    e = elem(0, 35)
    for k in (2, 4, 6):
        np.testing.assert_array_equal(e[k], pad)
    np.testing.assert_array_equal(e[5], R[0, 28])
    # window 5 is the first 5 of window 7; an interior element has no padding
    np.testing.assert_array_equal(window_inputs(R, 5, pad), W7[:, :15])
    assert not np.isin(pad, elem(0, 14)).any()
    with pytest.raises(ValueError):
        window_inputs(R, 8, pad)


def test_paper_scaling_folds_and_errors():
    R = np.stack([np.linspace(40e3, 60e3, 5), np.linspace(30e3, 50e3, 5), np.linspace(13e3, 25e3, 5)], -1)[:, None]
    lo, hi = minmax_fit(R)
    N = to_paper_scale(R, lo, hi)
    np.testing.assert_allclose(N.min(0)[0], [32, 32, 16]) and np.testing.assert_allclose(N.max(0)[0], [50, 50, 25])
    folds = kfold_episodes(23, 10, 0)
    assert sorted(np.concatenate(folds).tolist()) == list(range(23)) and {len(f) for f in folds} == {2, 3}
    ref = np.array([[[1.0, 0.0, 2.0], [0.1, -2.0, 0.0]]])
    est = np.array([[[1.1, 5.0, 1.0], [9.0, -1.0, 0.0]]])
    e = component_errors(ref, est, 0.5)
    assert e["E_Fx"] == pytest.approx(10.0) and e["E_Fy"] == pytest.approx(50.0) and e["E_Fz"] == pytest.approx(50.0)
    assert e["n_Fx"] == 1 and e["MAE_Fx"] == pytest.approx((0.1 + 8.9) / 2)
    # eq. 14 as printed: every nonzero component over its own F (Fx: 10 % and 8.9 / 0.1 = 8900 %)
    e = component_errors(ref, est, 0.5, literal=True)
    assert e["E_all_Fx"] == pytest.approx((10.0 + 8900.0) / 2) and e["n_all_Fx"] == 2 and e["n_all_Fz"] == 1
    assert e["E_all_Fy"] == pytest.approx(50.0) and e["E_all_Fz"] == pytest.approx(50.0)  # zeros left out


def test_paper_ratio_fits_a_uniform_draw_not_a_skewed_one():
    """ntype Table 2 / Figs. 6-8: MAE / E = 0.60 / 1.11 / 0.55 N. With Table 2's absolute errors independent of F
    (their spread is 0.8x their mean; the relative errors' is 2-10x), 180 components of U[0, 4.8] N put all three
    inside the 5-95 % band of the ratio; a draw skewed to the same 0.6 N arithmetic mean (Beta(1, 7)) puts none."""
    from learn.experiments.ntype import PAPER_IMPLIED_FORCE_N, implied_force_band

    assert PAPER_IMPLIED_FORCE_N == pytest.approx((0.597, 1.106, 0.551), abs=2e-3)
    u, b = implied_force_band("uniform", trials=1000), implied_force_band("beta", 1.0, 7.0, trials=1000)
    assert u["component_mean_n"] == pytest.approx(2.4) and b["component_mean_n"] == pytest.approx(0.6)
    for c in ("Fx", "Fy", "Fz"):
        assert u[c]["paper_inside_5_95"] and not b[c]["paper_inside_5_95"]
        assert 0.5 < u[c]["ratio_n_p5_p50_p95"][1] < 1.0 and b[c]["ratio_n_p5_p50_p95"][2] < 0.3
    assert implied_force_band("uniform", trials=200, seed=1) == implied_force_band("uniform", trials=200, seed=1)


@pytest.fixture(scope="module")
def tiny_cli(tmp_path_factory):
    """One tiny ntype experiment through the CLI, its two tasks in two processes (the CLI's default on a multi-core
    machine); the tests below read it and reuse its data folder (`<out>/data`)."""
    from piezotwin.cli import app

    out = tmp_path_factory.mktemp("ntype_tiny") / "exp"
    res = CliRunner().invoke(app, ["experiment", "ntype", "--mode", "tiny", "--workers", "2", "-o", str(out)])
    assert res.exit_code == 0, res.output
    return out, json.loads((out / "metrics.json").read_text())


def test_experiment_ntype_tiny(tiny_cli):
    out, m = tiny_cli
    assert {"experiment", "mode", "dataset", "protocol", "models", "paper", "findings", "timing_s"} <= set(m)
    assert set(m["models"]) == {"mean", "rbf_col", "rbf_win", "elem_mlp", "map_cnn", "rbf_col_kernels"}
    # Table 1 also under MATLAB's reading of the spread, same spreads; the headline is eq. 9 as printed
    assert m["protocol"]["kernel"] == "eq9" and set(m["models"]["rbf_col_kernels"]["matlab"]) == {"1.0", "4.0", "7.0", "10.0"}
    assert set(m["models"]["rbf_col"]) == {"1.0", "4.0", "7.0", "10.0"}
    # and under eqs. 10-12 as printed (exact solve), with Phi's condition number on the first fold
    assert {"eq9+exact", "matlab+exact"} <= set(m["models"]["rbf_col_kernels"])
    cn = m["findings"]["table1_exact_phi_condition_fold1"]["eq9+exact"]
    assert cn["1.0"]["Fz"] < cn["10.0"]["Fz"] and "eq9+exact" in m["findings"]["table1_best_spread_exact"]
    assert set(m["models"]["rbf_win"]) == {"1", "5"}
    for k in ("E_Fx", "E_Fy", "E_Fz", "MAE_Fx", "n_Fz"):
        assert k in m["models"]["rbf_win"]["5"]["7.0"] and k in m["models"]["map_cnn"]
    assert m["paper"]["table1"]["7"] == [2.62, 3.44, 1.82] and m["paper"]["table3"]["5"] == [2.13, 2.71, 1.36]
    f = m["findings"]
    assert {"table1_best_spread", "table1_interior_optimum", "window5_beats_no_window", "best_paper_model",
            "map_cnn_beats_best_paper_model", "elem_mlp_beats_best_paper_model"} <= set(f)
    assert {"table1_best_spread_eq14_all", "implied_force_n_at_spread7_eq14_all", "implied_force_band"} <= set(f)
    assert "E_all_Fz" in m["models"]["rbf_col"]["7.0"] and "E_all_Fz" not in m["tasks"]["press_stroke"]["models"]["mean"]
    g = f["nearest_centre_median"]  # the report's reason for a best spread at the sweep's end
    assert set(g) == {"rbf_col_Fx", "rbf_col_Fy", "rbf_col_Fz", "rbf_w1", "rbf_w5"} and min(g.values()) > 0
    assert g["rbf_w5"] > g["rbf_w1"]  # 15 inputs that vary independently leave the centres farther apart than 3
    folds = m["protocol"]["fold_episodes"]
    assert len(folds) == 3 and len({k for g in folds for k in g}) == m["protocol"]["episodes"]
    # the window models beat the trivial mean in MAE on the held-out folds
    mean_mae = m["models"]["mean"]["MAE_Fz"]
    assert m["models"]["rbf_win"]["1"]["7.0"]["MAE_Fz"] < mean_mae
    # ours (element MLP) beats the best paper model (RBF, best window and spread) on the held-out folds
    best = min(m["models"]["rbf_win"][w][s]["MAE_Fz"] for w in m["models"]["rbf_win"] for s in m["models"]["rbf_win"][w])
    assert m["models"]["elem_mlp"]["MAE_Fz"] < best
    bp = f["best_paper_errors"]
    assert np.mean([m["models"]["elem_mlp"][f"E_{c}"] for c in ("Fx", "Fy", "Fz")]) < np.mean(list(bp.values()))
    text = (out / "report.md").read_text()
    assert "Table 1" in text and "Table 3" in text and "Table 4" in text and "2.62" in text and "Where we differ" in text
    assert (out / "spread.png").stat().st_size > 1000 and (out / "checkpoints" / "map_cnn" / "config.json").is_file()


def test_element_mlp_strain_inversion_and_mirror():
    rest, beta = np.array([50e3, 50e3, 25e3]), 0.7
    e = np.array([[-0.3, 0.05, -0.19], [0.0, 0.2, -0.5]])
    R = rest * (1 + e) ** 2 * np.exp(beta * e)
    np.testing.assert_allclose(invert_strain(R, rest, beta), e, atol=1e-10)
    E = np.arange(2 * 36 * 3, dtype=float).reshape(2, 36, 3)
    Em, Fm = mirror_x(E, E)
    np.testing.assert_array_equal(Em[0, 0], E[0, 5][[1, 0, 2]])  # element (0, 0) <- (5, 0), R_x <-> R_y
    np.testing.assert_array_equal(Fm[1, 6], E[1, 11] * [-1, 1, 1])  # element (0, 1) <- (5, 1), F_x -> -F_x
    np.testing.assert_array_equal(mirror_x(*mirror_x(E, E))[1], E)


def test_experiment_ntype_models_subset(tmp_path, tiny_cli):
    """`--models` on ntype: a bad name exits 2 with nothing written; a subset runs only that model (+ mean), here on
    the tiny run's data folder (`--data`)."""
    from piezotwin.cli import app

    res = CliRunner().invoke(app, ["experiment", "ntype", "--mode", "tiny", "--models", "rbf_col,foo",
                                   "-o", str(tmp_path / "bad")])
    assert res.exit_code == 2 and "foo" in res.output and not (tmp_path / "bad").exists()
    out = tmp_path / "sub"
    res = CliRunner().invoke(app, ["experiment", "ntype", "--mode", "tiny", "--models", "rbf_col", "-o", str(out),
                                   "--data", str(tiny_cli[0] / "data")])
    assert res.exit_code == 0, res.output
    m = json.loads((out / "metrics.json").read_text())
    assert set(m["models"]) == {"mean", "rbf_col", "rbf_col_kernels"}  # Table 1 under the other spread readings too
    assert (out / "report.md").read_text()


def test_symmetric_frames_transpose_and_mirror_y():
    """The crossed reading's symmetry: x <-> y with R_x <-> R_y and F_x <-> F_y; twice is the identity."""
    from learn.models.element_mlp import symmetric_frames

    E = np.arange(2 * 36 * 3, dtype=float).reshape(2, 36, 3)
    Et, Ft = symmetric_frames(E, E, "transpose")
    np.testing.assert_array_equal(Et[0, 1 * 6 + 4], E[0, 4 * 6 + 1][[1, 0, 2]])  # element (iy=1, ix=4) <- (4, 1)
    np.testing.assert_array_equal(symmetric_frames(Et, Ft, "transpose")[1], E)
    Ey, Fy = symmetric_frames(E, E, "mirror_y")
    np.testing.assert_array_equal(Fy[1, 0], E[1, 30] * [1, -1, 1])  # element (0, 0) <- (5, 0), F_y -> -F_y


@pytest.mark.parametrize("kernel", ["eq9", "matlab", "sigma"])
def test_rbf_kernel_readings_of_eq9(kernel):
    """The three readings of the paper's eq. 9 spread: "eq9" as printed, exp(-||X - X_j|| / (2 spread^2)) (norm not
    squared); "matlab" 0.5 at d = spread; "sigma" exp(-d^2 / (2 spread^2)); each unit is 0.5 at half_distance."""
    from learn.models.rbf import half_distance, kernel_phi

    s = 3.0
    d = np.array([0.0, 1.0, 4.0, 25.0])
    want = {"eq9": np.exp(-d / (2 * s * s)), "matlab": np.exp(-np.log(2) * (d / s) ** 2),
            "sigma": np.exp(-(d**2) / (2 * s * s))}[kernel]
    np.testing.assert_allclose(kernel_phi(kernel, s, d**2), want, rtol=1e-12)
    h = half_distance(kernel, s)
    assert h == pytest.approx({"eq9": 2 * np.log(2) * s * s, "matlab": s, "sigma": s * np.sqrt(2 * np.log(2))}[kernel])
    np.testing.assert_allclose(kernel_phi(kernel, s, np.array([h * h])), 0.5, rtol=1e-12)
    net = RBFNetwork(2, s, kernel, bias=False)
    net.centres_ = np.array([[0.0, 0.0], [3.0, 4.0]])
    np.testing.assert_allclose(net.hidden(np.array([[0.0, 0.0]])), kernel_phi(kernel, s, np.array([[0.0, 25.0]])), rtol=1e-12)


def test_rbf_exact_solve_is_eq12_and_its_conditioning_grows_with_spread():
    """Eqs. 10-12 as printed: one unit per training sample, w = Phi^-1 d, so the network reproduces every training
    target (eq. 11); wider units make Phi closer to singular (its condition number grows with the spread), which
    is what an unregularised solve amplifies; the RLS ridge (delta) is bounded instead."""
    from learn.experiments.ntype import phi_condition, split_reading
    from learn.models.rbf import RBFNetwork

    rng = np.random.default_rng(3)
    X = rng.uniform(16.0, 25.0, (120, 36))
    Y = rng.uniform(0.0, 4.8, (120, 36))
    for k in ("eq9", "matlab"):
        net = RBFNetwork(len(X), 7.0, k, solver="exact").fit(X, Y, centres=X)
        np.testing.assert_allclose(net.predict(X), Y, atol=1e-6)
        assert net.coef_.shape == (120, 36)  # no bias unit in eq. 10
    with pytest.raises(ValueError):
        RBFNetwork(10, 7.0, "eq9", solver="exact").fit(X, Y, centres=X[:10])
    with pytest.raises(ValueError):
        RBFNetwork(len(X), 7.0, "eq9", solver="exact").fit(X, Y, centres=X).partial_fit(X, Y)
    c = [phi_condition("eq9", s, X) for s in (1.0, 4.0, 10.0)]
    assert c[0] < c[1] < c[2] and c[0] < 10.0 and c[2] > 1e3
    assert split_reading("matlab+exact") == ("matlab", "exact") and split_reading("eq9") == ("eq9", "rls")


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    from learn.experiments import get_experiment

    return get_experiment("ntype").run(tmp_path_factory.mktemp("q") / "q", mode="quick", progress=False, log=lambda s: None)


@pytest.mark.slow
def test_experiment_ntype_quick(quick_run):
    """Issue 14's ntype targets that the quick run meets (bench/results/experiments/ntype-quick.json): on the paper's
    task window 5 beats no window on all three components, its errors are within 3x of Table 3's, and ours (the
    element MLP) beats the best paper model on all three."""
    from learn.experiments.ntype import PAPER_TABLE3

    F = quick_run["findings"]
    assert quick_run["task"] == "paper" and all(F["window5_beats_no_window"].values())
    w5 = quick_run["models"]["rbf_win"]["5"]
    best = min(w5, key=lambda s: sum(w5[s][f"E_{c}"] for c in ("Fx", "Fy", "Fz")))
    for c, p in zip(("Fx", "Fy", "Fz"), PAPER_TABLE3[5]):
        assert w5[best][f"E_{c}"] < 3.0 * p, (c, w5[best][f"E_{c}"], p)
    assert all(F["elem_mlp_beats_best_paper_model"].values())
    # eqs. 10-12 as printed: Phi over the training samples stays well conditioned (1080 samples in 36-D lie
    # 13-22 input units from their nearest neighbour), so the exact solve does not turn Table 1 up at large spread
    cn = F["table1_exact_phi_condition_fold1"]
    assert max(v for s in cn["eq9+exact"].values() for v in s.values()) < 1e6


@pytest.mark.slow
@pytest.mark.xfail(strict=False, reason="issue 14 open (measured in bench/results/experiments/ntype-quick*.json): "
                   "Table 1's best spread is 10, the sweep's edge, on seeds 0-2 (error flat from 7 to 10: F_z 4.25 -> "
                   "4.12 %), also under eqs. 10-12 as printed (exact solve: 4.20 -> 4.03 %) and MATLAB's spread; a test "
                   "input sits 13-22 input units from its nearest training sample: wider than every MATLAB unit swept "
                   "(0.5 at d = spread), narrower than eq. 9's from spread 3 on (0.5 at 12 units), where it flattens. "
                   "At the full budget (the paper's 3000 samples, ntype-full-paper*.json): 10 on seeds 0-1, 9 on seed 2 "
                   "by 0.001 points (flat from 7); F_z alone turns up at 8-9 by 0.02 points; the nearest sample 4 % closer. "
                   "Session 10 (bench/results/ntype-linear-*.json): the inputs follow eq. 13 as printed, and an affine map "
                   "of Table 1's own inputs gives F_z 3.05 % (quick) / 3.02 % (full), below the RBF at its widest spread "
                   "(4.12 / 3.42 %): the map is near-affine, so every wider, flatter unit still helps")
def test_experiment_ntype_quick_open_targets(quick_run):
    F = quick_run["findings"]
    assert F["table1_interior_optimum"]


def test_element_mlp_batched_members_match_one_after_another():
    """`ElementMLP.fit` trains the ensemble as one batched network (flat weights, per-member AdamW and early
    stopping) and `fit_sequential` one nn.Sequential after another with the same draws: the same members up to
    float summation order, also when the members hold different numbers of rows and stop at different epochs."""
    from learn.models.element_mlp import ElementMLP

    rng = np.random.default_rng(0)
    rest = np.array([40e3, 40e3, 20e3])
    R = [rest * np.exp(rng.normal(0, 0.05, (8, 36, 3))) for _ in range(10)]
    F = [np.abs(rng.normal(0, 1, (8, 36, 3))) * (rng.random((8, 36, 3)) < 0.4) for _ in range(10)]
    kw = {"n_seeds": 3, "hidden": 8, "max_epochs": 7, "patience": 1, "batch_size": 300}
    a = ElementMLP(rest, 2.0, **kw).fit(R, F, seed=5)
    b = ElementMLP(rest, 2.0, **kw).fit_sequential(R, F, seed=5)
    rows = [h["n_rows"] for h in a.history_]
    assert rows == [h["n_rows"] for h in b.history_] and len(set(rows)) > 1  # members of unequal size
    assert [h["epochs"] for h in a.history_] == [h["epochs"] for h in b.history_]
    for ha, hb in zip(a.history_, b.history_):
        assert ha["best_valid_loss"] == pytest.approx(hb["best_valid_loss"], rel=1e-5)
    pa, pb = a.predict(R[0]), b.predict(R[0])
    np.testing.assert_allclose(pa, pb, rtol=0, atol=1e-5 * np.abs(pb).max())


def _part(models, windows, sha="d0", seed=0):
    """A metrics.json of one process of the device run (the keys merge_runs reads)."""
    return {"experiment": "ntype", "mode": "full", "seed": seed, "task": "press_stroke",
            "dataset": {"dataset_sha256": "t" + sha, "content_sha256": sha}, "protocol": {"fold_episodes": [["e0"], ["e1"]], "spreads": [1.0, 7.0, 10.0],
                                                            "windows": windows},
            "models": {"mean": _e(9, 9, 9), **models}, "timing_s": {k: 1.0 for k in models},
            "findings": {"nearest_centre_median": {f"rbf_w{w}": 5.0 + w for w in windows}}}


def _e(x, y, z):
    return {"E_Fx": float(x), "E_Fy": float(y), "E_Fz": float(z), **{f"MAE{k}_F{c}": 0.1 for k in ("", "_loaded") for c in "xyz"}}


def test_merge_runs_recomputes_findings_across_parts():
    """The device's parts (one model group or window a process) merge into the metrics one process would have
    written: windows side by side, findings that span parts (window 5 vs Table 1, ours vs the best RBF) recomputed;
    parts of different data or seeds are refused."""
    from learn.experiments.ntype import merge_runs

    t1 = {"1.0": _e(9, 9, 9), "7.0": _e(4, 4, 3), "10.0": _e(5, 5, 4)}  # Table 1: best spread 7 (interior)
    w5 = {"1.0": _e(8, 8, 8), "7.0": _e(3, 3, 3.5), "10.0": _e(3.5, 3.5, 3.6)}  # beats Table 1 on Fx, Fy only
    w3 = {"1.0": _e(8, 8, 8), "7.0": _e(3.0, 3.0, 2.9), "10.0": _e(6, 6, 6)}
    parts = [_part({"elem_mlp": _e(2, 2, 3.2)}, []), _part({"rbf_win": {"5": w5}}, [5]),
             _part({"rbf_col": t1}, []), _part({"rbf_win": {"3": w3}}, [3])]
    m = merge_runs(parts)
    assert list(m["models"]["rbf_win"]) == ["3", "5"] and m["protocol"]["windows"] == [3, 5]
    F = m["findings"]
    assert F["table1_best_spread"] == 7.0 and F["table1_interior_optimum"]
    assert F["window5_beats_no_window"] == {"Fx": True, "Fy": True, "Fz": False}
    assert F["best_paper_model"] == "rbf_w3" and F["best_paper_errors"] == {"Fx": 3.0, "Fy": 3.0, "Fz": 2.9}
    assert F["elem_mlp_beats_best_paper_model"] == {"Fx": True, "Fy": True, "Fz": False}
    assert F["nearest_centre_median"] == {"rbf_w3": 8.0, "rbf_w5": 10.0}
    assert m["timing_s"] == {"elem_mlp": 1.0, "rbf_win": 2.0, "rbf_col": 1.0} and m["tasks"] == {}
    with pytest.raises(ValueError, match="different datasets"):
        merge_runs([parts[0], _part({"rbf_col": t1}, [], sha="other")])
    with pytest.raises(ValueError, match="seed"):
        merge_runs([parts[0], _part({"rbf_col": t1}, [], seed=1)])
    with pytest.raises(ValueError, match="more than one part"):
        merge_runs([parts[2], parts[2]])


@pytest.mark.slow
def test_device_full_script_round_trip(tmp_path):
    """bench/device_full_ntype.sh start / poll / collect at the tiny scale: the parts (Table 1, window 3, one
    process each) merge into the results file with the same models and findings as one process running both."""
    import dataclasses
    import os
    import subprocess
    import sys
    from pathlib import Path

    from learn.experiments import ntype as NT

    repo = Path(__file__).resolve().parents[1]
    env = {**os.environ, "NTYPE_MODE": "tiny", "NTYPE_SEEDS": "0", "NTYPE_PARTS": "w3 t1", "PY": sys.executable,
           "NTYPE_ROOT": str(tmp_path / "dev"), "NTYPE_RESULTS": str(tmp_path / "res"), "OUT": str(tmp_path / "out"),
           "NTYPE_GPU": "cpu", "PYTHONPATH": str(repo)}
    for cmd in ("start", "poll", "collect"):
        r = subprocess.run(["bash", "bench/device_full_ntype.sh", cmd, *(["240"] if cmd == "poll" else [])], cwd=repo,
                           env=env, capture_output=True, text=True, timeout=400)
        assert r.returncode == 0, (cmd, r.stdout, r.stderr)
    assert "all parts ended" in r.stdout or "done" in r.stdout
    m = json.loads((tmp_path / "res" / "ntype-full.json").read_text())
    assert (tmp_path / "out" / "ntype-full-device.tgz").stat().st_size > 1000
    md = dataclasses.replace(NT.MODES["tiny"], tasks=("paper",), alt_kernels=("eq9+exact",), windows=(3,))
    old = NT.MODES["tiny"]
    NT.MODES["tiny"] = md
    try:
        one = NT.run(tmp_path / "one", mode="tiny", data_dir=tmp_path / "dev" / "data" / "s0", models=["rbf_col", "rbf_win"],
                     seed=0, progress=False, log=lambda s: None)
    finally:
        NT.MODES["tiny"] = old
    assert m["dataset"]["content_sha256"] == one["dataset"]["content_sha256"]
    assert m["models"] == json.loads(json.dumps(one["models"]))
    for k in ("table1_best_spread", "window_best_spread", "best_paper_model", "best_paper_errors",
              "nearest_centre_median", "table1_best_spread_exact"):
        assert m["findings"][k] == json.loads(json.dumps(one["findings"][k])), k
    assert m["machine"]["missing"] == [] and m["machine"]["parts"].count(" done ") == 2


def test_linear_maps_recover_an_affine_sensor_and_its_crosstalk():
    """bench/bench_ntype_linear.py's maps: forces that are an affine function of each column's own resistances
    plus a neighbour's are recovered by Table 1's inputs and the wires' R_z (to round-off), not by the element's
    own column alone."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("bench_ntype_linear", Path(__file__).resolve().parents[1]
                                                  / "bench" / "bench_ntype_linear.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rng = np.random.default_rng(3)
    N = rng.uniform([32, 32, 16], [50, 50, 25], size=(400, 36, 3))
    F = 0.5 * (N - [32, 32, 16])
    m = np.arange(36)[np.arange(36) % 6 > 0]
    F[:, m, 2] += 0.3 * (N[:, m - 1, 2] - 16)  # element m's F_z also moves with its left neighbour's R_z
    P = mod.maps(N[:300], F[:300], N[300:], np.array([40.0, 40.0, 20.0]))
    ref = F[300:]
    assert np.abs(P["t1_linear"] - ref).max() < 1e-4  # the 1e-6 ridge's bias on inputs of 16-50 units
    assert np.abs(P["all_columns_linear"] - ref).max() < 1e-4
    own = np.abs(P["own_column_per_element"][..., 2] - ref[..., 2]).max()
    assert own > 0.1 and np.abs(P["own_column_per_element"][..., :2] - ref[..., :2]).max() < 1e-4
    assert np.isnan(P["fz_from_wires_rz"][..., 0]).all() and np.abs(P["fz_from_window5_rz"][..., 2] - ref[..., 2]).max() < 1e-4


def test_targets_table_met_and_not_met():
    """The experiment page's issue-14 table: met / not met from each run's findings, "not run" where a model
    group is missing (session 9's paper-methods-only files)."""
    from learn.experiments.ntype import merge_runs, targets_table

    t1 = {"1.0": _e(9, 9, 9), "7.0": _e(4, 4, 3), "10.0": _e(5, 5, 4)}
    w5 = {"1.0": _e(8, 8, 8), "7.0": _e(3, 3, 3.5), "10.0": _e(3.5, 3.5, 3.6)}
    full = merge_runs([_part({"elem_mlp": _e(2, 2, 3.6)}, []), _part({"rbf_win": {"5": w5}}, [5]), _part({"rbf_col": t1}, [])])
    full["protocol"]["samples"] = 3000
    full["machine"] = {"wall_s": 900.0, "cpu_s": 5000.0, "train_device": ["cuda"]}
    only = merge_runs([_part({"rbf_col": t1}, [])])
    only["protocol"]["samples"] = 3000
    text = targets_table({"full": full, "t1 only": only})
    rows = {r.split("|")[1].strip(): [c.strip() for c in r.split("|")[2:-1]] for r in text.splitlines()[2:]}
    assert rows["Table 1 best spread inside the 1-10 sweep (paper 7)"] == ["7 (met)", "7 (met)"]
    assert rows["window 5 better than no window (F_x, F_y, F_z)"] == ["yes, yes, no (**not met**)", "not run"]
    assert rows["window 5 within 3x of Table 3 (<= 6.39 / 8.13 / 4.08 %)"][0] == "3.00 / 3.00 / 3.50 % (met)"
    assert rows["ours (element MLP) better than the best RBF on all three"] == ["2.00 / 2.00 / 3.60 % (**not met**)", "not run"]
    assert "ours on cuda" in rows["cost"][0]


def test_tasks_in_processes_give_the_serial_numbers(tmp_path, tiny_cli):
    """Workers 2 (the CLI's default on a multi-core machine: the two tasks in spawned processes, one thread each,
    every model) gives the element-MLP numbers of a serial run of that model alone on both tasks (torch on one
    thread in both; same data): neither the processes nor the other models change a model's numbers."""
    from learn.experiments import ntype as NT

    side_dir, side = tiny_cli
    serial = NT.run(tmp_path / "serial", mode="tiny", data_dir=side_dir / "data", workers=1, models=["elem_mlp"],
                    progress=False, log=lambda s: None)
    for a, b in ((serial, side), (serial["tasks"]["press_stroke"], side["tasks"]["press_stroke"])):
        assert a["task"] == b["task"]
        ea, eb = a["models"]["elem_mlp"], b["models"]["elem_mlp"]
        errs = [k for k in ea if k.startswith(("E_", "MAE_"))]
        assert errs and all(ea[k] == eb[k] for k in errs)
    assert (side_dir / "press_stroke").is_dir() and (side_dir / "metrics.json").is_file()
