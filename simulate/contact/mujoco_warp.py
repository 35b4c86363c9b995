"""The contact stage on MuJoCo Warp: all episodes as batched worlds on one device (GPU, or Warp's CPU).

Same model, controls and outputs as the C MuJoCo `rollout` path of `simulate.contact.load_field.simulate_sensors`,
which calls `WarpWorlds.run` when generation.physics picks MuJoCo Warp: the sensordata columns the load field reads
(E, T, len(read_columns)) after every `substeps`-th step, so everything downstream (load field, sensor chain, recording) is shared.
Source of the engine: MuJoCo Warp 4.0 (`mujoco_warp`).

On CUDA one sample period (substeps x [set ctrl, step] + record sensors) is captured once as a CUDA graph
and replayed; per-step controls come from a device buffer indexed by a device-side step counter, so no
Python runs per physics step. Sensors are computed only in the step that is recorded (the other substeps
step a copy of the model with mjDSBL_SENSOR: sensors do not act on the dynamics, so the recorded values are
the same). `worlds_for` keeps one set of worlds per process, with its buffers and graphs, for the next batch.
Controls are uploaded and sensors read back in time chunks that bound device memory, two in flight: the device
steps one while the host takes the other's sensors (`WarpWorlds.run`). MuJoCo Warp computes in float32 (C MuJoCo
in float64) and its contact solver sums with atomics on the GPU, so results agree with the C path within float32
tolerances, not bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from simulate.contact.stick_slip_kernels import stick_slip_update


CHUNK_BYTES = 256 * 2**20  # device memory for one chunk of controls + recorded sensors (per set of buffers)
PIPELINE_SETS = 2  # chunks in flight (`WarpWorlds.run`): the device steps one while the host takes the other
CONTROL_THREADS = 4  # host threads making a chunk's controls (32k episodes: ~6 s of numpy per batch)


@wp.kernel
def _set_ctrl(seq: wp.array3d(dtype=wp.float32), counter: wp.array(dtype=wp.int32), ctrl: wp.array2d(dtype=wp.float32)):
    w, j = wp.tid()
    ctrl[w, j] = seq[w, counter[0], j]


@wp.kernel
def _record(sensordata: wp.array2d(dtype=wp.float32), counter: wp.array(dtype=wp.int32), out: wp.array3d(dtype=wp.float32)):
    w, j = wp.tid()
    out[w, counter[1], j] = sensordata[w, j]


@wp.kernel
def _record_columns(sensordata: wp.array2d(dtype=wp.float32), columns: wp.array(dtype=wp.int32),
                    counter: wp.array(dtype=wp.int32), out: wp.array3d(dtype=wp.float32)):
    w, j = wp.tid()
    out[w, counter[1], j] = sensordata[w, columns[j]]


@wp.kernel
def _advance(counter: wp.array(dtype=wp.int32), which: int):
    counter[which] = counter[which] + 1


def available() -> bool:
    """True when mujoco_warp is installed (an optional dependency: extra `gpu`): found on the path, not imported.
    Its import defines hundreds of Warp kernels (2.5-4 s of CPU, H100 host, bench/results/user-cli-h100-s12-*): it
    belongs to the processes that step worlds, not to the engine choice that the CLI makes before its first shard."""
    import importlib.util

    try:
        return importlib.util.find_spec("mujoco_warp") is not None
    except (ImportError, ValueError):
        return False


class WarpWorlds:
    """E batched MuJoCo Warp worlds of one scene on one device; run() replays the episodes' controls.

    Shapes: ctrl (E, nstep, nu) float; returns sensordata (E, n_samples, ns) float64, ns = nsensordata, or with
    `columns` (indices into the sensordata) only those, in that order: the values nothing downstream reads are
    then neither copied off the device nor stored.
    """

    def __init__(self, m, n_worlds: int, device: str, sensors_every_step: bool = False, box_primitive: bool = True,
                 columns: tuple[int, ...] | None = None):
        import copy

        import mujoco
        import mujoco_warp as mjw

        self.mjm, self.E, self.device = m, n_worlds, device
        self.mjd = mujoco.MjData(m)
        m = copy.copy(m)
        # box_primitive: box-box pairs through MuJoCo Warp's box-box primitive (a port of C MuJoCo's mjc_BoxBox,
        # which the C path runs): its default for box-box is the general convex collider (GJK/EPA), which reports
        # no contact for penetrations below ~1e-5 m (measured on Warp's CPU device, 10 mm boxes), where the
        # force-controlled presses of fabric_1, velostat and ntype sit (1-20 um); C MuJoCo's box-box ignores this
        # flag. The displacement-controlled cnt_pdms presses go mm deep and keep the convex collider, which steps
        # them faster: the compact 6 x 6 mixed-frequency bench on the H100 spent 114 s in MuJoCo Warp's worlds with
        # it (gpu-pipeline-h100-s7-mix-final.json) and 196 s with the primitive (gpu-pipeline-h100-s8-mix.json)
        if box_primitive:
            m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_NATIVECCD)
        quiet = copy.copy(m)  # the substeps between two records: same model, sensors off
        quiet.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
        self._buffers: tuple | None = None  # (chunk, substeps, [_ChunkSet]) of earlier runs, reused by the next
        self._loaded = False
        with wp.ScopedDevice(device):
            self.m = mjw.put_model(m)
            self.m_quiet = self.m if sensors_every_step else mjw.put_model(quiet)
            # per indenter-pad pair (m.npair: one per indenter) a box-box contact has at most 8 points, 3 rows each
            # (elliptic, condim 3), plus slack for the actuated joints' rows; njmax binds each world
            pairs = max(1, m.npair)
            self.d = mjw.put_data(m, self.mjd, nworld=n_worlds, nconmax=8 * pairs, njmax=8 * 3 * pairs + 2 * m.nu)
            self.counter = wp.zeros(2, dtype=wp.int32)
            self.columns = None if columns is None else wp.array(np.asarray(columns, np.int32), dtype=wp.int32)
        self.n_recorded = m.nsensordata if columns is None else len(columns)  # recorded sensor values per world

    n_extra = 0  # recorded values per world after the sensordata (subclasses: state of their own per-step kernels)

    def _reset_extra(self, qpos0: np.ndarray, sens0: np.ndarray) -> None:
        """Reset the state of a subclass's per-step kernels at the start of a run (nothing here)."""

    def _step_sample(self, seq: wp.array3d, out: wp.array3d, substeps: int) -> None:
        import mujoco_warp as mjw

        E, nu, ns = self.E, self.mjm.nu, self.n_recorded
        for i in range(substeps):
            wp.launch(_set_ctrl, dim=(E, nu), inputs=[seq, self.counter, self.d.ctrl])
            mjw.step(self.m if i == substeps - 1 else self.m_quiet, self.d)
            self._after_step()
            wp.launch(_advance, dim=1, inputs=[self.counter, 0])
        if self.columns is None:
            wp.launch(_record, dim=(E, ns), inputs=[self.d.sensordata, self.counter, out])
        else:
            wp.launch(_record_columns, dim=(E, ns), inputs=[self.d.sensordata, self.columns, self.counter, out])
        self._record_extra(out)
        wp.launch(_advance, dim=1, inputs=[self.counter, 1])

    def _after_step(self) -> None:
        """Launches after every physics step, inside the captured sample (subclasses: their per-step kernels)."""

    def _record_extra(self, out: wp.array3d) -> None:
        """Store the subclass's n_extra values of this sample after the sensordata in `out` (nothing here)."""

    def run(self, qpos0: np.ndarray, ctrl, sens0: np.ndarray, substeps: int, n_samples: int,
            out: np.ndarray | None = None) -> np.ndarray:
        """Reset the worlds to qpos0 (E, nq) at rest and replay the controls; sensors at samples 1..n-1 after
        each substeps-th step (sample 0 = sens0, computed by the caller with mj_forward).

        ctrl: (E, nstep, nu) array, or a function (steps, episodes) of two slices returning those rows; a chunk's
        controls are made on CONTROL_THREADS host threads (blocks of episodes; numpy releases the GIL). out: a
        (E, n_samples, n_recorded + n_extra) float64 array to fill (default a new one); sens0 has as many columns.

        The samples go in time chunks (CHUNK_BYTES of controls + sensors each), through PIPELINE_SETS sets of
        buffers: on CUDA every transfer is asynchronous (page-locked host buffers), and this thread only queues
        work (uploads, graph launches, copies back) while a helper thread takes chunk i's sensors into `out` and
        makes chunk i + PIPELINE_SETS's controls once chunk i has landed, so the device does not wait for the
        host between chunks (session 18's code, one chunk at a time: 15.6-16.7 s of worlds for velostat's 8192
        episodes on an H200; its controls made in this thread between launches: 20.0-22.9 s). On Warp's CPU
        device the same sets are used one after another (the controls are made straight into its buffers).
        """
        import mujoco_warp as mjw
        from concurrent.futures import ThreadPoolExecutor

        E, nu, ns = self.E, self.mjm.nu, self.n_recorded + self.n_extra
        ctrl_rows = ctrl if callable(ctrl) else (lambda sl, eps: ctrl[eps, sl])
        out = np.zeros((E, n_samples, ns)) if out is None else out
        out[:, 0] = sens0
        if E == 0 or n_samples < 2:
            return out
        per_sample = E * (substeps * nu + ns) * 4
        chunk = int(max(1, min(n_samples - 1, CHUNK_BYTES // per_sample)))
        starts = list(range(1, n_samples, chunk))
        n_sets = min(len(starts), PIPELINE_SETS)
        blocks = [slice(b, min(E, b + -(-E // CONTROL_THREADS))) for b in range(0, E, -(-E // CONTROL_THREADS))]
        dev = wp.get_device(self.device)
        cuda = dev.is_cuda
        stream = dev.stream if cuda else None

        with wp.ScopedDevice(self.device), ThreadPoolExecutor(1, thread_name_prefix="chunk") as pool, \
                ThreadPoolExecutor(CONTROL_THREADS, thread_name_prefix="controls") as workers:
            # the sets of an earlier run are reused where they hold this run's chunks (a graph indexes its buffers
            # by the device-side counter, not by their length): a batch's length groups then allocate and capture once
            b = self._buffers
            if b is None or b[1] != substeps or b[0] < chunk or len(b[2]) < n_sets:
                self._buffers = None  # free the old ones first
                self._buffers = (chunk, substeps, [self._chunk_set(chunk, substeps, cuda) for _ in range(n_sets)])
            sets = self._buffers[2][:n_sets]

            def fill(i: int) -> None:  # chunk i's controls (samples a .. a + k - 1) into its host buffer (the rows
                # after them, a short last chunk's or a larger reused buffer's, are left as they are: the step counter
                # never reaches them)
                a = starts[i]
                k = min(chunk, n_samples - a)
                host = sets[i % n_sets].ctrl_np
                steps = slice((a - 1) * substeps, (a - 1 + k) * substeps)

                def part(eps: slice) -> None:
                    host[eps, : k * substeps] = ctrl_rows(steps, eps)

                list(workers.map(part, blocks))

            def enqueue(i: int) -> None:  # chunk i on the device: controls up, k sample periods, sensors down
                s, k = sets[i % n_sets], min(chunk, n_samples - starts[i])
                if cuda:
                    wp.copy(s.seq, s.ctrl_host)
                self.counter.zero_()
                for _ in range(k):
                    if cuda:
                        wp.capture_launch(s.graph)
                    else:
                        self._step_sample(s.seq, s.rec, substeps)
                if cuda:
                    wp.copy(s.rec_host, s.rec)
                    stream.record_event(s.event)

            def take(i: int) -> None:  # chunk i's sensors into `out` (on CUDA once its copy has landed)
                s, a = sets[i % n_sets], starts[i]
                k = min(chunk, n_samples - a)
                if cuda:
                    wp.synchronize_event(s.event)
                out[:, a : a + k] = s.rec_np[:, :k]

            # the host threads keep the device fed: the launching thread (this one) queues chunk i while the helper
            # takes chunk i - n_sets's sensors and makes chunk i's controls (a CUDA launch queue holds a few sample
            # periods only, so work done between launches in this thread would let the device drain it and idle)
            ready = [pool.submit(fill, j) for j in range(n_sets)]  # ready[i] done: chunk i's controls are in place

            def take_then_fill(i: int) -> None:
                take(i)
                if i + n_sets < len(starts):
                    fill(i + n_sets)

            try:
                if cuda:
                    if not self._loaded:  # load (compile) every kernel before a graph capture (2 substeps: both
                        # models; a buffer of one step's controls holds only one)
                        self.counter.zero_()
                        self._step_sample(sets[0].seq, sets[0].rec, min(2, sets[0].seq.shape[1]))
                        self._loaded = True
                    for s in sets:
                        if s.graph is None:  # captured once (recorded, not run): its buffers are refilled in place
                            with wp.ScopedCapture(device=self.device) as cap:
                                self._step_sample(s.seq, s.rec, substeps)
                            s.graph = cap.graph
                mjw.reset_data(self.m, self.d)
                self.d.qpos.assign(np.ascontiguousarray(qpos0, np.float32))
                self._reset_extra(qpos0, sens0)
                for i in range(len(starts)):
                    ready[i].result()
                    enqueue(i)
                    ready.append(pool.submit(take_then_fill, i))
                for f in ready:
                    f.result()
            except BaseException:
                pool.shutdown(wait=False, cancel_futures=True)  # no more controls made for a run that failed
                raise
        return out

    def _chunk_set(self, chunk: int, substeps: int, cuda: bool) -> "_ChunkSet":
        """One set of chunk buffers: controls (E, chunk * substeps, nu) and recorded sensors (E, chunk, ns) on the
        device, and on CUDA their page-locked host twins (a fresh pageable array faults page by page, and only a
        page-locked one copies asynchronously) and the event that marks the set's sensors as landed."""
        E, nu, ns = self.E, self.mjm.nu, self.n_recorded + self.n_extra
        seq = wp.zeros((E, chunk * substeps, nu), dtype=wp.float32)
        rec = wp.zeros((E, chunk, ns), dtype=wp.float32)
        if not cuda:
            return _ChunkSet(seq, rec, seq, rec, seq.numpy(), rec.numpy())
        ctrl_host = wp.empty(seq.shape, dtype=wp.float32, device="cpu", pinned=True)
        rec_host = wp.empty(rec.shape, dtype=wp.float32, device="cpu", pinned=True)
        return _ChunkSet(seq, rec, ctrl_host, rec_host, ctrl_host.numpy(), rec_host.numpy(), event=wp.Event())


@dataclass
class _ChunkSet:
    """Buffers of one time chunk (`WarpWorlds.run`): shapes (E, chunk * substeps, nu) for the controls and
    (E, chunk, n_recorded + n_extra) for the sensors, float32; on Warp's CPU device the host buffers are the
    device ones; ctrl_np / rec_np: numpy views of the host buffers, made once here (the helper thread then touches
    no Warp call while this thread captures a graph). graph: the chunk's sample period captured on these buffers
    (CUDA)."""

    seq: wp.array
    rec: wp.array
    ctrl_host: wp.array
    rec_host: wp.array
    ctrl_np: np.ndarray
    rec_np: np.ndarray
    graph: object = None
    event: object = None


@wp.kernel
def _stick_slip_step(sensordata: wp.array2d(dtype=wp.float32), per: int, k_t: wp.float64, mu: wp.float64,
                     anchor: wp.array2d(dtype=wp.float64), force: wp.array2d(dtype=wp.float32)):
    """One physics step of `simulate.contact.press_stroke.stick_slip` for world w, indenter c (float64 state)."""
    w, c = wp.tid()
    cap = mu * wp.max(wp.float64(-sensordata[w, c * per + 6]), wp.float64(0.0))  # netforce z on the pad: -normal
    r = stick_slip_update(wp.float64(sensordata[w, c * per + 0]), wp.float64(sensordata[w, c * per + 1]), cap,
                          anchor[w, 2 * c + 0], anchor[w, 2 * c + 1], k_t)
    anchor[w, 2 * c + 0] = r[2]
    anchor[w, 2 * c + 1] = r[3]
    force[w, 2 * c + 0] = wp.float32(r[0])
    force[w, 2 * c + 1] = wp.float32(r[1])


@wp.kernel
def _record_shear(extra: wp.array2d(dtype=wp.float32), counter: wp.array(dtype=wp.int32), offset: int,
                  out: wp.array3d(dtype=wp.float32)):
    w, j = wp.tid()
    out[w, counter[1], offset + j] = extra[w, j]


class StickSlipWorlds(WarpWorlds):
    """Worlds of the "press_stroke" scene (simulate.contact.press_stroke): sensors at every step, and after each step
    the Coulomb stick-slip shear of every indenter (`_stick_slip_step`, the numpy `stick_slip` per step, state in
    float64) on the device; each recorded sample is the sensordata followed by the shear (x, y) per indenter."""

    def __init__(self, m, n_worlds: int, device: str, per_indenter: int, count: int, k_t: float, mu: float):
        super().__init__(m, n_worlds, device, sensors_every_step=True)
        self.per, self.count, self.k_t, self.mu = per_indenter, count, float(k_t), float(mu)
        self.n_extra = 2 * count
        with wp.ScopedDevice(device):
            self.anchor = wp.zeros((n_worlds, 2 * count), dtype=wp.float64)
            self.force = wp.zeros((n_worlds, 2 * count), dtype=wp.float32)

    def _reset_extra(self, qpos0: np.ndarray, sens0: np.ndarray) -> None:
        xy = np.stack([sens0[:, c * self.per : c * self.per + 2] for c in range(self.count)], axis=1)  # (E, C, 2)
        self.anchor.assign(np.ascontiguousarray(xy.reshape(self.E, -1), np.float64))
        self.force.zero_()

    def _after_step(self) -> None:
        wp.launch(_stick_slip_step, dim=(self.E, self.count),
                  inputs=[self.d.sensordata, self.per, wp.float64(self.k_t), wp.float64(self.mu), self.anchor, self.force])

    def _record_extra(self, out: wp.array3d) -> None:
        wp.launch(_record_shear, dim=(self.E, self.n_extra), inputs=[self.force, self.counter, self.mjm.nsensordata, out])


_CACHED: dict = {}  # (MJCF, n_worlds, device, stick_slip, box_primitive) -> WarpWorlds: one set per process


def release_worlds() -> None:
    """Drop the process's cached worlds (`worlds_for`): their device arrays, CUDA graph and page-locked sensor buffer
    are freed now, for a caller done stepping that still has other work to wait for (the GPU feed's driver while its
    writers finish), instead of at the process's exit."""
    _CACHED.clear()


def box_primitive_for(control: str) -> bool:
    """Whether a protocol's presses need MuJoCo Warp's box-box primitive (see WarpWorlds): force control holds
    contacts of a few micrometres; displacement control presses millimetres deep."""
    return control != "displacement"


def worlds_for(m, mjcf: str, n_worlds: int, device: str, stick_slip: tuple | None = None,
               box_primitive: bool = True, columns: tuple[int, ...] | None = None) -> WarpWorlds:
    """The process's worlds for this scene and batch size, made once (put_model, put_data for n_worlds, the
    CUDA graph) and reused by the next batch of the same shape (the GPU feed's physics processes step one
    batch after another); a different scene or size replaces them. stick_slip: (per_indenter, count, k_t, mu)
    for `StickSlipWorlds`. box_primitive: see WarpWorlds (False for displacement control: `box_primitive_for`).
    columns: the sensordata values to record (WarpWorlds; None: all)."""
    key = (mjcf, n_worlds, device, stick_slip, box_primitive, columns)
    if key not in _CACHED:
        _CACHED.clear()  # free the old worlds' device memory before allocating new ones
        _CACHED[key] = (WarpWorlds(m, n_worlds, device, box_primitive=box_primitive, columns=columns)
                        if stick_slip is None else StickSlipWorlds(m, n_worlds, device, *stick_slip))
    return _CACHED[key]
