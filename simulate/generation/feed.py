"""GPU feed: big batches of worlds on one GPU, a pool of writer processes for the shards.

Why (bench/README.md): MuJoCo Warp runs near its peak only with 16k-32k worlds per batch, and HDF5 at that rate
needs several host cores; worker processes that each simulate their own shard time-slice the GPU with smaller
batches. Here a three-stage pipeline runs over batches of several shards' episodes (FEED_WORLDS):

1. PHYSICS_PROCESSES processes step the next batches (`step_worlds`: protocols, controls, MuJoCo Warp) and write
   the sensordata straight into shared memory; the first batch's protocols are made by the driver while they
   import. One's host work (protocols) overlaps the other's physics, but their GPU stepping takes turns in batch
   order (GPU_TURNS): two batches stepped at once time-slice the GPU, so both came back at the end of twice one
   batch's stepping and the driver idled through it (velostat 16384 on an H200: 31 s per batch side by side
   against 16 s alone); in turns the first comes back after one batch's stepping and is run and written while
   the next steps;
2. the driver runs the load field and the sensor chain of batch b on the same GPU, slice by slice; each slice's
   outputs come back into reused page-locked buffers and are packed (before the next slice runs; PACK_OVERLAP:
   while it runs) into shared blocks that a `BlockPool`
   lends until their shard is written (`iter_produce`); each length group goes in SLICES_PER_LENGTH slices and
   a shard goes to the writers as soon as its episodes are packed, and the first batches are smaller
   (RAMP_BATCHES), so the writers start early (a modest run is one batch); while the driver waits for the first
   batch, the blocks its pack will fill are populated ahead (`BlockPool.populate_ahead`, sized by
   `batch_pack_bytes`), and go on being populated beside that batch's pack (POPULATE_THROUGH). Kinds with their
   own contact stage go in full batches from the first (no ramp: their batches are latency-bound); press_stroke's
   worlds step in the physics processes like the others' (`press_stroke_physics`, handed over as its own array), a
   stage without worlds (element_loads) runs here in the driver (`stage_in_driver`);
3. writer processes (spawned; one shard per task, at most PENDING_PER_WRITER queued each) write the shards and
   make their manifest entries.

Where the run mixes episode lengths (cnt_pdms at 0.1-2 Hz), the batches go by length instead (`_schedule`): every
shard's short episodes first, then the long ones in windows of shards; a shard is handed on when its last episode is
packed (`Producer` keeps its pieces across batches).

The files are those of `simulate.generation.run.write_shard`: an episode's channels do not depend on the batch it ran in.
A writer that dies is replaced and its shard resubmitted (up to max_retries); finished shards stay, so a
rerun resumes at the missing ones. Where /dev/shm has no room, the arrays travel pickled instead.
"""

from __future__ import annotations

import mmap
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scenes import SceneConfig
from simulate.contact.field_blocks import BlockSparse

FEED_WORLDS = 32768  # episodes per batch of worlds: 2.4e7 world-steps/s on an H100 (bench/results/physics-profile-h100-s4.json)
PENDING_PER_WRITER = 2  # shards handed to the writers and not yet written, per writer: one being written, one
# queued, so no writer idles while the driver packs the next batch (~1.4 GB per shard of 8192 bench episodes) ...
PENDING_RAM_FRACTION = 0.25  # ... and no more bytes pending than this fraction of the host's memory
RAMP_BATCHES = int(os.environ.get("PIEZOTWIN_RAMP_BATCHES", "2"))  # batches of worlds / 4 and worlds / 2 episodes before
# the full ones (see _groups); the variable: the bench's A/B (0: full batches from the first)
CONTACT_RAMP_BATCHES = int(os.environ.get("PIEZOTWIN_CONTACT_RAMP_BATCHES", "0"))  # the same for a kind with its own
# contact stage (ntype's press_stroke; see generate_feed); the variable: the bench's A/B
PHYSICS_PROCESSES = 2  # each steps its own batch: one's host work (its protocols) overlaps the other's GPU stepping
GPU_TURNS = os.environ.get("PIEZOTWIN_GPU_TURNS", "1") == "1"  # their GPU stepping in turns, in batch order (see
# `_gpu_turn`); the variable: the bench's A/B (0: side by side, as before session 22)
# where the driver's time went in the last generate_feed of this process (for bench/): "protocols (first batch, in
# the driver)" (made while the physics processes import), "start-up" (Warp, the
# sensor), "simulate" (load field, sensor chain, channel arrays; protocols and physics too for kinds with their
# own contact stage), "pack", "wait for physics", "wait for writers", "release staging" (the page-locked buffers,
# and the worlds a driver stepped itself, freed while the writers finish), "shut down" (the process pools); and,
# summed over the writer processes, "writers: episodes" (HDF5), "writers: close, fsync", "writers: sha256"; and
# summed over the physics tasks, "physics: ..." (see step_worlds; the first batch's apart)
LAST_RUN_SECONDS: dict[str, float] = {}
# the batches of that run in the order stepped: shards (first, last), episodes, their select ("all", "short <= n
# samples", "long > n samples") and the longest episode's samples (for bench/)
LAST_RUN_BATCHES: list[dict] = []


@dataclass(frozen=True)
class Select:
    """Which episodes of a feed batch its physics task steps: those longer than `cutoff` samples (long=True) or
    the others (see `_schedule`)."""

    long: bool
    cutoff: int

    def keeps(self, n_samples: int) -> bool:
        return (n_samples > self.cutoff) == self.long


def _shm_room(nbytes: int) -> bool:
    """Whether /dev/shm can take a block of nbytes (a full tmpfs would kill the writer with SIGBUS)."""
    import shutil

    try:
        return shutil.disk_usage("/dev/shm").free >= 2 * nbytes
    except OSError:
        return False


def _attach(name: str):
    """Attach a block another process of this run made. The feed's processes are spawned by the driver and share
    its resource tracker, which keeps a set of names: the creator registered the block, attaching (which registers
    it again before Python 3.13) adds nothing, and the one unlink unregisters it; were a process to unregister
    on attaching, the unlink would find the name gone (a KeyError traceback from the tracker)."""
    from multiprocessing import shared_memory

    return shared_memory.SharedMemory(name=name)


def _views(buf, where: list[tuple[int, str, tuple[int, ...]]]) -> list[np.ndarray]:
    return [np.ndarray(shape, np.dtype(dt), buffer=buf, offset=off) for off, dt, shape in where]


def _discard_stepped(stepped: tuple | None) -> None:
    """Unlink the shared blocks of a `step_worlds` result that no `Producer.batch` took (a run failing before it
    got there; a block already unlinked is skipped): else they would hold /dev/shm until the resource tracker
    reaps them at exit, with a warning."""
    for handed in (stepped[1].values() if stepped else ()):
        if not isinstance(handed[0], str):
            continue
        try:
            shm = _attach(handed[0])
        except FileNotFoundError:
            continue
        shm.close()
        shm.unlink()


TURN_ABORT = -1  # the turn file's value once the feed stops: a physics task still waiting for its turn raises


def new_turns() -> str:
    """A file holding the batch whose GPU stepping is due (int64, starting at batch 0), in /dev/shm where there is
    one; the feed passes its path to the physics tasks (`_gpu_turn`) and removes it when they are done."""
    import tempfile

    fd, path = tempfile.mkstemp(prefix="piezotwin-turn-", dir="/dev/shm" if os.path.isdir("/dev/shm") else None)
    os.pwrite(fd, np.int64(0).tobytes(), 0)
    os.close(fd)
    return path


def _turn_update(path: str, update: Callable[[int], int | None]) -> int:
    """Read the turn file under an exclusive lock and write update(value) where that is not None; the value read."""
    import fcntl

    fd = os.open(path, os.O_RDWR)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        now = int(np.frombuffer(os.pread(fd, 8, 0), np.int64)[0])
        new = update(now)
        if new is not None:
            os.pwrite(fd, np.int64(new).tobytes(), 0)
        return now
    finally:
        os.close(fd)  # (releases the lock)


def stop_turns(path: str) -> None:
    """The feed stops: every task waiting for its turn raises instead of stepping (a task stepping finishes)."""
    _turn_update(path, lambda now: TURN_ABORT)


class _gpu_turn:
    """`with _gpu_turn(path, b):` waits until batch b's GPU stepping is due (the batches before it have stepped),
    then hands the turn to batch b + 1 on the way out, failed or not (unless the feed stopped meanwhile)."""

    POLL_S = 0.002

    def __init__(self, path: str, b: int):
        self.path, self.b = path, b

    def __enter__(self):
        import time

        while True:
            now = _turn_update(self.path, lambda now: None)
            if now == self.b:
                return self
            if now == TURN_ABORT:
                raise RuntimeError(f"the feed stopped before batch {self.b}'s turn on the GPU")
            time.sleep(self.POLL_S)

    def __exit__(self, *exc):
        _turn_update(self.path, lambda now: self.b + 1 if now == self.b else None)
        return False


def step_worlds(cfg: SceneConfig, gids: list[int], threads: int = 1, submitted: float | None = None,
                select: Select | None = None, protos: list | None = None,
                turn: tuple[str, int] | None = None) -> tuple[list, dict, dict]:
    """Physics task (in the feed's physics process): the protocols of episodes `gids` (made here unless `protos`
    brings them, made by the driver; with `select`, only those it keeps, in the order of gids; each protocol's
    `index` is its episode's id) and, per length group,
    their (sensordata, target) from `simulate_sensors`, written straight into a shared-memory block the
    receiver unlinks: ({n_samples: (block name, layout)} or the arrays themselves where /dev/shm has no room);
    and where the task's time went ("waiting to start" since `submitted`, a time.time(), "imports", "protocols",
    "waiting for the GPU turn", "worlds": initial states, controls, MuJoCo Warp). turn: (turn file, this batch's
    index): the worlds step in the batch's turn (`_gpu_turn`), after the batches before it."""
    import time

    t0 = time.time()
    import simulate.contact.load_field  # noqa: F401 - the physics' imports, timed here ("imports")
    from sensors.data.manifest import episode_seed
    from simulate.generation.run import episode_protocols

    t1 = time.time()
    if protos is None:
        protos = episode_protocols(cfg, [episode_seed(cfg.generation.root_seed, k) for k in gids], gids)
    if select is not None:
        protos = [p for p in protos if select.keeps(p.n_samples)]
    t2 = time.time()
    spent = {"waiting to start": t0 - (submitted or t0), "imports": t1 - t0, "protocols": t2 - t1}
    if turn is None:
        return protos, _step_groups(cfg, protos, threads), spent | {"worlds": time.time() - t2}
    with _gpu_turn(*turn):
        t3 = time.time()
        out = _step_groups(cfg, protos, threads)
    return protos, out, spent | {"waiting for the GPU turn": t3 - t2, "worlds": time.time() - t3}


def _step_groups(cfg: SceneConfig, protos: list, threads: int) -> dict:
    """`step_worlds`' physics: per length group of `protos`, (sensordata, target) into shared memory (see there)."""
    from multiprocessing import shared_memory

    from simulate.contact.load_field import SLICED_CONTACT_STAGES, simulate_sensors, simulate_sensors_padded
    from simulate.generation.run import physics_runs

    if cfg.protocol.kind in SLICED_CONTACT_STAGES:  # press_stroke: its own physics array per length (small: 7 values
        # per indenter and sample), handed over like the rest
        from simulate.contact.press_stroke import press_stroke_physics

        return {n: _to_shm(press_stroke_physics(cfg, [protos[i] for i in idx], threads), np.zeros((len(idx), n)))
                for run in physics_runs(cfg, protos) for n, idx in run}

    out = {}
    groups = []
    for run in physics_runs(cfg, protos):
        if len(run) == 1:
            groups.append((run[0][0], run[0][1], None))
            continue
        padded = simulate_sensors_padded(cfg, [protos[i] for _, idx in run for i in idx], threads)  # small: copied below
        groups += [(n, idx, padded.pop(n)) for n, idx in run]
    for n, idx, done in groups:
        made = []

        def alloc(shape: tuple[int, ...]) -> np.ndarray:  # sensordata (E, n, ns) float64, then target (E, n)
            nbytes = 8 * (int(np.prod(shape)) + shape[0] * shape[1])
            if not _shm_room(nbytes):
                return np.zeros(shape)
            made.append(shared_memory.SharedMemory(create=True, size=nbytes))
            return np.ndarray(shape, np.float64, buffer=made[0].buf)

        if done is not None:
            out[n] = _to_shm(*done)
            continue
        sens, target = simulate_sensors(cfg, [protos[i] for i in idx], threads, alloc)
        if not made:
            out[n] = (sens, target)
            continue
        layout = _put_target(made[0], sens, target)
        sens = None  # the view released before the block is closed
        made[0].close()
        out[n] = (made[0].name, layout)
    return out


def _put_target(shm, sens: np.ndarray, target: np.ndarray) -> list:
    """Write target (E, n) into `shm` after sens (E, n, ...) float64, which fills its start; returns the layout the
    receiver reads them by (it unlinks the block: the shared resource tracker has it registered until then)."""
    np.ndarray(target.shape, np.float64, buffer=shm.buf, offset=sens.nbytes)[...] = target
    return [(0, sens.dtype.str, sens.shape), (sens.nbytes, "<f8", target.shape)]


def _to_shm(sens: np.ndarray, target: np.ndarray) -> tuple:
    """sens and target (float64) copied into a new shared-memory block: (block name, layout), or themselves where
    /dev/shm has no room."""
    from multiprocessing import shared_memory

    nbytes = sens.nbytes + target.nbytes
    if not _shm_room(nbytes):
        return sens, target
    shm = shared_memory.SharedMemory(create=True, size=max(1, nbytes))
    into = np.ndarray(sens.shape, np.float64, buffer=shm.buf)
    into[...] = sens
    layout = _put_target(shm, into, target)
    into = None
    shm.close()
    return shm.name, layout


# ---------------------------------------------------------------- physics processes started ahead of the feed

_PRESTARTED = None  # the physics processes `prestart_physics` started, until `generate_feed` takes them


def _warm_physics() -> float:
    """In a physics process started ahead (`prestart_physics`): the imports `step_worlds` needs, mujoco_warp's
    among them (it defines hundreds of Warp kernels: ~2 s of CPU; in the plain CLI it was paid inside the first
    batch's "worlds", which MuJoCo Warp stepping alone does not pay); returns the seconds they took."""
    import time

    t0 = time.perf_counter()
    try:
        import mujoco_warp  # noqa: F401
    except ImportError:  # a CPU engine's feed (tests): nothing to load ahead
        pass
    import sensors.data.manifest  # noqa: F401
    import simulate.contact.load_field  # noqa: F401
    import simulate.contact.mujoco_warp  # noqa: F401
    import simulate.generation.run  # noqa: F401

    return time.perf_counter() - t0


def stage_in_driver(cfg: SceneConfig) -> bool:
    """Whether the feed's driver runs this scene's contact stage itself, physics included: a kind with its own
    contact stage and no sliced form taking physics made elsewhere (`SLICED_CONTACT_STAGES`: press_stroke's worlds step
    in the physics processes like the others')."""
    from simulate.contact.load_field import CONTACT_STAGES, SLICED_CONTACT_STAGES

    if cfg.protocol.kind in CONTACT_STAGES and STAGES_IN_DRIVER:
        return True
    return cfg.protocol.kind in CONTACT_STAGES and cfg.protocol.kind not in SLICED_CONTACT_STAGES


STAGES_IN_DRIVER = os.environ.get("PIEZOTWIN_STAGES_IN_DRIVER", "0") == "1"  # every contact stage in the driver, its
# worlds too, as before session 25 (the bench's A/B)


def feed_likely(cfg: SceneConfig, physics: str, device: str, backend: str, executor: str,
                workers: int | None = None) -> bool:
    """Whether a `piezotwin generate` with these flags will likely run the GPU feed with its physics processes, judged
    without starting CUDA or importing mujoco_warp (the caller then starts them early): the local executor with more
    than one worker (None: chosen), Warp kernels, no CPU device or C MuJoCo asked for, a scene whose contact stage
    steps as worlds in those processes, mujoco_warp installed, and exactly one NVIDIA GPU in /proc/driver/nvidia/gpus."""
    from simulate.contact.mujoco_warp import available

    g = cfg.generation
    asked = g.physics if physics == "auto" and "physics" in g.model_fields_set else physics
    if executor != "local" or workers == 1 or backend != "warp" or device == "cpu" or asked == "mujoco":
        return False
    if stage_in_driver(cfg) or not available():
        return False
    try:
        return len(os.listdir("/proc/driver/nvidia/gpus")) == 1
    except OSError:
        return False


def prestart_physics() -> None:
    """Start the feed's PHYSICS_PROCESSES physics processes now, each importing what `step_worlds` needs
    (`_warm_physics`), for a caller with start-up of its own before `generate_feed` (the CLI: engine choice and Warp
    init, 2-3 s on a GPU machine), which their start-up then overlaps; `generate_feed` takes them. Where it does not
    run, `release_prestarted`."""
    global _PRESTARTED
    if _PRESTARTED is not None:
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    _PRESTARTED = ProcessPoolExecutor(PHYSICS_PROCESSES, mp_context=mp.get_context("spawn"))
    for _ in range(PHYSICS_PROCESSES):
        _PRESTARTED.submit(_warm_physics)


def _take_prestarted():
    global _PRESTARTED
    pool, _PRESTARTED = _PRESTARTED, None
    return pool


def release_prestarted() -> None:
    """Stop physics processes started ahead that no feed took (the run went another way, or failed first): their
    imports are cut short, not waited for."""
    pool = _take_prestarted()
    if pool is None:
        return
    import time

    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        p.terminate()
    deadline = time.monotonic() + 5.0  # the pool's own thread may reap them first: poll, not join
    for p in procs:
        while p.is_alive() and time.monotonic() < deadline:
            time.sleep(0.01)


SPARSE_INDEX = "\x00index"  # a BlockSparse channel's index array in a packed piece: its name + this (no channel name has it)
PACK_THREADS = 4  # threads copying a piece into its shared block (numpy copies release the GIL) ...
PACK_SPLIT_BYTES = 8 * 2**20  # ... where it has at least this many bytes; a smaller piece is copied in the driver's
# thread (a task per array and thread cost more than the copy: fabric_1's 8 KB-per-episode pieces, 53248 tasks and
# 5.2 s of "pack" for 8192 episodes under cProfile on the H200 host, bench/results/logs/profile-fabric_1-h200-s17.txt)
_PACKERS = None


def _pack_pool():
    global _PACKERS
    if _PACKERS is None:
        from concurrent.futures import ThreadPoolExecutor

        _PACKERS = ThreadPoolExecutor(PACK_THREADS, thread_name_prefix="pack")
    return _PACKERS


MADV_POPULATE_WRITE = 23  # Linux >= 5.14: fault a mapping's pages in writable in one call
ARENA_BYTES = 512 * 2**20  # blocks populated ahead are this size; pieces are carved from them one after another
ARENA_ALIGN = 64  # bytes: a carved piece starts on this boundary (every dtype's alignment)
POPULATE_MARGIN = 1.05  # populated ahead: the estimate (`batch_pack_bytes`) and this share more (alignment, lengths)
POPULATE_AHEAD = os.environ.get("PIEZOTWIN_POPULATE_AHEAD", "1") == "1"  # the GPU feed populates its first batch's
# blocks while that batch steps (`BlockPool.populate_ahead`); "0": off (the bench's A/B) ...
POPULATE_THROUGH = os.environ.get("PIEZOTWIN_POPULATE_THROUGH", "1") == "1"  # ... and goes on populating them (its
# thread; madvise releases the GIL) while the driver packs that batch, instead of stopping when the batch is back
# ("0", as before session 23: the bench's A/B): in turns the first batch comes back sooner, with fewer GB populated
# (cnt_pdms 8192 on an H200, session 23: 4.8-8.1 GB against 16.1 side by side; pack 16.3-16.5 s against 11.5 s).
# Alternated in one call (bench/h200_s23.sh C): pack 12.0 / 9.9 s through against 16.4 / 16.2 s stopping, wall
# 58.5 / 55.0 s against 58.2 / 59.8 s (the writers bound the wall)
RESERVE_STAGING = os.environ.get("PIEZOTWIN_RESERVE_STAGING", "1") == "1"  # ... and, on a GPU, page-locks the staging
# buffers its first slice copies back into (`probe_batch`'s plan; ~0.35 s per GB on the H200 host, 7.3 GB for velostat's
# 2048-episode slices); "0": off (the bench's A/B)


def _populate(shm) -> None:
    """Fault every page of a shared block in, writable: `madvise(MADV_POPULATE_WRITE)` through ctypes (the GIL is
    released meanwhile), else (an older kernel) one write per page."""
    import ctypes

    view = np.frombuffer(shm.buf, np.uint8)
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.madvise(ctypes.c_void_p(view.ctypes.data), ctypes.c_size_t(view.size), MADV_POPULATE_WRITE) == 0:
            return
    except (OSError, AttributeError):
        pass
    view[:: mmap.PAGESIZE] = 0
    view = None


class BlockPool:
    """The driver's shared-memory blocks, reused batch after batch: a fresh tmpfs page costs a page fault on first
    touch (copies into new blocks ran at ~1 GB/s, into reused ones at ~5 GB/s on a 2-core host; 3.1 against
    15 GB/s on the 16-core H200 host, bench/results/pack-copy-h200-s16.json). A block is lent to one packed piece
    until its shard is written, then returned; close() unlinks them all.

    `populate_ahead` fills ARENA_BYTES blocks (arenas) in a background thread while the driver has nothing else to
    do (it waits for its first batch of worlds); `get` then carves pieces from them one after another, and an arena
    is free again once every piece carved from it has come back."""

    def __init__(self) -> None:
        import threading
        from multiprocessing import shared_memory

        self._new = shared_memory.SharedMemory
        self.blocks: dict = {}  # name -> SharedMemory
        self.free: set[str] = set()
        self.arenas: dict[str, list[int]] = {}  # arena name -> [bytes carved, pieces lent], in the order populated
        self.draining = False
        self._lock = threading.Lock()  # arenas are added by the populating thread
        self._stop = threading.Event()
        self._filler = None

    def populate_ahead(self, nbytes: int) -> None:
        """Start populating arenas of ARENA_BYTES, up to nbytes in all, in a background thread (`stop_populating`
        ends it; the arenas populated by then are used first)."""
        import threading

        def fill() -> None:
            made = 0
            while made < nbytes and not self._stop.is_set():
                size = min(ARENA_BYTES, -(-(nbytes - made) // mmap.PAGESIZE) * mmap.PAGESIZE)
                if not _shm_room(size):
                    break
                shm = self._new(create=True, size=size)
                _populate(shm)
                with self._lock:
                    self.blocks[shm.name] = shm
                    self.arenas[shm.name] = [0, 0]
                made += size

        self._stop.clear()
        self._filler = threading.Thread(target=fill, name="populate-blocks", daemon=True)
        self._filler.start()

    def populated_bytes(self) -> int:
        """The bytes of arenas populated so far (`populate_ahead` may still be adding more)."""
        with self._lock:
            return sum(self.blocks[n].size for n in self.arenas)

    def stop_populating(self, wait: bool = False) -> int:
        """End `populate_ahead` (the arena being populated is finished first, in its thread unless `wait`); returns
        the bytes of arenas populated so far."""
        if self._filler is not None:
            self._stop.set()
            if wait:
                self._filler.join()
                self._filler = None
        return self.populated_bytes()

    def get(self, nbytes: int) -> tuple:
        """Room for nbytes: (block, offset), carved from an arena with room where one was populated ahead, else
        the smallest free block that fits (offset 0), else a new block; (None, 0) where /dev/shm has no room even
        after dropping the free blocks (the caller then keeps its arrays in process memory)."""
        with self._lock:
            for name, (used, lent) in self.arenas.items():
                start = -(-used // ARENA_ALIGN) * ARENA_ALIGN
                if start + nbytes <= self.blocks[name].size:
                    self.arenas[name] = [start + nbytes, lent + 1]
                    return self.blocks[name], start
        fits = sorted((self.blocks[n].size, n) for n in self.free if self.blocks[n].size >= nbytes)
        if fits:
            self.free.discard(fits[0][1])
            return self.blocks[fits[0][1]], 0
        if not _shm_room(nbytes):
            for name in list(self.free):
                self._drop(name)
            if not _shm_room(nbytes):
                return None, 0
        shm = self._new(create=True, size=max(1, nbytes))
        self.blocks[shm.name] = shm
        return shm, 0

    def put(self, name: str) -> None:
        """A piece of block `name` came back (its shard is written)."""
        with self._lock:
            if name in self.arenas:
                arena = self.arenas[name]
                arena[1] -= 1
                if arena[1] == 0:  # every piece carved from it is back: carve from the start again
                    arena[0] = 0
                    if self.draining:
                        del self.arenas[name]
                        self._drop(name)
                return
        if name in self.blocks:
            self.free.add(name)
            if self.draining:
                self._drop(name)

    def drain(self) -> None:
        """No more gets: unlink the free blocks now and every block as it comes back (freeing the pages of a
        large pool takes seconds; done while the last shards are written, not after)."""
        self.stop_populating(wait=True)
        self.draining = True
        for name in list(self.free):
            self._drop(name)
        with self._lock:
            for name in [n for n, (_, lent) in self.arenas.items() if lent == 0]:
                del self.arenas[name]
                self._drop(name)

    def _drop(self, name: str) -> None:
        self.free.discard(name)
        shm = self.blocks.pop(name)
        try:
            shm.close()
        except BufferError:  # a view still alive (an error unwinding): the memory goes with the process
            pass
        shm.unlink()

    def close(self) -> None:
        self.stop_populating(wait=True)
        self.arenas.clear()
        for name in list(self.blocks):
            self._drop(name)


@dataclass
class PackedShard:
    """One shard's recorded channels, as the producer made them: pieces of stacked episodes (one per simulated
    slice), and for each episode in file order its id, attrs and (piece, row). With a `BlockPool` the per-episode
    arrays of each piece sit in a shared-memory block (`blocks[piece]` = (block name, name -> (offset, dtype,
    shape))) and only this metadata crosses to the writer; without one (or without room) they travel pickled."""

    shard: int
    specs: dict[str, tuple[str, tuple[str, ...], str, bool]] = field(default_factory=dict)  # name -> units, dims, desc, per_episode
    pieces: list[dict[str, np.ndarray]] = field(default_factory=list)  # arrays not in a block (time; all without room)
    episodes: list[tuple[str, dict, int, int]] = field(default_factory=list)  # (id, attrs, piece, row), in global order
    blocks: list[tuple[str, dict[str, tuple[int, str, tuple[int, ...]]]] | None] = field(default_factory=list)
    sparse: list[dict[str, tuple[tuple[int, ...], int]]] = field(default_factory=list)  # per piece: its BlockSparse
    # channels, name -> (dense shape, block), their blocks and index held as `name` and `name + SPARSE_INDEX`

    @property
    def n_episodes(self) -> int:
        return len(self.episodes)

    @property
    def block_names(self) -> list[str]:
        return [b[0] for b in self.blocks if b is not None]

    @property
    def nbytes(self) -> int:
        """Bytes of its arrays held for the writer (in blocks or in process memory)."""
        shared = sum(int(np.prod(shape)) * np.dtype(dt).itemsize for b in self.blocks if b for _, dt, shape in b[1].values())
        return shared + sum(a.nbytes for piece in self.pieces for a in piece.values())

    def add_piece(self, arrays: dict[str, np.ndarray | BlockSparse], pool: BlockPool | None) -> None:
        """Append a piece, copying its per-episode arrays into a block of `pool` (or into process memory: the
        arrays given may be views of buffers the next slice overwrites). A `BlockSparse` channel goes as its
        blocks and index (`sparse`)."""
        sparse, flat = {}, {}
        for n, a in arrays.items():
            if isinstance(a, BlockSparse):
                sparse[n] = (a.shape, a.block)
                flat[n], flat[n + SPARSE_INDEX] = a.blocks, a.index
            else:
                flat[n] = a
        arrays = flat
        self.sparse.append(sparse)
        per_ep = [n for n in arrays if n.removesuffix(SPARSE_INDEX) in self.specs and self.specs[n.removesuffix(SPARSE_INDEX)][3]]
        padded = lambda nbytes: -(-nbytes // ARENA_ALIGN) * ARENA_ALIGN  # every array on an aligned offset
        shm, offset = pool.get(sum(padded(arrays[n].nbytes) for n in per_ep)) if pool is not None else (None, 0)
        if shm is None:
            self.pieces.append({n: np.array(a) for n, a in arrays.items()})
            self.blocks.append(None)
            return
        layout, copies = {}, []
        for n in per_ep:
            a = arrays[n]
            copies.append((np.ndarray(a.shape, a.dtype, buffer=shm.buf, offset=offset), a))
            layout[n] = (offset, a.dtype.str, a.shape)
            offset += padded(a.nbytes)
        if sum(a.nbytes for _, a in copies) < PACK_SPLIT_BYTES:  # a small piece: copied here
            for dst, a in copies:
                np.copyto(dst, a)
        else:  # one task per thread, each copying its share of every array's rows (the first touch of a block's
            # pages is the cost)
            def share(k: int) -> None:
                for dst, a in copies:
                    step = -(-len(a) // PACK_THREADS)
                    np.copyto(dst[k * step : (k + 1) * step], a[k * step : (k + 1) * step])

            list(_pack_pool().map(share, range(PACK_THREADS)))
        copies = None
        self.pieces.append({n: np.array(a) for n, a in arrays.items() if n not in layout})
        self.blocks.append((shm.name, layout))

    def arrays(self, bufs: dict) -> list[dict[str, np.ndarray | BlockSparse]]:
        """The pieces with their shared arrays as views of the attached blocks (`bufs`: block name -> buffer), their
        sparse channels as `BlockSparse` over those views."""
        out = []
        for piece, block, sparse in zip(self.pieces, self.blocks, self.sparse):
            shared = {} if block is None else dict(zip(block[1], _views(bufs[block[0]], list(block[1].values()))))
            got = {**piece, **shared}
            for n, (shape, size) in sparse.items():
                got[n] = BlockSparse(got[n], got.pop(n + SPARSE_INDEX), shape, size)
            out.append(got)
        return out


def write_packed_shard(cfg: SceneConfig, out_dir: str, packed: PackedShard, sensor_attrs: dict, mjcf: str) -> tuple[dict, dict]:
    """Writer task: write one packed shard atomically (what write_shard would write); returns its manifest
    entry (sha256 of the file just written, from the page cache; content hash and summary as the writer made
    them), so the driver need not read it back, and
    the seconds this writer spent on "episodes" (HDF5), "close, fsync" and "sha256"."""
    import time

    from sensors.data.manifest import shard_entry
    from sensors.data.recording import Channel
    from simulate.generation.run import config_sha256, shard_writer
    from simulate.generation.shards import maybe_inject_fault

    maybe_inject_fault(packed.shard)
    attached = {name: _attach(name) for name in dict.fromkeys(packed.block_names)}  # the driver owns them
    try:
        pieces = packed.arrays({name: shm.buf for name, shm in attached.items()})
        t0 = time.perf_counter()
        with shard_writer(cfg, Path(out_dir), packed.shard, sensor_attrs, mjcf) as w:
            for ep_id, attrs, piece, row in packed.episodes:
                arrays = pieces[piece]
                # a field sent as its blocks tells the writer which of them are zero (the same file, less scanning)
                ch = {name: Channel(arrays[name][row] if per_ep else arrays[name], units, dims, desc,
                                    arrays[name].nonzero_blocks(row) if isinstance(arrays[name], BlockSparse) else None)
                      for name, (units, dims, desc, per_ep) in packed.specs.items()}
                w.add_episode(ep_id, ch, attrs)
            t1 = time.perf_counter()
        t2 = time.perf_counter()
        pieces = arrays = ch = None  # drop the views before the blocks are closed
    finally:
        for shm in attached.values():
            try:
                shm.close()
            except BufferError:  # views still held by a failing write's frames: the process cleans up
                pass
    entry = shard_entry(w.path, [e[0] for e in packed.episodes], [e[1]["seed"] for e in packed.episodes], config_sha256(cfg),
                        content_sha256=w.content_sha256, summary=w.summary)
    return entry, {"episodes": t1 - t0, "close, fsync": t2 - t1, "sha256": time.perf_counter() - t2}


SIZING_VALUES_PER_SAMPLE = 20  # float64 values per sample that batch sizing counts (the whole sensordata, as when
# the batches were measured; `simulate_sensors` now keeps 7 per indenter, so the sizing has ~3x headroom)
BATCH_RAM_FRACTION = 0.1  # a batch's sensordata (float64, in shared memory) at most this much of the host's memory


def feed_worlds(cfg: SceneConfig) -> int:
    """Episodes per feed batch: FEED_WORLDS for each episode length the protocol draws (`length_groups` step one
    after another, so mixed frequencies keep FEED_WORLDS worlds in each), while the batch's sensordata stays
    within BATCH_RAM_FRACTION of the host's memory."""
    from simulate.contact.load_field import CONTACT_STAGES

    p, s = cfg.protocol, cfg.sampling
    if p.kind in CONTACT_STAGES:
        # the stage's load field runs in the driver (press_stroke: its taxel fields by Warp kernels on the device,
        # ~3 GB of float64 fields per 8192 ntype episodes; on the host, numpy's (episodes, samples, indenters,
        # taxels) temporaries)
        return FEED_WORLDS // 4
    if p.kind != "sinusoid":
        return FEED_WORLDS
    freqs = sorted(set(p.frequencies_hz))
    mean_samples = sum(cfg.episode_duration_s(f) for f in freqs) / len(freqs) * s.sample_rate_hz + 1
    # sized as measured (20 float64 values per sample, session 11): the sensordata now keeps READ_PER_INDENTER of
    # them (`read_columns`), so a batch holds ~7/20 of this; the batches stay those the benches measured
    per_episode = 8 * SIZING_VALUES_PER_SAMPLE * mean_samples
    ram = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    return max(FEED_WORLDS, min(FEED_WORLDS * len(freqs), int(BATCH_RAM_FRACTION * ram / per_episode)))


def _groups(cfg: SceneConfig, todo: list[int], worlds: int, ramp: int | None = None) -> list[list[int]]:
    """Consecutive runs of the shards to make, each with >= `worlds` episodes where the shards allow, after a
    ramp of `ramp` (default RAMP_BATCHES) smaller batches (worlds / 4, then worlds / 2): the driver and the writers
    start on a small first batch instead of idling while the first full one steps in the physics processes."""
    from simulate.generation.run import episode_ids_of_shard

    ramp = RAMP_BATCHES if ramp is None else ramp
    groups: list[list[int]] = [[]]
    n = 0
    for s in todo:
        if n >= worlds >> max(0, ramp - len(groups) + 1):
            groups.append([])
            n = 0
        groups[-1].append(s)
        n += len(episode_ids_of_shard(cfg, s))
    return [g for g in groups if g]


LENGTH_SCHEDULE = True  # schedule runs of mixed episode lengths by length (`_schedule`); False: `_groups` always
LENGTH_SPLIT = 2.0  # a run whose longest episodes are more than this many times its shortest is scheduled by length ...
LENGTH_SAMPLE = 512  # ... judged on the protocols of its first this many episodes (drawn in the driver, ~30 us each)
SAMPLE_MARGIN = 1.25  # batches by length sized on the sample's shares, with this margin (see _schedule)


def _schedule(cfg: SceneConfig, todo: list[int], worlds: int) -> list[tuple[list[int], Select | None]]:
    """The feed's batches in the order the physics steps them: (shards, select), select None for all their episodes.

    A batch's length groups step one after another, each for its length's sequential steps, and below ~15k
    worlds a step costs about the same whatever the worlds (STEP_S_FLOOR in `simulate.contact.load_field`). So
    a batch of whole shards of mixed lengths takes as long as its longest episodes whatever its size (session 10,
    cnt_pdms at 0.1-2 Hz: the first batch 43 s, at 2/3 the episodes 41 s), and the driver and the writers idle
    meanwhile. Where the run's longest episodes are more than LENGTH_SPLIT times its shortest (judged on its first
    LENGTH_SAMPLE episodes), the short episodes (<= longest / LENGTH_SPLIT samples) of every shard step first, in
    batches of at most FEED_WORLDS episodes per length and BATCH_RAM_FRACTION of the host's memory; the driver runs
    their sensor chain and packs them while the long ones step in windows of consecutive shards of at least
    FEED_WORLDS / 2 long episodes each (fewer windows repeat the long episodes' sequential steps less often, more
    let the first windows' writes overlap the later windows' stepping); a shard goes to the writers when the last
    of its episodes is packed. An episode's channels do not depend on its batch, and each file lists its episodes
    in id order as before. Otherwise the batches of `_groups` (whole shards, `worlds` episodes after a ramp)."""
    import math

    from sensors.data.manifest import episode_seed
    from simulate.generation.run import episode_ids_of_shard, episode_protocols

    eps = {s: len(episode_ids_of_shard(cfg, s)) for s in todo}
    sample = [k for s in todo for k in episode_ids_of_shard(cfg, s)[:LENGTH_SAMPLE]][:LENGTH_SAMPLE]
    n = [p.n_samples for p in episode_protocols(cfg, [episode_seed(cfg.generation.root_seed, k) for k in sample], sample)]
    if not LENGTH_SCHEDULE or not n or max(n) <= LENGTH_SPLIT * min(n):
        return [(g, None) for g in _groups(cfg, todo, worlds)]
    cutoff = int(max(n) / LENGTH_SPLIT)
    ram = BATCH_RAM_FRACTION * os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    total = sum(eps.values())

    def windows(lengths: list[int], min_parts: int) -> list[list[int]]:
        """Consecutive runs of the shards, about equal in episodes, each with about FEED_WORLDS of these lengths'
        episodes per length at most and their sensordata (SIZING_VALUES_PER_SAMPLE float64 per sample) within `ram`, as
        expected from the sample's share and mean length (SAMPLE_MARGIN: a share a little above the sample's
        does not split a batch in two: two batches of short episodes would step side by side first and hold the
        long ones back, as the H100 measured: -s11-mix-split)."""
        share = len(lengths) / len(n)
        cap = min(FEED_WORLDS * len(set(lengths)), ram / (8 * SIZING_VALUES_PER_SAMPLE * (sum(lengths) / len(lengths) + 1)))
        parts = min(len(todo), max(1, min_parts, math.ceil(total * share / (SAMPLE_MARGIN * max(1.0, cap)))))
        out, acc = [[]], 0
        for s in todo:
            if out[-1] and acc >= len(out) * total / parts:
                out.append([])
            out[-1].append(s)
            acc += eps[s]
        return out

    short, long = [k for k in n if k <= cutoff], [k for k in n if k > cutoff]
    long_parts = round(total * len(long) / len(n) / max(1, FEED_WORLDS // 2))
    return ([(w, Select(False, cutoff)) for w in windows(short, 1)]
            + [(w, Select(True, cutoff)) for w in windows(long, long_parts)])


def produce(cfg: SceneConfig, shards: list[int], sensor, threads: int = 1, seconds: dict | None = None,
            stepped: tuple[list, dict] | None = None, pool: BlockPool | None = None) -> list[PackedShard]:
    """`iter_produce`'s shards in the order of `shards`."""
    packs = {p.shard: p for p in iter_produce(cfg, shards, sensor, threads, seconds, stepped, pool)}
    return [packs[s] for s in shards]


PACK_OVERLAP = os.environ.get("PIEZOTWIN_PACK_OVERLAP", "0") == "1"  # pack slice i (a thread of the driver; the copies
# release the GIL) while slice i + 1 runs its load field and sensor chain, its outputs in the other set of staging
# buffers. Off by default: on the H100 (session 12, velostat 8192 episodes, same machine, off / on / off / on) the
# plain CLI took 68.0 / 67.5 / 60.8 / 70.3 s: with the 12 writers busy the two stages slow each other (simulate
# 8.9-10.2 s -> 15.7-16.2 s), the tail after the physics no shorter (20.9 s mean off, 21.9 on); without writers
# the stage alone went 6.52 -> 5.54 s (feed-stage-velostat-h100-s12-overlap.json). The variable: the bench's A/B
_PACK_STAGE = None


def _pack_stage():
    global _PACK_STAGE
    if _PACK_STAGE is None:
        from concurrent.futures import ThreadPoolExecutor

        _PACK_STAGE = ThreadPoolExecutor(1, thread_name_prefix="pack-stage")
    return _PACK_STAGE


SLICES_PER_LENGTH = int(os.environ.get("PIEZOTWIN_FEED_SLICES", "4"))  # slices (at most SENSOR_SLICE episodes each)
# per length group of a batch: a modest run's shards are handed to the writers as the last length group's slices
# finish, not after the whole batch. The variable: the bench's A/B (the writes left after the last slice, its share)


PROBE_EPISODES = 64  # protocols drawn to estimate a batch's mean episode length (`batch_pack_bytes`; ~30 us each)


def _planned_nbytes(a: np.ndarray | BlockSparse) -> int:
    """Bytes a channel's array of the probe plans for a pack: a taxel field the probe's zero load sends as blocks
    counts SPARSE_MAX_SHARE of its dense bytes, the most a field sent as blocks can hold (one loaded on more goes
    whole: cnt_pdms' deformation and pressure, planned at half with its all-zero shear at half, come out right)."""
    from simulate.contact import field_blocks

    return int(a.nbytes * max(0.0, field_blocks.SPARSE_MAX_SHARE)) if isinstance(a, BlockSparse) else a.nbytes


def batch_pack_bytes(cfg: SceneConfig, sensor, gids: list[int], threads: int = 1, protos: list | None = None) -> int:
    """The bytes the pack of episodes `gids` (a batch of the worlds path) will need, estimated before their physics
    is back (`probe_batch`)."""
    return probe_batch(cfg, sensor, gids, threads, protos)[0]


def probe_batch(cfg: SceneConfig, sensor, gids: list[int], threads: int = 1,
                protos: list | None = None) -> tuple[int, dict[tuple, int]]:
    """What a batch of the worlds path (episodes `gids`) will need, estimated before its physics is back: one of
    them through the load field and the sensor chain on zero sensordata (its channels' shapes and dtypes do not
    depend on the load; on a GPU it also loads the sensor's kernels, ahead of the first slice). Returns
    - the bytes its pack will need: per sample, times the mean length of up to PROBE_EPISODES of their protocols,
      times their count (a taxel field sent as its non-zero blocks: `_planned_nbytes`);
    - its staging plan ((site, slot) -> bytes, for `sensors.warp_setup.reserve_staging`): the page-locked buffers
      its largest slice copies back into, from the probe's copies per sample times that slice's samples (the slices
      of `simulate_slices` with SLICES_PER_LENGTH pieces, from the lengths of up to PROBE_EPISODES protocols; the
      slots the pack alternates where PACK_OVERLAP).
    protos: those of `gids`, where made already (else the probed ones are drawn here)."""
    from sensors.data.manifest import episode_seed
    from sensors.warp_setup import host_staging, staging_log
    from simulate.contact.load_field import SLICED_CONTACT_STAGES, build_model, read_columns
    from simulate.generation.run import SENSOR_SLICE, episode_protocols, simulate_slices

    every = max(1, len(gids) // PROBE_EPISODES)
    probe = gids[::every][:PROBE_EPISODES]
    seeds = [episode_seed(cfg.generation.root_seed, k) for k in probe]
    protos = episode_protocols(cfg, seeds, probe) if protos is None else protos[::every][:PROBE_EPISODES]
    n = protos[0].n_samples
    if cfg.protocol.kind in SLICED_CONTACT_STAGES:  # press_stroke's own physics array
        from simulate.contact.press_stroke import PHYSICS_COLUMNS

        zero = {n: (np.zeros((1, n, cfg.indenter.count, PHYSICS_COLUMNS)), np.zeros((1, n)))}
    else:
        zero = {n: (np.zeros((1, n, len(read_columns(build_model(cfg))))), np.zeros((1, n)))}
    with host_staging(), staging_log() as log:
        per_episode = sum(_planned_nbytes(c.data[:1]) for _, _, arrays in simulate_slices(cfg, seeds[:1], sensor, threads,
                                                                                          probe[:1], protos[:1], zero)
                          for c in arrays.values() if c.per_episode)
    lengths = np.array([p.n_samples for p in protos])
    slice_samples = 0  # samples of the largest slice: per length group, its episodes in SLICES_PER_LENGTH pieces
    for length in np.unique(lengths):
        count = round(len(gids) * float(np.mean(lengths == length)))
        per = min(SENSOR_SLICE, max(1, -(-count // max(1, SLICES_PER_LENGTH))))
        slice_samples = max(slice_samples, per * int(length))
    slots = (0, 1) if PACK_OVERLAP else (0,)
    plan = {(site, slot): int(-(-nbytes * slice_samples // n)) for (site, _), nbytes in log.items() for slot in slots}
    return int(per_episode / n * float(np.mean(lengths)) * len(gids)), plan


def iter_produce(cfg: SceneConfig, shards: list[int], sensor, threads: int = 1, seconds: dict | None = None,
                 stepped: tuple[list, dict] | None = None, pool: BlockPool | None = None) -> Iterator[PackedShard]:
    """Simulate the episodes of `shards` as one batch and pack each shard's recorded channels, yielding each
    shard as soon as all its episodes are packed (`Producer.batch` of a fresh producer)."""
    return Producer(cfg, sensor, threads, seconds, pool).batch(shards, stepped)


class Producer:
    """The driver's side of the feed: runs the load field and sensor chain of batch after batch and packs each
    shard's recorded channels, keeping a shard's pieces across batches until its last episode is packed (a
    shard's episodes may come in several batches: `_schedule`). seconds: adds the time spent simulating and
    packing. pool: pack into its shared blocks."""

    def __init__(self, cfg: SceneConfig, sensor, threads: int = 1, seconds: dict | None = None, pool: BlockPool | None = None):
        self.cfg, self.sensor, self.threads, self.pool = cfg, sensor, threads, pool
        self.seconds = {} if seconds is None else seconds
        self.packs: dict[int, PackedShard] = {}
        self.left: dict[int, int] = {}  # shard -> its episodes not yet packed
        self.placed: dict[int, tuple[str, dict, int, int]] = {}  # episode id -> (id, attrs, piece, row)
        self.finished: set[int] = set()  # shards yielded

    def batch(self, shards: list[int], stepped: tuple[list, dict] | None = None) -> Iterator[PackedShard]:
        """Simulate a batch of the episodes of `shards` and pack them, yielding each shard as soon as all its
        episodes (of this batch and earlier ones) are packed. stepped: `step_worlds` of these episodes (all of
        them, or those its select kept: the protocols' indices say which), run in the physics process; this
        process then runs only the load field and the sensor chain. Each slice's outputs come back from the GPU
        into reused page-locked buffers (`host_staging`) and is packed before the next slice runs (or, with
        PACK_OVERLAP, while it runs, its copies in the other set of buffers: `staging_slot`); each length group
        goes in SLICES_PER_LENGTH slices or more."""
        import time

        from sensors.data.manifest import episode_seed
        from sensors.warp_setup import host_staging, staging_slot
        from simulate.generation.run import (
            episode_attrs,
            episode_ids_of_shard,
            simulate_slices,
        )

        cfg, seconds, packs, left, placed = self.cfg, self.seconds, self.packs, self.left, self.placed
        ids = {s: episode_ids_of_shard(cfg, s) for s in shards}
        owner = {k: s for s in shards for k in ids[s]}
        for s in shards:
            if s not in packs and s not in self.finished:
                packs[s], left[s] = PackedShard(s), len(ids[s])
        protos, physics, blocks = None, None, []
        if stepped is not None:
            protos, physics = stepped[0], {}
            gids = [p.index for p in protos]
            for n, handed in stepped[1].items():
                if isinstance(handed[0], str):  # (block name, layout): views of the block, unlinked below
                    blocks.append(_attach(handed[0]))
                    handed = tuple(_views(blocks[-1].buf, handed[1]))
                physics[n] = handed
        else:
            gids = [k for s in shards for k in ids[s]]
        seeds = [episode_seed(cfg.generation.root_seed, k) for k in gids]

        def pack(pos: list[int], protos_s: list, arrays: dict) -> list[PackedShard]:
            """Pack one slice's outputs into their shards' pieces; the shards it completes (in the driver's
            pack thread where PACK_OVERLAP, while the next slice runs; one slice at a time, in slice order)."""
            t1 = time.perf_counter()
            runs: dict[int, list[int]] = {}
            for j, i in enumerate(pos):
                runs.setdefault(owner[gids[i]], []).append(j)
            done = []
            for s, rows in runs.items():
                p = packs[s]
                p.specs = {n: (c.units, c.dims, c.description, c.per_episode) for n, c in arrays.items()}
                take = slice(rows[0], rows[-1] + 1) if rows[-1] - rows[0] + 1 == len(rows) else rows
                p.add_piece({n: (c.data[take] if c.per_episode else c.data) for n, c in arrays.items()}, self.pool)
                for r, j in enumerate(rows):
                    i = pos[j]
                    placed[gids[i]] = (f"ep-{gids[i]:06d}", episode_attrs(seeds[i], protos_s[j], gids[i]),
                                       len(p.pieces) - 1, r)
                left[s] -= len(rows)
                if not left[s]:
                    p.episodes = [placed.pop(k) for k in ids[s]]
                    done.append(packs.pop(s))
                    del left[s]
                    self.finished.add(s)
            seconds["pack"] = seconds.get("pack", 0.0) + time.perf_counter() - t1
            return sorted(done, key=lambda p: p.shard)

        pending = None  # the previous slice's pack (a future) where PACK_OVERLAP
        try:
            with host_staging():
                slices = simulate_slices(cfg, seeds, self.sensor, self.threads, gids, protos, physics, SLICES_PER_LENGTH)
                k = 0
                while True:
                    t0 = time.perf_counter()
                    with staging_slot(k % 2 if PACK_OVERLAP else 0):  # slice k - 1's views stay valid meanwhile
                        item = next(slices, None)
                    t1 = time.perf_counter()
                    seconds["simulate"] = seconds.get("simulate", 0.0) + t1 - t0
                    if pending is not None:
                        done, pending = pending.result(), None
                        seconds["wait for pack"] = seconds.get("wait for pack", 0.0) + time.perf_counter() - t1
                        yield from done
                    if item is None:
                        break
                    if PACK_OVERLAP:
                        pending = _pack_stage().submit(pack, *item)
                    else:
                        yield from pack(*item)
                    item = None
                    k += 1
        finally:
            if pending is not None:  # an error unwinding: let the pack stop touching the blocks first
                try:
                    pending.result()
                except BaseException:  # noqa: BLE001 - the first error is the one raised
                    pass
            physics = None
            for shm in blocks:
                try:
                    shm.close()
                except BufferError:  # a view still alive (an error unwinding): the memory goes with it
                    pass
                shm.unlink()


def generate_feed(
    cfg: SceneConfig, out: Path, todo: list[int], writers: int, *, backend: str = "warp", device: str = "cpu",
    threads: int = 1, max_retries: int = 3, on_shard: Callable[[int, int, bool], None] | None = None,
    worlds: int | None = None,
) -> dict[int, dict]:
    """Make the shards `todo` of cfg's dataset in `out`: simulate here, write in `writers` processes.
    Returns the writers' manifest entries by shard."""
    import multiprocessing as mp
    import time
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    from sensors.data.manifest import episode_seed
    from sensors.registry import make_sensor
    from sensors.warp_setup import init_warp
    from simulate.contact.load_field import CONTACT_STAGES
    from simulate.contact.mjcf import build_mjcf
    from simulate.generation.run import (
        config_sha256,
        episode_ids_of_shard,
        episode_protocols,
        shard_sensor_attrs,
    )
    from simulate.generation.shards import ShardFailedError, check_written

    LAST_RUN_SECONDS.clear()
    LAST_RUN_BATCHES.clear()
    seconds = LAST_RUN_SECONDS
    t_start = time.perf_counter()

    def add(key: str, t0: float) -> None:
        seconds[key] = seconds.get(key, 0.0) + time.perf_counter() - t0

    ctx = mp.get_context("spawn")
    # the worlds step in their own processes, batches ahead of the load field + sensor chain here (kinds with
    # their own contact stage run it here); they start first, so their start-up overlaps the driver's
    # (or were started ahead by the caller: prestart_physics)
    if stage_in_driver(cfg):
        release_prestarted()
        physics = None
    else:
        physics = _take_prestarted()
        if physics is None:  # started here: their imports begin now, as prestart_physics's would
            physics = ProcessPoolExecutor(PHYSICS_PROCESSES, mp_context=ctx)
            for _ in range(PHYSICS_PROCESSES):
                physics.submit(_warm_physics)
    # a kind with its own contact stage: no ramp, since its latency-bound batches cost about the same whatever their
    # size (STEP_S_FLOOR), so a ramp's small batches each cost a full one's time and overlap nothing (ntype 8192
    # episodes on an H200, stepped in the driver then: ramp of 2048, 4096 then 2048 against one batch,
    # bench/results/logs/profile-ntype-ramp*-h200-s16.txt; again with its worlds in the physics processes, ntype 24576:
    # 43.5 / 39.9 s with CONTACT_RAMP_BATCHES = 2 against 40.3 / 38.6 s without, user-cli-h200-s26-ntype-ramp*.json)
    batches = ([(g, None) for g in _groups(cfg, todo, worlds or feed_worlds(cfg), ramp=CONTACT_RAMP_BATCHES)]
               if cfg.protocol.kind in CONTACT_STAGES
               else _schedule(cfg, todo, worlds or feed_worlds(cfg)))
    groups = [g for g, _ in batches]

    turns = new_turns() if physics and GPU_TURNS else None

    def step(b: int, protos: list | None = None):
        return physics.submit(step_worlds, cfg, [k for s in groups[b] for k in episode_ids_of_shard(cfg, s)], threads,
                              time.time(), batches[b][1], protos, (turns, b) if turns else None)

    ahead = []
    try:
        if physics:
            # the first batch's protocols are made here while the physics processes still import (their "waiting to
            # start", 2.6-4.4 s on the H200 host against 1.1-2.3 s for 8192 protocols there:
            # bench/results/user-cli-h200-s17-*.json), so its worlds start that much sooner; later batches make their own
            t0 = time.perf_counter()
            first = [k for s in groups[0] for k in episode_ids_of_shard(cfg, s)]
            first_protos = episode_protocols(cfg, [episode_seed(cfg.generation.root_seed, k) for k in first], first)
            add("protocols (first batch, in the driver)", t0)
            ahead = [step(b, first_protos if b == 0 else None) for b in range(min(PHYSICS_PROCESSES, len(groups)))]
        if backend == "warp":
            init_warp()
        sensor = make_sensor(cfg, backend, device)
        mjcf, sha = build_mjcf(cfg), config_sha256(cfg)
        sensor_attrs = shard_sensor_attrs(cfg, sensor)
    except BaseException:
        if turns:  # a task waiting for its turn raises (a removed file too)
            stop_turns(turns)
            os.unlink(turns)
        if physics:
            physics.shutdown(wait=False, cancel_futures=True)
        raise
    pool = ProcessPoolExecutor(writers, mp_context=ctx)
    pending: dict = {}  # future -> packed shard (kept until its file is checked, for a resubmit)
    shared = BlockPool()  # the packed pieces' blocks, lent until their shard is written
    ram_budget = PENDING_RAM_FRACTION * os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    entries: dict[int, dict] = {}
    attempts: dict[int, int] = {}

    def release(p: PackedShard) -> None:
        for name in p.block_names:
            shared.put(name)

    def submit(p: PackedShard) -> None:
        nonlocal pool
        attempts[p.shard] = attempts.get(p.shard, 0) + 1
        while True:
            try:
                pending[pool.submit(write_packed_shard, cfg, str(out), p, sensor_attrs, mjcf)] = p
                return
            except BrokenProcessPool:
                # a writer died after the last collect, so the pool refuses new work: settle the writes it held
                # (collect starts a new pool and resubmits the lost ones), start one here if collect did not
                bad = pool
                collect(None)
                if pool is bad:
                    pool.shutdown(wait=False, cancel_futures=True)
                    pool = ProcessPoolExecutor(writers, mp_context=ctx)

    def collect(room_for: int | None, block: bool = True) -> None:
        """Handle finished writes; wait until `room_for` more shards fit under PENDING_PER_WRITER per writer
        (a batch larger than that waits for every write), or with None until every write is done; with
        block=False only those already finished."""
        nonlocal pool
        while pending:
            waiting = block and (room_for is None or len(pending) + room_for > max(PENDING_PER_WRITER * writers, room_for)
                       or sum(p.nbytes for p in pending.values()) > ram_budget)
            done, _ = wait(list(pending), timeout=None if waiting else 0, return_when=FIRST_COMPLETED)
            if not done:
                return
            broken = []
            for f in done:
                p = pending.pop(f)
                try:
                    entries[p.shard], spent = f.result()
                    for k, v in spent.items():
                        seconds[f"writers: {k}"] = seconds.get(f"writers: {k}", 0.0) + v
                    check_written(out, p.shard, sha)
                except BrokenProcessPool:
                    broken.append(p)
                    continue
                except Exception as exc:
                    if attempts[p.shard] > max_retries:
                        raise ShardFailedError(f"shard {p.shard}: failed {attempts[p.shard]} time(s); last error: "
                                               f"{type(exc).__name__}: {exc} (complete shards are kept: rerun to resume)") from exc
                    submit(p)
                    continue
                release(p)
                if on_shard:
                    on_shard(p.shard, p.n_episodes, False)
            if broken:  # a writer died: every write still in the pool is lost with it
                broken += list(pending.values())
                pending.clear()
                pool.shutdown(wait=False, cancel_futures=True)
                pool = ProcessPoolExecutor(writers, mp_context=ctx)
                for p in sorted(broken, key=lambda p: p.shard):
                    if attempts[p.shard] > max_retries:
                        raise ShardFailedError(f"shard {p.shard}: failed {attempts[p.shard]} time(s); last error: the "
                                               "writer process died (complete shards are kept: rerun to resume)")
                    submit(p)

    produce = Producer(cfg, sensor, threads, seconds, shared)
    add("start-up", t_start)
    stepped = None
    try:  # (the populating inside: an interrupt there still stops the pools and unlinks the blocks below)
        if physics and POPULATE_AHEAD:  # while the first batch steps: the blocks its pack will fill, populated ahead
            t0 = time.perf_counter()
            try:
                need, staging = probe_batch(cfg, sensor, first, threads, first_protos)
            except Exception:  # noqa: BLE001 - an estimate only: the batch itself raises whatever is wrong
                need, staging = None, None
                seconds["populate ahead: skipped, the estimate failed"] = 0.0
            if need is not None:
                shared.populate_ahead(min(int(need * POPULATE_MARGIN) + 2**20, int(ram_budget)))
            add("populate ahead: estimate", t0)
            if staging and device != "cpu" and RESERVE_STAGING:  # the page-locked buffers of the first slice too
                from sensors.warp_setup import reserve_staging

                t0 = time.perf_counter()
                seconds["reserve staging: GB page-locked (a size, not seconds)"] = reserve_staging(staging) / 1e9
                add("reserve staging", t0)
        first_protos = None
        for b, group in enumerate(groups):
            t0 = time.perf_counter()
            select = batches[b][1]
            # bounded memory: at most PENDING_PER_WRITER shards per writer not yet written (a batch of short
            # episodes completes only the shards without long ones: none where the run has many episodes)
            collect(0 if select is not None and not select.long else len(group))
            add("wait for writers", t0)
            stepped = None
            if physics:
                t0 = time.perf_counter()
                try:
                    stepped = ahead[0].result()  # left in `ahead` until it is back: an interrupt meanwhile still
                    ahead.pop(0)  # unlinks its block once the physics process is done with it (the finally below)
                except BrokenProcessPool:
                    raise RuntimeError(f"the physics process died stepping shards {group} (complete shards are kept: "
                                       "rerun to resume)") from None
                add("wait for physics (first batch)" if b == 0 else "wait for physics", t0)
                if b == 0:  # the driver has work now: populating stops (the arenas made so far are used first) or,
                    # POPULATE_THROUGH, goes on beside the pack; recorded: how far it had got
                    done = shared.populated_bytes() if POPULATE_THROUGH else shared.stop_populating()
                    seconds["populate ahead: GB populated (a size, not seconds)"] = done / 1e9
                for k, v in stepped[2].items():  # the physics processes' own split (summed over batches)
                    key = f"physics{' (first batch)' if b == 0 else ''}: {k}"
                    seconds[key] = seconds.get(key, 0.0) + v
                if b + PHYSICS_PROCESSES < len(groups):
                    ahead.append(step(b + PHYSICS_PROCESSES))
                elif not ahead:  # the last batch is here: the physics processes exit (free the GPU) meanwhile
                    physics.shutdown(wait=False)
            LAST_RUN_BATCHES.append({
                "shards": [group[0], group[-1]], "select": "all" if select is None else
                f"{'long >' if select.long else 'short <='} {select.cutoff} samples",
                "episodes": len(stepped[0]) if stepped else sum(len(episode_ids_of_shard(cfg, s)) for s in group),
                "max_samples": max((p.n_samples for p in stepped[0]), default=0) if stepped else None})
            for p in produce.batch(group, stepped):
                submit(p)  # as soon as its episodes are packed: the writers start while the batch's last slices run
                collect(0, block=False)
        shared.drain()
        t0 = time.perf_counter()
        if device != "cpu":  # the last copies from the GPU are packed: unpin the staging buffers while the writers finish
            from sensors.warp_setup import release_staging

            release_staging()
            if physics is None:  # the driver stepped the worlds itself (a kind with its own contact stage): free them
                from simulate.contact.mujoco_warp import release_worlds

                release_worlds()
            add("release staging", t0)
            t0 = time.perf_counter()
        collect(None)
        add("wait for writers", t0)
    except BaseException:
        _discard_stepped(stepped)  # the batch in hand, where the failure came before its Producer unlinked it
        raise
    finally:
        t0 = time.perf_counter()
        pool.shutdown(wait=True, cancel_futures=True)
        if turns:  # (a failure: no task still waits for a turn that will not come)
            stop_turns(turns)
        if physics:
            physics.shutdown(wait=True, cancel_futures=True)
        if turns:
            os.unlink(turns)
            for fut in ahead:  # batches stepped ahead that no Producer took (a failure): their blocks go too
                if fut.done() and not fut.cancelled() and fut.exception() is None:
                    _discard_stepped(fut.result())
        shared.close()
        add("shut down", t0)
    return entries
