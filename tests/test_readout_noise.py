"""Readout noise drawn in the Warp readout kernel (counter-based RNG, Kellet pink filter) against its numpy
mirror `readout_noise_batch`, and the statistics of that noise: rms, 1/f spectrum, stationarity from step 0."""

import numpy as np
import pytest
import warp as wp

from scenes import load_scene
from sensors import electronics as el
from sensors.data.manifest import episode_seed
from sensors.cnt_pdms.params import electronics_params

FS = 100.0


@pytest.fixture(scope="module")
def ep():
    return electronics_params(load_scene("cnt_pdms"))


def seeds(n, root=11):
    return [episode_seed(root, k) for k in range(n)]


def near_balance(ep, E, T, C):
    """Constant channel conductance [E,T,C] just off the bridge balance: the ADC code is set by the noise."""
    return np.full((E, T, C), 1.0 / (ep.bridge_resistance_ohm * 1.001))


def kernel_readout(ep, g, noise, state=None, t0=0):
    E, T, C = g.shape
    gd = wp.array(g.reshape(-1), dtype=wp.float64, device="cpu")
    return el.readout_warp(gd, (E, T, C), noise, ep, state, "cpu", t0=t0)


def test_uniforms_are_splitmix64_outputs():
    """u(key, n) is the top 53 bits of output n of SplitMix64 seeded with key (reference outputs for key 0)."""
    ref = np.array([0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4], np.uint64)
    with np.errstate(over="ignore"):
        u = el._uniform(np.zeros((1, 1), np.uint64), np.arange(2, dtype=np.uint64))[0]
    np.testing.assert_array_equal(u, ((ref >> np.uint64(11)) + np.uint64(1)) * 2.0**-53)


def test_kernel_noise_matches_numpy_mirror(ep):
    E, T, C = 6, 500, 5
    s = seeds(E) + [0, 2**64 - 1]  # the ends of the seed range too
    E = len(s)
    g = near_balance(ep, E, T, C)
    white_v, pink_v = 3e-3, 5e-3  # several LSB, so the codes follow the noise
    got, _ = kernel_readout(ep, g, el.NoiseSeeds(s, white_v, pink_v))
    ref, _ = el.readout_numpy(g, el.readout_noise_batch(s, T, C, white_v, pink_v), ep)
    d = got["adc"].astype(int) - ref["adc"].astype(int)
    assert np.abs(d).max() <= 1
    assert (d == 0).mean() > 0.999
    assert np.ptp(ref["adc"]) > 20  # the noise really moves the codes
    np.testing.assert_allclose(got["filtered_v"], ref["filtered_v"], rtol=0, atol=2 * ep.lsb_v)
    # the explicit-noise path of the kernel fed the mirror gives the same codes
    expl, _ = kernel_readout(ep, g, el.readout_noise_batch(s, T, C, white_v, pink_v))
    assert np.abs(expl["adc"].astype(int) - got["adc"].astype(int)).max() <= 1


def test_noise_is_deterministic_and_seed_dependent():
    a = el.readout_noise_batch([3, 4], 300, 4, 1e-4, 2e-4)
    np.testing.assert_array_equal(a, el.readout_noise_batch([3, 4], 300, 4, 1e-4, 2e-4))
    np.testing.assert_array_equal(a[1], el.readout_noise_v(4, 300, 4, 1e-4, 2e-4))
    assert np.abs(np.corrcoef(a[0, :, 0], a[1, :, 0])[0, 1]) < 0.2  # other seed: other noise
    assert np.abs(np.corrcoef(a[0, :, 0], a[0, :, 1])[0, 1]) < 0.2  # other channel: other noise
    # white and pink come from separate streams: the parts add up and are uncorrelated
    w, p = el.readout_noise_batch([3, 4], 300, 4, 1e-4, 0.0), el.readout_noise_batch([3, 4], 300, 4, 0.0, 2e-4)
    np.testing.assert_allclose(a, w + p, rtol=1e-12, atol=1e-18)
    assert abs(np.corrcoef(w.ravel(), p.ravel())[0, 1]) < 0.05


def test_white_and_pink_rms(ep):
    s = seeds(300)
    white = el.readout_noise_batch(s, 620, 2, 1e-3, 0.0)
    pink = el.readout_noise_batch(s, 620, 2, 0.0, 1e-3)
    assert np.sqrt(np.mean(white**2)) == pytest.approx(1e-3, rel=0.05)
    assert np.sqrt(np.mean(pink**2)) == pytest.approx(1e-3, rel=0.05)
    # the kernel's noise has the same rms: ADC codes near balance spread like the mirror's
    g = near_balance(ep, 50, 620, 2)
    got, _ = kernel_readout(ep, g, el.NoiseSeeds(s[:50], 0.0, 5e-3))
    v = got["adc"] * ep.lsb_v
    assert np.sqrt(np.mean((v - v.mean()) ** 2)) == pytest.approx(5e-3, rel=0.05)


def test_pink_spectrum_is_one_over_f():
    T = 2000
    x = el.readout_noise_batch(seeds(200), T, 2, 0.0, 1.0).transpose(0, 2, 1).reshape(-1, T)
    psd = np.mean(np.abs(np.fft.rfft(x * np.hanning(T), axis=-1)) ** 2, axis=0)
    f = np.fft.rfftfreq(T, 1.0 / FS)
    band = (f >= FS / 500) & (f <= FS / 4)
    slope = np.polyfit(np.log(f[band]), np.log(psd[band]), 1)[0]
    assert slope == pytest.approx(-1.0, abs=0.1)


def test_pink_noise_is_stationary_from_the_first_sample():
    """The filter starts in its stationary state: no ramp-up of the rms (a zero start reads ~20 % low here)."""
    x = el.readout_noise_batch(seeds(400), 620, 4, 0.0, 1.0)
    first = np.sqrt(np.mean(x[:, :50] ** 2))
    last = np.sqrt(np.mean(x[:, -50:] ** 2))
    assert first == pytest.approx(last, rel=0.1)


def test_chunked_readout_equals_one_shot(ep):
    E, T, C, cut = 3, 700, 4, 290
    s = seeds(E, root=5)
    g = near_balance(ep, E, T, C) * (1.0 + 0.01 * np.sin(np.arange(T) / 40.0))[None, :, None]
    noise = el.NoiseSeeds(s, 3e-3, 5e-3)
    whole, st = kernel_readout(ep, g, noise)
    a, st_a = kernel_readout(ep, g[:, :cut], noise)
    b, st_b = kernel_readout(ep, g[:, cut:], noise, state=st_a, t0=cut)
    for k in whole:
        np.testing.assert_array_equal(np.concatenate([a[k], b[k]], axis=1), whole[k], err_msg=k)
    for f in ("filt", "primed", "pink"):
        np.testing.assert_array_equal(getattr(st_b, f), getattr(st, f), err_msg=f)


@pytest.mark.parametrize("mode", ["zero_phase", "causal"])
def test_time_parallel_readout_equals_serial(mode):
    """The time-chunked readout (the CUDA default; forced here on the CPU) against the serial kernel on the
    same inputs: the pink state differs only by float64 rounding of the chunk scan, so codes agree within one
    count (nearly all exactly) and every output computed from an equal code is equal; the carried state too."""
    ep_m = electronics_params(load_scene("cnt_pdms", [f"sensor.electronics.filter_mode={mode}"]))
    E, T, C = 4, 403, 3
    s = seeds(E, root=3)
    g = near_balance(ep_m, E, T, C) * (1.0 + 0.01 * np.sin(np.arange(T) / 30.0))[None, :, None]
    noise = el.NoiseSeeds(s, 3e-3, 5e-3)
    gd = wp.array(g.reshape(-1), dtype=wp.float64, device="cpu")
    ref, st = el.readout_warp(gd, (E, T, C), noise, ep_m, None, "cpu", parallel=False)
    assert np.ptp(ref["adc"]) > 20
    for chunks in (True, 1, 10, 13, T):  # 10: a last chunk shorter than the others (34 of 41 samples)
        got, st_g = el.readout_warp(gd, (E, T, C), noise, ep_m, None, "cpu", parallel=chunks)
        d = got["adc"].astype(int) - ref["adc"].astype(int)
        assert np.abs(d).max() <= 1 and (d == 0).mean() > 0.999, chunks
        for k in ("resistance", "bridge_v"):
            np.testing.assert_array_equal(got[k], ref[k], err_msg=k)
        if mode == "zero_phase":  # pass-through: equal codes give equal outputs
            for k in ("filtered_v", "resistance_measured"):
                np.testing.assert_array_equal(got[k][d == 0], ref[k][d == 0], err_msg=k)
        else:  # the causal filter sums codes: a one-count difference decays through it
            np.testing.assert_allclose(got["filtered_v"], ref["filtered_v"], rtol=0, atol=2 * ep_m.lsb_v)
            np.testing.assert_allclose(st_g.filt, st.filt, rtol=0, atol=2 * ep_m.lsb_v)
        np.testing.assert_allclose(st_g.pink, st.pink, rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(st_g.primed, st.primed)
    # streaming in two calls on the parallel path carries the pink and filter state like one call
    cut = 170
    a, st_a = el.readout_warp(wp.array(g[:, :cut].reshape(-1), dtype=wp.float64, device="cpu"), (E, cut, C), noise,
                              ep_m, None, "cpu", parallel=True)
    b, _ = el.readout_warp(wp.array(g[:, cut:].reshape(-1), dtype=wp.float64, device="cpu"), (E, T - cut, C), noise,
                           ep_m, st_a, "cpu", t0=cut, parallel=True)
    d = np.concatenate([a["adc"], b["adc"]], 1).astype(int) - ref["adc"].astype(int)
    assert np.abs(d).max() <= 1 and (d == 0).mean() > 0.999
    np.testing.assert_allclose(np.concatenate([a["filtered_v"], b["filtered_v"]], 1), ref["filtered_v"], rtol=0,
                               atol=2 * ep_m.lsb_v)


def test_fresh_state_on_the_device_and_no_state_back(ep):
    """state=None makes the zero state on the device (no upload): the same outputs and carried state as the zero
    state passed in; return_state=False gives the same outputs and no state."""
    E, T, C = 3, 257, 2
    g = near_balance(ep, E, T, C) * (1.0 + 0.01 * np.sin(np.arange(T) / 20.0))[None, :, None]
    noise = el.NoiseSeeds(seeds(E, root=9), 3e-3, 5e-3)
    gd = wp.array(g.reshape(-1), dtype=wp.float64, device="cpu")
    for par in (False, True):
        a, st_a = el.readout_warp(gd, (E, T, C), noise, ep, None, "cpu", parallel=par)
        b, st_b = el.readout_warp(gd, (E, T, C), noise, ep, el.ElectronicsState.zeros(E * C), "cpu", parallel=par)
        c, st_c = el.readout_warp(gd, (E, T, C), noise, ep, None, "cpu", parallel=par, return_state=False)
        assert st_c is None and np.ptp(a["adc"]) > 20
        for k in a:
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
            np.testing.assert_array_equal(a[k], c[k], err_msg=k)
        for f in ("filt", "primed", "pink"):
            np.testing.assert_array_equal(getattr(st_a, f), getattr(st_b, f), err_msg=f)


def test_chunk_decay_is_the_repeated_product():
    full, last = el._chunk_decay(41, 403, 10)
    for a, f, la in zip(el.PINK_A, full, last):
        x = 1.0
        for i in range(41):
            x *= float(a)
            if i == 33:
                assert la == x  # the last chunk: 403 - 9 * 41 = 34 samples
        assert f == x
