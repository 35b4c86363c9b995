"""Generation over many processes or machines: shards as independent tasks, the driver writes the manifest.

A shard is a pure function of (config, shard index) (`simulate.generation.run.write_shard`): its episodes draw from
`episode_seed(root_seed, k)` only, so a dataset made by 1 process, a local pool of W processes or a Ray
cluster holds the same per-episode channels, byte for byte. Each task writes its own shard atomically
(`*.tmp`, renamed when whole); the driver skips shards already complete (resume), checks each finished
shard, and writes `manifest.json` last.

Executors (`generate(..., executor=...)`):

- ``"local"`` with ``workers == 1``: the serial loop of `simulate.generation.run.generate` in this process.
- ``"local"`` with ``workers > 1``: a `concurrent.futures.ProcessPoolExecutor` (spawn context). A worker
  that dies (killed, segfault, out of memory) breaks the pool; the driver starts a new pool and resubmits
  the unfinished shards. A shard that raises is retried too. Each shard gets at most ``1 + max_retries``
  attempts; after that `ShardFailedError` names it (the shards already written stay, a rerun resumes).
- ``"ray"``: one `@ray.remote(max_retries=..., retry_exceptions=True)` task per shard, on the cluster at
  ``address`` (`ray.init(address=...)`) or on a local one started here with ``workers`` CPUs. Ray is an
  optional extra (``pip install 'piezotwin[ray]'``). On a real cluster every node needs piezotwin
  installed and ``out_dir`` on storage all nodes share.

GPUs: with one GPU and the contact stage on MuJoCo Warp there, ``"local"`` with ``workers > 1`` runs the GPU
feed (`simulate.generation.feed`): this process steps the episodes of several shards as one big batch of worlds and W
writer processes write the shards (same files; ``feed=False`` forces the per-shard workers). With several
GPUs the local pool pins worker k to GPU k mod n (through CUDA_VISIBLE_DEVICES, set before the worker imports
Warp), so W workers spread over all GPUs of the host.

MuJoCo rollout threads per worker: ``threads`` (default ``generation.threads // workers``, at least 1);
they do not change the output (each rollout trajectory is deterministic on its own).

Fault injection for tests (read in the worker): ``PIEZOTWIN_FAULT_SHARD=k`` and
``PIEZOTWIN_FAULT_MARKER=<path>`` make the first attempt at shard k fail (the marker file records that it
happened, so the retry succeeds); ``PIEZOTWIN_FAULT_MODE=exit`` (default) kills the worker process
(`os._exit`), ``raise`` raises an exception.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Callable

from scenes import SceneConfig
from sensors.data.manifest import first_missing_shards
from simulate.generation.feed import release_prestarted
from simulate.generation.shards import ShardFailedError, check_written, maybe_inject_fault

EXECUTORS = ("local", "ray")
DEFAULT_MAX_RETRIES = 3

__all__ = ["EXECUTORS", "ShardFailedError", "generate", "shard_task"]


# --------------------------------------------------------------------------- worker side

_CACHE: dict[tuple, tuple] = {}  # per worker process: (config sha, backend, device) -> (sensor, mjcf)


def shard_task(
    cfg: SceneConfig, out_dir: str, shard: int, backend: str = "warp", device: str = "cpu", threads: int = 1
) -> tuple[int, int, float]:
    """Generate shard `shard` into `out_dir` (in whatever process runs this); returns (shard, episodes, seconds).

    The sensor model and MJCF are built once per process and config, then reused across shards.
    """
    from simulate.generation.run import config_sha256, episode_ids_of_shard, write_shard

    t0 = time.perf_counter()
    maybe_inject_fault(shard)
    key = (config_sha256(cfg), backend, device)
    if key not in _CACHE:
        from sensors.registry import make_sensor
        from sensors.warp_setup import init_warp
        from simulate.contact.mjcf import build_mjcf

        if backend == "warp":
            init_warp()
        _CACHE.clear()
        _CACHE[key] = (make_sensor(cfg, backend, device), build_mjcf(cfg))
    sensor, mjcf = _CACHE[key]
    write_shard(cfg, Path(out_dir), shard, sensor, mjcf, threads=threads)
    return shard, len(episode_ids_of_shard(cfg, shard)), time.perf_counter() - t0


# --------------------------------------------------------------------------- driver side


def generate(
    cfg: SceneConfig,
    out_dir: str | Path,
    *,
    executor: str = "local",
    workers: int = 1,
    address: str | None = None,
    backend: str = "warp",
    device: str = "cpu",
    threads: int | None = None,
    max_retries: int = DEFAULT_MAX_RETRIES,
    on_shard: Callable[[int, int, bool], None] | None = None,
    feed: bool | None = None,
) -> Path:
    """Generate the dataset of `cfg` into `out_dir` with the chosen executor; returns the manifest path.

    on_shard(shard_index, n_episodes, skipped) is called in the driver as each shard finishes (skipped
    shards first), in completion order. feed: simulate here and write in `workers` processes (default: with
    MuJoCo Warp on a single GPU; see the module docstring).
    """
    import time

    from simulate.generation import run

    LAST_GENERATE_SECONDS.clear()
    t0 = time.perf_counter()
    if executor not in EXECUTORS:
        raise ValueError(f"executor must be one of {', '.join(EXECUTORS)} (got {executor!r})")
    if workers < 1:
        raise ValueError(f"workers must be >= 1 (got {workers})")
    if max_retries < 0:
        raise ValueError(f"max_retries must be >= 0 (got {max_retries})")
    run.check_record(cfg)
    if executor == "local" and workers == 1:
        release_prestarted()
        return run.generate(cfg, out_dir, backend=backend, device=device, on_shard=on_shard)

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ns = run.n_shards(cfg)
    sha = run.config_sha256(cfg)
    todo = first_missing_shards(out, ns, sha)
    for s in range(ns):
        if s not in todo and on_shard:
            on_shard(s, len(run.episode_ids_of_shard(cfg, s)), True)
    if threads is None:
        threads = max(1, cfg.generation.threads // workers) if executor == "local" else 1
    described = None
    if todo:
        kw = dict(backend=backend, device=device, threads=threads)
        use_feed = executor == "local" and (feed if feed is not None else _feed_by_default(cfg))
        t1 = time.perf_counter()
        LAST_GENERATE_SECONDS["checks, imports"] = t1 - t0
        if use_feed:
            from simulate.generation.feed import generate_feed

            described = generate_feed(cfg, out, todo, workers, max_retries=max_retries, on_shard=on_shard, **kw)
        else:
            release_prestarted()
            if executor == "local":
                _run_local(cfg, out, todo, workers, max_retries, on_shard, kw)
            else:
                _run_ray(cfg, out, todo, workers, address, max_retries, on_shard, kw)
        t0 = time.perf_counter()
        LAST_GENERATE_SECONDS["shards"] = t0 - t1
    else:
        release_prestarted()
    path = run.write_dataset_manifest(cfg, out, described)
    LAST_GENERATE_SECONDS["manifest"] = time.perf_counter() - t0
    return path


# where the last multi-worker `generate` of this process spent its time (for bench/): "checks, imports" (config,
# finished shards, the executor's choice), "shards", "manifest"
LAST_GENERATE_SECONDS: dict[str, float] = {}


def _feed_by_default(cfg: SceneConfig) -> bool:
    """The GPU feed pays off where the contact stage runs on MuJoCo Warp on the only GPU."""
    from simulate.contact.load_field import physics_engine

    engine, device = physics_engine(cfg)
    return engine == "mujoco_warp" and device.startswith("cuda") and _cuda_device_count() == 1


def _cuda_device_count() -> int:
    from sensors.warp_setup import init_warp

    init_warp()
    import warp as wp

    return wp.get_cuda_device_count()


def _pin_gpu(counter, n_gpus: int) -> None:
    """Pool initializer (before the worker imports Warp): this worker uses GPU k mod n_gpus only."""
    with counter.get_lock():
        k = counter.value
        counter.value += 1
    visible = os.environ.get("CUDA_VISIBLE_DEVICES")
    ids = visible.split(",") if visible else [str(i) for i in range(n_gpus)]
    os.environ["CUDA_VISIBLE_DEVICES"] = ids[k % len(ids)]


def _run_local(cfg, out: Path, todo: list[int], workers: int, max_retries: int, on_shard, kw: dict) -> None:
    """At most `workers` shards in flight; a dead worker breaks the pool: its in-flight shards are retried
    in a new pool (each in-flight shard is charged one attempt, as it cannot be told which one died). A pool that
    broke before a submit refuses it: that shard never ran, is not charged, and goes to the next pool."""
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    from simulate.generation.run import config_sha256

    sha = config_sha256(cfg)
    queue = list(todo)
    attempts = {s: 0 for s in todo}
    ctx = mp.get_context("spawn")

    def failed(s: int, msg: str) -> None:
        if attempts[s] > max_retries:
            raise ShardFailedError(
                f"shard {s}: failed {attempts[s]} time(s); last error: {msg} (complete shards are kept: rerun to resume)"
            )
        queue.insert(0, s)

    pin = {}
    n_gpus = _cuda_device_count() if str(kw.get("device", "cpu")).startswith("cuda") else 0
    if n_gpus > 1:  # spread the workers over the GPUs: worker k sees only GPU k mod n as its cuda:0
        pin = dict(initializer=_pin_gpu, initargs=(ctx.Value("i", 0), n_gpus))
        kw = {**kw, "device": "cuda:0"}
    while queue:
        pool = ProcessPoolExecutor(max_workers=min(workers, len(queue)), mp_context=ctx, **pin)
        try:
            futs: dict = {}
            broken = False
            while True:
                while not broken and queue and len(futs) < workers:
                    s = queue[0]
                    try:  # a worker may die between two results: the pool then refuses new work
                        futs[pool.submit(shard_task, cfg, str(out), s, **kw)] = s
                    except BrokenProcessPool:
                        broken = True  # s never ran: it stays first in the queue for the next pool
                        break
                    queue.pop(0)
                    attempts[s] += 1
                if not futs:
                    break
                done, _ = wait(futs, return_when=FIRST_COMPLETED)
                for f in sorted(done, key=futs.get):
                    s = futs.pop(f)
                    try:
                        _, n, _ = f.result()
                        check_written(out, s, sha)
                    except BrokenProcessPool:
                        broken = True
                        failed(s, "the worker process died")
                        continue
                    except Exception as exc:  # noqa: BLE001 - retried, then reported
                        failed(s, f"{type(exc).__name__}: {exc}")
                        continue
                    if on_shard:
                        on_shard(s, n, False)
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _run_ray(cfg, out: Path, todo: list[int], workers: int, address, max_retries: int, on_shard, kw: dict) -> None:
    try:
        import ray
    except ImportError:
        raise RuntimeError("executor 'ray' needs Ray: pip install 'piezotwin[ray]' (or pip install ray)") from None
    from simulate.generation.run import config_sha256

    started_here = False
    if not ray.is_initialized():
        init_kw: dict = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
        if address:
            ray.init(address=address, **init_kw)
        else:
            ray.init(num_cpus=workers, **init_kw)
        started_here = True
    try:
        sha = config_sha256(cfg)
        task = ray.remote(num_cpus=1, max_retries=max_retries, retry_exceptions=True)(shard_task)
        cfg_ref = ray.put(cfg)
        refs = {task.remote(cfg_ref, str(out), s, **kw): s for s in todo}
        while refs:
            done, _ = ray.wait(list(refs), num_returns=1)
            s = refs.pop(done[0])
            try:
                _, n, _ = ray.get(done[0])
                check_written(out, s, sha)
            except Exception as exc:  # noqa: BLE001 - Ray already retried it max_retries times
                for r in refs:
                    ray.cancel(r)
                raise ShardFailedError(
                    f"shard {s}: failed {1 + max_retries} time(s) on Ray; last error: {type(exc).__name__}: "
                    f"{str(exc).splitlines()[0] if str(exc) else ''} (complete shards are kept: rerun to resume)"
                ) from exc
            if on_shard:
                on_shard(s, n, False)
    finally:
        if started_here:
            ray.shutdown()
