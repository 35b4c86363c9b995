"""velostat paper compensators: K-means / G_J, silhouette, memberships, creep tracking, BP net, experiment."""

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from learn.models.velostat import (
    BPCompensator,
    CreepTracker,
    KMeans,
    gj_criterion,
    semi_trapezoid,
    silhouette_samples,
    silhouette_score,
)
from scenes import load_scene

torch.set_num_threads(1)


def test_kmeans_hand_made_1d():
    x = np.array([0.0, 1.0, 2.0, 10.0, 11.0, 12.0, 50.0, 52.0])
    km = KMeans(3).fit(x)
    np.testing.assert_array_equal(km.cluster_centers_[:, 0], [1.0, 11.0, 51.0])
    np.testing.assert_array_equal(km.labels_, [0, 0, 0, 1, 1, 1, 2, 2])
    # G_J: p_k * mean pairwise distance: 3/8 * 4/3 + 3/8 * 4/3 + 2/8 * 2
    assert km.gj_ == pytest.approx(3 / 8 * 4 / 3 * 2 + 2 / 8 * 2)
    assert gj_criterion(x, km.labels_) == pytest.approx(km.gj_)
    np.testing.assert_array_equal(km.predict([0.4, 30.0, 40.0]), [0, 1, 2])
    # online update moves the nearest centre by 1/n of the gap
    km.partial_fit([15.0])
    assert km.cluster_centers_[1, 0] == pytest.approx(11.0 + 4.0 / 4)


def test_kmeans_2d_and_kmeanspp():
    rng = np.random.default_rng(0)
    c = np.array([[0, 0], [5, 5], [0, 8]], float)
    X = np.concatenate([c[k] + 0.1 * rng.standard_normal((20, 2)) for k in range(3)])
    km = KMeans(3, init="k-means++", n_init=3, seed=1).fit(X)
    got = km.cluster_centers_[np.argsort(km.cluster_centers_[:, 0] + 10 * km.cluster_centers_[:, 1])]
    np.testing.assert_allclose(got, c[np.argsort(c[:, 0] + 10 * c[:, 1])], atol=0.1)


def test_silhouette_exact_values():
    x = np.array([0.0, 1.0, 10.0, 11.0])
    lab = np.array([0, 0, 1, 1])
    # point 0: a = 1, b = (10 + 11) / 2 = 10.5 -> s = 9.5 / 10.5; point 1: a = 1, b = 9.5 -> 8.5 / 9.5
    want = np.array([9.5 / 10.5, 8.5 / 9.5, 8.5 / 9.5, 9.5 / 10.5])
    np.testing.assert_allclose(silhouette_samples(x, lab), want)
    assert silhouette_score(x, lab) == pytest.approx(want.mean())
    # the n-D path agrees with the 1-D path; a singleton scores 0
    np.testing.assert_allclose(silhouette_samples(np.column_stack([x, 0 * x]), lab), want)
    s = silhouette_samples(np.array([0.0, 1.0, 5.0]), np.array([0, 0, 1]))
    assert s[2] == 0.0 and s[0] == pytest.approx((5.0 - 1.0) / 5.0)  # a = 1, b = 5


def test_semi_trapezoid_shapes():
    lo, hi = 0.00612, 0.02374  # the paper's eqs. 8-9
    d = np.array([0.0, lo, (lo + hi) / 2, hi, 0.1])
    t1, t2 = semi_trapezoid(d, lo, hi)
    np.testing.assert_allclose(t1, [0, 0, 0.5, 1, 1])
    np.testing.assert_allclose(t2, [1, 1, 0.5, 0, 0])
    g = np.linspace(0, 0.05, 200)
    t1, t2 = semi_trapezoid(g, lo, hi)
    assert np.all(np.diff(t1) >= 0) and np.all(np.diff(t2) <= 0) and np.allclose(t1 + t2, 1)
    assert t1[g > 0.01] .min() >= 0 and (0.00612 + 0.01762 == pytest.approx(hi))
    with pytest.raises(ValueError):
        semi_trapezoid(d, hi, lo)


def _creep_recording(rng, levels=(2.0, 5.0, 9.0), hold=300, ramp=20, rest=50, r_open=60000.0, noise=0.0):
    """Synthetic recording at 10 Hz: G = k (F + c), c relaxes in log time during holds (creep adds
    conductance); returns R (ohm), the creep-free R, the force."""
    k = 1.0 / 5000.0
    F, C = [np.zeros(rest)], [np.zeros(rest)]
    for lv in levels:
        F += [np.linspace(0, lv, ramp, endpoint=False) + lv / ramp, np.full(hold, lv), np.linspace(lv, 0, ramp)]
        t = np.arange(1, hold + 1) / 10.0
        c = 0.25 * lv * np.log1p(t / 0.5) / np.log1p(30 / 0.5)
        C += [np.zeros(ramp), c, np.full(ramp, c[-1])]
        F.append(np.zeros(rest)), C.append(np.zeros(rest))
    F, C = np.concatenate(F), np.concatenate(C)
    g = k * (F + C)
    with np.errstate(divide="ignore"):
        R = np.minimum(1.0 / g, r_open)
        R0 = np.minimum(1.0 / (k * F), r_open)
    R = R * (1 + noise * rng.standard_normal(len(R)))
    return np.minimum(R, r_open), R0, F


def test_creep_compensation_removes_most_hold_error():
    rng = np.random.default_rng(0)
    train = [_creep_recording(rng, lv)[0] for lv in ((1.0, 4.0, 8.0), (3.0, 6.0, 12.0))]
    tr = CreepTracker(smooth=1, lag=1, domain="conductance").fit(train)
    lo, hi = tr.bounds
    assert 0 < lo < hi and 0 < tr.silhouette_ <= 1
    R, R0, F = _creep_recording(rng, (2.0, 5.0, 9.0))
    Rc, stage = tr.transform(R)
    hold = (F > 0) & (np.abs(np.gradient(F)) < 1e-9)
    err_raw = np.abs(1 / R[hold] - 1 / R0[hold]).max()
    err_comp = np.abs(1 / Rc[hold] - 1 / R0[hold]).max()
    assert err_comp < 0.1 * err_raw  # most of the log-creep error is gone
    assert np.mean(stage[hold] == 0) > 0.9 and np.all(stage[R >= 60000.0] == -1)
    # streaming == batch, partial_fit keeps a valid band
    st = tr.stream()
    np.testing.assert_allclose([st.step(v)[0] for v in R], Rc)
    tr.partial_fit(R)
    assert tr.bounds[0] < tr.bounds[1]
    # state round trip
    assert np.allclose(CreepTracker.from_state(tr.state()).predict(R), tr.predict(R))
    # given bounds (the paper's band) stay in use; the K-means band is still fitted
    fixed = CreepTracker(smooth=1, lag=1, bounds=(0.00612, 0.02374)).fit(train, score=False)
    assert fixed.bounds == (0.00612, 0.02374) and 0 < fixed.kmeans_bounds_[0] < fixed.kmeans_bounds_[1]


def test_bp_beats_trivial_baseline_on_held_out():
    rng = np.random.default_rng(1)

    def data(n):
        unit = rng.integers(0, 6, n).astype(float)
        F = rng.uniform(1, 15, n)
        R = 3000.0 / (F * (1 + 0.1 * unit))
        return np.column_stack([unit, R]), F[:, None]

    x, y = data(300)
    xv, yv = data(60)
    xt, yt = data(200)
    bp = BPCompensator(hidden=6, max_epochs=80, patience=30).fit([x], [y], valid=([xv], [yv]), seed=0)
    rmse = np.sqrt(np.mean((bp.predict(xt) - yt) ** 2))
    base = np.sqrt(np.mean((yt - y.mean()) ** 2))
    assert rmse < 0.5 * base
    st = bp.stream()
    np.testing.assert_allclose(np.stack([st.step(v) for v in xt[:20]]), bp.predict(xt[:20]), atol=1e-5)


def test_bp_log_onehot_inputs(tmp_path):
    """ln R + one-hot unit (our default in the experiment) fits per-unit power laws over a 30x range of R, where
    the literal min-max R squeezes the loaded range near 0; checkpoint and stream take the raw (id, R)."""
    from learn.checkpoint import load_checkpoint, save_checkpoint

    rng = np.random.default_rng(2)

    def data(n):
        unit = rng.integers(0, 4, n).astype(float)
        F = rng.uniform(1, 15, n)
        R = np.minimum(20000.0 / (F * (1 + 0.5 * unit)) ** 1.05, 60000.0)  # ~700 ohm .. 20 kohm
        return np.column_stack([unit, R]), F[:, None]

    x, y = data(400)
    xv, yv = data(80)
    xt, yt = data(200)
    fit = lambda **hp: BPCompensator(hidden=6, max_epochs=60, patience=20, **hp).fit([x], [y], valid=([xv], [yv]))
    ours = fit(r_input="log", encoding="onehot")
    assert ours.hparams["n_ids"] == 4 and ours.n_in == 5
    rmse = lambda m: float(np.sqrt(np.mean((m.predict(xt) - yt) ** 2)))
    assert rmse(ours) < 0.25 * float(np.std(yt))  # ~0.55 N of ~4 N; the literal inputs get ~2.1 N here
    back = load_checkpoint(save_checkpoint(ours, tmp_path / "bp"))
    np.testing.assert_allclose(back.predict(xt), ours.predict(xt))
    st = ours.stream()
    np.testing.assert_allclose(np.stack([st.step(v) for v in xt[:10]]), ours.predict(xt[:10]), atol=1e-5)
    with pytest.raises(ValueError):
        BPCompensator(r_input="volt")


def test_bp_registered_and_checkpoint_roundtrip(tmp_path):
    from learn.checkpoint import load_checkpoint, save_checkpoint
    from learn.models import MODELS

    assert "bp" in MODELS
    x = np.column_stack([np.zeros(50), np.linspace(200, 3000, 50)])
    y = 3000 / x[:, 1:]
    bp = BPCompensator(hidden=3, max_epochs=5).fit([x], [y])
    back = load_checkpoint(save_checkpoint(bp, tmp_path / "bp"))
    np.testing.assert_allclose(back.predict(x), bp.predict(x))


def test_experiment_velostat_tiny(tmp_path):
    from learn.experiments import EXPERIMENTS, get_experiment

    assert "velostat" in EXPERIMENTS
    out = tmp_path / "exp"
    m = get_experiment("velostat").run(out, mode="tiny", models=["raw_bp", "paper_cluster", "literal_unit", "tcn"],
                                       progress=False, log=lambda s: None)
    j = json.loads((out / "metrics.json").read_text())
    assert set(j) >= {"creep", "clustering", "bp_search", "models", "paper", "findings", "datasets", "split"}
    assert set(j["models"]) == {"mean", "raw_bp", "paper_cluster", "literal_unit", "tcn"}
    # ours: a seed ensemble (tiny: 2 members), each member reported on the same test; it beats the trivial mean
    T = j["models"]["tcn"]
    assert T["hparams"]["member"] == "tcn" and T["hparams"]["n_members"] == 2
    assert [mm["seed"] for mm in T["members"]] == [0, 1]
    assert T["test"]["rmse"] < j["models"]["mean"]["test"]["rmse"]
    assert T["test"]["rmse"] <= sum(mm["test"]["rmse"] for mm in T["members"]) / 2 + 1e-9
    F = j["findings"]
    assert set(F["ours_vs_every_paper_model"]["rmse"]) == {"raw_bp", "paper_cluster", "literal_unit"}
    assert isinstance(F["ours_beats_every_paper_model_on_every_metric"], bool)
    from learn.checkpoint import load_checkpoint
    ck = load_checkpoint(out / "checkpoints" / "tcn")
    assert ck.kind == "ensemble" and len(ck.members) == 2
    assert j["bp_search"]["paper_cluster"]["inputs"] == {"r_input": "log", "encoding": "onehot"}
    assert j["bp_search"]["literal_unit"]["inputs"] == {"r_input": "ohm", "encoding": "index"}
    # the literal chain trains through (sect. 4.2 step 6: no early stop on validation), the others early-stop
    lt, pt = j["bp_search"]["literal_unit"]["training"], j["bp_search"]["paper_cluster"]["training"]
    assert lt["patience"] >= lt["max_epochs"] and pt["patience"] < pt["max_epochs"]
    # eq. 24 on R in ohm: the top third of the forces gets a small share of the scaled input (R ~ F^-1.05)
    c = F["literal_input_crowding"]
    assert c["r_median_1n_ohm"] > c["r_median_10n_ohm"] > c["r_median_15n_ohm"] > 0
    assert 0.0 < c["share_10_15n"] < 0.1
    assert {"silhouette", "bounds", "centres", "gj", "r_drift_raw_mean", "r_drift_comp_mean"} <= set(j["creep"])
    assert j["clustering"]["k_elbow"] >= 1 and j["paper"]["silhouette"] == 0.931
    for k in ("raw_bp", "paper_cluster", "literal_unit"):
        assert {"holds", "ae", "test"} <= set(j["models"][k])
        assert {"max_err_mean", "drift_mean"} <= set(j["models"][k]["holds"])
    assert j["creep"]["r_drift_comp_mean"] < j["creep"]["r_drift_raw_mean"]
    # Fig. 22a: one compensated-calibration BP read on measured and on compensated R
    sb = j["creep"]["force_same_bp"]
    assert sb["bp"] == "paper_cluster" and sb["raw"]["n_holds"] == sb["compensated"]["n_holds"] > 0
    assert F["creep_drift_removed_frac"] == pytest.approx(sb["drift_removed_frac"])
    # the readout diagnostic: both delta readings at every noise scale, the ideal readout without noise
    rs = j["creep"]["readout_sensitivity"]
    assert len(rs) == 2 * 3 and {r["reading"] for r in rs} == {"paper", "ours"}
    assert [r["noise_ohm"] for r in rs if r["reading"] == "paper"] == pytest.approx([20.0, 10.0, 0.0])
    assert F["creep_target"]["removed_frac"] == pytest.approx(F["r_drift_removed_frac"])
    # ours: both input sets trained, the one with the lower validation RMSE kept
    assert set(T["valid_rmse_by_inputs"]) == {"raw", "calibrated", "aged"}
    assert T["inputs"] == min(T["valid_rmse_by_inputs"], key=T["valid_rmse_by_inputs"].get)
    text = (out / "report.md").read_text()
    assert "0.931" in text and "Where we differ" in text
    for p in ("delta_clusters.png", "units.png", "creep.png", "ae_error.png"):
        assert (out / p).stat().st_size > 1000
    assert m["mode"] == "tiny"


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    from learn.experiments import get_experiment

    return get_experiment("velostat").run(tmp_path_factory.mktemp("q") / "q", mode="quick", progress=False,
                                          log=lambda s: None)


@pytest.mark.slow
def test_experiment_velostat_quick(quick_run):
    """Issue 14's targets that the quick run meets (bench/results/experiments/velostat-quick.json)."""
    m = quick_run
    assert m["findings"]["r_drift_removed_frac"] > 0.3  # Figs. 9-10 (resistance): the paper's band removes ~half
    assert all(m["findings"]["all_beat_mean"].values())
    R = m["models"]
    assert R["paper_unit"]["test"]["rmse"] < R["literal_unit"]["test"]["rmse"]  # ln R + one-hot beats the literal
    # the calibration sweep: every unit has a training calibration to 15 N
    assert len(m["clustering"]["units_with_data"]) == 36
    # Ward on the units' calibrations (eq. 10): the paper's "about 5" groups
    assert 4 <= m["clustering"]["k_elbow"] <= 6
    assert m["creep"]["silhouette"] >= 0.8
    # the K-means of Fig. 6 on eq. 3 as printed (one detection cycle of the measured R) lands within 2x of the
    # paper's band (eqs. 8-9); so does the one-cycle delta of the 0.5 s average
    assert m["findings"]["kmeans_paper_reading"]["band_within_2x"]
    lo, hi = m["creep"]["one_cycle"]["kmeans_bounds"]
    assert 0.5 < lo / 0.00612 < 2.0 and 0.5 < hi / 0.02374 < 2.0
    # the readout diagnostic: the readout noise is what keeps eq. 3 as printed from the paper's silhouette and
    # drift removal (an ideal readout: silhouette near the paper's 0.931, most of the R drift removed)
    rs = {(r["reading"], r["noise_scale"]): r for r in m["creep"]["readout_sensitivity"]}
    assert rs["paper", 0.0]["silhouette"] > 0.85 > rs["paper", 1.0]["silhouette"] + 0.2
    assert rs["paper", 0.0]["r_drift_removed_frac"] > 0.9 > rs["paper", 0.5]["r_drift_removed_frac"] > rs["paper", 1.0]["r_drift_removed_frac"]
    # ours (a 3-seed TCN ensemble) beats the paper's literal chains on the held-out RMSE, MAE, R^2, both hold errors
    # and the A-E share < 1 N, and every chain on the worst hold error. Since session 12's residual default
    # (adopted on validation, quick seeds 0-2) ours picks the raw inputs at seed 0 (validation RMSE 1.141 N against
    # the residual sets' 1.245 / 1.275), which no longer beats raw_bp / paper_unit on RMSE nor every chain on the
    # worst A-E point (velostat-quick.json; seed 0's calibrated ours did, 0.807 N); session 13's derivative matching
    # (adopted on validation) keeps the raw pick (1.151 against 1.249 / 1.260 N), test RMSE 1.158 N
    assert R["tcn"]["hparams"]["n_members"] == 3 and len(R["tcn"]["members"]) == 3
    V = m["findings"]["ours_vs_every_paper_model"]
    for met in ("mae", "rmse", "r2", "hold_max_err_mean", "hold_max_err_worst", "ae_below_1n"):
        assert V[met]["literal_unit"] and V[met]["literal_cluster"], met
    assert all(V["hold_max_err_worst"].values()), V["hold_max_err_worst"]
    assert R["tcn"]["test"]["rmse"] < 0.65 * R["literal_unit"]["test"]["rmse"]  # 1.16 against 1.99 N
    # the literal cluster chain trained through sect. 4.2's 500 epochs meets the paper's test-RMSE bound (< 2 N)
    assert m["bp_search"]["literal_cluster"]["test_holds_rmse"] < 2.0
    assert m["findings"]["literal_input_crowding"]["share_10_15n"] < 0.05
    # the units' spread the literal unit index must map (the paper bounds none): resistivity domains 1 -/+ 0.65
    # (an estimate) hold most of it, shuffled over the film, so neighbours along the literal index are nearly
    # as far apart as random units (roughness ~1) and R at equal force spans several times over the units
    us = m["clustering"]["unit_spread"]
    assert 0.3 < us["levels_n"]["10"]["std_ln_r"] < 0.5 and us["levels_n"]["10"]["max_over_min"] > 3.0
    assert us["between_domain_share"] > 0.6 and us["roughness_index"] > 0.5
    # the K-means of Fig. 6 per loading speed: slow ramps overlap the creep stage (lower band and silhouette)
    bs = m["creep"]["by_speed"]
    assert bs[0]["speed_mm_per_min"] < bs[-1]["speed_mm_per_min"]
    assert bs[0]["silhouette"] < bs[-1]["silhouette"] and bs[0]["kmeans_bounds"][1] < bs[-1]["kmeans_bounds"][1]


@pytest.mark.slow
@pytest.mark.xfail(strict=False, reason="issue 14 open (measured in bench/results/experiments/velostat-quick.json): "
                   "the R hold drift removed (Figs. 9-10) is 49.3 % on the quick test (52.0 % on the full budget's 711 "
                   "test holds), and eq. 3 as printed clusters at silhouette 0.59 (0.55 full): both limited by the "
                   "readout noise (an estimate; the readout diagnostic: with an ideal readout 0.90 / 0.81 and 97 / 96 %, quick / full); the literal "
                   "chains, trained through sect. 4.2's 500 epochs, miss their own bound on the worst A-E point (5.82 / "
                   "3.36 N quick, 5.06 / 5.34 N full, unit / cluster index; the worst points are 1 mm/min staircases read "
                   "low at 13-15 N): R in ohm min-max scaled gives 10-15 N 1.6 % of the input, and a scalar unit index "
                   "cannot follow 36 curves whose levels jump along the index (roughness 0.67, std ln R 0.41 over the "
                   "units; the paper bounds neither); ours loses the unsigned hold drift to two compensated chains "
                   "(noise-following; its signed drift is the smallest) and, with session 12's residual default and "
                   "session 13's derivative matching (ours picks the raw inputs at seed 0 on validation), RMSE / mean "
                   "hold error / A-E to raw_bp and paper_unit")
def test_experiment_velostat_quick_open_targets(quick_run):
    m = quick_run
    F = m["findings"]
    assert F["creep_target"]["met"]
    assert F["kmeans_paper_reading"]["silhouette_ge_0_8"]
    assert all(v["met"] for v in F["literal_bound"].values())
    assert F["ours_beats_every_paper_model_on_every_metric"]


def test_calibration_holds_do_not_depend_on_the_loading_speed():
    """The experiment's calibrations hold every level 5 s at 1 and 6 mm/min alike (the A-E test's holds)."""
    from learn.experiments.velostat import CAL, CAL_HOLD_S, CAL_S
    from sensors.data.manifest import episode_seed
    from simulate.protocols.indenter import make_episode_protocol

    holds = {}
    for v in (1.0, 6.0):
        cfg = load_scene("velostat", [*CAL, f"protocol.duration_s={CAL_S}", f"protocol.loading_speeds_m_per_s=[{v / 6e4}]"])
        p = make_episode_protocol(cfg, episode_seed(0, 0), 0).params
        t, f = np.asarray(p["knots_t_s"]), np.asarray(p["knots_f_n"])
        flat = (np.diff(f) == 0) & (f[1:] > 0)
        holds[v] = np.diff(t)[flat]
        assert len(holds[v]) == 15 and t[-1] <= CAL_S
    np.testing.assert_allclose(holds[1.0], CAL_HOLD_S)
    np.testing.assert_allclose(holds[6.0], CAL_HOLD_S)


def test_calibration_sweep_covers_every_unit_and_split_keeps_the_first_round():
    from types import SimpleNamespace

    from learn.experiments.velostat import calibration_split
    from sensors.data.manifest import episode_seed
    from simulate.protocols.indenter import make_episode_protocol

    cfg = load_scene("velostat", ["protocol.kind=velostat_calibration_sweep", "generation.episodes=80"])
    rnd = load_scene("velostat", ["protocol.kind=velostat_calibration", "generation.episodes=80"])
    P = [make_episode_protocol(cfg, episode_seed(0, k), k) for k in range(80)]
    units = [p.params["unit"] for p in P]
    assert sorted(units[:36]) == list(range(36)) and sorted(units[36:72]) == list(range(36))  # one round = every unit
    assert units[:36] != units[36:72] and units[:36] != list(range(36))  # shuffled per round
    for k, p in enumerate(P[:5]):  # the same staircase as the random kind, only the unit differs
        q = make_episode_protocol(rnd, episode_seed(0, k), k)
        assert p.params["kind"] == q.params["kind"] == "velostat_calibration" and p.kind == "velostat_calibration_sweep"
        assert p.params["knots_f_n"] == q.params["knots_f_n"] and p.params["knots_t_s"] == q.params["knots_t_s"]
        assert max(p.params["knots_f_n"]) == 15.0
    with pytest.raises(ValueError, match="global index"):
        make_episode_protocol(cfg, episode_seed(0, 0))
    seqs = [SimpleNamespace(meta={"global_index": k}) for k in (39, 3, 0, 37, 38, 36, *range(4, 36), 1, 2)]
    sp = calibration_split(seqs)
    assert [s.meta["global_index"] for s in sp["valid"]] == [36, 37, 38, 39] and not sp["test"]
    assert sorted(s.meta["global_index"] for s in sp["train"]) == list(range(36))


def test_hold_diagnostics_bands_and_readout_resolution():
    """Per-band means of the hold rows, and the force channel's resolution in ohm: at the preset's 50 uA and 12 bits
    the ADC step alone is several % of the few hundred ohm of a 15 N press, above the paper's 0.6 % creep bound."""
    from learn.experiments.velostat import hold_diagnostics

    cfg = load_scene("velostat")
    d = np.array([[1.0, 0.2, 0.1, 1.0, 0], [2.0, 0.1, 0.1, 0.5, 2], [10.0, 0.03, 0.02, 0.6, 5]])
    out = hold_diagnostics(d, cfg)
    assert [b["n_holds"] for b in out["bands"]] == [2, 1]
    assert out["bands"][0]["r_drift_raw"] == pytest.approx(0.15) and out["bands"][0]["flips_per_hold"] == 1.0
    assert out["bands"][1]["force_n"] == [8.0, 16.0] and out["bands"][1]["creep_start_s_median"] == 0.6
    assert out["adc_step_ohm"] == pytest.approx(3.3 / 4096 / 50e-6) and out["noise_ohm"] == pytest.approx(20.0)
    assert out["adc_step_ohm"] / 400.0 > 0.00612


def test_site_sweep_presses_every_paper_site_in_turn():
    """The A-E test (sect. 5.4, Fig. 23: each corner and the centre, 1-15 N): velostat_site_sweep puts episode k at
    A-E[k mod 5], the same staircase as velostat_staircase; the random kind left sites out (10 episodes, 6 sites)."""
    from sensors.data.manifest import episode_seed
    from simulate.protocols.compression_tester import SITES_AE, site_xy_m
    from simulate.protocols.indenter import make_episode_protocol

    ov = ["protocol.staircase_max_n=15", "protocol.step_hold_s=5", "generation.episodes=10"]
    cfg = load_scene("velostat", ["protocol.kind=velostat_site_sweep", *ov])
    rnd = load_scene("velostat", ["protocol.kind=velostat_staircase", *ov])
    P = [make_episode_protocol(cfg, episode_seed(0, k), k) for k in range(10)]
    assert [p.params["site"] for p in P] == list(SITES_AE) * 2
    for k, p in enumerate(P):
        q = make_episode_protocol(rnd, episode_seed(0, k), k)
        assert p.params["kind"] == q.params["kind"] == "velostat_staircase"
        assert p.params["knots_f_n"] == q.params["knots_f_n"] and max(p.params["knots_f_n"]) == 15.0
        np.testing.assert_allclose(p.offset_xy_m, site_xy_m(cfg, p.params["site"]))
    assert {"A", "B", "C", "D", "E"} - {make_episode_protocol(rnd, episode_seed(0, k), k).params["site"] for k in range(10)}
    with pytest.raises(ValueError, match="global index"):
        make_episode_protocol(cfg, episode_seed(0, 0))


def test_reread_matches_the_readout_and_contact_age():
    """The readout diagnostic re-reads the true R as the force channel does: x0 is V / I (compliance kept), x1 has the
    readout's noise and ADC step (rms error ~ sqrt(20^2 + 16^2 / 12) ohm); the contact age restarts at every touch."""
    from learn.experiments.velostat import contact_age_s, reread

    cfg = load_scene("velostat")
    r = np.r_[np.full(4000, 1000.0), np.full(10, 1e12)]
    ideal = reread(r, cfg, 0.0, np.random.default_rng(0))
    assert ideal[0] == pytest.approx(1000.0) and ideal[-1] == pytest.approx(3.0 / 50e-6)
    e = reread(r, cfg, 1.0, np.random.default_rng(0))[:4000] - 1000.0
    assert np.sqrt(np.mean(e ** 2)) == pytest.approx(np.sqrt(20.0 ** 2 + 16.11 ** 2 / 12), rel=0.1)
    half = reread(r, cfg, 0.5, np.random.default_rng(0))[:4000] - 1000.0
    assert np.std(half) < 0.7 * np.std(e)
    t = np.array([0, 1, 1, 1, 0, 0, 1, 1], bool)
    np.testing.assert_allclose(contact_age_s(t, 10.0), [0, 0.1, 0.2, 0.3, 0, 0, 0.1, 0.2])


def test_unit_spread_ratios_and_layout():
    """unit_spread: R ratios at equal force, and the layout of the spread over the units (roughness 0 for a smooth
    surface along the index, ~1 for the same levels scattered at random; the share between film domains)."""
    from learn.experiments.velostat import unit_spread

    levels = np.arange(1.0, 16.0)
    u = np.arange(36)
    law = levels[None] ** -1.05
    smooth = 1e4 * np.exp(0.02 * u)[:, None] * law  # ln R rises 0.02 per unit index
    s = unit_spread(u, smooth, levels, 6)
    assert s["levels_n"]["1"]["max_over_min"] == pytest.approx(np.exp(0.02 * 35))
    assert s["levels_n"]["15"]["std_ln_r"] == pytest.approx(0.02 * np.std(u))
    assert s["roughness_index"] < 0.01
    perm = np.random.default_rng(0).permutation(36)
    rough = [unit_spread(u, smooth[np.random.default_rng(k).permutation(36)], levels, 6)["roughness_index"] for k in range(20)]
    assert 0.8 < np.mean(rough) < 1.2
    dom = u // 12  # three domains of 12 units, one level each: all the spread lies between the domains
    s = unit_spread(u, 1e4 * np.exp(0.5 * dom)[:, None] * law, levels, 6, domain=dom)
    assert s["domains"] == 3 and s["between_domain_share"] == pytest.approx(1.0)
    assert s["levels_n"]["5"]["max_over_min"] == pytest.approx(np.exp(1.0))
    s = unit_spread(u, smooth[perm], levels, 6, domain=np.zeros(36, int))
    assert s["between_domain_share"] == pytest.approx(0.0, abs=1e-12)


def test_kmeans_by_speed_slow_ramps_lower_the_loading_band():
    """kmeans_by_speed groups the staircases by loading speed; on a 1-10 N staircase of R ~ F^-1 with log-time creep
    in each 10 s hold, R moves per period in proportion to the ramp speed, so the loading band of the slow
    staircases sits below the fast ones' and their stages overlap more (lower silhouette)."""
    from learn.data import Sequence
    from learn.experiments.velostat import MODES, kmeans_by_speed

    rate = 10.0

    def staircase(v_n_per_s: float, seed: int) -> np.ndarray:
        f, t_hold = [], []
        for lv in range(1, 11):
            ramp = np.arange(lv - 1 + v_n_per_s / rate, lv, v_n_per_s / rate)
            f += list(ramp) + [lv] * int(10 * rate)
            t_hold += [0.0] * len(ramp) + list(np.arange(1, int(10 * rate) + 1) / rate)
        f, t_hold = np.maximum(np.asarray(f), 0.05), np.asarray(t_hold)
        r = 1e4 / f * (1 - 0.05 * np.log1p(t_hold / 0.5))  # creep lowers R through each hold
        return r * (1 + 1e-3 * np.random.default_rng(seed).standard_normal(len(r)))
    seqs = [Sequence(x=staircase(v, k)[:, None], y=np.zeros((1, 1)), inputs=["r"], targets=["f"], units={},
                     meta={"speed_mm_per_min": mm})
            for k, (v, mm) in enumerate([(0.1, 1.0), (0.1, 1.0), (1.0, 6.0)])]
    out = kmeans_by_speed(seqs, MODES["quick"].tracker, 0)
    assert [(b["speed_mm_per_min"], b["n_recordings"]) for b in out] == [(1.0, 2), (6.0, 1)]
    slow, fast = out
    assert slow["kmeans_bounds"][1] < fast["kmeans_bounds"][1]
    assert slow["silhouette"] < fast["silhouette"]


def test_targets_table_marks_each_target_from_the_findings():
    """targets_table: one column per run, each target met / not met by the issue's thresholds; a partial run (no
    TCN) says ours was not tested."""
    from learn.experiments.velostat import target_flags, targets_table

    def run(sil, k, removed, partial=False):
        m = {"mode": "x", "creep": {"silhouette": sil, "paper_reading": {"silhouette": 0.55}},
             "clustering": {"k_elbow": k}, "machine": {"wall_s": 300.0},
             "findings": {"kmeans_paper_reading": {"band_ratio": [1.3, 2.5], "band_within_2x": False},
                          "creep_target": {"removed_frac": removed, "met": removed >= 0.5},
                          "literal_bound": {"literal_unit": {"test_holds_rmse": 1.5, "ae_max": 2.5, "met": False}},
                          "ours_vs_every_paper_model": {"rmse": {"raw_bp": True}}, "ours_beats_every_paper_model_on_every_metric": True},
             "bp_search": {"literal_unit": {"train_rmse": 2.0}}, "models": {} if partial else {"tcn": {}}}
        if partial:
            m["partial"] = "chains only"
        return m
    t = targets_table({"quick": run(0.83, 4, 0.496), "full": run(0.69, 3, 0.52, partial=True)}).splitlines()
    assert t[0] == "| target | quick | full |"
    row = {r.split(" | ")[0].strip("| "): r.split(" | ")[1:] for r in t[2:]}
    assert row["silhouette >= 0.8 (0.5 s delta period; eq. 3 as printed)"][0].startswith("0.830 (met)")
    assert row["silhouette >= 0.8 (0.5 s delta period; eq. 3 as printed)"][1].startswith("0.690 (**not met**)")
    assert row["Ward elbow 4-6 groups"] == ["4 (met)", "3 (**not met**) |"]
    assert row["creep compensation removes >= 50 % of the hold drift (R, Figs. 9-10)"] == ["49.6 % (**not met**)", "52.0 % (met) |"]
    assert "(**not met**)" in row["K-means band (eq. 3 as printed) within 2x of 0.00612 / 0.02374"][0]
    assert row["ours beats every paper chain on every metric"] == ["met", "not tested (partial run) |"]
    fr = run(0.83, 5, 0.52)
    fr["clustering"]["first_round"] = {"k_elbow": 3}
    fr["machine"]["train_device_tcn"] = "cuda"
    t = targets_table({"full seed 1": fr}).splitlines()
    assert t[0] == "| target | full seed 1 |"
    # the same thresholds as flags (the one-speed rule counts them): a partial run leaves ours unscored
    assert target_flags(run(0.83, 4, 0.496)) == {"band": False, "sil": True, "ward": True, "drift": False,
                                                 "literal": False, "ours": True}
    assert target_flags(run(0.69, 3, 0.52, partial=True)) == {"band": False, "sil": False, "ward": False, "drift": True,
                                                              "literal": False, "ours": None}
    assert target_flags({"findings": {}})["band"] is None
    row = {r.split(" | ")[0].strip("| "): r.split(" | ")[1:] for r in t[2:]}
    assert row["Ward elbow 4-6 groups"] == ["5 (met); one calibration per unit 3 |"]
    assert row["wall time (quick: < 10 min on 2 shared cores); CPU time"] == ["5.0 min (device machine, ours on cuda) |"]


def test_ae_runs_hold_every_staircase_to_15n():
    """Sect. 5.4 presses each site 1-15 N: at every loading speed of the preset the A-E staircase reaches 15 N and
    holds its 5 s inside the quick and full runs' A-E episodes (the quick run's 110 s cut 1 mm/min before 15 N)."""
    from learn.experiments.velostat import MODES, scenes_of
    from sensors.data.manifest import episode_seed
    from simulate.protocols.indenter import make_episode_protocol

    for mode in ("quick", "full"):
        cfg = scenes_of(MODES[mode], [], 0)["ae"]
        speeds = set()
        for k in range(cfg.generation.episodes):
            p = make_episode_protocol(cfg, episode_seed(cfg.generation.root_seed, k), k).params
            t, f = np.asarray(p["knots_t_s"]), np.asarray(p["knots_f_n"])
            top = np.flatnonzero(f == 15.0)
            assert len(top) == 2 and t[top[1]] - t[top[0]] == pytest.approx(5.0)
            assert t[top[1]] <= cfg.protocol.duration_s + 1e-9, (mode, k, p["speed_m_per_s"])
            speeds.add(round(p["speed_m_per_s"] * 6e4, 3))
        assert min(speeds) == pytest.approx(min(cfg.protocol.loading_speeds_m_per_s) * 6e4)


@pytest.mark.slow  # two spawned processes import torch: ~20 s on 2 loaded cores
def test_search_hidden_workers_same_nets():
    """The hidden-node search in worker processes trains the same nets as one after another (same seeds, CPU,
    one thread): equal validation scores, the same chosen size, equal predictions."""
    from learn.models.velostat import search_hidden

    rng = np.random.default_rng(3)
    u = rng.integers(0, 4, 300).astype(float)
    f = rng.uniform(1, 15, 300)
    r = 2e4 * (1 + 0.3 * u) / f
    xs, ys = [np.column_stack([u, r])], [f[:, None]]
    valid = ([xs[0][:60]], [ys[0][:60]])
    hp = {"max_epochs": 4, "patience": 4, "r_input": "log", "encoding": "onehot"}
    a, sa = search_hidden(xs, ys, valid, hidden=[3, 5], seed=1, **hp)
    b, sb = search_hidden(xs, ys, valid, hidden=[3, 5], seed=1, workers=2, **hp)
    assert sa == sb and a.hparams["hidden"] == b.hparams["hidden"]
    np.testing.assert_array_equal(a.predict(xs[0]), b.predict(xs[0]))
    assert sa[3] != sa[5]  # two different nets, not one scored twice


@pytest.mark.slow  # three tiny runs (~25 s each on 2 cores) and three spawned processes
def test_experiment_velostat_tcn_workers_same_numbers(tmp_path, monkeypatch):
    """Ours' members trained one after another (tcn_batched False), with the input sets side by side in processes
    (tcn_workers) or not, give the same nets on the CPU; all of them as one batched network (the default) gives the
    same nets up to float summation order: ours' validation RMSEs within 1e-4 N, the chains' numbers equal."""
    import dataclasses

    from learn.experiments import velostat as V

    kw = dict(mode="tiny", models=["raw_bp", "paper_unit", "tcn"], progress=False, log=lambda s: None,
              data_dir=tmp_path / "data")
    c = V.run(tmp_path / "c", **kw)
    monkeypatch.setitem(V.MODES, "tiny", dataclasses.replace(V.MODES["tiny"], tcn_batched=False))
    a = V.run(tmp_path / "a", **kw)
    b = V.run(tmp_path / "b", tcn_workers=3, **kw)
    assert b["run"]["tcn_workers"] == 3 and a["run"]["tcn_workers"] == 1
    assert c["run"]["tcn_batched"] and not a["run"]["tcn_batched"]
    assert a["models"]["tcn"]["valid_rmse_by_inputs"] == b["models"]["tcn"]["valid_rmse_by_inputs"]
    for k in a["models"]:
        assert a["models"][k]["test"]["rmse"] == b["models"][k]["test"]["rmse"], k
        if k != "tcn":
            assert a["models"][k]["test"]["rmse"] == c["models"][k]["test"]["rmse"], k
    va, vc = a["models"]["tcn"]["valid_rmse_by_inputs"], c["models"]["tcn"]["valid_rmse_by_inputs"]
    assert set(va) == set(vc) and all(abs(va[v] - vc[v]) < 1e-4 for v in va), (va, vc)
    assert abs(a["models"]["tcn"]["test"]["rmse"] - c["models"]["tcn"]["test"]["rmse"]) < 1e-4


def test_ae_errors_top_steps_by_loading_speed():
    """ae_errors: the worst A-E point and the top steps' (13-15 N) signed error per staircase speed, from
    hand-made staircases: a slow one reading 1.5 N low at the top, a fast one 0.5 N high."""
    from learn.data import Sequence
    from learn.experiments.velostat import ae_errors

    rate = 10.0
    tg = np.repeat(np.arange(1.0, 16.0), 30)  # 15 levels, 3 s each
    seqs, preds = [], []
    for site, v, off in (("A", 1.0, -1.5), ("E", 6.0, 0.5)):
        seqs.append(Sequence(x=np.zeros((len(tg), 3)), y=tg[:, None], inputs=[], targets=["force"], units={},
                             meta={"site": site, "speed_mm_per_min": v}, extra={"target": tg}))
        preds.append(tg + np.where(tg >= 13, off, 0.1))
    a = ae_errors(seqs, preds, rate)
    assert a["n"] == 30 and a["max_abs_n"] == pytest.approx(1.5)
    assert a["top_signed_by_speed_n"] == {"1": pytest.approx(-1.5), "6": pytest.approx(0.5)}
    assert a["worst_point"][0] == "A" and a["worst_point"][1] >= 13 and a["worst_point"][3] == 1.0


@pytest.mark.slow  # two tiny runs (~25 s each on 2 cores), the second's shards in 2 spawned processes
def test_ours_only_run_merges_into_the_record_of_the_same_data(tmp_path):
    """bench/device_full_velostat.py's ours-only path: a run with ours_only (data shards in processes) makes the same
    data and the same ours as the whole run, and merge_ours puts ours into the record (chains kept, findings
    recomputed, partial dropped); a record of other data is refused."""
    import importlib.util
    import json as _json

    from learn.experiments import velostat as V

    spec = importlib.util.spec_from_file_location("dfv", Path(__file__).parents[1] / "bench" / "device_full_velostat.py")
    dfv = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(dfv)
    kw = dict(mode="tiny", progress=False, log=lambda s: None)
    rec = V.run(tmp_path / "rec", **kw)
    new = V.run(tmp_path / "ours", ours_only=True, gen_workers=2, **kw)
    assert new["ours_only"] and set(new["models"]) == {"mean", "raw_bp", "paper_unit", "tcn"}
    assert new["datasets"]["mix"]["content_sha256"] == rec["datasets"]["mix"]["content_sha256"]
    old = _json.loads(_json.dumps(rec))
    old["models"].pop("tcn")
    old["partial"] = "the paper's chains only"
    m = dfv.merge_ours(old, new, {"commit": "abc", "tcn_device": "cpu"}, "none", "abc")
    assert "partial" not in m and m["machine"]["ours"]["replaced_partial"] == "the paper's chains only"
    assert m["models"]["tcn"]["test"] == rec["models"]["tcn"]["test"]  # the same ours as the whole run
    assert m["models"]["literal_unit"] == rec["models"]["literal_unit"]  # the record's chains untouched
    assert all(c["equal"] for c in m["machine"]["ours"]["chains_refitted_vs_record"].values())
    assert m["findings"]["ours_vs_every_paper_model"] == rec["findings"]["ours_vs_every_paper_model"]
    old["datasets"]["cal"]["content_sha256"] = "0" * 64
    with pytest.raises(ValueError, match="content_sha256"):
        dfv.merge_ours(old, new, {}, "none", "abc")


@pytest.mark.slow  # two tiny runs through the shell script (~1 min on 2 cores)
def test_device_script_ours_only_start_poll_collect(tmp_path):
    """bench/device_full_velostat.sh as the coordinator types it, at the tiny scale on the CPU: a recorded run
    (start, poll, collect), then VF_ONLY=ours (start, poll, collect) merges ours into that record (exit 0); with the
    record's data hash changed, collect refuses (exit 3) and leaves the record as it was."""
    import os
    import subprocess
    import sys

    root = Path(__file__).parents[1]
    dest = tmp_path / "dest"
    env = {**os.environ, "PY": sys.executable, "PYTHONPATH": str(root), "OUT": str(tmp_path / "out"), "VF_MODE": "tiny",
           "VF_SEEDS": "0", "VF_WORKERS": "1", "VF_TCN": "cpu", "VF_DEST": str(dest), "VF_POLL_S": "240",
           "VF_COMMIT": "test"}

    def sh(cmd: str, **extra) -> subprocess.CompletedProcess:
        return subprocess.run(["bash", str(root / "bench" / "device_full_velostat.sh"), cmd], cwd=root,
                              env={**env, **extra}, capture_output=True, text=True, timeout=600)

    rec = {"VF_RUN": str(tmp_path / "rec")}
    for c in ("start", "poll", "collect"):
        assert sh(c, **rec).returncode == 0, c
    path = dest / "velostat-tiny.json"
    m = json.loads(path.read_text())
    tcn = m["models"].pop("tcn")
    m["partial"] = "the paper's chains only"
    path.write_text(json.dumps(m))
    ours = {"VF_RUN": str(tmp_path / "ours"), "VF_ONLY": "ours", "VF_GEN_WORKERS": "2"}
    assert sh("start", **ours).returncode == 0
    r = sh("collect", **ours)  # at once, no poll: collect waits for the seed's "done" before it merges
    assert r.returncode == 0, r.stdout + r.stderr
    assert "waiting for seeds 0" in r.stdout and "every seed done: 0" in r.stdout
    merged = json.loads(path.read_text())
    assert merged["models"]["tcn"]["test"] == tcn["test"] and "partial" not in merged
    # the model the experiment trains today (residual on the compensated chain where the picked inputs hold it)
    from learn.experiments import velostat as V

    res = V.MODES["tiny"].tcn_residual
    want = res if res in V.TCN_INPUTS[merged["models"]["tcn"]["inputs"]] else None
    assert merged["models"]["tcn"]["hparams"]["member_hparams"].get("residual_input") == want
    # the checkout's commit (git here; VF_COMMIT where the copy has no .git)
    assert merged["machine"]["ours"]["git_commit"] not in ("", "unknown") and merged["machine"]["ours"]["gen_workers"] == 2
    merged["datasets"]["mix"]["content_sha256"] = "0" * 64
    path.write_text(json.dumps(merged))
    before = path.read_text()
    r = sh("collect", **ours)
    assert r.returncode == 3 and "REFUSED" in r.stdout
    assert path.read_text() == before


def test_design_rule_adopts_on_paired_differences(tmp_path):
    """bench_velostat_hold_drift.rule: paired differences candidate - default per seed; adopt only if the drift falls
    by more than its standard error and the RMSE rises by at most its own (hand-computed cases)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("hd", Path(__file__).parents[1] / "bench" / "bench_velostat_hold_drift.py")
    hd = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hd)

    def files(drifts, rmses):
        out = []
        for s, ((d0, d1), (r0, r1)) in enumerate(zip(drifts, rmses)):
            p = tmp_path / f"s{s}.json"
            p.write_text(json.dumps({"seed": s, "default": {"inputs": "aged", "valid_rmse": r0, "drift_mean": d0,
                                                            "drift_signed_mean": 0.0},
                                     "variants": {"residual": {"picked": "aged", "by_inputs": {"aged": {
                                         "valid_rmse": r1, "drift_mean": d1, "drift_signed_mean": 0.0}}}}}))
            out.append(str(p))
        return out

    # drift differences -0.02, -0.03, -0.04: mean -0.03, SE 0.01/sqrt(3); RMSE differences +0.01, 0, -0.01: mean 0
    r = hd.rule("residual", files([(0.2, 0.18), (0.2, 0.17), (0.2, 0.16)], [(1.0, 1.01), (1.0, 1.0), (1.0, 0.99)]),
                str(tmp_path / "rule.json"))
    assert r["differences"]["drift_mean"]["mean"] == pytest.approx(-0.03)
    assert r["differences"]["drift_mean"]["se"] == pytest.approx(0.01 / np.sqrt(3))
    assert r["adopted"] and r["residual_input_sets"] == ["calibrated", "aged"]
    # the same drift gain but the RMSE up by 0.02-0.04 (mean 0.03 > SE 0.0058): kept
    r = hd.rule("residual", files([(0.2, 0.18), (0.2, 0.17), (0.2, 0.16)], [(1.0, 1.02), (1.0, 1.03), (1.0, 1.04)]),
                str(tmp_path / "rule.json"))
    assert not r["adopted"] and r["conditions"]["drift_falls_by_more_than_se"]
    # a drift change within its SE (-0.05, +0.04, 0.0): kept
    r = hd.rule("residual", files([(0.2, 0.15), (0.2, 0.24), (0.2, 0.2)], [(1.0, 1.0)] * 3), str(tmp_path / "rule.json"))
    assert not r["conditions"]["drift_falls_by_more_than_se"] and not r["adopted"]


def test_silhouette_of_the_staircases_falls_with_creep_and_slow_ramps():
    """bench/bench_velostat_silhouette.py's physics (the generated table): on Fig. 6 staircases the creep tracker's
    K-means separates the stages less well when the film creeps (contact aging gives every hold a fast start) and
    when the ramps are slow (more loading samples between the clusters)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("bvs", Path(__file__).parents[1] / "bench" / "bench_velostat_silhouette.py")
    bvs = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bvs)
    sil = {k: bvs.variant([], speeds, amp)["period_0_5_s"]["silhouette"]
           for k, speeds, amp in (("creep, 1-6", bvs.SPEEDS_MM_PER_MIN, "preset"), ("no creep, 1-6", bvs.SPEEDS_MM_PER_MIN, 0.0),
                                  ("creep, 6", (6,), "preset"))}
    assert sil["no creep, 1-6"] > sil["creep, 1-6"] + 0.03
    assert sil["creep, 6"] > sil["creep, 1-6"] + 0.05
    assert max(sil.values()) < 0.931  # none reaches the paper's (sect. 3.2)
