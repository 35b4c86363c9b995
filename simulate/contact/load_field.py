"""Batched MuJoCo episodes -> per-taxel load field (deformation, pressure, shear).

One `mujoco.rollout` call runs all episodes (open-loop controls, no Python stepping); the sensors of
the MJCF (joint positions + the netforce contact sensor) are read at every `substeps`-th step.
The taxel fields are then computed in vectorised numpy:

- deformation: geometric overlap of the indenter (at its simulated pose) with the undeformed pad top,
  averaged over each taxel cell (box: exact cell coverage; sphere: 4 x 4 supersampling), spread by a
  row-normalised Gaussian elastic-layer kernel of width pad.spread_length_m
  (Johnson, Contact Mechanics, 1985, sect. 5.8, thin elastic layer), and never less than the overlap
  itself (the surface cannot stay inside the rigid indenter): max(overlap, kernel * overlap).
- pressure: Winkler distribution of MuJoCo's net normal contact force, proportional to the
  deformation, so that sum(pressure * taxel_area) == normal force exactly.
- shear: MuJoCo's net tangential contact force distributed with the same weights.
"""

from __future__ import annotations

from collections.abc import Iterator

import mujoco
import mujoco.rollout
import numpy as np

from scenes.config import SceneConfig
from sensors.base import LoadBatch
from sensors.taxels import (
    interval_coverage,
    sphere_overlap,
    spread_matrix,
    taxel_area_m2,
    taxel_xy_m,
)
from simulate.contact.mjcf import SENSORS_PER_INDENTER, build_mjcf, contact_design
from simulate.protocols.indenter import EpisodeProtocol, target_waveforms, xy_waveforms

MAX_STEPS_PER_CHUNK = 4_000_000  # episodes x steps per rollout call (bounds the rollout's output memory)

# sensordata layout of build_mjcf: jointpos x, y, z; contact netforce: found, force(3), torque(3), dist, pos(3), ...
_POS = slice(0, 3)
_FOUND = 3
_FORCE = slice(4, 7)
READ_PER_INDENTER = 7  # the values of each indenter's block that anything downstream reads: jointpos, found, force


def read_columns(m: mujoco.MjModel) -> tuple[int, ...]:
    """The sensordata indices `simulate_sensors` keeps: each indenter's first READ_PER_INDENTER values (jointpos
    x, y, z; contact found, force). The contact sensor's torque, dist, pos, normal and tangent (13 of every 20
    values) are read by nothing: on MuJoCo Warp they stay on the device (fabric_1, 8192 episodes: 2.3 GB of float64
    sensordata in the GPU feed's shared memory instead of 6.7 GB). The MJCF keeps them (its text is in every shard
    and in the content hash)."""
    per = SENSORS_PER_INDENTER
    return tuple(c * per + j for c in range(m.nsensordata // per) for j in range(READ_PER_INDENTER))


def build_model(cfg: SceneConfig) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(build_mjcf(cfg))


def episode_controls(
    cfg: SceneConfig, protocols: list[EpisodeProtocol], nstep: int, steps: slice | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(E, nstep, 3) actuator controls for steps i = 0..nstep-1 (evaluated at t = (i + 1) dt) and the
    (E, nstep) commanded target at those times; with `steps` (i0:i1), only those rows, equal to the same
    rows of the whole arrays (so the GPU path can make them chunk by chunk while the worlds step).

    Displacement control: the z servo gets ctrl = q* + (kv / kp) dq*/dt with q* = -d (1 + k_pad / kp):
    velocity feed-forward (no servo lag) and static feed-forward of the servo deflection under the
    design pad stiffness. Force control: ctrl_z = -F (a force pushing the indenter down).
    """
    des = contact_design(cfg)
    dt = cfg.sampling.physics_timestep_s
    i0, i1 = (0, nstep) if steps is None else (steps.start, steps.stop)
    a, b = max(0, i0 - 1), min(nstep, i1 + 1)  # one step of margin: the same central differences as the whole
    t = (np.arange(a, b) + 1.0) * dt
    E = len(protocols)
    ctrl = np.zeros((E, b - a, 3))
    target = target_waveforms(protocols, cfg, t)
    ctrl[:, :, :2] = xy_waveforms(protocols, cfg, t)
    if cfg.protocol.control == "displacement":
        kp, kv = des.servo_kp_n_per_m, des.servo_kv_n_s_per_m
        q = -target * (1.0 + des.pad_stiffness_n_per_m / kp)
        dq = np.gradient(q, dt, axis=1) if b - a > 1 else np.zeros_like(q)
        ctrl[:, :, 2] = q + (kv / kp) * dq
    else:
        ctrl[:, :, 2] = -target
    return ctrl[:, i0 - a : i1 - a], target[:, i0 - a : i1 - a]


def sample_targets(cfg: SceneConfig, protocols: list[EpisodeProtocol], n: int) -> np.ndarray:
    """(E, n) commanded target at the sample times k * substeps * dt (the rows the sensors are read at)."""
    t = (np.arange(n) * cfg.sampling.substeps).astype(float) * cfg.sampling.physics_timestep_s
    return target_waveforms(protocols, cfg, t)


def _initial_states(m: mujoco.MjModel, cfg: SceneConfig, protocols: list[EpisodeProtocol], ctrl0: np.ndarray):
    """(E, nstate) full-physics initial states and (E, nsensordata) sensors at t = 0."""
    d = mujoco.MjData(m)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    nstate = mujoco.mj_stateSize(m, spec)
    states = np.zeros((len(protocols), nstate))
    sens = np.zeros((len(protocols), m.nsensordata))
    for e, p in enumerate(protocols):
        mujoco.mj_resetData(m, d)
        d.qpos[:] = (p.offset_xy_m[0], p.offset_xy_m[1], cfg.indenter.start_gap_m)
        d.ctrl[:] = ctrl0[e]
        mujoco.mj_forward(m, d)
        mujoco.mj_getState(m, d, states[e], spec)
        sens[e] = d.sensordata
    return states, sens


def episode_length(protocols: list[EpisodeProtocol]) -> int:
    """The common n_samples of a batch of episodes (>= 2)."""
    ns = {p.n_samples for p in protocols}
    if len(ns) != 1:
        raise ValueError(f"run_episodes: all protocols must have the same n_samples (got {sorted(ns)})")
    n = ns.pop()
    if n < 2:
        raise ValueError(f"run_episodes: n_samples must be >= 2 (got {n})")
    return n


def physics_engine(cfg: SceneConfig) -> tuple[str, str]:
    """(engine, warp device) for generation.physics: "mujoco" (C, CPU threads) or "mujoco_warp" (batched
    worlds on generation.device); "auto" = MuJoCo Warp when a CUDA device and mujoco_warp are present."""
    g = cfg.generation
    if g.physics == "mujoco":
        return "mujoco", "cpu"
    from sensors.warp_setup import resolve_device
    from simulate.contact import mujoco_warp as contact_mjw

    if g.physics == "auto":
        dev = resolve_device("auto")
        return ("mujoco_warp", dev) if dev != "cpu" and contact_mjw.available() else ("mujoco", "cpu")
    if not contact_mjw.available():
        raise ValueError("generation.physics: 'mujoco_warp' needs the mujoco_warp package "
                         "(pip install 'piezotwin[gpu]'); allowed without it: mujoco, auto")
    return "mujoco_warp", resolve_device("auto" if g.device == "auto" else g.device)


def simulate_sensors(
    cfg: SceneConfig, protocols: list[EpisodeProtocol], threads: int = 1, alloc=None,
) -> tuple[np.ndarray, np.ndarray]:
    """Run the episodes; returns their sensordata at the sample times, the `read_columns` only (E, T, 7 per
    indenter), and target (E, T).
    Stepping: C MuJoCo's rollout on `threads` threads, or MuJoCo Warp worlds (`physics_engine`).
    alloc(shape) -> float64 array: where the sensordata goes (default np.zeros; the GPU feed's physics
    process passes a view of a shared-memory block, so the worlds' output needs no second copy)."""
    engine, device = physics_engine(cfg)
    n = episode_length(protocols)
    sub = cfg.sampling.substeps
    nstep = (n - 1) * sub
    mjcf = build_mjcf(cfg)
    m = mujoco.MjModel.from_xml_string(mjcf)
    E = len(protocols)
    cols = read_columns(m)
    if engine == "mujoco_warp":
        from simulate.contact.mujoco_warp import box_primitive_for, worlds_for

        # controls are made chunk by chunk on a host thread while the worlds step (no (E, nstep, 3) array)
        states0, sens0 = _initial_states(m, cfg, protocols, episode_controls(cfg, protocols, nstep, slice(0, 1))[0][:, 0])
        qpos0 = states0[:, 1 : 1 + m.nq]  # full-physics state = (time, qpos, qvel, ...)
        worlds = worlds_for(m, mjcf, E, device, box_primitive=box_primitive_for(cfg.protocol.control), columns=cols)
        out = worlds.run(qpos0, lambda sl, eps: episode_controls(cfg, protocols[eps], nstep, sl)[0], sens0[:, cols], sub, n,
                         out=None if alloc is None else alloc((E, n, len(cols))))
    else:
        ctrl, _ = episode_controls(cfg, protocols, nstep)
        states0, sens0 = _initial_states(m, cfg, protocols, ctrl[:, 0])
        rows = np.arange(1, n) * sub - 1
        out = np.zeros((E, n, len(cols))) if alloc is None else alloc((E, n, len(cols)))
        out[:, 0] = sens0[:, cols]
        datas = [mujoco.MjData(m) for _ in range(max(1, threads))]
        data_arg = datas if threads > 1 else datas[0]
        chunk = max(max(1, threads), MAX_STEPS_PER_CHUNK // nstep)
        for a in range(0, E, chunk):
            b = min(E, a + chunk)
            _, sd = mujoco.rollout.rollout(m, data_arg, states0[a:b], ctrl[a:b], nstep=nstep)
            out[a:b, 1:] = sd[:, rows][..., cols]
    return out, sample_targets(cfg, protocols, n)


# MuJoCo Warp step time against worlds, one GPU: t(W) = STEP_S_FLOOR + W / WORLD_STEPS_PER_S, fitted to the H100
# figures of bench/README.md (1024 worlds 2.2e6, 32768 worlds 2.38e7 world-steps/s): below ~15k worlds a step
# costs about the same whatever the worlds (kernel launches), above it the worlds' work sets the pace
STEP_S_FLOOR = 0.44e-3
WORLD_STEPS_PER_S = 3.5e7


def world_groups(groups: list[tuple[int, list[int]]]) -> list[list[tuple[int, list[int]]]]:
    """Length groups (n_samples, positions), shortest first, merged into runs of worlds for MuJoCo Warp.

    Worlds of one run step together for as many samples as its longest episode (the shorter ones padded,
    their extra samples dropped). A few worlds step no faster than many, so small groups of mixed lengths run
    faster as one padded batch than one after another, and large groups faster apart; the contiguous
    partition of the sorted lengths with the least modelled time (STEP_S_FLOOR, WORLD_STEPS_PER_S) is taken.
    """
    k = len(groups)
    best = [0.0] + [float("inf")] * k  # best[j]: least time for the first j groups
    cut = [0] * (k + 1)
    for j in range(1, k + 1):
        worlds = 0
        for i in range(j, 0, -1):  # last run = groups i-1 .. j-1
            worlds += len(groups[i - 1][1])
            t = best[i - 1] + groups[j - 1][0] * (STEP_S_FLOOR + worlds / WORLD_STEPS_PER_S)
            if t < best[j]:
                best[j], cut[j] = t, i - 1
    runs, j = [], k
    while j > 0:
        runs.append(groups[cut[j]:j])
        j = cut[j]
    return runs[::-1]


def padded_controls(cfg: SceneConfig, protocols: list[EpisodeProtocol], nsteps: np.ndarray):
    """Controls (steps, episodes) -> rows for worlds of mixed lengths: each episode's own `episode_controls`
    (its own nstep, so the same rows as when it runs alone), its last row held past its end."""

    def rows(steps: slice, eps: slice) -> np.ndarray:
        ps, ns = protocols[eps], nsteps[eps]
        out = np.empty((len(ps), steps.stop - steps.start, 3))
        for nstep in np.unique(ns):
            j = np.flatnonzero(ns == nstep)
            group = [ps[i] for i in j]
            a, b = steps.start, min(steps.stop, int(nstep))
            if b > a:
                out[j, : b - a] = episode_controls(cfg, group, int(nstep), slice(a, b))[0]
            if b < steps.stop:
                last = out[j, b - a - 1] if b > a else episode_controls(cfg, group, int(nstep), slice(int(nstep) - 1, int(nstep)))[0][:, 0]
                out[j, max(0, b - a):] = last[:, None, :]
        return out

    return rows


def simulate_sensors_padded(cfg: SceneConfig, protocols: list[EpisodeProtocol], threads: int = 1) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """MuJoCo Warp only: episodes of mixed lengths as one batch of worlds, stepped as long as the longest;
    returns {n_samples: (sensordata (E_n, n, `read_columns`), target (E_n, n))} in `length_groups` order. An episode's
    samples depend only on its own controls up to then, so each equals its run in a batch of its own length."""
    from simulate.contact.mujoco_warp import box_primitive_for, worlds_for

    engine, device = physics_engine(cfg)
    if engine != "mujoco_warp":
        raise ValueError("simulate_sensors_padded: MuJoCo Warp only (the C path runs each length as its own rollout)")
    sub = cfg.sampling.substeps
    lengths = np.array([p.n_samples for p in protocols])
    if lengths.min() < 2:
        raise ValueError(f"run_episodes: n_samples must be >= 2 (got {lengths.min()})")
    n = int(lengths.max())
    nsteps = (lengths - 1) * sub
    mjcf = build_mjcf(cfg)
    m = mujoco.MjModel.from_xml_string(mjcf)
    ctrl = padded_controls(cfg, protocols, nsteps)
    states0, sens0 = _initial_states(m, cfg, protocols, ctrl(slice(0, 1), slice(0, len(protocols)))[:, 0])
    cols = read_columns(m)
    out = worlds_for(m, mjcf, len(protocols), device, box_primitive=box_primitive_for(cfg.protocol.control),
                     columns=cols).run(states0[:, 1 : 1 + m.nq], ctrl, sens0[:, cols], sub, n)
    res = {}
    for k in sorted(set(lengths.tolist())):
        j = np.flatnonzero(lengths == k)
        res[k] = (out[j, :k], sample_targets(cfg, [protocols[i] for i in j], k))
    return res


def load_field(cfg: SceneConfig, pos_rel_m: np.ndarray, force_n: np.ndarray):
    """Taxel fields from the indenter pose and net contact force.

    pos_rel_m: (E, T, 3) indenter lowest point relative to (0, 0, pad top).
    force_n: (E, T, 3) tangential x, y and normal compressive z contact force.
    Returns deformation_m (E, T, N), pressure_pa (E, T, N), shear_pa (E, T, N, 2).
    """
    pad, ind = cfg.pad, cfg.indenter
    E, T, _ = pos_rel_m.shape
    nx, ny = pad.taxels_x, pad.taxels_y
    sx = spread_matrix(pad.size_x_m, nx, pad.spread_length_m)
    sy = spread_matrix(pad.size_y_m, ny, pad.spread_length_m)
    pen = np.clip(-pos_rel_m[..., 2], 0.0, None)  # (E, T)
    if ind.shape == "box":
        cx = interval_coverage(pos_rel_m[..., 0], ind.size_x_m / 2, pad.size_x_m, nx)  # (E, T, nx)
        cy = interval_coverage(pos_rel_m[..., 1], ind.size_y_m / 2, pad.size_y_m, ny)  # (E, T, ny)
        overlap = pen[..., None, None] * cy[..., :, None] * cx[..., None, :]
        spread = pen[..., None, None] * (cy @ sy.T)[..., :, None] * (cx @ sx.T)[..., None, :]
    else:
        overlap = sphere_overlap(cfg, pos_rel_m.reshape(-1, 3), ind.radius_m)  # (E T, ny, nx)
        spread = np.einsum("ij,fjk,lk->fil", sy, overlap, sx, optimize=True).reshape(E, T, ny, nx)
        overlap = overlap.reshape(E, T, ny, nx)
    # the surface cannot stay inside the rigid indenter: under it the deflection is at least the overlap
    deform = np.maximum(overlap, spread)
    deform = deform.reshape(E, T, nx * ny)

    area = taxel_area_m2(cfg)
    weights = deform
    wsum = weights.sum(axis=-1)
    fn = np.clip(force_n[..., 2], 0.0, None)
    loaded = fn > 0.0
    fallback = loaded & (wsum <= 0.0)
    if fallback.any():  # force without resolvable overlap (sub-sample depth): a kernel at the indenter centre
        xy = taxel_xy_m(cfg)
        c = pos_rel_m[fallback][:, :2]
        g = np.exp(-((xy[None, :, :] - c[:, None, :]) ** 2).sum(-1) / (2 * pad.spread_length_m**2))
        weights = weights.copy()
        weights[fallback] = g
        wsum = weights.sum(axis=-1)
    scale = np.where(loaded, 1.0 / (area * np.where(wsum > 0, wsum, 1.0)), 0.0)  # (E, T)
    share = weights * scale[..., None]  # (E, T, N), sums to 1 / area where loaded
    pressure = share * fn[..., None]
    shear = share[..., None] * force_n[..., None, :2]
    return deform, pressure, shear


# protocol kinds with their own contact stage: kind -> "module:function(cfg, protocols, threads) -> LoadBatch"
CONTACT_STAGES: dict[str, str] = {
    "press_stroke": "simulate.contact.press_stroke:run_press_stroke",
    "element_loads": "simulate.contact.element_loads:run_element_loads",
}
# those with a sliced form: "module:function(cfg, protocols, threads, slice_episodes, device_fields, physics)" yielding
# (slice of protocols, LoadBatch) as `iter_load_batches` does
SLICED_CONTACT_STAGES: dict[str, str] = {"press_stroke": "simulate.contact.press_stroke:iter_press_stroke"}


def run_episodes(cfg: SceneConfig, protocols: list[EpisodeProtocol], threads: int = 1) -> LoadBatch:
    """Simulate E episodes (same n_samples) in one batched rollout and return their load fields."""
    return next(iter_load_batches(cfg, protocols, threads))[1]


def iter_load_batches(
    cfg: SceneConfig, protocols: list[EpisodeProtocol], threads: int = 1, slice_episodes: int | None = None,
    device_fields: str | None = None, physics: tuple[np.ndarray, np.ndarray] | None = None,
) -> Iterator[tuple[slice, LoadBatch]]:
    """Simulate E episodes (same n_samples) in one batch of worlds, then yield their load fields in slices
    of at most `slice_episodes` episodes (default all): (slice of protocols, LoadBatch). physics: their
    (sensordata, target) from `simulate_sensors`, already run elsewhere (the GPU feed's physics process).

    The physics wants many worlds at once; the load field and the sensor chain after it need device memory
    per episode, so they go slice by slice. device_fields: on the MuJoCo Warp path, leave deformation,
    pressure and shear as Warp arrays on this device (see LoadBatch) for a sensor chain that runs there.
    """
    if cfg.protocol.kind in CONTACT_STAGES:
        import importlib

        if cfg.protocol.kind in SLICED_CONTACT_STAGES:  # one batch of physics, its fields slice by slice (on the device)
            module, fn = SLICED_CONTACT_STAGES[cfg.protocol.kind].split(":")
            stage_physics = None if physics is None else physics[0]  # its own physics array (`_step_groups`)
            yield from getattr(importlib.import_module(module), fn)(cfg, protocols, threads, slice_episodes, device_fields,
                                                                    stage_physics)
            return
        module, fn = CONTACT_STAGES[cfg.protocol.kind].split(":")
        yield slice(0, len(protocols)), getattr(importlib.import_module(module), fn)(cfg, protocols, threads)
        return
    sens, target = physics if physics is not None else simulate_sensors(cfg, protocols, threads)
    E = len(protocols)
    step = E if slice_episodes is None else max(1, slice_episodes)
    for a in range(0, E, step):
        sl = slice(a, min(E, a + step))
        yield sl, load_batch(cfg, sens[sl], target[sl], device_fields)


HOST_PASS_THREADS = 4  # threads for load_batch's host passes over a large batch's sensordata (numpy copies release
# the GIL): on the H100 host fabric_1's 8192 episodes (6.7 GB of float64 sensordata) spent 3.6 s in those passes
# and 1.2 s more making the pose contiguous for the upload, on one thread (feed-stage-fabric_1-h100-s11.json) ...
HOST_PASS_MIN_BYTES = 1 << 28  # ... for batches of at least this much sensordata (256 MiB; smaller ones: one thread)
_HOST_PASSES = None


def host_rows(part, n_rows: int, nbytes: int) -> None:
    """Run part(slice of rows) over rows 0..n_rows: in one call below HOST_PASS_MIN_BYTES (the bytes the pass
    reads), else split over HOST_PASS_THREADS threads (numpy's copies and casts release the GIL; an elementwise
    pass gives the same values bit for bit whatever the split, tests/test_load_field_host_passes.py)."""
    global _HOST_PASSES
    if nbytes < HOST_PASS_MIN_BYTES or HOST_PASS_THREADS <= 1 or n_rows <= 1:
        part(slice(None))
        return
    if _HOST_PASSES is None:
        from concurrent.futures import ThreadPoolExecutor

        _HOST_PASSES = ThreadPoolExecutor(HOST_PASS_THREADS, thread_name_prefix="load-batch")
    step = max(1, -(-n_rows // (4 * HOST_PASS_THREADS)))
    list(_HOST_PASSES.map(part, [slice(a, min(n_rows, a + step)) for a in range(0, n_rows, step)]))


def as_float32(a: np.ndarray) -> np.ndarray:
    """a as float32 (a itself where it is already), the cast split over rows by `host_rows`: the recorded load
    channels of a large slice (fabric_1's 8192 episodes: 2.7 s on one thread of the H200 host, session 17)."""
    if a.dtype == np.float32:
        return a
    out = np.empty(a.shape, np.float32)

    def part(e: slice) -> None:
        np.copyto(out[e], a[e], casting="unsafe")  # astype's cast

    host_rows(part, len(a), a.nbytes)
    return out


# estimate: MuJoCo Warp's float32 contact solve leaves a lateral contact force on a normal press, where C MuJoCo's
# float64 solve gives exactly 0: on velostat episodes made on an H200 at most 2.6e-4 N whatever the normal force
# (1.3e-5 of it at 5-20 N, up to 6 % below 0.01 N; bench/gpu_lateral_residual.py,
# results/gpu-lateral-residual-h200-s18-velostat.json), shear fields <= 1.9 Pa against 1.1e5 Pa of pressure
# (results/gpu-zero-fields-h200-s18-*.json). A tangential force below TANGENTIAL_RESIDUAL_N plus
# TANGENTIAL_RESIDUAL_SHARE of the normal one is solver residual, not load (a stroke or a slip loads tens of %)
TANGENTIAL_RESIDUAL_N = 1e-3  # ~4x the largest lateral residual measured
TANGENTIAL_RESIDUAL_SHARE = 1e-4  # ~8x the median share at 5-20 N


def lateral_residual(lateral_n: np.ndarray, normal_n: np.ndarray) -> np.ndarray:
    """Where a lateral contact force |F_xy| (N) beside the normal one |F_z| (N) is the float32 solver's residual:
    below TANGENTIAL_RESIDUAL_N + TANGENTIAL_RESIDUAL_SHARE x |F_z| (bool, elementwise)."""
    return lateral_n < TANGENTIAL_RESIDUAL_N + TANGENTIAL_RESIDUAL_SHARE * normal_n


def _columns(sens: np.ndarray, top: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """load_batch's pose (contiguous), world position, force (tangential x, y, normal compressive z) and contact
    count out of sensordata (E, T, ns), split over episodes by `host_rows`. A tangential force below
    TANGENTIAL_RESIDUAL_N + TANGENTIAL_RESIDUAL_SHARE x the normal one is the float32 solver's residual and reads 0,
    so both engines give a normal press no shear (C MuJoCo's is 0 already: its values are unchanged)."""
    E, T, _ = sens.shape
    off = np.array([0.0, 0.0, top])
    q = np.empty((E, T, 3), sens.dtype)
    pos_world = np.empty((E, T, 3), np.result_type(sens.dtype, off.dtype))
    force = np.empty((E, T, 3), sens.dtype)
    found = np.empty((E, T), np.int64)

    def part(e: slice) -> None:
        np.copyto(q[e], sens[e, :, _POS])
        np.add(q[e], off, out=pos_world[e])
        np.copyto(force[e, :, :2], sens[e, :, _FORCE.start : _FORCE.start + 2])
        np.negative(sens[e, :, _FORCE.start + 2], out=force[e, :, 2])
        tangential = force[e, :, :2]
        tangential[lateral_residual(np.hypot(tangential[..., 0], tangential[..., 1]), np.abs(force[e, :, 2]))] = 0.0
        np.copyto(found[e], sens[e, :, _FOUND], casting="unsafe")

    host_rows(part, E, sens.nbytes)
    return q, pos_world, force, found


def load_batch(cfg: SceneConfig, sens: np.ndarray, target: np.ndarray, device_fields: str | None = None,
               fields: tuple | None = None) -> LoadBatch:
    """LoadBatch of episodes from their sensordata (E, T, ns: `read_columns`, or all of it) and target (E, T): pose and net force
    from the MJCF sensors, the taxel fields by `load_field` (numpy) or, on the MuJoCo Warp path, by Warp
    kernels on the physics device (kept there as flat Warp arrays when device_fields names that device).
    fields: (deformation, pressure, shear) made already (the GPU feed's time chunks), not computed again."""
    top = cfg.pad.thickness_m
    q, pos_world, force, found = _columns(sens, top)  # force on the pad, global frame
    engine, device = physics_engine(cfg)
    if fields is not None:
        deform, pressure, shear = fields
    elif engine == "mujoco_warp":  # the GPU path: the numpy field would be the host's largest cost
        from simulate.contact.load_field_kernels import load_field_warp

        deform, pressure, shear = load_field_warp(cfg, q, force, device, to_host=device_fields != device)
    else:
        deform, pressure, shear = load_field(cfg, q, force)
    n = sens.shape[1]
    return LoadBatch(
        time_s=np.arange(n) / cfg.sampling.sample_rate_hz,
        target=target,
        indenter_pos_m=pos_world,
        contact_force_n=force,
        contact_points=found,
        deformation_m=deform,
        pressure_pa=pressure,
        shear_pa=shear,
        taxel_xy_m=taxel_xy_m(cfg),
        taxel_area_m2=taxel_area_m2(cfg),
        control=cfg.protocol.control,
    )
