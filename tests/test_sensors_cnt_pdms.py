"""Physics of the CNT-PDMS chain (no MuJoCo): creep, relaxation, monotone resistance, closed loops,
rate dependence, percolation law, Mullins drift, asymmetric loops, filter modes, ADC, and Warp == numpy."""

import numpy as np
import pytest

from scenes import load_scene
from sensors.analysis import hysteresis_error_fso, loop_area
from sensors.cnt_pdms.model import CntPdmsSensor
from sensors.electronics import ElectronicsState, readout_numpy
from sensors.cnt_pdms.params import MODE_DISPLACEMENT, MODE_FORCE, electronics_params, taxel_params
from sensors.cnt_pdms.reference import taxel_chain_numpy
from sensors.cnt_pdms.kernels import TaxelChainWarp

FS = 100.0


@pytest.fixture(scope="module")
def cfg():
    return load_scene("cnt_pdms")


@pytest.fixture(scope="module")
def tp(cfg):
    return taxel_params(cfg)


def hold(level, T=2000, ramp=50):
    x = np.full(T, level, np.float32)
    x[:ramp] = np.linspace(0, level, ramp)
    return x[None, :, None]


def sinus(d0, f, cycles, settle=20):
    T = settle + int(cycles * FS / f)
    t = np.arange(T) / FS
    d = np.where(np.arange(T) < settle, 0.0, d0 * (1 - np.cos(2 * np.pi * f * (t - settle / FS))) / 2)
    return d.astype(np.float32)


def test_creep_grows_under_held_force(tp):
    strain, stress, _, _ = taxel_chain_numpy(hold(20e3), MODE_FORCE, tp)
    e = strain[0, :, 0]
    assert np.allclose(stress[0, 60:, 0], 20e3, rtol=1e-4)  # force control holds the stress
    assert np.all(np.diff(e[60:]) >= -1e-9)  # creep: strain never falls under a held force
    assert e[-1] > e[60] * 1.02  # and grows measurably over 20 s


def test_stress_relaxes_under_held_displacement(tp):
    _, stress, _, st = taxel_chain_numpy(hold(0.02), MODE_DISPLACEMENT, tp)
    s = stress[0, :, 0]
    assert np.all(np.diff(s[55:]) <= 1e-3)  # monotone relaxation (and Mullins softening) after the ramp
    assert s[55] > s[-1] * 1.02
    soft = 1.0 - tp.softening * float(st.damage[0])  # Mullins-type softening of the damaged matrix
    e_inf = soft * tp.youngs_modulus_pa * 0.02 / (1 - 0.02 / tp.lock_strain)
    assert s[-1] == pytest.approx(e_inf, rel=0.02)  # relaxes toward the equilibrium law


def test_resistance_falls_monotonically_under_slow_compression(tp):
    ramp = np.linspace(0, 0.05, 3000, dtype=np.float32)[None, :, None]
    _, _, g, _ = taxel_chain_numpy(ramp, MODE_DISPLACEMENT, tp)
    r = 1.0 / g[0, :, 0]
    assert np.all(np.diff(r) <= 1e-9)
    assert r[-1] < 0.5 * r[0]


def punch(cfg, strain):
    """Strain history [T] applied to the taxels under a centred 10 x 10 mm punch -> drive [1, T, N]."""
    nx, ny = cfg.pad.taxels_x, cfg.pad.taxels_y
    x = ((np.arange(nx) + 0.5) / nx - 0.5) * cfg.pad.size_x_m
    y = ((np.arange(ny) + 0.5) / ny - 0.5) * cfg.pad.size_y_m
    X, Y = np.meshgrid(x, y)
    mask = ((np.abs(X) < 0.005) & (np.abs(Y) < 0.005)).ravel().astype(np.float32)
    return (strain[None, :, None] * mask[None, None, :]).astype(np.float32)


def test_loops_close_after_repeated_cycles(cfg):
    """Without the slow Mullins damage the chain reaches a periodic steady state and its loops close."""
    sen = CntPdmsSensor(cfg.model_copy(update={"sensor": cfg.sensor.model_copy(update={
        "mullins": cfg.sensor.mullins.model_copy(update={"damage_max": 0.0})})}), backend="numpy")
    f = 1.0
    d = sinus(0.02, f, cycles=8)
    out = sen.run(punch(cfg, d), [0])
    n = int(FS / f)
    F = out["force"][0]
    R = out["resistance"][0, :, 0]
    # the end of the last two cycles returns to the same state (periodic steady state)
    assert abs(F[-1] - F[-1 - n]) < 1e-3 * F.max()
    assert abs(R[-1] - R[-1 - n]) < 1e-4 * R.max()
    # and each loop is closed: start and end of one cycle coincide
    assert abs(F[-n] - F[-1]) < 2e-3 * F.max()


def test_material_hysteresis_grows_with_frequency_in_the_paper_band(cfg):
    """The material (true resistance, no filter) carries the hysteresis: loop area and max error rise with
    frequency, and at 0.5 Hz the max error is in the band around the paper's 12.4 % FSO."""
    sen = CntPdmsSensor(cfg, backend="numpy")
    errs, areas = [], []
    for f in (0.1, 0.5, 1.0, 2.0):
        d = sinus(0.032, f, cycles=3)
        out = sen.run(punch(cfg, d), [1])
        n = int(FS / f)
        F, y = out["force"][0, -n:], out["resistance"][0, -n:, 0]
        errs.append(hysteresis_error_fso(F, y, d[-n:]))
        areas.append(loop_area(F, y))
    assert errs == sorted(errs), errs
    assert areas == sorted(areas), areas
    assert 8.0 <= errs[1] <= 17.0, errs


def test_loops_are_asymmetric_and_amplitude_dependent(cfg):
    """Loading and unloading differ in shape, not only by a delay: the force gap in the lower and upper third of
    the resistance span differ (>= 1.3x at full scale); a small press gives a more symmetric loop."""
    from sensors.analysis import third_gaps_fso

    sen = CntPdmsSensor(cfg, backend="numpy")
    ratio = {}
    for a in (0.008, 0.032):
        d = sinus(a, 0.5, cycles=3)
        out = sen.run(punch(cfg, d), [1])
        n = int(FS / 0.5)
        lo, up = third_gaps_fso(out["force"][0, -n:], out["resistance"][0, -n:, 0], d[-n:])
        ratio[a] = max(lo, up) / min(lo, up)
    assert ratio[0.032] >= 1.3, ratio
    assert ratio[0.008] < ratio[0.032], ratio


def test_mullins_drift_over_the_first_cycles(cfg):
    """A fresh sample's R_min drifts over its first cycles (network damage) and the drift slows down."""
    sen = CntPdmsSensor(cfg, backend="numpy")
    f, cycles = 0.5, 6
    d = sinus(0.032, f, cycles=cycles, settle=0)
    r = sen.run(punch(cfg, d), [1])["resistance"][0, :, 0]
    n = int(FS / f)
    r_min = np.array([r[k * n:(k + 1) * n].min() for k in range(cycles)])
    step = np.diff(r_min)
    assert r_min[-1] > r_min[0] * 1.005, r_min  # drifts by more than 0.5 %
    assert step[0] > step[-1] > 0, step  # and settles


def test_percolation_power_law():
    """R ~ (phi - phi_c)^-t above threshold (Kirkpatrick 1973; Stauffer & Aharony)."""
    from sensors.percolation import percolation_conductivity

    phi_c, t = 0.002, 2.0
    phi = phi_c + np.logspace(-5, -3, 9)
    r = 1.0 / percolation_conductivity(phi, phi_c, t, 1e4)
    slope = np.polyfit(np.log(phi - phi_c), np.log(r), 1)[0]
    assert slope == pytest.approx(-t, rel=1e-6)
    assert percolation_conductivity(phi_c * 0.9, phi_c, t, 1e4) == 0.0


def test_network_conductance_numpy_equals_warp(tp):
    """The shared network stage: strain raises the conductance (paths + tunneling), damage lowers it,
    below threshold the path term holds at its floor; Warp == numpy."""
    from sensors.percolation import conductance_ratio_numpy, conductance_ratio_warp

    from dataclasses import replace

    x, dmg = np.meshgrid(np.linspace(0, 0.05, 40, dtype=np.float32), np.linspace(0, 0.9, 30, dtype=np.float32))
    for q in (tp.net, replace(tp.net, exponent=1.8)):  # t = 2 takes the product path, others log/exp
        np.testing.assert_allclose(conductance_ratio_warp(x, dmg, q), conductance_ratio_numpy(x, dmg, q), rtol=2e-6)
    a = conductance_ratio_numpy(x, dmg, tp.net)
    assert a[0, 0] == pytest.approx(1.0)
    assert np.all(np.diff(a[0]) > 0) and np.all(np.diff(a[:, 0]) <= 0)
    assert a[-1, 0] == pytest.approx(tp.net.floor**tp.net.exponent, rel=1e-5)  # 90 % damaged: below threshold


def test_filter_modes(cfg):
    """zero_phase (default, paper sect. 2.2) follows the material without lag; causal lags it; off = raw ADC."""
    from sensors.analysis import phase_lag_deg

    d = sinus(0.032, 2.0, cycles=3)
    lag = {}
    for mode in ("zero_phase", "causal", "off"):
        c = cfg.model_copy(update={"sensor": cfg.sensor.model_copy(update={
            "electronics": cfg.sensor.electronics.model_copy(update={"filter_mode": mode})})})
        out = CntPdmsSensor(c, backend="numpy").run(punch(cfg, d), [2])
        n = 50
        lag[mode] = phase_lag_deg(out["resistance"][0, -n:, 0], out["resistance_measured"][0, -n:, 0], 2.0, FS)
    assert abs(lag["zero_phase"]) < 1.0 and abs(lag["off"]) < 1.0, lag
    assert lag["causal"] > 10.0, lag  # ~40 ms of a 500 ms cycle


def test_adc_quantizes_and_clips(cfg):
    from dataclasses import replace

    ep = replace(electronics_params(cfg), amp_gain=300.0)  # a gain that can reach both rails
    rb = ep.bridge_resistance_ohm
    # conductances spanning from far below to far above the bridge balance
    r = np.array([rb * 0.2, rb * 0.9, rb, rb * 1.05, rb * 5.0])
    g = (1.0 / r)[None, :, None]
    out, _ = readout_numpy(g, np.zeros_like(g), ep, ElectronicsState.zeros(1))
    codes = out["adc"][0, :, 0]
    assert codes.min() >= ep.code_min and codes.max() <= ep.code_max
    assert codes[0] == ep.code_min and codes[-1] == ep.code_max  # clipped at both rails
    v = ep.amp_gain * out["bridge_v"][0, 1, 0]
    assert abs(codes[1] * ep.lsb_v - v) <= ep.lsb_v / 2 + 1e-12  # quantization within half an LSB
    assert codes[2] == 0  # balanced bridge reads zero


def test_warp_matches_numpy_reference(cfg, tp):
    rng = np.random.default_rng(3)
    E, T, N = 3, 400, 7
    d = sinus(1.0, 0.5, cycles=2)[:T]
    drive = (d[None, :, None] * rng.uniform(0.005, 0.04, (E, 1, N))).astype(np.float32)
    for mode, scale in ((MODE_DISPLACEMENT, 1.0), (MODE_FORCE, 2.0e6)):
        ref = taxel_chain_numpy(drive * scale, mode, tp)
        chain = TaxelChainWarp(tp, E, N, "cpu")
        got = chain.run(drive * scale, mode)
        for a, b in zip(ref[:3], got):
            np.testing.assert_allclose(b, a, rtol=2e-5, atol=1e-6 * np.abs(a).max())


def test_fused_pad_sum_equals_chain_then_sum(cfg, tp):
    """The taxel kernel with the pad's channel sum fused in (CUDA's path; on the CPU one lane per partial sum):
    strain, stress, pad conductance, force and the carried state equal the plain kernel + per-row sum bit for
    bit, at every prefetch depth, in two pieces as in one, and with nothing per taxel written."""
    import warp as wp

    from sensors import electronics as el

    rng = np.random.default_rng(11)
    E, T, N = 2, 90, 13
    drive = rng.uniform(0, 0.04, (E, T, N)).astype(np.float32)
    for mode, scale in ((MODE_DISPLACEMENT, 1.0), (MODE_FORCE, 2.0e6)):
        dv = wp.array((drive * scale).reshape(-1), dtype=wp.float32, device="cpu")
        ref = TaxelChainWarp(tp, E, N, "cpu")
        s, st, c = (x.numpy() for x in ref.run_device(dv, T, mode))
        g, f = (x.numpy() for x in el.sum_channels_warp(wp.array(c, device="cpu"), wp.array(st, device="cpu"),
                                                         np.zeros(N, np.int32), 1, tp.taxel_area_m2, (E, T, N), "cpu"))
        for depth in (0, 1, 3):
            ch = TaxelChainWarp(tp, E, N, "cpu")
            s2, st2, g2, f2 = (x.numpy() for x in ch.run_pad_device(dv, T, mode, tp.taxel_area_m2, depth=depth))
            for a, b in ((s, s2), (st, st2), (g, g2), (f, f2)):
                np.testing.assert_array_equal(b, a)
            for a, b in zip(vars(ref.state()).values(), vars(ch.state()).values()):
                np.testing.assert_array_equal(b, a)
        ch = TaxelChainWarp(tp, E, N, "cpu")  # two pieces, nothing per taxel written
        half = [wp.array((drive[:, a:b] * scale).reshape(-1), dtype=wp.float32, device="cpu") for a, b in ((0, 40), (40, T))]
        p1, p2 = ch.run_pad_device(half[0], 40, mode, tp.taxel_area_m2, False, False), \
            ch.run_pad_device(half[1], T - 40, mode, tp.taxel_area_m2, False, False)
        assert p1[0] is None and p1[1] is None
        np.testing.assert_array_equal(np.concatenate([p1[2].numpy().reshape(E, -1), p2[2].numpy().reshape(E, -1)], 1),
                                      g.reshape(E, T))


def test_warp_streaming_equals_one_piece(cfg, tp):
    rng = np.random.default_rng(4)
    drive = rng.uniform(0, 0.03, (2, 300, 5)).astype(np.float32)
    whole = TaxelChainWarp(tp, 2, 5).run(drive, MODE_DISPLACEMENT)
    ch = TaxelChainWarp(tp, 2, 5)
    parts = [ch.run(drive[:, :120], MODE_DISPLACEMENT), ch.run(drive[:, 120:], MODE_DISPLACEMENT)]
    for i in range(3):
        np.testing.assert_array_equal(np.concatenate([parts[0][i], parts[1][i]], axis=1), whole[i])


def test_full_chain_warp_matches_numpy(cfg):
    d = sinus(0.02, 2.0, cycles=2)
    drive = np.concatenate([punch(cfg, d), punch(cfg, 0.5 * d)])
    a = CntPdmsSensor(cfg, backend="numpy").run(drive, [5, 6])
    b = CntPdmsSensor(cfg, backend="warp").run(drive, [5, 6])
    for k in ("strain", "force", "resistance", "voltage", "resistance_measured"):
        np.testing.assert_allclose(b[k], a[k], rtol=1e-4, atol=1e-6 * float(np.abs(a[k]).max()), err_msg=k)
    assert np.abs(b["adc"].astype(int) - a["adc"].astype(int)).max() <= 1


def test_noise_is_seeded(cfg):
    sen = CntPdmsSensor(cfg, backend="numpy")
    n1, n2, n3 = sen.noise([7], 500), sen.noise([7], 500), sen.noise([8], 500)
    np.testing.assert_array_equal(n1, n2)
    assert not np.allclose(n1, n3)
    e = cfg.sensor.electronics
    many = sen.noise(list(range(100, 160)), 500)
    assert many.std() == pytest.approx(np.hypot(e.white_noise_v, e.pink_noise_v), rel=0.05)


def test_readout_noise_batch_equals_per_episode():
    """The blocked batch draw gives each episode exactly its own seed's noise (order and values)."""
    from sensors import electronics as el

    seeds = [7, 3, 11, 5] * 40  # 160 episodes x 36 channels: many row blocks, cut inside episodes
    big = el.readout_noise_batch(seeds, 400, 36, 1e-4, 2e-4)
    for i in (0, 1, 77, 159):
        np.testing.assert_array_equal(big[i], el.readout_noise_v(seeds[i], 400, 36, 1e-4, 2e-4))
    small = el.readout_noise_batch(seeds[:3], 50, 2, 1e-4, 2e-4)
    np.testing.assert_array_equal(small[2], el.readout_noise_v(seeds[2], 50, 2, 1e-4, 2e-4))
    np.testing.assert_array_equal(small[2], big[2, :50, :2])  # counter-based: a shorter episode is a prefix


def test_approx_math_kernels_equal_exact_on_cpu():
    """The taxel step's approximate divisions / exp (kernels.APPROX_MATH, CUDA's __fdividef / __expf) fall back to the
    exact operations on the CPU: the plain and the fused kernels give the exact kernels' bits there (so the CPU path's
    bytes do not depend on the switch). CUDA against the CPU: tests/test_gpu.py (rtol 1e-5)."""
    import warp as wp

    from sensors.cnt_pdms.kernels import TaxelChainWarp, taxel_kernels, taxel_sum_kernel
    from sensors.cnt_pdms.params import taxel_params

    tp = taxel_params(load_scene("cnt_pdms"))
    E, T, N = 2, 120, 40
    drive = np.random.default_rng(5).uniform(0, 0.04, (E, T, N)).astype(np.float32)
    for mode, scale in ((0, 1.0), (1, 2e6)):
        got = {}
        for approx in (False, True):
            ch = TaxelChainWarp(tp, E, N, "cpu")
            dc = wp.array((drive * scale).reshape(-1), dtype=wp.float32, device="cpu")
            o = [wp.empty(E * T * N, dtype=wp.float32, device="cpu") for _ in range(3)]
            wp.launch(taxel_kernels(tp.n_prony, tp.n_play, approx)["chain"], dim=E * N,
                      inputs=[dc, T, N, mode, ch.params, *ch._state_args(), *o], device="cpu")
            ch.reset()
            pg, pf = (wp.empty(E * N * T, dtype=wp.float64, device="cpu") for _ in range(2))
            s2 = [wp.empty(E * T * N, dtype=wp.float32, device="cpu") for _ in range(2)]
            wp.launch(taxel_sum_kernel(tp.n_prony, tp.n_play, approx=approx), dim=E * N,
                      inputs=[dc, T, N, N, 1, mode, ch.params, *ch._state_args(), 1, 1, *s2, pg, pf], device="cpu")
            got[approx] = [x.numpy() for x in (*o, *s2, pg, pf)]
        assert np.abs(got[False][2]).max() > 0
        for x, y in zip(got[False], got[True]):
            np.testing.assert_array_equal(y, x)
