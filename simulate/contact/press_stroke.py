"""Contact stage of protocol kind "press_stroke": several force-controlled indenters press at random
positions and stroke tangentially (ntype's 3-D loads).

MuJoCo runs the scene (simulate/contact/mjcf.py with indenter.count indenters, force-controlled z motors, stiff
x/y position servos that impose the strokes) in one batched `mujoco.rollout`; each indenter's normal force
is its MuJoCo netforce contact sensor.

Tangential load. With the contact impedance d = 0.01 that makes MuJoCo's normal contact a spring
(simulate/contact/mjcf.py), MuJoCo's friction is a weak velocity-proportional drag, not Coulomb stick (a 2.5 N
sideways push slides the indenter at ~1 cm/s). So the shear comes from a Coulomb stick-slip spring on the
indenter's *simulated* tangential path, evaluated at every physics step:

    f = k_t (x - a),   and where |f| > mu N:  a <- x - (mu N / k_t) f/|f|,  f = mu N f/|f|
    (a: the stick anchor; a = x while out of contact)

with k_t = G A / h (simulate.contact.mjcf.shear_stiffness_n_per_m) and N the MuJoCo normal force: elastic stick
until the friction cone, then sliding at mu N (Johnson, Contact Mechanics, 1985, sect. 7.2, the
Cattaneo-Mindlin stick-slip limit; a Dahl/bristle-type rate-independent friction law). MuJoCo's own
tangential contact force (the drag) is not used.

Load field on the pad's taxel grid: each indenter's normal force and shear are spread uniformly over its
footprint (a flat punch on a Winkler layer), deformation = penetration x footprint coverage.
"""

from __future__ import annotations

import mujoco
import mujoco.rollout
import numpy as np

from scenes.config import SceneConfig
from sensors.base import LoadBatch
from sensors.taxels import interval_coverage, sphere_overlap, taxel_area_m2, taxel_xy_m
from simulate.contact.mjcf import SENSORS_PER_INDENTER, shear_stiffness_n_per_m
from simulate.contact.stick_slip_kernels import stick_slip_path
from simulate.protocols.indenter import (
    EpisodeProtocol,
    press_stroke_force,
    press_stroke_xy,
    stack_indenters,
)

MAX_STEPS_PER_CHUNK = 1_000_000  # episodes x physics steps per rollout call
PARK_HEIGHT_M = 0.002  # inactive indenters float this far above the pad


def _controls(cfg: SceneConfig, protocols: list[EpisodeProtocol], t: np.ndarray) -> np.ndarray:
    """(E, len(t), 3 count) controls: x, y servo targets and -F_z for each indenter."""
    c = cfg.indenter.count
    ctrl = np.zeros((len(protocols), len(t), 3 * c))
    for e, p in enumerate(protocols):
        for i, ind in enumerate(p.params["indenters"]):
            ctrl[e, :, 3 * i : 3 * i + 2] = press_stroke_xy(ind, t)
            ctrl[e, :, 3 * i + 2] = -press_stroke_force(ind, t)
    return ctrl


def controls_batch(cfg: SceneConfig, protocols: list[EpisodeProtocol], t: np.ndarray) -> np.ndarray:
    """`_controls` over the episodes at once (the MuJoCo Warp path makes controls for 32k episodes at a time):
    the same command law on `stack_indenters`, so the same values (tests/test_press_stroke_mjw.py)."""
    c = cfg.indenter.count
    ctrl = np.zeros((len(protocols), len(t), 3 * c))
    tt = np.asarray(t, float)[None, :]
    for i in range(c):
        ind = stack_indenters([p.params["indenters"][i] for p in protocols])
        ctrl[:, :, 3 * i : 3 * i + 2] = press_stroke_xy(ind, tt)
        ctrl[:, :, 3 * i + 2] = -press_stroke_force(ind, tt)
    return ctrl


def stick_slip(xy: np.ndarray, normal_n: np.ndarray, k_t: float, mu: float) -> np.ndarray:
    """Coulomb stick-slip shear force (N) on the pad along a tangential path: the numpy reference of the Warp
    kernels (`simulate.contact.stick_slip_kernels`: the C MuJoCo path runs `stick_slip_path`, MuJoCo Warp a step
    kernel after every device step).

    xy: (E, S, C, 2) indenter x/y at physics steps; normal_n: (E, S, C) normal force (N, >= 0).
    Returns (E, S, C, 2) tangential force on the pad (in the direction the indenter drags the surface).
    """
    E, S, C, _ = xy.shape
    anchor = xy[:, 0].copy()
    out = np.zeros_like(xy)
    for s in range(S):
        x = xy[:, s]
        cap = mu * normal_n[:, s]
        in_contact = cap > 0.0
        anchor = np.where(in_contact[..., None], anchor, x)
        f = k_t * (x - anchor)
        mag = np.sqrt((f * f).sum(-1))
        slip = mag > cap
        scale = np.where(slip, cap / np.where(mag > 0, mag, 1.0), 1.0)
        f = f * scale[..., None]
        anchor = np.where(slip[..., None], x - f / k_t, anchor)
        out[:, s] = f
    return out


def run_press_stroke(cfg: SceneConfig, protocols: list[EpisodeProtocol], threads: int = 1) -> LoadBatch:
    """Simulate E "press_stroke" episodes (same n_samples) and return their load fields on the taxel grid.

    LoadBatch.target / indenter_pos_m are those of the first indenter; contact_force_n is the sum over
    indenters (x, y: stick-slip shear on the pad; z: MuJoCo normal force); contact_points counts the
    indenters in contact.
    """
    return next(iter_press_stroke(cfg, protocols, threads))[1]


PHYSICS_COLUMNS = 7  # per sample and indenter: position x, y, z (m), normal force (N), shear x, y (N), contacts


def iter_press_stroke(cfg: SceneConfig, protocols: list[EpisodeProtocol], threads: int = 1,
                      slice_episodes: int | None = None, device_fields: str | None = None,
                      physics: np.ndarray | None = None):
    """`run_press_stroke` as (slice of protocols, LoadBatch) pieces after one batch of physics: on MuJoCo Warp of at
    most slice_episodes episodes (default all), on C MuJoCo one piece. device_fields: on the MuJoCo Warp path with box
    indenters, the taxel fields are made by Warp kernels on that device and stay there (flat Warp arrays, see
    LoadBatch), for a sensor chain that runs there (`press_fields_warp`; the numpy `_load_batch` is its reference).
    physics: `press_stroke_physics` of these protocols, run elsewhere (the GPU feed's physics process)."""
    from simulate.contact.load_field import physics_engine

    P = press_stroke_physics(cfg, protocols, threads) if physics is None else physics
    engine, device = physics_engine(cfg)
    gpu = engine == "mujoco_warp"
    dev = device_fields if gpu and device_fields == device else None
    E = len(protocols)
    step = max(1, slice_episodes) if gpu and slice_episodes is not None else max(1, E)
    for a in range(0, E, step):
        sl = slice(a, min(E, a + step))
        p = P[sl]
        yield sl, _load_batch(cfg, protocols[sl], p[..., 0:3], p[..., 3], p[..., 4:6], p[..., 6], dev)


def press_stroke_physics(cfg: SceneConfig, protocols: list[EpisodeProtocol], threads: int = 1) -> np.ndarray:
    """The physics of E "press_stroke" episodes (same n_samples n): per sample and indenter its position, MuJoCo
    normal force, stick-slip shear and contact count, (E, n, C, PHYSICS_COLUMNS) float64 (columns as named there).
    C MuJoCo: one batched rollout, the stick-slip over every physics step on the host; MuJoCo Warp: the same model,
    controls and stick-slip as batched worlds (float32 physics, the stick-slip a step kernel)."""
    n = protocols[0].n_samples
    if any(p.n_samples != n for p in protocols) or n < 2:
        raise ValueError("run_press_stroke: all protocols need the same n_samples >= 2")
    C = cfg.indenter.count
    sub = cfg.sampling.substeps
    dt = cfg.sampling.physics_timestep_s
    nstep = (n - 1) * sub
    m = mujoco.MjModel.from_xml_string(_mjcf(cfg))
    E = len(protocols)
    # initial states: active indenters touching the pad at their start position, inactive ones parked above
    d = mujoco.MjData(m)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    states = np.zeros((E, mujoco.mj_stateSize(m, spec)))
    sens0 = np.zeros((E, m.nsensordata))
    for e, p in enumerate(protocols):
        mujoco.mj_resetData(m, d)
        for i, ind in enumerate(p.params["indenters"]):
            z0 = cfg.indenter.start_gap_m if ind["active"] else PARK_HEIGHT_M
            d.qpos[3 * i : 3 * i + 3] = (*press_stroke_xy(ind, np.zeros(1))[0], z0)
        d.ctrl[:] = _controls(cfg, [p], np.zeros(1))[0, 0]
        mujoco.mj_forward(m, d)
        mujoco.mj_getState(m, d, states[e], spec)
        sens0[e] = d.sensordata
    k_t, mu = shear_stiffness_n_per_m(cfg), cfg.indenter.friction
    per = SENSORS_PER_INDENTER
    from simulate.contact.load_field import physics_engine

    out = np.zeros((E, n, C, PHYSICS_COLUMNS))
    engine, device = physics_engine(cfg)
    if engine == "mujoco_warp":  # the same model, controls and stick-slip, as batched worlds (float32 physics)
        from simulate.contact.mujoco_warp import worlds_for

        rec = worlds_for(m, _mjcf(cfg), E, device, (per, C, k_t, mu)).run(
            states[:, 1 : 1 + m.nq], lambda sl, eps: controls_batch(cfg, protocols[eps], (np.arange(sl.start, sl.stop) + 1.0) * dt),
            np.concatenate([sens0, np.zeros((E, 2 * C))], axis=1), sub, n)
        sd = rec[..., : m.nsensordata].reshape(E, n, C, per)
        out[..., 0:3], out[..., 3] = sd[..., 0:3], np.clip(-sd[..., 6], 0.0, None)
        out[..., 4:6], out[..., 6] = rec[..., m.nsensordata :].reshape(E, n, C, 2), sd[..., 3]
        return out
    ctrl = _controls(cfg, protocols, (np.arange(nstep) + 1.0) * dt)
    rows = np.arange(1, n) * sub - 1
    datas = [mujoco.MjData(m) for _ in range(max(1, threads))]
    chunk = max(1, MAX_STEPS_PER_CHUNK // nstep)
    for a in range(0, E, chunk):
        b = min(E, a + chunk)
        _, sd = mujoco.rollout.rollout(m, datas if threads > 1 else datas[0], states[a:b], ctrl[a:b], nstep=nstep)
        sd = np.concatenate([sens0[a:b, None], sd], axis=1).reshape(b - a, nstep + 1, C, per)
        normal = np.clip(-sd[..., 6], 0.0, None)  # netforce on the pad, z: compressive normal = -F_z
        shear = stick_slip_path(sd[..., 0:2], normal, k_t, mu)  # the Warp kernel of `stick_slip`
        r = np.concatenate([[0], rows + 1])
        sdr = sd[:, r]
        out[a:b, ..., 0:3], out[a:b, ..., 3], out[a:b, ..., 4:6], out[a:b, ..., 6] = sdr[..., 0:3], normal[:, r], shear[:, r], sdr[..., 3]
    return out


def _mjcf(cfg: SceneConfig) -> str:
    from simulate.contact.mjcf import build_mjcf

    return build_mjcf(cfg)


def _load_batch(cfg, protocols, pos, fn, ft, found, device_fields: str | None = None) -> LoadBatch:
    """The LoadBatch of indenter positions pos (E, T, C, 3), normal forces fn (E, T, C), shear ft (E, T, C, 2) and
    contact flags found (E, T, C). device_fields: the taxel fields by `press_fields_warp` on that device, left
    there (box indenters; else the numpy field below, its reference)."""
    pad, ind = cfg.pad, cfg.indenter
    E, T, C, _ = pos.shape
    nx, ny = pad.taxels_x, pad.taxels_y
    area = taxel_area_m2(cfg)
    if device_fields is not None and ind.shape == "box":
        from simulate.contact.load_field_kernels import press_fields_warp

        deform, pressure, shear, w = press_fields_warp(cfg, pos, fn, ft, device_fields)
        return _with_totals(cfg, protocols, pos, fn, ft, found, w, deform, pressure, shear)
    pen = np.clip(-pos[..., 2], 0.0, None)  # (E, T, C)
    if ind.shape == "box":
        cx = interval_coverage(pos[..., 0], ind.size_x_m / 2, pad.size_x_m, nx)  # (E, T, C, nx)
        cy = interval_coverage(pos[..., 1], ind.size_y_m / 2, pad.size_y_m, ny)
        cover = cy[..., :, None] * cx[..., None, :]  # (E, T, C, ny, nx)
    else:  # cells under the sphere's contact disc at its simulated depth
        q = pos.reshape(-1, 3).copy()
        cover = sphere_overlap(cfg, q, ind.radius_m).reshape(E, T, C, ny, nx)
        cover = (cover > 0).astype(float)
    cover = cover.reshape(E, T, C, nx * ny)
    deform = (pen[..., None] * cover).sum(2)
    w = cover.sum(-1)
    share = np.where(w[..., None] > 0, cover / (area * np.where(w > 0, w, 1.0))[..., None], 0.0)  # (E,T,C,N) 1/m2
    pressure = (share * fn[..., None]).sum(2)
    shear = (share[..., None] * ft[..., None, :]).sum(2)
    return _with_totals(cfg, protocols, pos, fn, ft, found, w, deform, pressure, shear)


def _with_totals(cfg, protocols, pos, fn, ft, found, w, deform, pressure, shear) -> LoadBatch:
    """The LoadBatch of the fields and the per-frame totals (w: (E, T, C) each indenter's footprint in cells)."""
    pad = cfg.pad
    T = pos.shape[1]
    # loads that found no cell (footprint off the pad) are dropped from the field and the totals alike
    on = (w > 0).astype(float)
    force = np.concatenate([(ft * on[..., None]).sum(2), (fn * on).sum(2)[..., None]], axis=-1)
    rate = cfg.sampling.sample_rate_hz
    t = np.arange(T) / rate
    target = np.stack([press_stroke_force(p.params["indenters"][0], t) for p in protocols])
    return LoadBatch(
        time_s=t,
        target=target,
        indenter_pos_m=pos[:, :, 0] + np.array([0.0, 0.0, pad.thickness_m]),
        contact_force_n=force,
        contact_points=(found > 0).sum(-1).astype(np.int64),
        deformation_m=deform,
        pressure_pa=pressure,
        shear_pa=shear,
        taxel_xy_m=taxel_xy_m(cfg),
        taxel_area_m2=taxel_area_m2(cfg),
        control=cfg.protocol.control,
    )
