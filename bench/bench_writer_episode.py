"""The shard writer's cost per episode, split by part, per family's default preset and compression, at two revisions.

    python bench/bench_writer_episode.py [--base 344a0a0] [--families cnt_pdms,fabric_1,velostat,ntype]
                                         [--codecs lzf,lz4,zstd,none] [--repeats 3] [--tag cpu]

Episodes of each preset's default protocol and record (C MuJoCo, numpy sensor chain; cnt_pdms one episode per
frequency of its preset, so the mean length is the preset's) are simulated once and cached (``--cache``). Then one
shard of the preset's ``episodes_per_shard`` episodes (the simulated ones cycled under new ids and global indices)
is written as a shard writer writes it (`RecordingWriter.add_episode`, then the manifest entry), with each
compression, in a fresh process per (revision, family, compression, repeat), interleaved; best of ``repeats``. Each
process writes the shard twice and times the second (a writer process of the GPU feed writes shard after shard).
``--base REV`` runs the same at an earlier commit (a temporary `git worktree`; its default Blosc2 threads, i.e. the
environment as given) beside this checkout. Per episode, split by part:

- "objects, attributes": copying the episode's cached group (`_Template`: group, datasets, attributes) and writing
  the attributes that changed;
- "data": writing the channels' arrays (chunking, shuffle + compression, Fletcher-32, the writes to the file);
- "digest": the episode's part of the content hash (`_episode_digest`: SHA-256 over its data and attributes);
- "other": the rest of `add_episode` (checks, attribute encoding, the template lookup);
- "close": the shard's content hash, closing the file (HDF5 metadata), fsync and rename (per episode);
- "manifest": the manifest entry the writer makes (`shard_entry`: SHA-256 of the file's bytes; per episode).

The parts are the writer process's CPU time (`time.process_time`, all its threads: Blosc2's too; robust to other
jobs on a shared machine; HDF5's writes into the page cache count, the disk's fsync wait does not), "total" their
sum, "wall" the wall time of the same (close, fsync and manifest included).

Stacked estimate (this checkout, the scaling codec): the same shard's episodes of one length written as a layout
the format does not have, to price the next step: one dataset per channel holding all of them (episodes, time, ...),
one stack per episode length, chunks of one episode (and <= 1 MiB, as above), the per-episode attributes as columns, the same per-episode content digests; CPU per
episode, same process and conditions, closing the file but no fsync and no manifest entry: compare it with the parts
before "close" ("stacked_estimate" in the file; not a format, nothing reads it).

Scaling (``--scale-codec``, default lz4; this checkout only): ``--scale-shards`` shards of each family written by
W = 1 and W = ``os.cpu_count()`` writer processes at once (spawned, one shard per task, as the GPU feed's pool),
wall time from the first submit to the last file, best of ``repeats``; speedup = wall(1) / wall(W). Also bytes per episode on disk against the channels' raw bytes. Writes bench/results/writer-episode-<tag>.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CODECS = ("lzf", "lz4", "zstd", "none")
_clock = time.process_time
PARTS = ("objects, attributes", "data", "digest", "other", "close", "manifest")


def episodes_of(fam: str, cache: Path) -> tuple[list[tuple[str, dict, dict]], int]:
    """((id, channels, attrs) of the cached episodes of a family's preset, its episodes_per_shard); simulated and
    cached if absent. The cache is a recording of the project's own format (uncompressed; the channels' order and
    episodes_per_shard in its root attributes), read back through `Recording`."""
    from sensors.data.recording import Recording, RecordingWriter

    path = cache / f"{fam}.h5"
    if path.exists():
        with Recording(path) as rec:
            order = rec.attrs["bench_channel_order"]
            eps = [(ep, {name: rec.channel(ep, name) for name in order[ep]}, rec.episode_attrs(ep))
                   for ep in rec.episode_ids]
            return with_feed_hints(eps), int(rec.attrs["bench_episodes_per_shard"])
    from scenes import load_scene
    from sensors.data.manifest import episode_seed
    from sensors.registry import make_sensor
    from simulate.generation.run import _episode_attrs, simulate_episodes

    cfg = load_scene(fam, [])
    freqs = cfg.protocol.frequencies_hz if cfg.protocol.kind == "sinusoid" else [None]
    eps = []
    for k, f in enumerate(freqs):
        c = load_scene(fam, [f"protocol.frequencies_hz=[{f}]"] if f is not None else [])
        seed = episode_seed(0, k)
        r = simulate_episodes(c, [seed], [f"ep-{k:06d}"], make_sensor(c, "numpy", "cpu"), indices=[k])[0]
        eps.append((r.ep_id, r.channels, _episode_attrs(r, k)))
    cache.mkdir(parents=True, exist_ok=True)
    extra = {"bench_channel_order": {ep: list(ch) for ep, ch, _ in eps},
             "bench_episodes_per_shard": int(cfg.generation.episodes_per_shard)}
    with RecordingWriter(path, source="sim", config_json="{}", root_seed=0, shard_index=0, sensor_attrs={},
                         extra_attrs=extra, compression="none") as w:
        for ep, ch, attrs in eps:
            w.add_episode(ep, ch, attrs)
    return with_feed_hints(eps), cfg.generation.episodes_per_shard


def with_feed_hints(eps: list) -> list:
    """The episodes as the GPU feed hands them to its writers: a taxel field it would send as its non-zero blocks
    (`simulate.contact.field_blocks`: at most SPARSE_MAX_SHARE of its blocks loaded) carries their flags
    (`Channel.nonzero_blocks`, since session 27), computed here by the numpy reference of the device's flag kernel
    (not timed: the device makes them). A revision whose Channel has no such field gets the episodes unchanged."""
    import dataclasses

    import numpy as np

    from sensors.data.recording import Channel

    if "nonzero_blocks" not in {f.name for f in dataclasses.fields(Channel)}:
        return eps
    from simulate.contact.field_blocks import FIELD_BLOCK, SPARSE_MAX_SHARE, blocks_of

    out = []
    for ep, ch, attrs in eps:
        ch = dict(ch)
        for name, c in ch.items():
            d = c.data
            if d.ndim >= 2 and d.dtype == np.float32 and len(c.dim_names) > 1 and c.dim_names[1] == "taxel":
                block, mask = blocks_of(d[None], FIELD_BLOCK).nonzero_blocks(0)
                if mask.mean() <= SPARSE_MAX_SHARE:
                    ch[name] = dataclasses.replace(c, nonzero_blocks=(block, mask))
        out.append((ep, ch, attrs))
    return out


def write_shard_timed(path: Path, eps: list, n: int, codec: str) -> dict[str, float]:
    """Write n episodes (eps cycled) into one shard as a shard writer does, timing each part (seconds)."""
    from sensors.data import recording as R
    from sensors.data.manifest import shard_entry

    parts = dict.fromkeys(PARTS, 0.0)
    orig_write, orig_digest = R._Template.write, R._episode_digest

    def timed_write(self, dest, ep_id, channels, arrays):  # `_Template.write`, objects and data timed apart
        t0 = _clock()
        R.h5o.copy(self.file.id, b"ep", dest.id, ep_id.encode())
        gid = R.h5g.open(dest.id, ep_id.encode())
        for key, arr in arrays.items():
            if R._value_key(arr) != self.values[key]:
                R.h5a.open(gid, key.encode()).write(arr, mtype=self.mtypes[key])
        t1 = _clock()
        for name, ch in channels.items():
            dsid = R.h5d.open(gid, name.encode())
            if hasattr(R, "_write_rows"):  # since session 18: all-zero chunks left unwritten (`rows`: its first
                # commits, before the taxel blocks, the base of writer-episode-cpu-s18-blocks.json)
                hint = getattr(ch, "nonzero_blocks", None)  # since session 27: the feed's flags of zero blocks
                R._write_rows(dsid, ch.data, self.chunks[name] if hasattr(self, "chunks") else self.rows[name],
                              *(() if hint is None else (hint,)))
            else:
                dsid.write(R.h5s.ALL, R.h5s.ALL, R.np.asarray(ch.data, order="C"))
        t2 = _clock()
        parts["objects, attributes"] += t1 - t0
        parts["data"] += t2 - t1

    def timed_digest(*a, **k):
        t0 = _clock()
        d = orig_digest(*a, **k)
        parts["digest"] += _clock() - t0
        return d

    R._Template.write, R._episode_digest = timed_write, timed_digest
    try:
        w = R.RecordingWriter(path, source="sim", config_json="{}", root_seed=0, shard_index=0,
                              sensor_attrs={"family": "x"}, mjcf="<mujoco/>", compression=codec)
        w0 = time.perf_counter()
        with w:
            t0 = _clock()
            for k in range(n):
                _, ch, attrs = eps[k % len(eps)]
                w.add_episode(f"ep-{k:06d}", ch, {**attrs, "global_index": k})
            t1 = _clock()
        t2 = _clock()
        shard_entry(path, [f"ep-{k:06d}" for k in range(n)], list(range(n)), "0" * 64)
        t3 = _clock()
        w3 = time.perf_counter()
    finally:
        R._Template.write, R._episode_digest = orig_write, orig_digest
    parts["other"] = (t1 - t0) - parts["objects, attributes"] - parts["data"] - parts["digest"]
    parts["close"] = t2 - t1
    parts["manifest"] = t3 - t2
    parts["total"] = t3 - t0
    parts["wall"] = w3 - w0
    return parts


def one(fam: str, codec: str, cache: Path, scratch: Path) -> dict:
    """One timed shard in this process (the code on sys.path): ms per episode by part, bytes per episode."""
    eps, n = episodes_of(fam, cache)
    p = scratch / f"{fam}-{codec}-{os.getpid()}.h5"
    try:
        write_shard_timed(p, eps, n, codec)  # a writer process writes shard after shard: the second one is timed
        parts = write_shard_timed(p, eps, n, codec)
        size = p.stat().st_size / n
    finally:
        p.unlink(missing_ok=True)
    return {"ms_per_episode": {k: 1e3 * v / n for k, v in parts.items()}, "bytes_per_episode": size,
            "episodes_per_shard": n, "blosc_nthreads_env": os.environ.get("BLOSC_NTHREADS")}


def stacked_estimate(fam: str, codec: str, cache: Path, scratch: Path) -> dict:
    """CPU ms per episode (and bytes) of the shard's same-length episodes written stacked (see the module docstring)."""
    import h5py
    import numpy as np

    from sensors.data import recording as R

    eps, n = episodes_of(fam, cache)
    rows = [(k, *eps[k % len(eps)]) for k in range(n)]  # the shard's episodes, as the v1 shard above
    lengths = sorted({r[2]["time"].data.shape[0] for r in rows})
    p = scratch / f"stacked-{fam}-{os.getpid()}.h5"
    best = float("inf")
    for _ in range(2):  # the second: warm
        t0 = _clock()
        with h5py.File(p, "w", libver=R._LIBVER) as f:
          for length in lengths:  # one stack per episode length
            group = [r for r in rows if r[2]["time"].data.shape[0] == length]
            g = f.create_group(f"stack-{length}")
            for name, c in group[0][2].items():
                a = np.stack([r[2][name].data for r in group])
                chunk = (R._chunk_len(a.shape[1], a[0, 0].nbytes),) + a.shape[2:] if a.ndim > 1 else ()
                kw = {"fletcher32": True}
                kw.update({"lzf": dict(compression="lzf", shuffle=True), "gzip": dict(compression="gzip", compression_opts=1, shuffle=True),
                           "none": {}}.get(codec) or R._blosc2(codec))
                ds = g.create_dataset(name, data=a, chunks=(1,) + chunk, **kw)
                ds.attrs["units"], ds.attrs["dim_names"], ds.attrs["description"] = c.units, json.dumps(list(c.dim_names)), c.description
            cols = g.create_group("_attrs")
            for key in group[0][3]:
                vals = [{**r[3], "global_index": r[0]}[key] for r in group]
                arr = np.array(vals, dtype=h5py.string_dtype()) if isinstance(vals[0], str) else np.asarray(vals)
                cols.create_dataset(key, data=arr)
            g.create_dataset("_ids", data=np.array([f"ep-{r[0]:06d}" for r in group], dtype=h5py.string_dtype()))
          for k, _, ch, attrs in rows:
                R._episode_digest(f"ep-{k:06d}", R._decoded_attrs(R._encode_attrs({**attrs, "global_index": k}, "x")),
                                  {nm: (c.data, c.units, c.dim_names, c.description) for nm, c in ch.items()})
        best = min(best, _clock() - t0)
    size = p.stat().st_size
    p.unlink()
    return {"codec": codec, "episodes": n, "ms_per_episode": 1e3 * best / n, "bytes_per_episode": size / n}


def _scale_task(fam: str, codec: str, cache: str, scratch: str, k: int) -> float:
    eps, n = episodes_of(fam, Path(cache))
    p = Path(scratch) / f"scale-{fam}-{k}.h5"
    t = time.perf_counter()
    write_shard_timed(p, eps, n, codec)
    dt = time.perf_counter() - t
    p.unlink()
    return dt


def scale(fam: str, codec: str, cache: Path, scratch: Path, shards: int, workers: int) -> float:
    """Wall seconds for `shards` shards written by `workers` spawned writer processes (started and warmed first)."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as pool:
        list(pool.map(_scale_task, [fam] * workers, [codec] * workers, [str(cache)] * workers, [str(scratch)] * workers,
                      range(workers)))  # start-up, imports, templates: not timed
        t = time.perf_counter()
        list(pool.map(_scale_task, [fam] * shards, [codec] * shards, [str(cache)] * shards, [str(scratch)] * shards,
                      range(shards)))
        return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--base", default=None, help="an earlier commit to measure beside this checkout")
    ap.add_argument("--families", default="cnt_pdms,fabric_1,velostat,ntype")
    ap.add_argument("--codecs", default=",".join(CODECS))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tag", default="cpu")
    ap.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "piezotwin-writer-episodes-v3")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    ap.add_argument("--stacked-only", action="store_true", help="only the stacked estimate, into the existing results file")
    ap.add_argument("--one", nargs=2, metavar=("FAMILY", "CODEC"), help=argparse.SUPPRESS)
    ap.add_argument("--scratch", type=Path, default=None, help="where the shards are written (default: beside results)")
    ap.add_argument("--scale-codec", default="lz4")
    ap.add_argument("--scale-shards", type=int, default=8)
    a = ap.parse_args()
    if a.one:
        print(json.dumps(one(*a.one, a.cache, a.scratch)))
        return
    if a.stacked_only:
        path = a.out / f"writer-episode-{a.tag}.json"
        res = json.loads(path.read_text())
        with tempfile.TemporaryDirectory(dir=ROOT / "bench") as tmp:
            for fam in a.families.split(","):
                got = min((stacked_estimate(fam, a.scale_codec, a.cache, Path(tmp)) for _ in range(a.repeats)),
                          key=lambda g: g["ms_per_episode"])
                res["families"][fam]["stacked_estimate"] = got
                print(f"{fam} stacked estimate ({a.scale_codec}): {got['ms_per_episode']:.2f} ms CPU/episode, "
                      f"{got['bytes_per_episode'] / 1e3:.0f} kB", flush=True)
        path.write_text(json.dumps(res, indent=1) + "\n")
        return
    env = dict(os.environ)  # as given: the base revision keeps Blosc2's default threads unless this sets them
    codecs, fams = a.codecs.split(","), a.families.split(",")
    subprocess.run([sys.executable, "-c", "import sys; sys.path.insert(0, '.');"
                    "from bench.bench_writer_episode import episodes_of; from pathlib import Path;"
                    + "".join(f"episodes_of({f!r}, Path({str(a.cache)!r}));" for f in fams)],
                   cwd=ROOT, env={**env, "PYTHONPATH": str(ROOT)}, check=True)  # simulate + cache once
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    dirty = bool(subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT, capture_output=True,
                                text=True).stdout.strip())
    res = {"host": platform.node(), "cpus": os.cpu_count(), "machine": f"this {os.cpu_count()}-core host",
           "head": head + ("+changes" if dirty else ""), "base": a.base, "repeats": a.repeats,
           "loadavg_at_start": list(os.getloadavg()), "families": {}}
    with tempfile.TemporaryDirectory() as tmp:
        revs = {"head": ROOT}
        if a.base:
            base = Path(tmp) / "base"
            subprocess.run(["git", "worktree", "add", "-q", "--detach", str(base), a.base], cwd=ROOT, check=True)
            revs["base"] = base
        scratch = a.scratch or Path(tempfile.mkdtemp(dir=ROOT / "bench"))
        try:
            best: dict = {}
            for r in range(a.repeats):
                for fam in fams:
                    for codec in codecs:
                        for rev in (list(revs) if r % 2 == 0 else list(revs)[::-1]):
                            out = subprocess.run(
                                [sys.executable, str(Path(__file__).resolve()), "--one", fam, codec, "--cache", str(a.cache),
                                 "--scratch", str(scratch)],
                                cwd=revs[rev], env={**env, "PYTHONPATH": str(revs[rev])}, capture_output=True, text=True,
                                check=True)
                            got = json.loads(out.stdout.strip().splitlines()[-1])
                            key = (rev, fam, codec)
                            if key not in best or got["ms_per_episode"]["total"] < best[key]["ms_per_episode"]["total"]:
                                best[key] = got
                print(f"repeat {r + 1}/{a.repeats} done", flush=True)
            stacked: dict = {}
            for r in range(a.repeats):
                for fam in fams:
                    got = stacked_estimate(fam, a.scale_codec, a.cache, scratch)
                    if fam not in stacked or got["ms_per_episode"] < stacked[fam]["ms_per_episode"]:
                        stacked[fam] = got
            ncpu = os.cpu_count() or 1
            walls: dict = {}
            if a.scale_shards:
                sys.path.insert(0, str(ROOT))  # spawned workers import this module from the checkout
                os.environ["PYTHONPATH"] = str(ROOT)
                for r in range(a.repeats):
                    for fam in fams:
                        for w in ((1, ncpu) if r % 2 == 0 else (ncpu, 1)):
                            dt = scale(fam, a.scale_codec, a.cache, scratch, a.scale_shards, w)
                            walls[(fam, w)] = min(walls.get((fam, w), float("inf")), dt)
                print("scaling done", flush=True)
        finally:
            if a.base:
                subprocess.run(["git", "worktree", "remove", "--force", str(revs["base"])], cwd=ROOT, check=False)
            if a.scratch is None:
                subprocess.run(["rm", "-rf", str(scratch)], check=False)
    for fam in fams:
        eps, n = episodes_of(fam, a.cache)
        raw = sum(c.data.nbytes for _, ch, _ in eps for c in ch.values()) / len(eps)
        samples = sum(ch["time"].data.shape[0] for _, ch, _ in eps) / len(eps)
        res["families"][fam] = {"samples_per_episode": samples, "channels": len(eps[0][1]), "raw_bytes_per_episode": raw,
                                "episodes_per_shard": n,
                                **{rev: {c: best[(rev, fam, c)] for c in codecs} for rev in revs}}
        if fam in stacked:
            res["families"][fam]["stacked_estimate"] = stacked[fam]
            print(f"{fam} stacked estimate ({a.scale_codec}): {stacked[fam]['ms_per_episode']:.2f} ms CPU/episode, "
                  f"{stacked[fam]['bytes_per_episode'] / 1e3:.0f} kB", flush=True)
        if walls:
            w1, wn = walls[(fam, 1)], walls[(fam, ncpu)]
            res["families"][fam]["scaling"] = {"codec": a.scale_codec, "shards": a.scale_shards, "workers": [1, ncpu],
                                               "wall_s": [w1, wn], "speedup": w1 / wn,
                                               "ms_wall_per_episode": [1e3 * w / (a.scale_shards * n) for w in (w1, wn)]}
            print(f"{fam} scaling ({a.scale_codec}): {a.scale_shards} shards, 1 writer {w1:.2f} s, {ncpu} writers {wn:.2f} s, "
                  f"x{w1 / wn:.2f}", flush=True)
        for rev in revs:
            for c in codecs:
                b = best[(rev, fam, c)]
                ms = b["ms_per_episode"]
                print(f"{fam} {rev} {c}: {ms['total']:.2f} ms CPU/episode, wall {ms['wall']:.2f} (" + ", ".join(f"{k} {ms[k]:.2f}" for k in PARTS)
                      + f"), {b['bytes_per_episode'] / 1e3:.0f} kB of {raw / 1e3:.0f} kB", flush=True)
    res["loadavg_at_end"] = list(os.getloadavg())
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / f"writer-episode-{a.tag}.json"
    path.write_text(json.dumps(res, indent=1) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
