"""GPU feed: big batches of worlds on one GPU, a pool of writer processes for the shards.

Why (bench/README.md): MuJoCo Warp runs near its peak only with 16k-32k worlds per batch, and HDF5 at that rate
needs several host cores; worker processes that each simulate their own shard time-slice the GPU with smaller
batches. Here a three-stage pipeline runs over batches of several shards' episodes (FEED_WORLDS):

1. PHYSICS_PROCESSES processes step the next batches (`step_worlds`: protocols, controls, MuJoCo Warp; the
   GPU time-slices between them, so one's host work overlaps the other's physics) and hand the sensordata
   over in shared memory;
2. the driver runs the load field and the sensor chain of batch b on the same GPU, slice by slice, and copies
   each shard's recorded channels once into shared memory (`produce`);
3. writer processes (spawned; one shard per task) write the shards and make their manifest entries.

The files are those of `simulate.run.write_shard`: an episode's channels do not depend on the batch it ran in.
A writer that dies is replaced and its shard resubmitted (up to max_retries); finished shards stay, so a
rerun resumes at the missing ones. Where /dev/shm has no room, the arrays travel pickled instead.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from scenes import SceneConfig

FEED_WORLDS = 32768  # episodes per batch of worlds: 1.6e7 world-steps/s on an H100 (bench/results/gpu-pipeline-h100-physics.json)
MAX_PENDING_BATCHES = 2  # batches handed to the writers and not yet written (bounds host memory)
PHYSICS_PROCESSES = 2  # each steps its own batch: one's host work (protocols, controls) overlaps the other's GPU work
# where the driver's time went in the last generate_feed of this process (for bench/): "simulate" (protocols,
# physics, load field, sensor chain, channel arrays), "pack", "wait for writers"
LAST_RUN_SECONDS: dict[str, float] = {}


def _shm_room(nbytes: int) -> bool:
    """Whether /dev/shm can take a block of nbytes (a full tmpfs would kill the writer with SIGBUS)."""
    import shutil

    try:
        return shutil.disk_usage("/dev/shm").free >= 2 * nbytes
    except OSError:
        return False


def _attach(name: str):
    """Attach a block another process owns (this process's resource tracker must not unlink it at exit)."""
    from multiprocessing import resource_tracker, shared_memory

    shm = shared_memory.SharedMemory(name=name)
    resource_tracker.unregister(shm._name, "shared_memory")  # noqa: SLF001 - Python < 3.13 has no track=False
    return shm


def _share(arrays: list[np.ndarray]):
    """Copy arrays into one new shared-memory block: (block, [(offset, dtype, shape)]), or (None, None) where
    /dev/shm has no room (the caller then sends the arrays pickled)."""
    from multiprocessing import shared_memory

    size = sum(a.nbytes for a in arrays)
    if not _shm_room(size):
        return None, None
    shm = shared_memory.SharedMemory(create=True, size=max(1, size))
    where, offset = [], 0
    for a in arrays:
        np.ndarray(a.shape, a.dtype, buffer=shm.buf, offset=offset)[...] = a
        where.append((offset, a.dtype.str, a.shape))
        offset += a.nbytes
    return shm, where


def _views(buf, where: list[tuple[int, str, tuple[int, ...]]]) -> list[np.ndarray]:
    return [np.ndarray(shape, np.dtype(dt), buffer=buf, offset=off) for off, dt, shape in where]


def step_worlds(cfg: SceneConfig, gids: list[int], threads: int = 1) -> tuple[list, dict]:
    """Physics task (in the feed's physics process): the protocols of episodes `gids` and, per length group,
    their (sensordata, target) from `simulate_sensors`, handed over in a shared-memory block the receiver
    unlinks: ({n_samples: (block name, layout)} or the arrays themselves where /dev/shm has no room)."""
    from sensors.manifest import episode_seed
    from simulate.contact import simulate_sensors
    from simulate.run import episode_protocols, length_groups

    protos = episode_protocols(cfg, [episode_seed(cfg.generation.root_seed, k) for k in gids], gids)
    out = {}
    for n, idx in length_groups(protos):
        sens, target = simulate_sensors(cfg, [protos[i] for i in idx], threads)
        shm, where = _share([sens, target])
        if shm is None:
            out[n] = (sens, target)
        else:
            from multiprocessing import resource_tracker

            resource_tracker.unregister(shm._name, "shared_memory")  # noqa: SLF001 - the receiver owns it now
            out[n] = (shm.name, where)
            shm.close()
    return protos, out


@dataclass
class PackedShard:
    """One shard's recorded channels, as the producer made them: pieces of stacked episodes (one per simulated
    slice), and for each episode in file order its id, attrs and (piece, row). `share()` moves the stacked
    arrays into one shared-memory block (what crosses to the writer is then only this metadata)."""

    shard: int
    specs: dict[str, tuple[str, tuple[str, ...], str, bool]] = field(default_factory=dict)  # name -> units, dims, desc, per_episode
    pieces: list[dict[str, np.ndarray]] = field(default_factory=list)
    episodes: list[tuple[str, dict, int, int]] = field(default_factory=list)  # (id, attrs, piece, row), in global order
    shm_name: str | None = None
    layout: list[dict[str, tuple[int, str, tuple[int, ...]]]] = field(default_factory=list)  # piece -> name -> (offset, dtype, shape)

    @property
    def n_episodes(self) -> int:
        return len(self.episodes)

    def share(self):
        """Move the per-episode arrays into a new shared-memory block; returns the block (the caller unlinks
        it), or None where /dev/shm has no room for it (the arrays then travel pickled, as they are)."""
        per_ep = [n for n, spec in self.specs.items() if spec[3]]
        shm, where = _share([piece[n] for piece in self.pieces for n in per_ep])
        if shm is None:
            return None
        it = iter(where)
        for piece in self.pieces:
            self.layout.append({n: next(it) for n in per_ep})
            for n in per_ep:
                del piece[n]
        self.shm_name = shm.name
        return shm

    def arrays(self, buf) -> list[dict[str, np.ndarray]]:
        """The pieces with their shared arrays as views of `buf` (the attached block)."""
        out = []
        for piece, where in zip(self.pieces, self.layout or [{}] * len(self.pieces)):
            out.append({**piece, **dict(zip(where, _views(buf, list(where.values()))))})
        return out


def write_packed_shard(cfg: SceneConfig, out_dir: str, packed: PackedShard, sensor_attrs: dict, mjcf: str) -> dict:
    """Writer task: write one packed shard atomically (what write_shard would write); returns its manifest
    entry (sha256 of the file just written, from the page cache), so the driver need not read it back."""
    from sensors.manifest import shard_entry
    from sensors.recording import Channel
    from simulate.executors import _maybe_inject_fault
    from simulate.run import config_sha256, shard_writer

    _maybe_inject_fault(packed.shard)
    shm = _attach(packed.shm_name) if packed.shm_name is not None else None  # the driver owns the block
    try:
        pieces = packed.arrays(shm.buf) if shm is not None else packed.pieces
        with shard_writer(cfg, Path(out_dir), packed.shard, sensor_attrs, mjcf) as w:
            for ep_id, attrs, piece, row in packed.episodes:
                arrays = pieces[piece]
                ch = {name: Channel(arrays[name][row] if per_ep else arrays[name], units, dims, desc)
                      for name, (units, dims, desc, per_ep) in packed.specs.items()}
                w.add_episode(ep_id, ch, attrs)
        pieces = arrays = ch = None  # drop the views before the block is closed
    finally:
        if shm is not None:
            try:
                shm.close()
            except BufferError:  # views still held by a failing write's frames: the process cleans up
                pass
    return shard_entry(w.path, [e[0] for e in packed.episodes], [e[1]["seed"] for e in packed.episodes], config_sha256(cfg))


def _groups(cfg: SceneConfig, todo: list[int], worlds: int) -> list[list[int]]:
    """Consecutive runs of the shards to make, each with >= `worlds` episodes where the shards allow."""
    from simulate.run import episode_ids_of_shard

    groups: list[list[int]] = [[]]
    n = 0
    for s in todo:
        if n >= worlds:
            groups.append([])
            n = 0
        groups[-1].append(s)
        n += len(episode_ids_of_shard(cfg, s))
    return [g for g in groups if g]


def produce(cfg: SceneConfig, shards: list[int], sensor, threads: int = 1, seconds: dict | None = None,
            stepped: tuple[list, dict] | None = None) -> list[PackedShard]:
    """Simulate the episodes of `shards` as one batch and pack each shard's recorded channels (seconds: adds
    the time spent simulating and packing). stepped: `step_worlds` of these episodes, run in the physics
    process; this process then runs only the load field and the sensor chain."""
    import time

    from sensors.manifest import episode_seed
    from simulate.run import episode_attrs, episode_ids_of_shard, simulate_slices

    gids = [k for s in shards for k in episode_ids_of_shard(cfg, s)]
    owner = {k: s for s in shards for k in episode_ids_of_shard(cfg, s)}
    seeds = [episode_seed(cfg.generation.root_seed, k) for k in gids]
    packs = {s: PackedShard(s) for s in shards}
    placed: dict[int, tuple[str, dict, int, int]] = {}
    seconds = {} if seconds is None else seconds
    protos, physics, blocks = None, None, []
    if stepped is not None:
        protos, physics = stepped[0], {}
        for n, handed in stepped[1].items():
            if isinstance(handed[0], str):  # (block name, layout): views of the block, unlinked below
                blocks.append(_attach(handed[0]))
                handed = tuple(_views(blocks[-1].buf, handed[1]))
            physics[n] = handed
    try:
        t0 = time.perf_counter()
        for pos, protos_s, arrays in simulate_slices(cfg, seeds, sensor, threads, gids, protos, physics):
            t1 = time.perf_counter()
            seconds["simulate"] = seconds.get("simulate", 0.0) + t1 - t0
            runs: dict[int, list[int]] = {}
            for j, i in enumerate(pos):
                runs.setdefault(owner[gids[i]], []).append(j)
            for s, rows in runs.items():
                p = packs[s]
                p.specs = {n: (c.units, c.dims, c.description, c.per_episode) for n, c in arrays.items()}
                take = slice(rows[0], rows[-1] + 1) if rows[-1] - rows[0] + 1 == len(rows) else rows
                p.pieces.append({n: (c.data[take] if c.per_episode else c.data) for n, c in arrays.items()})
                for r, j in enumerate(rows):
                    i = pos[j]
                    placed[gids[i]] = (f"ep-{gids[i]:06d}", episode_attrs(seeds[i], protos_s[j], gids[i]), len(p.pieces) - 1, r)
            t0 = time.perf_counter()
            seconds["pack"] = seconds.get("pack", 0.0) + t0 - t1
    finally:
        physics = None
        for shm in blocks:
            try:
                shm.close()
            except BufferError:  # a view still alive (an error unwinding): the memory goes with it
                pass
            shm.unlink()
    for k in gids:
        packs[owner[k]].episodes.append(placed[k])
    return [packs[s] for s in shards]


def generate_feed(
    cfg: SceneConfig, out: Path, todo: list[int], writers: int, *, backend: str = "warp", device: str = "cpu",
    threads: int = 1, max_retries: int = 3, on_shard: Callable[[int, int, bool], None] | None = None,
    worlds: int | None = None,
) -> dict[int, dict]:
    """Make the shards `todo` of cfg's dataset in `out`: simulate here, write in `writers` processes.
    Returns the writers' manifest entries by shard."""
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    from sensors.registry import make_sensor
    from sensors.warp_setup import init_warp
    from simulate.executors import ShardFailedError, _check_written
    from simulate.mjcf import build_mjcf
    from simulate.run import config_sha256, shard_sensor_attrs

    if backend == "warp":
        init_warp()
    sensor = make_sensor(cfg, backend, device)
    mjcf, sha = build_mjcf(cfg), config_sha256(cfg)
    sensor_attrs = shard_sensor_attrs(cfg, sensor)
    ctx = mp.get_context("spawn")
    pool = ProcessPoolExecutor(writers, mp_context=ctx)
    pending: dict = {}  # future -> packed shard (kept until its file is checked, for a resubmit)
    blocks: dict = {}  # shard -> its shared-memory block (unlinked once the shard is written)
    batch_of: dict[int, int] = {}
    entries: dict[int, dict] = {}
    attempts: dict[int, int] = {}

    def release(p: PackedShard) -> None:
        shm = blocks.pop(p.shard, None)
        if shm:
            shm.close()
            shm.unlink()

    def submit(p: PackedShard) -> None:
        if p.shard not in blocks:
            blocks[p.shard] = p.share()
        attempts[p.shard] = attempts.get(p.shard, 0) + 1
        pending[pool.submit(write_packed_shard, cfg, str(out), p, sensor_attrs, mjcf)] = p

    def collect(block_until_batch: int | None) -> None:
        """Handle finished writes; wait until no shard of a batch <= block_until_batch is pending."""
        nonlocal pool
        while pending:
            waiting = block_until_batch is not None and any(batch_of[p.shard] <= block_until_batch for p in pending.values())
            done, _ = wait(list(pending), timeout=None if waiting else 0, return_when=FIRST_COMPLETED)
            if not done:
                return
            broken = []
            for f in done:
                p = pending.pop(f)
                try:
                    entries[p.shard] = f.result()
                    _check_written(out, p.shard, sha)
                except BrokenProcessPool:
                    broken.append(p)
                    continue
                except Exception as exc:  # noqa: BLE001 - retried, then reported
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

    import time

    from simulate.contact import CONTACT_STAGES
    from simulate.run import episode_ids_of_shard

    LAST_RUN_SECONDS.clear()
    seconds = LAST_RUN_SECONDS

    def add(key: str, t0: float) -> None:
        seconds[key] = seconds.get(key, 0.0) + time.perf_counter() - t0

    groups = _groups(cfg, todo, worlds or FEED_WORLDS)
    # the worlds step in their own processes, batches ahead of the load field + sensor chain here (kinds with
    # their own contact stage run it here)
    physics = None if cfg.protocol.kind in CONTACT_STAGES else ProcessPoolExecutor(PHYSICS_PROCESSES, mp_context=ctx)

    def step(b: int):
        return physics.submit(step_worlds, cfg, [k for s in groups[b] for k in episode_ids_of_shard(cfg, s)], threads)

    try:
        ahead = [step(b) for b in range(min(PHYSICS_PROCESSES, len(groups)))] if physics else []
        for b, group in enumerate(groups):
            t0 = time.perf_counter()
            collect(b - MAX_PENDING_BATCHES)  # bounded memory: at most MAX_PENDING_BATCHES batches not yet written
            add("wait for writers", t0)
            stepped = None
            if physics:
                t0 = time.perf_counter()
                try:
                    stepped = ahead.pop(0).result()
                except BrokenProcessPool:
                    raise RuntimeError(f"the physics process died stepping shards {group} (complete shards are kept: "
                                       "rerun to resume)") from None
                add("wait for physics", t0)
                if b + PHYSICS_PROCESSES < len(groups):
                    ahead.append(step(b + PHYSICS_PROCESSES))
            for p in produce(cfg, group, sensor, threads, seconds, stepped):
                batch_of[p.shard] = b
                submit(p)
        t0 = time.perf_counter()
        collect(len(todo))
        add("wait for writers", t0)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        if physics:
            physics.shutdown(wait=True, cancel_futures=True)
        for shard in list(blocks):
            release(PackedShard(shard))
    return entries
