"""CUDA vs CPU equivalence of the fabric, velostat and ntype Warp chains (cnt_pdms: tests/test_gpu.py).

For each family: (a) the Warp kernels on random but physically sensible drives, device under test vs "cpu";
(b) the whole sensor `.run(...)` on the device under test vs "cpu"; (c) two runs on the device under test
bit-identical; plus a check that every Warp launch of each family's sensor runs on the device it was given.
The device under test is the `gpu_device` fixture (tests/conftest.py): $PIEZOTWIN_TEST_GPU_DEVICE, default
cuda:0, skipped without CUDA; PIEZOTWIN_TEST_GPU_DEVICE=cpu runs the same comparisons cpu vs cpu (checks the
test logic on a machine without a GPU). Run: pytest -m gpu tests/test_gpu_families.py

Tolerances (one place, used by every comparison below). Every kernel is float32 with the same operation order
on both devices: one thread per (episode, taxel/element/sample) loops over time / taxels sequentially, no
atomics, no cross-thread reductions. Warp compiles CUDA without fast-math by default (module option
fast_math=False), so the differences left are (i) FMA contraction, which LLVM (CPU) and NVVM (CUDA) apply at
different places, and (ii) CUDA's libdevice expf/logf/powf, accurate to ~2 ulp where the CPU libm is ~0.5
ulp. Each is a few ulp (float32 eps = 6e-8) per step; the recursions (Prony, creep, lag) are contracting,
so the error stays bounded instead of growing with T. RTOL = 1e-5 leaves ~100x headroom over that. As a
proxy, the float32 numpy references (sensors/*_ref.py: no FMA, numpy's libm, log1p for log(1 + x)) against
Warp on the cpu, on these same drives, use at most 8 % of the tolerance below (ntype strain; others <= 7 %).
ATOL_FRAC
scales an absolute floor to each array's magnitude for entries that are near zero by cancellation (ntype
strain of a column the load does not stretch, effective fabric load near release). Integer outputs
(ADC / multimeter counts) come from floor/round of values that agree to RTOL: a value within RTOL of a code
boundary may land on the neighbouring code, so they agree within 1 count; values computed from equal codes
must then agree exactly (same numpy code on both sides).
"""

import numpy as np
import pytest

from scenes import load_scene

pytestmark = pytest.mark.gpu

RTOL = 1e-5
ATOL_FRAC = 1e-6


def assert_close(actual, desired, name, rtol=RTOL, atol_frac=ATOL_FRAC):
    """|actual - desired| <= atol_frac * max|desired| + rtol * |desired|; NaNs must sit at the same places."""
    desired = np.asarray(desired)
    scale = float(np.nanmax(np.abs(desired))) if np.isfinite(desired).any() else 0.0
    np.testing.assert_allclose(actual, desired, rtol=rtol, atol=atol_frac * scale, err_msg=name)


def assert_identical(a: dict, b: dict, what: str):
    """Two runs on one device: every output bit-identical (no atomics, fixed summation order)."""
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(np.asarray(a[k]), np.asarray(b[k]), err_msg=f"{what}: {k} not deterministic")


def waves(rng, E, T, N, hi, every=20, rest=0.3):
    """Random ramp-and-hold loads [E, T, N] in [0, hi] (float32): a level is held for `every` samples, then
    ramps linearly to the next over `every` samples; levels are U(-rest * hi, hi) clipped at 0, so contacts
    come and go (exact zeros: unloaded) as in an indentation sequence."""
    n = T // (2 * every) + 2
    lv = np.repeat(rng.uniform(-rest * hi, hi, (E, n, N)), 2, axis=1)  # each level twice: hold, then ramp
    t = np.arange(T) / every
    i = np.floor(t).astype(int)
    w = (t - i)[None, :, None]
    x = lv[:, i] * (1 - w) + lv[:, i + 1] * w
    return np.clip(x, 0.0, None).astype(np.float32)


def devices(gpu_device):
    """The order every test runs in: reference on cpu, then the device under test twice (determinism)."""
    return "cpu", gpu_device, gpu_device


# --------------------------------------------------------------------------------------------------- fabric


def _fabric_kernel(p, load, device):
    from sensors.fabric.kernels import FabricChainWarp
    from sensors.fabric.reference import press_draws

    E, T, N = load.shape
    ch = FabricChainWarp(p, E, N, device)
    ch.set_draws(press_draws(list(range(E)), p))  # per-press contact area and knit set from the episode seeds
    x1, g1 = ch.run(load[:, : T // 2])
    x2, g2 = ch.run(load[:, T // 2 :])  # streaming: the Prony, play and press states carried on the device
    st = ch.state()
    return {"x": np.concatenate([x1, x2], 1), "g": np.concatenate([g1, g2], 1), "prony": st.prony_n, "play": st.play_n,
            "press": st.press}


@pytest.mark.parametrize("layers", [1, 3, 6, 12])
def test_fabric_kernel_cuda_equals_cpu(gpu_device, layers):
    from sensors.fabric.reference import fabric_params

    cfg = load_scene(f"fabric_{layers}")
    p = fabric_params(cfg)
    load = waves(np.random.default_rng(layers), 4, 400, 9, cfg.protocol.amplitude_max)
    a, b, c = (_fabric_kernel(p, load, d) for d in devices(gpu_device))
    assert a["x"].max() > 0 and np.ptp(a["g"]) > 0  # the drive exercises the chain
    for k in a:
        assert_close(b[k], a[k], f"fabric_{layers} {k}")
    assert_identical(b, c, f"fabric_{layers} kernel on {gpu_device}")


def _multimeter_agrees(b, a, cfg):
    """Multimeter outputs of two runs whose true resistances agree to RTOL: same range unless the resistance
    sits within RTOL of a range boundary, counts within 1 on the same range, readings equal where counts are."""
    mm = cfg.sensor.multimeter
    r = a["resistance"].astype(np.float64) * (1.0 + mm.gain_error)
    near_edge = (np.abs(r[..., None] / np.asarray(mm.ranges_ohm) - 1.0) < 10 * RTOL).any(-1)
    same_range = b["dmm_range_ohm"] == a["dmm_range_ohm"]
    assert np.all(same_range | near_edge), "multimeter range differs away from a range boundary"
    dc = np.abs(b["dmm_counts"].astype(np.int64) - a["dmm_counts"].astype(np.int64))
    assert dc[same_range].max(initial=0) <= 1, "multimeter counts differ by more than 1"
    eq = same_range & (dc == 0)
    np.testing.assert_array_equal(b["resistance_measured"][eq], a["resistance_measured"][eq])


def test_fabric_sensor_cuda_equals_cpu_and_is_deterministic(gpu_device):
    from sensors.fabric.model import FabricSensor

    cfg = load_scene("fabric_3", ["pad.taxels_x=3", "pad.taxels_y=3"])
    force = waves(np.random.default_rng(11), 3, 500, 9, cfg.protocol.amplitude_max / 9)  # N per taxel
    seeds = [4, 5, 6]
    a, b, c = (FabricSensor(cfg, device=d).run(force, seeds) for d in devices(gpu_device))
    assert np.ptp(a["resistance"]) > 0.1 * a["resistance"].max()
    for k in ("force_taxel", "force", "load_effective", "resistance"):
        assert_close(b[k], a[k], f"fabric sensor {k}")
    _multimeter_agrees(b, a, cfg)
    assert_identical(b, c, f"fabric sensor on {gpu_device}")


# ------------------------------------------------------------------------------------------------- velostat


def _velostat_pressure(cfg, rng, E, T, n_loaded=6):
    """Pressure [E, T, N] (Pa): n_loaded random taxels per episode under ramp-and-hold presses of up to
    150 kPa (15 N on one 10 x 10 mm taxel cell), the rest unloaded; all released for the first and the middle
    10 samples (no touch: open circuit, compliance voltage, NaN position)."""
    N = cfg.pad.n_taxels
    pr = np.zeros((E, T, N), np.float32)
    w = waves(rng, E, T, n_loaded, 1.5e5)
    w[:, :10] = w[:, T // 2 : T // 2 + 10] = 0.0
    for e in range(E):
        pr[e][:, rng.choice(N, n_loaded, replace=False)] = w[e]
    return pr


def _velostat_film(s, pressure, device):
    from sensors.velostat.kernels import run_film_warp

    T = pressure.shape[1]
    g1, st = run_film_warp(pressure[:, : T // 2], s.fp, device)
    g2, st = run_film_warp(pressure[:, T // 2 :], s.fp, device, state=st)  # creep state carried over
    g = np.concatenate([g1, g2], 1)
    return {"g": g, "creep": st}, g


def test_velostat_kernels_cuda_equal_cpu(gpu_device):
    from sensors.velostat.model import VelostatSensor
    from sensors.velostat.kernels import run_readout_warp

    cfg = load_scene("velostat")
    s = VelostatSensor(cfg, backend="numpy")  # only its film / readout parameters
    rng = np.random.default_rng(21)
    pressure = _velostat_pressure(cfg, rng, 3, 400)
    noise = s.noise([7, 8, 9], 400)
    (a, ga), (b, _), (c, _) = (_velostat_film(s, pressure, d) for d in devices(gpu_device))
    assert np.ptp(a["g"]) > 0 and np.abs(a["creep"]).max() > 0
    for k in a:
        assert_close(b[k], a[k], f"velostat film {k}")
    assert_identical(b, c, f"velostat film on {gpu_device}")
    # readout kernel on the same conductance (the cpu one), so only the readout's own differences show
    ra, rb, rc = (run_readout_warp(ga, noise, s.rp, d) for d in devices(gpu_device))
    _velostat_readout_agrees(rb, ra, s.rp, "velostat readout kernel")
    assert_identical(rb, rc, f"velostat readout on {gpu_device}")


def _velostat_readout_agrees(b, a, rp, what):
    """Readout outputs: analog values to RTOL, ADC codes within 1; where all three codes of a sample agree the
    decoded outputs (code-centre voltage, resistance, touch, position) are the same numpy arithmetic on the same
    codes, hence identical; where one differs they differ by at most one code's worth."""
    for k in ("resistance_film", "resistance", "voltage_true"):
        assert_close(b[k], a[k], f"{what} {k}")
    dc = np.abs(b["adc"].astype(np.int64) - a["adc"].astype(np.int64))
    assert dc.max() <= 1, f"{what}: ADC codes differ by {dc.max()}"
    same = (dc == 0).all(-1)
    for k in ("voltage", "resistance_measured", "position_measured"):
        np.testing.assert_array_equal(b[k][same], a[k][same], err_msg=f"{what} {k} (equal codes)")
    lsb = np.float32(rp.adc_range_v / 2**rp.adc_bits)
    np.testing.assert_allclose(b["voltage"], a["voltage"], rtol=0, atol=1.01 * lsb, err_msg=f"{what} voltage")
    np.testing.assert_allclose(b["resistance_measured"], a["resistance_measured"], rtol=0,
                               atol=1.01 * lsb / rp.current_a, err_msg=f"{what} resistance_measured")
    both = np.isfinite(a["position_measured"]) & np.isfinite(b["position_measured"])
    step = 1.01 * lsb / rp.drive_v * max(rp.size_x_m, rp.size_y_m)  # one code of the X or Y probe, in m
    assert np.abs(b["position_measured"][both] - a["position_measured"][both]).max(initial=0) <= step
    # a touch flag can only flip on a force-channel code at the 0.98 x compliance threshold
    flip = np.isnan(a["position_measured"][..., 0]) != np.isnan(b["position_measured"][..., 0])
    assert np.all(dc[..., 0][flip] == 1), f"{what}: touch differs away from a code boundary"


def test_velostat_sensor_cuda_equals_cpu_and_is_deterministic(gpu_device):
    from sensors.velostat.model import VelostatSensor

    cfg = load_scene("velostat")
    pressure = _velostat_pressure(cfg, np.random.default_rng(22), 3, 300)
    seeds = [1, 2, 3]
    a, b, c = (VelostatSensor(cfg, device=d).run(pressure, seeds) for d in devices(gpu_device))
    assert np.isfinite(a["position_measured"]).any() and np.isnan(a["position_measured"]).any()  # touch and none
    for k in ("force", "contact_xy", "unit"):
        np.testing.assert_array_equal(b[k], a[k], err_msg=f"velostat sensor {k} (numpy on both)")
    _velostat_readout_agrees(b, a, VelostatSensor(cfg, backend="numpy").rp, "velostat sensor")
    assert_identical(b, c, f"velostat sensor on {gpu_device}")


# ---------------------------------------------------------------------------------------------------- ntype


def _ntype_force(rng, E, T, M):
    """Electrode forces [E, T, M, 3] (N, world frame, z up): ramp-and-hold shear of up to +-3 N per axis and a
    press of up to 4.8 N (the paper's range) pushing the electrode down (F_z <= 0); loaded whenever pressed."""
    fz = waves(rng, E, T, M, 4.8)
    sx, sy = (waves(rng, E, T, M, 6.0) - 3.0 for _ in range(2))
    touch = fz > 0
    return np.stack([sx * touch, sy * touch, -fz], -1).astype(np.float32)


def _ntype_kernel(p, force, device):
    from sensors.ntype.kernels import ntype_chain_warp

    T = force.shape[1]
    d1, s1, r1, q = ntype_chain_warp(force[:, : T // 2], p, device)
    d2, s2, r2, q = ntype_chain_warp(force[:, T // 2 :], p, device, q0=q)  # lag state carried over
    cat = lambda u, v: np.concatenate([u, v], 1)  # noqa: E731
    return {"displacement": cat(d1, d2), "strain": cat(s1, s2), "resistance": cat(r1, r2), "lag": q}


def test_ntype_kernel_cuda_equals_cpu(gpu_device):
    from sensors.ntype.model import ntype_params

    cfg = load_scene("ntype")
    p = ntype_params(cfg)
    force = _ntype_force(np.random.default_rng(31), 3, 300, cfg.sensor.element.n_elements)
    a, b, c = (_ntype_kernel(p, force, d) for d in devices(gpu_device))
    assert np.ptp(a["resistance"]) > 0.1 * p.rest_ohm.min()
    for k in a:
        assert_close(b[k], a[k], f"ntype kernel {k}")
    assert_identical(b, c, f"ntype kernel on {gpu_device}")


def test_ntype_sensor_cuda_equals_cpu_and_is_deterministic(gpu_device):
    from sensors.ntype.model import NtypeSensor
    from simulate.characterize.ntype import patch_load

    cfg = load_scene("ntype")
    rng = np.random.default_rng(32)
    E = 4
    centres = rng.uniform(-0.05, 0.05, (E, 2))
    forces = np.column_stack([rng.uniform(-3, 3, (E, 2)), rng.uniform(0.5, 4.8, E)])
    load = patch_load(cfg, centres, forces, n_steps=40)
    seeds = [1, 2, 3, 4]
    a, b, c = (NtypeSensor(cfg, device=d).run_load(load, seeds) for d in devices(gpu_device))
    for k in ("force_element", "force_electrode", "force"):
        np.testing.assert_array_equal(b[k], a[k], err_msg=f"ntype sensor {k} (numpy on both)")
    for k in ("displacement", "strain", "resistance"):
        assert_close(b[k], a[k], f"ntype sensor {k}")
    # the readout is numpy on both sides: relative noise (same seeds), then rounding to resolution_ohm; a
    # resistance within RTOL of a rounding edge may land one quantum away
    q = cfg.sensor.readout.resolution_ohm
    np.testing.assert_allclose(b["resistance_measured"], a["resistance_measured"], rtol=RTOL, atol=q,
                               err_msg="ntype sensor resistance_measured")
    assert_identical(b, c, f"ntype sensor on {gpu_device}")


@pytest.mark.parametrize("nx,ny,r_on", [(6, 6, 100.0), (6, 6, 0.0), (5, 3, 5e3)])
def test_ntype_scan_kernel_cuda_equals_numpy(gpu_device, nx, ny, r_on):
    """The scanned readout's Warp kernel (feedback scheme: one thread per frame, float64 Gaussian elimination with
    partial pivoting) on the device under test reads what the numpy batched Schur solve reads (sensors/ntype/scan.py),
    over more frames than one launch chunk, and twice bit-identically. float64 on both sides: the only differences
    are FMA contraction and pivot-order round-off, ~1e-15 relative on these well-conditioned 12 x 12 systems."""
    from sensors.ntype.kernels import SCAN_CHUNK
    from sensors.ntype.scan import scan_apparent

    rng = np.random.default_rng(33)
    R = rng.uniform(5e3, 80e3, (SCAN_CHUNK + 257, nx * ny, 3))  # two launches, the second partial
    R[:3] = rng.uniform(16e3, 50e3, 3)  # frames where every column reads alike (symmetric networks)
    ref = scan_apparent(R, nx, ny, "feedback", 5.0, r_on, 1e3)  # numpy
    b, c = (scan_apparent(R, nx, ny, "feedback", 5.0, r_on, 1e3, backend="warp", device=d) for d in devices(gpu_device)[1:])
    np.testing.assert_allclose(b, ref, rtol=1e-9, err_msg=f"ntype scan on {gpu_device}")
    assert_identical({"apparent": b}, {"apparent": c}, f"ntype scan on {gpu_device}")
    if r_on > 0:  # the scan acted: the switch residue moves every reading, by more than the tolerance
        assert np.abs(b / R - 1).max() > 1e-3


# ----------------------------------------------------------------------------------------- device plumbing


def _family_run(family, device):
    """One small run of a family's sensor (backend warp) on `device`."""
    from sensors.registry import make_sensor

    rng = np.random.default_rng(41)
    if family == "cnt_pdms":
        cfg = load_scene("cnt_pdms")
        from sensors.cnt_pdms.params import MODE_FORCE

        s = make_sensor(cfg, "warp", device)
        drive = rng.uniform(0, 0.02, (1, 20, cfg.pad.n_taxels)) * (2e6 if s.mode == MODE_FORCE else 1.0)
        return s.run(drive.astype(np.float32), [0])
    if family == "fabric":
        cfg = load_scene("fabric_1")
        return make_sensor(cfg, "warp", device).run(waves(rng, 1, 20, 1, 2.0), [0])
    if family == "velostat":
        cfg = load_scene("velostat")
        return make_sensor(cfg, "warp", device).run(_velostat_pressure(cfg, rng, 1, 20), [0])
    cfg = load_scene("ntype")
    f = _ntype_force(rng, 1, 20, cfg.sensor.element.n_elements)
    return make_sensor(cfg, "warp", device).run(f * np.array([1, 1, -1], np.float32), f, [0])


@pytest.mark.parametrize("family", ["cnt_pdms", "fabric", "velostat", "ntype"])
def test_every_launch_runs_on_the_requested_device(gpu_device, family, monkeypatch):
    """A family that dropped `device` somewhere (a hard-coded "cpu", a missing device= on an array) would pass
    the comparisons above trivially (cpu == cpu); here every launch must name the requested device (None,
    Warp's default device, counts as a miss) and every array it gets must live there."""
    import warp as wp

    from sensors.warp_setup import init_warp

    init_warp()
    want = str(wp.get_device(gpu_device))
    seen = []

    def spy(real):
        def launch(kernel, *args, **kw):
            dev = kw.get("device")
            lists = [a for a in args if isinstance(a, (list, tuple))]
            lists += [kw.get("inputs") or [], kw.get("outputs") or []]
            arrays = [x for lst in lists for x in lst if isinstance(x, wp.array)]
            seen.append((getattr(kernel, "key", str(kernel)), None if dev is None else str(wp.get_device(dev)),
                         sorted({str(x.device) for x in arrays})))
            return real(kernel, *args, **kw)

        return launch

    monkeypatch.setattr(wp, "launch", spy(wp.launch))
    monkeypatch.setattr(wp, "launch_tiled", spy(wp.launch_tiled))
    _family_run(family, gpu_device)
    assert seen, f"{family}: no Warp launch (backend warp should run kernels)"
    for key, dev, arr_devs in seen:
        assert dev == want, f"{family}: kernel {key} launched on {dev}, not {want}"
        assert arr_devs in ([], [want]), f"{family}: kernel {key} got arrays on {arr_devs}, not {want}"
