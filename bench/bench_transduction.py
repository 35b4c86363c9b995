"""Transduction chain speed: Warp (CPU, and CUDA when present) vs the numpy reference, in one run.

Measures taxel-steps/s of the per-taxel kernel alone and of the whole chain (taxel kernel + channel sums +
bridge/ADC/filter readout) on E episodes x (side x side) taxels x T steps, with the drive already on the
device (host transfers are reported apart). Writes bench/results/transduction-<host>.json and prints ratios.

    python bench/bench_transduction.py                       # CPU: numpy vs Warp
    python bench/bench_transduction.py --gpu-episodes 256    # adds CUDA at the issue's size (256 x 64 x 64 x 1000)
    python bench/bench_transduction.py --velostat --side 32  # velostat film kernel: aging vs spectrum creep (Warp CPU)
    python bench/bench_transduction.py --only ntype          # the ntype chain alone (merged into the results file)

ntype: the sensor chain from electrode forces to outputs (NtypeSensor.run: element kernel, scan of the 12 x 12
wire matrix, noise, resolution) with the ideal ohmmeter and with the default "feedback" scan, numpy and Warp
backends, interleaved best-of runs; the ratio feedback / ideal is the cost of the scanned readout (issue 14
allows 1.5x for a default-on stage).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np


def _drive(E: int, T: int, N: int) -> np.ndarray:
    t = np.arange(T, dtype=np.float32) / 100.0
    amp = np.random.default_rng(0).uniform(0.005, 0.04, (E, 1, N)).astype(np.float32)
    return (amp * (0.5 - 0.5 * np.cos(2 * np.pi * 1.0 * t))[None, :, None]).astype(np.float32)


def bench_numpy(cfg, E, T, N):
    from sensors.cnt_pdms.params import taxel_params
    from sensors.cnt_pdms.reference import taxel_chain_numpy

    d = _drive(E, T, N)
    t0 = time.perf_counter()
    taxel_chain_numpy(d, 0, taxel_params(cfg))
    return E * T * N / (time.perf_counter() - t0)


def bench_warp(cfg, E, T, N, device, repeats=3):
    import warp as wp

    from sensors import electronics as el
    from sensors.cnt_pdms.params import electronics_params, taxel_params
    from sensors.cnt_pdms.kernels import TaxelChainWarp

    tp, ep = taxel_params(cfg), electronics_params(cfg)
    chain = TaxelChainWarp(tp, E, N, device)
    host = _drive(E, T, N).reshape(-1)
    t0 = time.perf_counter()
    drive = wp.array(host, dtype=wp.float32, device=chain.device)
    wp.synchronize_device(chain.device)
    h2d = time.perf_counter() - t0
    outs = [wp.empty(E * T * N, dtype=wp.float32, device=chain.device) for _ in range(3)]
    chain.run_device(drive, T, 0, outs)  # warm-up / compile
    wp.synchronize_device(chain.device)
    best = float("inf")
    for _ in range(repeats):
        chain.reset()
        t0 = time.perf_counter()
        chain.run_device(drive, T, 0, outs)
        wp.synchronize_device(chain.device)
        best = min(best, time.perf_counter() - t0)
    noise = np.zeros((E, T, 1))
    tc = np.zeros(N, np.int32)

    def whole_chain():
        chain.run_device(drive, T, 0, outs)
        g, _ = el.sum_channels_warp(outs[2], outs[1], tc, 1, tp.taxel_area_m2, (E, T, N), chain.device)
        el.readout_warp(g, (E, T, 1), noise, ep, None, chain.device)

    whole_chain()  # compile
    best_full = float("inf")
    for _ in range(repeats):
        chain.reset()
        wp.synchronize_device(chain.device)
        t0 = time.perf_counter()
        whole_chain()
        wp.synchronize_device(chain.device)
        best_full = min(best_full, time.perf_counter() - t0)
    # where the whole chain's time goes: each stage alone, synchronised between stages (best of `repeats`)
    stage_s = {"taxel kernel": float("inf"), "channel sums": float("inf"), "readout + copies back": float("inf")}
    for _ in range(repeats):
        chain.reset()
        wp.synchronize_device(chain.device)
        t0 = time.perf_counter()
        chain.run_device(drive, T, 0, outs)
        wp.synchronize_device(chain.device)
        t1 = time.perf_counter()
        g, _ = el.sum_channels_warp(outs[2], outs[1], tc, 1, tp.taxel_area_m2, (E, T, N), chain.device)
        wp.synchronize_device(chain.device)
        t2 = time.perf_counter()
        el.readout_warp(g, (E, T, 1), noise, ep, None, chain.device)
        wp.synchronize_device(chain.device)
        t3 = time.perf_counter()
        for k, v in zip(stage_s, (t1 - t0, t2 - t1, t3 - t2)):
            stage_s[k] = min(stage_s[k], v)
    return {"kernel": E * T * N / best, "chain": E * T * N / best_full, "h2d_s": h2d, "device": chain.device,
            "chain_seconds": best_full, "stage_seconds": stage_s}


def _best(fn, sync, repeats, setup=None):
    """Best wall time of fn() over `repeats`, synchronised, after one warm-up; setup() runs before each, untimed."""
    (setup or (lambda: None))()
    fn()  # warm-up / compile
    sync()
    best = float("inf")
    for _ in range(repeats):
        (setup or (lambda: None))()
        sync()
        t0 = time.perf_counter()
        fn()
        sync()
        best = min(best, time.perf_counter() - t0)
    return best


def bench_cuda_chain(cfg, E, T, N, device="cuda:0", repeats=5, depths=(0, 1, 2, 4)):
    """The whole cnt_pdms chain on CUDA as CntPdmsSensor.run does it on a whole-pad readout (issue 16): taxel
    kernel, tiled channel sum, readout with the noise drawn in the kernel, the readout's outputs copied to
    page-locked host buffers (as the GPU feed does, int16 codes); "before" with the serial readout (one thread
    per episode and channel), "after" with the time-parallel one (sensors/electronics.py), same inputs, same
    run; "fused" with the pad's channel sum inside the taxel kernel (the CUDA default since session 7). Stages
    alone are synchronised one by one; the taxel state is reset (an upload) outside the timed
    region; best of `repeats`."""
    import warp as wp

    from sensors import electronics as el
    from sensors.cnt_pdms.kernels import TaxelChainWarp
    from sensors.cnt_pdms.params import electronics_params, taxel_params
    from sensors.warp_setup import host_staging

    tp, ep = taxel_params(cfg), electronics_params(cfg)
    e = cfg.sensor.electronics
    noise = el.NoiseSeeds(list(range(E)), e.white_noise_v, e.pink_noise_v)
    drive = wp.array(_drive(E, T, N).reshape(-1), dtype=wp.float32, device=device)
    outs3 = [wp.empty(E * T * N, dtype=wp.float32, device=device) for _ in range(3)]
    chain = TaxelChainWarp(tp, E, N, device)
    tc = np.zeros(N, np.int32)
    sync = lambda: wp.synchronize_device(device)  # noqa: E731
    keep = {"resistance", "bridge_v", "adc", "filtered_v", "resistance_measured"}
    box = {}

    def kernels():
        chain.run_device(drive, T, 0, outs3)
        box["g"], _ = el.sum_channels_warp(outs3[2], outs3[1], tc, 1, tp.taxel_area_m2, (E, T, N), device)

    def readout(parallel, keep=keep):
        el.readout_warp(box["g"], (E, T, 1), noise, ep, None, device, keep=keep, adc_dtype=np.int16, parallel=parallel,
                        return_state=False)  # as CntPdmsSensor.run: its episodes end in the call

    res = {"episodes": E, "taxels": N, "steps": T, "device_name": wp.get_device(device).name}
    with host_staging():
        rs = chain.reset
        t_k = _best(kernels, sync, repeats, rs)
        t_br = _best(lambda: readout(False), sync, repeats, rs)
        t_b = _best(lambda: (kernels(), readout(False)), sync, repeats, rs)
        t_ar0 = _best(lambda: readout(True, keep=set()), sync, repeats, rs)
        t_ar = _best(lambda: readout(True), sync, repeats, rs)
        t_a = _best(lambda: (kernels(), readout(True)), sync, repeats, rs)
        # the channel sum fused into the taxel kernel (warp partial sums + a row pass, sensors/cnt_pdms/kernels.py):
        # prefetch depths, then the whole chain as CntPdmsSensor.run does it on CUDA for the default record
        # (strain and stress written per taxel) and for a record of channel outputs only (nothing per taxel)
        n_parts = N // 32 if wp.get_device(device).is_cuda else N
        bufs = outs3[:2] + [wp.empty(E * n_parts * T, dtype=wp.float64, device=device) for _ in range(2)]

        def fused(depth, per_taxel=True, fresh=False):  # outputs in reused buffers, as the plain kernel's outs3
            _, _, box["g"], box["f"] = chain.run_pad_device(drive, T, 0, tp.taxel_area_m2, write_strain=per_taxel,
                                                            write_stress=per_taxel, depth=depth, outs=None if fresh else bufs)

        t_depth = {d: _best(lambda d=d: fused(d), sync, repeats, rs) for d in depths}
        depth = min(t_depth, key=t_depth.get)
        t_f = t_depth[depth]
        t_f0 = _best(lambda: fused(depth, False), sync, repeats, rs)
        t_fresh = _best(lambda: fused(depth, True, True), sync, repeats, rs)  # fresh device arrays per call
        t_plain_fresh = _best(lambda: chain.run_device(drive, T, 0), sync, repeats, rs)  # the plain kernel, fresh arrays
        t_fa = _best(lambda: (fused(depth), readout(True)), sync, repeats, rs)
        t_fa0 = _best(lambda: (fused(depth, False), readout(True)), sync, repeats, rs)
        # GPU time of each kernel and copy of one fused chain + readout (what bounds it), then the host's gaps
        rs(); sync()
        wp.timing_begin(cuda_filter=wp.TIMING_ALL)
        t0 = time.perf_counter()
        fused(depth); readout(True); sync()
        t_prof = time.perf_counter() - t0
        activity = [{"name": r.name.split("::")[-1][:80], "ms": r.elapsed} for r in wp.timing_end()]
        # equivalence on these inputs: the fused sums against the tiled pass (float64 sums of float32 values)
        rs(); fused(depth); g_f, f_f = box["g"].numpy(), box["f"].numpy()
        rs(); kernels(); g_t, f_t = box["g"].numpy(), box["f"].numpy()
    n = E * T * N
    res["fused"] = {
        "taxel_steps_per_s_chain": n / t_fa, "chain_seconds": t_fa, "prefetch_depth": depth,
        "seconds_by_prefetch_depth": {str(d): t for d, t in t_depth.items()},
        "stage_seconds": {"fused taxel kernel + row sums (strain, stress written)": t_f,
                          "fused taxel kernel + row sums (nothing per taxel written)": t_f0,
                          "parallel readout + copies back": t_ar},
        "no_per_taxel_outputs": {"taxel_steps_per_s_chain": n / t_fa0, "chain_seconds": t_fa0},
        "fused_kernel_fresh_arrays_seconds": t_fresh, "plain_kernel_fresh_arrays_seconds": t_plain_fresh,
        "g_max_rel_diff_vs_tiled_sum": float(np.max(np.abs(g_f - g_t) / np.abs(g_t))),
        "g_equal_fraction": float(np.mean(g_f == g_t)),
        "force_max_abs_diff_n": float(np.max(np.abs(f_f - f_t))), "force_max_n": float(np.max(np.abs(f_t))),
        "activities_one_chain": {"wall_ms": t_prof * 1e3, "gpu_ms": sum(a["ms"] for a in activity), "list": activity},
    }
    res["before"] = {"taxel_steps_per_s_chain": n / t_b, "chain_seconds": t_b,
                     "stage_seconds": {"taxel kernel + channel sums": t_k, "serial readout + copies back": t_br}}
    res["after"] = {"taxel_steps_per_s_chain": n / t_a, "chain_seconds": t_a,
                    "stage_seconds": {"taxel kernel + channel sums": t_k, "parallel readout (no copies)": t_ar0,
                                      "parallel readout + copies back": t_ar}}
    return res


def bench_fabric(E: int, T: int, N: int, device: str = "cpu", repeats: int = 7) -> dict:
    """fabric_1 kernel with the per-press area and knit set (issue 13) and without (the chain before), same run."""
    from dataclasses import replace

    import warp as wp

    from scenes import load_scene
    from sensors.fabric.kernels import FabricChainWarp
    from sensors.fabric.reference import fabric_params, press_draws

    p = replace(fabric_params(load_scene("fabric_1")), n_taxels=N)
    t = np.arange(T, dtype=np.float32) / 10.0
    amp = np.random.default_rng(0).uniform(0.5, 2.0, (E, 1, N)).astype(np.float32)
    drive = np.clip(amp * np.sin(2 * np.pi * 0.05 * t)[None, :, None], 0.0, None).astype(np.float32)  # presses
    chains = {}
    for name, press in (("before", False), ("after", True)):
        ch = FabricChainWarp(p, E, N, device, with_press=press)
        ch.set_draws(press_draws(list(range(E)), p))
        ch.run(drive)  # compile
        chains[name] = ch
    best = {name: float("inf") for name in chains}
    for _ in range(repeats):  # interleaved, best of each: a shared machine's load hits both alike
        for name, ch in chains.items():
            ch.reset()
            wp.synchronize_device(ch.device)
            t0 = time.perf_counter()
            ch.run(drive)
            wp.synchronize_device(ch.device)
            best[name] = min(best[name], time.perf_counter() - t0)
    out = {name: E * T * N / b for name, b in best.items()}
    out["cost_after_over_before"] = out["before"] / out["after"]
    return out


def bench_velostat_film(E: int, T: int, N: int, repeats: int = 3) -> dict:
    """velostat film kernel on Warp CPU, both creep models on the same pressure in one run: taxel-steps/s."""
    from scenes import load_scene
    from sensors.registry import make_sensor
    from sensors.velostat.kernels import run_film_warp

    d = _drive(E, T, N) * 1e6  # 5-40 kPa presses
    d[:, :, ::2] = 0.0  # half the taxels unloaded
    out = {}
    for model in ("spectrum", "aging"):
        cfg = load_scene("velostat", [f"sensor.creep.model={model}", f"pad.taxels_x={int(np.sqrt(N))}",
                                      f"pad.taxels_y={int(np.sqrt(N))}"])
        fp = make_sensor(cfg, "warp").fp
        run_film_warp(d[:1, :10], fp)  # compile
        best = np.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            run_film_warp(d, fp)
            best = min(best, time.perf_counter() - t0)
        out[model] = E * T * N / best
    out["ratio_aging_over_spectrum_time"] = out["spectrum"] / out["aging"]
    return out


def bench_ntype(E: int = 150, T: int = 100, repeats: int = 7) -> dict:
    """ntype chain (NtypeSensor.run) per frame: {numpy, warp} x {ideal, feedback}, plus the scan stage alone."""
    from scenes import load_scene
    from sensors.ntype.model import NtypeSensor
    from sensors.ntype.scan import scan_apparent

    rng = np.random.default_rng(0)
    labels = rng.uniform(0.0, 4.8, (E, T, 36, 3))  # the paper's load range per element and component
    elec = labels * np.array([0.8, 0.8, -0.8])  # electrode forces (z down); the crosstalk share is immaterial here
    seeds = list(range(E))
    runs = {}
    for backend in ("numpy", "warp"):
        for scan in ("ideal", "feedback"):
            s = NtypeSensor(load_scene("ntype", [f"sensor.readout.scan={scan}"]), backend=backend, device="cpu")
            s.run(labels[:1, :2], elec[:1, :2], seeds[:1])  # compile
            runs[(backend, scan)] = s
    best = {k: float("inf") for k in runs}
    cpu = {k: float("inf") for k in runs}  # process CPU time: less sensitive to a shared machine than wall time
    for _ in range(repeats):  # interleaved, best of each: a shared machine's load hits all alike
        for k, s in runs.items():
            t0, c0 = time.perf_counter(), time.process_time()
            s.run(labels, elec, seeds)
            best[k] = min(best[k], time.perf_counter() - t0)
            cpu[k] = min(cpu[k], time.process_time() - c0)
    R = runs[("numpy", "ideal")].run(labels, elec, seeds)["resistance"]
    scan_best = {"numpy": float("inf"), "warp": float("inf")}
    for _ in range(repeats):
        for b in scan_best:
            t0 = time.perf_counter()
            scan_apparent(R, 6, 6, "feedback", 5.0, 100.0, 1e3, backend=b)
            scan_best[b] = min(scan_best[b], time.perf_counter() - t0)
    F = E * T
    out = {"frames": F, "load_avg_1min": os.getloadavg()[0], "us_per_frame": {f"{b}_{s}": 1e6 * t / F for (b, s), t in best.items()},
           "scan_us_per_frame": {b: 1e6 * t / F for b, t in scan_best.items()}}
    out["cpu_us_per_frame"] = {f"{b}_{s}": 1e6 * t / F for (b, s), t in cpu.items()}
    out["feedback_over_ideal"] = {b: best[(b, "feedback")] / best[(b, "ideal")] for b in ("numpy", "warp")}
    out["feedback_over_ideal_cpu"] = {b: cpu[(b, "feedback")] / cpu[(b, "ideal")] for b in ("numpy", "warp")}
    out["scan_numpy_over_warp"] = scan_best["numpy"] / scan_best["warp"]
    return out


def _print_ntype(n: dict) -> None:
    u = n["us_per_frame"]
    print(f"ntype chain ({n['frames']} frames, us/frame): numpy ideal {u['numpy_ideal']:.2f}, feedback {u['numpy_feedback']:.2f}; "
          f"warp ideal {u['warp_ideal']:.2f}, feedback {u['warp_feedback']:.2f}")
    print(f"  feedback / ideal: numpy {n['feedback_over_ideal']['numpy']:.2f}x, warp {n['feedback_over_ideal']['warp']:.2f}x "
          f"(issue 14 allows 1.5x); by process CPU time numpy {n['feedback_over_ideal_cpu']['numpy']:.2f}x, "
          f"warp {n['feedback_over_ideal_cpu']['warp']:.2f}x; scan alone {n['scan_us_per_frame']['numpy']:.2f} vs {n['scan_us_per_frame']['warp']:.2f} "
          f"us/frame (numpy / warp {n['scan_numpy_over_warp']:.1f}x)")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--episodes", type=int, default=16, help="CPU batch (the numpy reference runs on the same)")
    ap.add_argument("--side", type=int, default=64)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--gpu-episodes", type=int, default=256)
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    ap.add_argument("--velostat", action="store_true", help="only the velostat film kernel: aging vs spectrum creep")
    ap.add_argument("--only", choices=["ntype"], help="run this family alone and merge it into the results file")
    ap.add_argument("--tag", default="", help="result file name: transduction-<tag>.json (default gpu / cpu)")
    ap.add_argument("--cuda-only", action="store_true", help="stop after the cnt_pdms CUDA figures (no fabric / ntype)")
    a = ap.parse_args()
    if a.velostat:
        from sensors.warp_setup import init_warp

        init_warp()
        v = bench_velostat_film(a.episodes, a.steps, a.side * a.side)
        print(f"velostat film, warp cpu: spectrum {v['spectrum']:.3g}, aging {v['aging']:.3g} taxel-steps/s; "
              f"time aging / spectrum {v['ratio_aging_over_spectrum_time']:.2f}x")
        return
    if a.only == "ntype":
        path = a.out / "transduction-cpu.json"
        res = json.loads(path.read_text()) if path.exists() else {"host": platform.node()}
        res["ntype_cpu"] = bench_ntype()
        _print_ntype(res["ntype_cpu"])
        a.out.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(res, indent=2))
        print(f"wrote {path}")
        return

    from scenes import load_scene
    from sensors.warp_setup import init_warp

    init_warp()
    import warp as wp

    cfg = load_scene("cnt_pdms")
    N = a.side * a.side
    res: dict = {"host": platform.node(), "cpu": platform.processor() or platform.machine(), "taxels": N, "steps": a.steps}
    res["numpy_ref"] = {"episodes": a.episodes, "taxel_steps_per_s": bench_numpy(cfg, a.episodes, a.steps, N)}
    w = bench_warp(cfg, a.episodes, a.steps, N, "cpu")
    res["warp_cpu"] = {"episodes": a.episodes, "taxel_steps_per_s_kernel": w["kernel"], "taxel_steps_per_s_chain": w["chain"]}
    print(f"numpy reference : {res['numpy_ref']['taxel_steps_per_s']:.3g} taxel-steps/s  ({a.episodes} x {N} x {a.steps})")
    print(f"warp cpu        : kernel {w['kernel']:.3g}, whole chain {w['chain']:.3g} taxel-steps/s")
    print(f"  ratio warp-cpu / numpy: {w['chain'] / res['numpy_ref']['taxel_steps_per_s']:.2f}x")
    if wp.get_cuda_device_count() > 0:
        g = bench_warp(cfg, a.gpu_episodes, a.steps, N, "cuda:0")
        res["warp_cuda"] = {
            "episodes": a.gpu_episodes, "device_name": wp.get_device("cuda:0").name,
            "taxel_steps_per_s_kernel": g["kernel"], "taxel_steps_per_s_chain": g["chain"], "h2d_s": g["h2d_s"],
            "chain_seconds": g["chain_seconds"], "stage_seconds": g["stage_seconds"],
        }
        print(f"warp cuda ({res['warp_cuda']['device_name']}): kernel {g['kernel']:.3g}, whole chain {g['chain']:.3g} "
              f"taxel-steps/s ({a.gpu_episodes} x {N} x {a.steps}); h2d of the drive {g['h2d_s']:.2f} s")
        print("  stages alone: " + ", ".join(f"{k} {1e3 * v:.2f} ms" for k, v in g["stage_seconds"].items())
              + f"; whole chain {1e3 * g['chain_seconds']:.2f} ms")
        print(f"  ratio cuda / warp-cpu: {g['chain'] / w['chain']:.0f}x; cuda / numpy: {g['chain'] / res['numpy_ref']['taxel_steps_per_s']:.0f}x")
        c = bench_cuda_chain(cfg, a.gpu_episodes, a.steps, N)
        res["warp_cuda_chain"] = c
        fz = c["fused"]
        print(f"  chain fused (prefetch {fz['prefetch_depth']}): {fz['taxel_steps_per_s_chain']:.3g} taxel-steps/s "
              f"({1e3 * fz['chain_seconds']:.2f} ms); nothing per taxel written: "
              f"{fz['no_per_taxel_outputs']['taxel_steps_per_s_chain']:.3g}; "
              + ", ".join(f"{s} {1e3 * v:.2f} ms" for s, v in fz["stage_seconds"].items())
              + "; by prefetch depth: " + ", ".join(f"{d}: {1e3 * v:.2f} ms" for d, v in fz["seconds_by_prefetch_depth"].items())
              + f"; fresh arrays per call: fused kernel {1e3 * fz['fused_kernel_fresh_arrays_seconds']:.2f} ms, "
              f"plain kernel {1e3 * fz['plain_kernel_fresh_arrays_seconds']:.2f} ms"
              + f"; g vs tiled sum: max rel diff {fz['g_max_rel_diff_vs_tiled_sum']:.2g}, equal {fz['g_equal_fraction']:.4f}")
        act = fz["activities_one_chain"]
        print(f"  one fused chain + readout: wall {act['wall_ms']:.2f} ms, GPU {act['gpu_ms']:.2f} ms: "
              + ", ".join(f"{a['name']} {a['ms']:.3f}" for a in act["list"]))
        for k in ("before", "after"):
            print(f"  chain {k}: {c[k]['taxel_steps_per_s_chain']:.3g} taxel-steps/s ({1e3 * c[k]['chain_seconds']:.2f} ms); "
                  + ", ".join(f"{s} {1e3 * v:.2f} ms" for s, v in c[k]["stage_seconds"].items()))
        if a.cuda_only:
            _write(res, a)
            return
    fe = min(a.episodes, 4)
    fb = bench_fabric(fe, a.steps, N, "cpu")
    res["fabric_warp_cpu"] = {"episodes": fe, "taxel_steps_per_s_before": fb["before"], "taxel_steps_per_s_after": fb["after"],
                              "cost_after_over_before": fb["cost_after_over_before"]}
    print(f"fabric warp cpu : {fb['before']:.3g} taxel-steps/s without the press state, {fb['after']:.3g} with "
          f"(cost {fb['cost_after_over_before']:.2f}x; issue 13 allows 1.5x)")
    if wp.get_cuda_device_count() > 0:
        fg = bench_fabric(a.gpu_episodes, a.steps, N, "cuda:0")
        res["fabric_warp_cuda"] = {"episodes": a.gpu_episodes, "taxel_steps_per_s_before": fg["before"],
                                   "taxel_steps_per_s_after": fg["after"], "cost_after_over_before": fg["cost_after_over_before"]}
        print(f"fabric warp cuda: cost of the press state {fg['cost_after_over_before']:.2f}x")
    res["ntype_cpu"] = bench_ntype()
    _print_ntype(res["ntype_cpu"])
    _write(res, a)


def _write(res: dict, a) -> None:
    a.out.mkdir(parents=True, exist_ok=True)
    tag = a.tag or ("gpu" if "warp_cuda" in res else "cpu")
    path = a.out / f"transduction-{tag}.json"
    path.write_text(json.dumps(res, indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
