"""The run loop: scene -> MuJoCo load field -> sensor chain -> HDF5 shards + manifest, resumable.

Episode k (global index) draws everything from `episode_seed(root_seed, k)`: its protocol (stream 0 of
the seed) and its readout noise (stream 1). A shard is a pure function of (config, shard index), so a
rerun skips complete shards and regenerates the first missing one; files appear whole or not at all.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scenes import SceneConfig, config_json
from sensors.base import LoadBatch, SensorModel
from sensors.data.manifest import (
    build_manifest,
    episode_seed,
    first_missing_shards,
    shard_path,
)
from sensors.data.recording import Channel, RecordingWriter
from sensors.registry import make_sensor
from simulate.contact.load_field import (
    CONTACT_STAGES,
    iter_load_batches,
    physics_engine,
    simulate_sensors_padded,
    world_groups,
)
from simulate.contact.mjcf import build_mjcf
from simulate.protocols.indenter import EpisodeProtocol, make_episode_protocol

LOAD_CHANNELS: dict[str, tuple[str, tuple[str, ...], str]] = {
    "time": ("s", ("time",), "sample time"),
    "target": ("m", ("time",), "commanded indenter displacement (m) or force (N)"),
    "position": ("m", ("time", "xyz"), "indenter position (lowest point), world frame"),
    "contact_force": ("N", ("time", "xyz"), "net MuJoCo contact force on the pad; z = compressive normal"),
    "deformation": ("m", ("time", "taxel"), "surface deflection of the pad, + into the pad"),
    "pressure": ("Pa", ("time", "taxel"), "normal pressure (Winkler distribution of the contact force)"),
    "shear": ("Pa", ("time", "taxel", "xy"), "tangential traction on the pad"),
}


@dataclass
class EpisodeResult:
    """Everything recorded for one episode: channel name -> (array [T, ...], units, dims, description)."""

    ep_id: str
    seed: int
    protocol: EpisodeProtocol
    channels: dict[str, Channel]


def simulate_episodes(
    cfg: SceneConfig, seeds: list[int], ids: list[str], sensor: SensorModel, threads: int = 1,
    indices: list[int] | None = None,
) -> list[EpisodeResult]:
    """Simulate episodes (any mix of lengths: grouped by length into batched rollouts). indices: the
    episodes' global indices (seeds[i] = episode_seed(root_seed, indices[i])), for kinds that sweep."""
    results: dict[int, EpisodeResult] = {}
    for pos, protos, arrays in simulate_slices(cfg, seeds, sensor, threads, indices):
        for j, i in enumerate(pos):
            results[i] = EpisodeResult(ids[i], seeds[i], protos[j], episode_channels(arrays, j))
    return [results[i] for i in range(len(seeds))]


@dataclass
class ChannelArray:
    """One recorded channel of a slice of episodes: data (E, T, ...) (per_episode) or (T, ...) shared by all."""

    data: np.ndarray
    units: str
    dims: tuple[str, ...]
    description: str
    per_episode: bool = True


def simulate_slices(
    cfg: SceneConfig, seeds: list[int], sensor: SensorModel, threads: int = 1, indices: list[int] | None = None,
    protos: list[EpisodeProtocol] | None = None, physics: dict[int, tuple[np.ndarray, np.ndarray]] | None = None,
    pieces: int = 1,
) -> Iterator[tuple[list[int], list[EpisodeProtocol], dict[str, ChannelArray]]]:
    """Simulate the episodes of `seeds` and yield their recorded channels slice by slice: (positions in
    seeds, their protocols, channel name -> ChannelArray). Episodes of one length run as one batch of worlds
    (MuJoCo Warp) or one rollout (C MuJoCo); on the GPU the load field and sensor chain then go per
    SENSOR_SLICE episodes, with the taxel fields left on the device for a sensor that takes them.
    protos, physics: the episodes' protocols and, per length, (sensordata, target) of its `length_groups`
    entry, made elsewhere (the GPU feed steps the worlds in another process). pieces: on the GPU, each length
    group in at least this many slices (at most SENSOR_SLICE episodes each), so the GPU feed can hand on the
    shards finished by the first ones while the rest run."""
    protos = protos or episode_protocols(cfg, seeds, indices)
    engine, engine_device = physics_engine(cfg)
    gpu = engine == "mujoco_warp"
    on_device = engine_device if gpu and getattr(sensor, "device_load", False) and sensor.device == engine_device else None
    for run in physics_runs(cfg, protos):
        padded = None
        if physics is None and len(run) > 1:  # small groups of mixed lengths: one padded batch of worlds
            padded = simulate_sensors_padded(cfg, [protos[i] for _, idx in run for i in idx], threads)
        for n, idx in run:
            done = physics[n] if physics is not None else None if padded is None else padded.pop(n)
            per = min(SENSOR_SLICE, max(1, -(-len(idx) // max(1, pieces))))
            for sl, batch in iter_load_batches(cfg, [protos[i] for i in idx], threads, per if gpu else None, on_device, done):
                part = idx[sl]
                out = run_sensor(cfg, sensor, batch if on_device else batch.on_host(), [seeds[i] for i in part],
                                 [protos[i] for i in part])
                batch = recorded_fields_on_host(cfg, batch)
                yield part, [protos[i] for i in part], channel_arrays(batch, out, cfg, sensor)


def episode_protocols(cfg: SceneConfig, seeds: list[int], indices: list[int] | None = None) -> list[EpisodeProtocol]:
    """The episodes' protocols; with a scene `randomize` section each episode's draws (from its seed) go into
    its protocol (protocol.* paths, the placement) and into ``params['randomized']`` (recorded, and used by
    `run_sensor` for the sensor.* paths)."""
    from dataclasses import replace

    from scenes.scene_randomize import PLACEMENT, draw, with_values

    out = []
    for i, s in enumerate(seeds):
        vals = draw(cfg, s)
        c = with_values(cfg, {k: v for k, v in vals.items() if k.startswith("protocol.")})
        p = make_episode_protocol(c, s, None if indices is None else indices[i])
        if vals:
            off = np.array(p.offset_xy_m, dtype=float)
            for ax, key in enumerate(PLACEMENT):
                if key in vals:
                    off[ax] = vals[key]
            p = replace(p, offset_xy_m=off, params={**p.params, "randomized": vals})
        out.append(p)
    return out


def _episode_slice(batch: LoadBatch, j: int) -> LoadBatch:
    return _episodes(batch, slice(j, j + 1))


def _episodes(batch: LoadBatch, e: slice) -> LoadBatch:
    from dataclasses import replace

    return replace(batch, target=batch.target[e], indenter_pos_m=batch.indenter_pos_m[e], contact_force_n=batch.contact_force_n[e],
                   contact_points=batch.contact_points[e], deformation_m=batch.deformation_m[e], pressure_pa=batch.pressure_pa[e],
                   shear_pa=batch.shear_pa[e])


def run_sensor(cfg: SceneConfig, sensor: SensorModel, batch: LoadBatch, seeds: list[int], protos: list[EpisodeProtocol]) -> dict[str, np.ndarray]:
    """The sensor chain over a batch; episodes whose scene draws set sensor.* paths run one by one through a
    sensor built from their own scene (the same seeds, so an episode's output does not depend on its batch)."""
    from scenes.scene_randomize import with_values

    own = [{k: v for k, v in p.params.get("randomized", {}).items() if k.startswith("sensor.")} for p in protos]
    if not any(own):
        return sensor.run_load(batch, seeds)
    batch = batch.on_host()
    parts = []
    for j, vals in enumerate(own):
        sj = make_sensor(with_values(cfg, vals), sensor.backend, sensor.device) if vals else sensor
        parts.append(sj.run_load(_episode_slice(batch, j), [seeds[j]]))
    return {k: np.concatenate([p[k] for p in parts], axis=0) for k in parts[0]}


def length_groups(protos: list[EpisodeProtocol]) -> list[tuple[int, list[int]]]:
    """(n_samples, positions) of the episodes of each length, shortest first: one batch of worlds each."""
    return [(n, [i for i, p in enumerate(protos) if p.n_samples == n]) for n in sorted({p.n_samples for p in protos})]


def physics_runs(cfg: SceneConfig, protos: list[EpisodeProtocol]) -> list[list[tuple[int, list[int]]]]:
    """The `length_groups` of the episodes, as runs of the physics: each length alone on C MuJoCo and for
    kinds with their own contact stage; on MuJoCo Warp, small groups merged into padded batches of worlds
    (`simulate.contact.load_field.world_groups`)."""
    groups = length_groups(protos)
    if physics_engine(cfg)[0] != "mujoco_warp" or cfg.protocol.kind in CONTACT_STAGES:
        return [[g] for g in groups]
    return world_groups(groups)


def recorded_fields_on_host(cfg: SceneConfig, batch: LoadBatch) -> LoadBatch:
    """The batch with the taxel fields that generation.record keeps as float32 on the host (the others empty):
    a batch whose fields are on the device gets them rounded there and copied back through page-locked buffers
    as their non-zero taxel blocks (`simulate.contact.field_blocks`: a `BlockSparse` whose episode rows are the
    host's astype(float32), byte for byte; a field with most blocks non-zero comes whole, as a numpy array); a
    host batch is returned as it is."""
    if not batch.fields_on_device:
        return batch
    from dataclasses import replace

    from simulate.contact.load_field_kernels import fields_f32_blocks_to_host

    keep = cfg.generation.record
    E, T = batch.target.shape
    names = {"deformation": "deformation_m", "pressure": "pressure_pa", "shear": "shear_pa"}
    want = [k for k in names if keep is None or k in keep]
    shapes = {"deformation": (E, T, -1), "pressure": (E, T, -1), "shear": (E, T, -1, 2)}
    got = fields_f32_blocks_to_host({k: getattr(batch, names[k]) for k in want}, {k: shapes[k] for k in want})
    empty = {"deformation": np.empty((E, T, 0), np.float32), "pressure": np.empty((E, T, 0), np.float32),
             "shear": np.empty((E, T, 0, 2), np.float32)}
    return replace(batch, **{names[k]: got.get(k, empty[k]) for k in names})


def _records_fields(cfg: SceneConfig) -> bool:
    keep = cfg.generation.record
    return keep is None or bool({"deformation", "pressure", "shear"} & set(keep))


def channel_arrays(batch: LoadBatch, out: dict[str, np.ndarray], cfg: SceneConfig, sensor: SensorModel) -> dict[str, ChannelArray]:
    """The recorded channels of a batch (generation.record, default all), in file order: load channels, then
    the sensor's outputs; float32 except time (float64) and the sensor's own dtypes."""
    from simulate.contact.load_field import as_float32  # the cast of a large slice split over threads

    arrays = {  # made only for the channels kept (the taxel fields may still be on the device otherwise)
        "time": lambda: batch.time_s.astype(np.float64),
        "target": lambda: as_float32(batch.target),
        "position": lambda: as_float32(batch.indenter_pos_m),
        "contact_force": lambda: as_float32(batch.contact_force_n),
        "deformation": lambda: as_float32(batch.deformation_m),  # float32 already on the GPU path
        "pressure": lambda: as_float32(batch.pressure_pa),
        "shear": lambda: as_float32(batch.shear_pa),
    }
    keep = cfg.generation.record
    ch = {}
    for name, make in arrays.items():
        if keep is not None and name not in keep:
            continue
        units, dims, desc = LOAD_CHANNELS[name]
        if name == "target" and cfg.protocol.control == "force":
            units = "N"
        ch[name] = ChannelArray(make(), units, dims, desc, per_episode=name != "time")
    for name, spec in sensor.outputs.items():
        if keep is None or name in keep:
            ch[name] = ChannelArray(out[name], spec.units, spec.dims, spec.description)
    return ch


def episode_channels(arrays: dict[str, ChannelArray], j: int) -> dict[str, Channel]:
    """Episode j's channels (views) of a slice's channel arrays."""
    return {name: Channel(c.data[j] if c.per_episode else c.data, c.units, c.dims, c.description) for name, c in arrays.items()}


def check_record(cfg: SceneConfig) -> None:
    """generation.record must name channels this scene produces (ValueError naming the allowed ones)."""
    from sensors.registry import sensor_class

    keep = cfg.generation.record
    if keep is None:
        return
    allowed = list(LOAD_CHANNELS) + list(sensor_class(cfg.sensor.family).outputs)
    bad = [k for k in keep if k not in allowed]
    if bad or not keep:
        raise ValueError(f"generation.record: unknown channel(s) {bad or '(empty list)'}; allowed: {', '.join(allowed)}")


def episode_ids_of_shard(cfg: SceneConfig, shard: int) -> list[int]:
    g = cfg.generation
    return list(range(shard * g.episodes_per_shard, min(g.episodes, (shard + 1) * g.episodes_per_shard)))


def n_shards(cfg: SceneConfig) -> int:
    g = cfg.generation
    return -(-g.episodes // g.episodes_per_shard)


PIPELINE_PARTS = 4  # a shard is simulated in up to this many batches; batch i is written while batch i+1 runs
MIN_BATCH = 4  # ... of at least this many episodes


GPU_BATCH = 16384  # MuJoCo Warp worlds per batch: 1.24e7 world-steps/s on an H100 (6.6e6 at 4096, 1.6e7 at 32k)
SENSOR_SLICE = 4096  # episodes per load field + sensor chain pass on the GPU (bounds its device memory)


def shard_batches(n_episodes: int, max_batch: int | None = None) -> list[slice]:
    """Contiguous batches of a shard's episodes: up to PIPELINE_PARTS, each >= MIN_BATCH episodes; with
    max_batch (batched GPU worlds), as few batches of at most max_batch as cover the shard."""
    size = max(MIN_BATCH, -(-n_episodes // PIPELINE_PARTS))
    if max_batch is not None:
        size = min(max_batch, n_episodes)
    return [slice(a, min(n_episodes, a + size)) for a in range(0, n_episodes, size)]


def _episode_attrs(r: EpisodeResult, k: int) -> dict:
    return episode_attrs(r.seed, r.protocol, k)


def episode_attrs(seed: int, protocol: EpisodeProtocol, k: int) -> dict:
    """/episodes/<id> attrs of episode k (global index)."""
    return {
        "seed": seed,
        "global_index": k,
        "frequency_hz": protocol.frequency_hz,
        "amplitude": protocol.amplitude,
        "amplitude_units": "N" if protocol.control == "force" else "m",
        "offset_xy_m": np.asarray(protocol.offset_xy_m),
        "n_samples": protocol.n_samples,
        "control": protocol.control,
        "kind": protocol.kind,
        **{f"rand.{k}": float(v) for k, v in sorted(protocol.params.get("randomized", {}).items())},
    }


def write_shard(
    cfg: SceneConfig, out_dir: Path, shard: int, sensor: SensorModel, mjcf: str, *, threads: int | None = None
) -> Path:
    """Generate and atomically write one shard (a pure function of config and shard index).

    The shard's episodes run in contiguous batches (`shard_batches`); a writer thread writes and compresses
    batch i into the shard file while batch i+1 is simulated (MuJoCo and the Warp kernels release the GIL),
    so on a free core the HDF5 write costs no wall time, and at most two batches are held in memory.
    An episode's channels do not depend on the batch it runs in. threads: MuJoCo rollout threads (default
    generation.threads); it does not change the output either.
    """
    from concurrent.futures import ThreadPoolExecutor

    g = cfg.generation
    gids = episode_ids_of_shard(cfg, shard)
    seeds = [episode_seed(g.root_seed, k) for k in gids]
    ids = [f"ep-{k:06d}" for k in gids]
    engine, _ = physics_engine(cfg)
    writer = shard_writer(cfg, out_dir, shard, shard_sensor_attrs(cfg, sensor), mjcf)

    def write(results: list[EpisodeResult], ks: list[int]) -> None:
        for r, k in zip(results, ks):
            w.add_episode(r.ep_id, r.channels, _episode_attrs(r, k))

    with writer as w, ThreadPoolExecutor(1, thread_name_prefix="shard-writer") as pool:
        pending = None
        try:
            for sl in shard_batches(len(gids), GPU_BATCH if engine == "mujoco_warp" else None):
                results = simulate_episodes(cfg, seeds[sl], ids[sl], sensor, threads=g.threads if threads is None else threads,
                                            indices=gids[sl])
                if pending is not None:
                    pending.result()  # one batch in flight: bounded memory, errors surface here
                pending = pool.submit(write, results, gids[sl])
                del results
            pending.result()
        except BaseException:
            if pending is not None:  # let the writer stop touching the file before it is discarded
                pending.cancel()
                try:
                    pending.result()
                except BaseException:  # noqa: BLE001 - the first error is the one raised
                    pass
            raise
    return writer.path


def shard_sensor_attrs(cfg: SceneConfig, sensor: SensorModel) -> dict:
    """/sensor attrs of a shard: the sensor's own plus the taxel positions (m)."""
    from sensors.taxels import taxel_xy_m

    return {**sensor.attrs(), "taxel_xy_m": taxel_xy_m(cfg)}


def shard_writer(cfg: SceneConfig, out_dir: Path, shard: int, sensor_attrs: dict, mjcf: str) -> RecordingWriter:
    """The (atomic) RecordingWriter of one shard, with its provenance attributes."""
    g = cfg.generation
    engine, engine_device = physics_engine(cfg)
    return RecordingWriter(
        shard_path(out_dir, shard),
        source="sim",
        config_json=config_json(cfg),
        root_seed=g.root_seed,
        shard_index=shard,
        sensor_attrs=sensor_attrs,
        mjcf=mjcf,
        compression=g.compression,
        # the contact engine that ran (generation.physics may say "auto"); MuJoCo Warp on a GPU is float32 and
        # may sum with GPU atomics, so its shards are not guaranteed bit-reproducible (C MuJoCo's are)
        extra_attrs={"physics_engine": engine, "physics_device": engine_device},
    )


def config_sha256(cfg: SceneConfig) -> str:
    import hashlib

    return hashlib.sha256(config_json(cfg).encode()).hexdigest()


def generate(
    cfg: SceneConfig,
    out_dir: str | Path,
    *,
    backend: str = "warp",
    device: str = "cpu",
    on_shard: Callable[[int, int, bool], None] | None = None,
) -> Path:
    """Generate the dataset into out_dir (created), resuming at missing shards; returns manifest path.

    on_shard(shard_index, n_episodes, skipped) is called after each shard (for progress bars).
    This is the serial path; simulate.generation.executors.generate spreads shards over processes or a Ray cluster.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ns = n_shards(cfg)
    sha = config_sha256(cfg)
    todo = set(first_missing_shards(out, ns, sha))
    check_record(cfg)
    sensor = make_sensor(cfg, backend, device)
    mjcf = build_mjcf(cfg)
    for s in range(ns):
        if s in todo:
            write_shard(cfg, out, s, sensor, mjcf)
        if on_shard:
            on_shard(s, len(episode_ids_of_shard(cfg, s)), s not in todo)
    return write_dataset_manifest(cfg, out)


def write_dataset_manifest(cfg: SceneConfig, out_dir: str | Path, described: dict[int, dict] | None = None) -> Path:
    """Describe the (complete) shards of cfg's dataset in out_dir and write manifest.json (the driver's job);
    described: manifest entries the writers already made (sensors.data.manifest.shard_entry)."""
    return build_manifest(
        Path(out_dir),
        name=cfg.name,
        n_shards=n_shards(cfg),
        episodes_per_shard=cfg.generation.episodes_per_shard,
        config_sha256=config_sha256(cfg),
        root_seed=cfg.generation.root_seed,
        extra={"paper": cfg.paper, "family": cfg.sensor.family, "episodes": cfg.generation.episodes},
        described=described,
    )
