"""A dataset directory: recording shards plus ``manifest.json``; seeds, splits and resumption.

Layout::

    <dir>/shard-00000.h5, shard-00001.h5, ...   one recording each (sensors.data.recording)
    <dir>/manifest.json                         written last, atomically

Seeds. ``episode_seed(root_seed, k)`` is a pure function of ``(root_seed, k)`` where ``k`` is the
global episode index (shard * episodes_per_shard + position): it is the first uint64 of
``SeedSequence(root_seed, spawn_key=(k,))``, which is exactly the k-th child of
``SeedSequence(root_seed).spawn(n)`` for any ``n > k``. So ``derive_seeds(root_seed, n)[k] ==
episode_seed(root_seed, k)``, and a seed never depends on how many episodes or shards there are.
``shard_seed(root_seed, i)`` uses the two-element key ``(SHARD_KEY, i)``, which never collides
with an episode's one-element key.

Content hash. Each shard entry carries the recording's ``content_sha256`` (a hash of its data and of the
attributes that are not timestamps or code versions, sensors.data.recording) and the manifest a
``content_sha256`` over them: equal for equal data, so a regenerated dataset is checked by one number, where
``dataset_sha256`` (over the files' bytes, which hold their creation time) differs between identical runs.

Summary. Each shard's writer stores its summary (sample count, duration, per channel units, dims and finite
min / max: ``summary_json``, sensors.data.recording); the manifest's ``summary`` merges them over the shards
(``merge_summaries``), so a dataset's channel ranges read without opening a shard. A dataset whose shards were
written without one has no ``summary``.

Resumption. A shard counts as present when its file opens as a recording whose config_sha256 is
the dataset's (``is_shard_complete``); ``first_missing_shards`` lists those still to generate.
Because shards are renamed into place only when whole, an interrupted run leaves at most a
``.tmp`` file, which the rerun overwrites.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sensors.data.recording import Recording, _natural_key, merge_summaries

MANIFEST_FORMAT = "piezotwin-dataset"
MANIFEST_VERSION = 1
MANIFEST_NAME = "manifest.json"
SHARD_KEY = 0x5348_4152  # "SHAR": namespace of shard seeds
SPLIT_NAMES = ("train", "valid", "test")

__all__ = [
    "MANIFEST_FORMAT",
    "MANIFEST_NAME",
    "ManifestError",
    "build_manifest",
    "derive_seeds",
    "describe_shard",
    "episode_key",
    "episode_seed",
    "file_sha256",
    "first_missing_shards",
    "is_shard_complete",
    "make_splits",
    "read_manifest",
    "shard_files",
    "shard_path",
    "shard_seed",
    "verify_manifest",
    "write_manifest",
]


class ManifestError(ValueError):
    """manifest.json is missing, malformed or of another format."""


# --------------------------------------------------------------------------- seeds


def episode_seed(root_seed: int, global_episode_index: int) -> int:
    """Seed of episode ``k`` (a uint64 as a Python int); independent of the episode count."""
    if global_episode_index < 0:
        raise ValueError("episode index must be >= 0")
    ss = np.random.SeedSequence(int(root_seed), spawn_key=(int(global_episode_index),))
    return int(ss.generate_state(1, np.uint64)[0])


def derive_seeds(root_seed: int, n: int) -> list[int]:
    """Seeds of episodes 0..n-1 from ``SeedSequence(root_seed).spawn(n)``.

    Equal to ``[episode_seed(root_seed, k) for k in range(n)]``.
    """
    return [int(c.generate_state(1, np.uint64)[0]) for c in np.random.SeedSequence(int(root_seed)).spawn(n)]


def shard_seed(root_seed: int, shard_index: int) -> int:
    """Seed of shard ``i`` (for per-shard randomness); never equal-by-construction to an episode's."""
    ss = np.random.SeedSequence(int(root_seed), spawn_key=(SHARD_KEY, int(shard_index)))
    return int(ss.generate_state(1, np.uint64)[0])


# --------------------------------------------------------------------------- shards


def shard_path(directory: str | os.PathLike, i: int) -> Path:
    return Path(directory) / f"shard-{int(i):05d}.h5"


def episode_key(shard_file: str | os.PathLike, ep_id: str) -> str:
    """The ``"shard/episode"`` id used in splits, e.g. ``"shard-00003/ep-0007"``."""
    return f"{Path(shard_file).stem}/{ep_id}"


def file_sha256(path: str | os.PathLike, bufsize: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(bufsize):
            h.update(chunk)
    return h.hexdigest()


def is_shard_complete(
    path: str | os.PathLike,
    expected_config_sha256: str | None,
    *,
    deep: bool = False,
) -> bool:
    """True when ``path`` is a whole recording made from the expected config.

    False for a missing, truncated, corrupt or foreign file, a recording of another config, or
    one with no episodes. ``deep=True`` also reads every dataset (catches damaged chunks).
    """
    path = Path(path)
    if not path.is_file():
        return False
    try:
        with Recording(path) as rec:
            if expected_config_sha256 is not None and rec.config_sha256 != expected_config_sha256:
                return False
            if not rec.episode_ids:
                return False
            if deep:
                for ep in rec.episode_ids:
                    for name in rec.channels(ep):
                        rec.read(ep, name)
        return True
    except Exception:  # noqa: BLE001 - any failure to read means "not complete"
        return False


def first_missing_shards(
    directory: str | os.PathLike, n_shards: int, config_sha256: str | None
) -> list[int]:
    """Indices of the shards in ``range(n_shards)`` that still need generating."""
    return [i for i in range(n_shards) if not is_shard_complete(shard_path(directory, i), config_sha256)]


def describe_shard(path: str | os.PathLike, *, with_sha256: bool = True) -> dict[str, Any]:
    """Manifest entry of one shard: file, sha256, content_sha256, episodes, episode_seeds, shard_seed, bytes.

    Episode seeds come from each episode's ``seed`` attribute and the shard seed from the root
    attribute ``shard_seed`` (None where absent).
    """
    path = Path(path)
    with Recording(path) as rec:
        eps = rec.episode_ids
        seeds = [rec.episode_attrs(ep).get("seed") for ep in eps]
        sseed = rec.attrs.get("shard_seed")
        cfg = rec.config_sha256
        content = rec.content_sha256
        summary = _stored_summary(rec)
    return shard_entry(path, eps, seeds, cfg, sseed, with_sha256=with_sha256, content_sha256=content, summary=summary)


def _stored_summary(rec: Recording) -> dict[str, Any] | None:
    """The summary a shard's writer stored ({"n_samples", "duration_s", "channels"}), None where it has none."""
    if not rec.has_stored_summary:
        return None
    s = rec.summary(from_data=False)
    return {k: s[k] for k in ("n_samples", "duration_s", "channels")}


def shard_entry(
    path: str | os.PathLike, episodes: list[str], episode_seeds: list, config_sha256: str, shard_seed: int | None = None,
    *, with_sha256: bool = True, content_sha256: str | None = None, summary: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Manifest entry of a shard whose episodes and seeds the caller knows (the process that just wrote it:
    no need to read every episode back); `describe_shard` reads them from the file. content_sha256: the
    writer's (RecordingWriter.content_sha256); None reads it from the file's root attribute. summary: the
    shard's stored summary (RecordingWriter.summary), carried under "summary" until `build_manifest` merges the
    shards' into the dataset's (it is not written per shard)."""
    path = Path(path)
    if content_sha256 is None:
        with Recording(path) as rec:
            content_sha256 = rec.content_sha256
    return {
        "file": path.name,
        "sha256": file_sha256(path) if with_sha256 else None,
        "content_sha256": content_sha256,
        "bytes": path.stat().st_size,
        "episodes": list(episodes),
        "episode_seeds": list(episode_seeds),
        "shard_seed": shard_seed,
        "config_sha256": config_sha256,
        **({"summary": dict(summary)} if summary is not None else {}),
    }


# --------------------------------------------------------------------------- splits


_DIGITS = re.compile(r"(\d+)")


def _natural_order(ids: Iterable[str]) -> list[str]:
    """ids in natural order (`_natural_key`, ties broken by the text). Dataset ids share their non-digit parts
    ("shard-00003.h5/ep-000123"): their order is then the numeric one of their digit runs, sorted by numpy (the
    per-id Python key took seconds for 200k episodes); other id sets take the general key."""
    ids = list(ids)
    parts = [_DIGITS.split(e) for e in ids]
    if ids and all(len(p) == len(parts[0]) and p[0::2] == parts[0][0::2] for p in parts):
        try:
            cols = [np.array([int(p[k]) for p in parts], dtype=np.int64) for k in range(1, len(parts[0]), 2)]
        except OverflowError:  # a digit run beyond int64: the general key
            cols = None
        if cols is not None:
            order = np.lexsort([np.array(ids)] + cols[::-1])
            return [ids[i] for i in order]
    return sorted(ids, key=lambda e: (_natural_key(e), e))


def make_splits(
    episode_ids: Iterable[str],
    seed: int,
    fractions: Sequence[float] = (0.8, 0.1, 0.1),
) -> dict[str, list[str]]:
    """Deterministic, disjoint train/valid/test split of ``episode_ids``.

    The ids are put in natural order first (so the input order does not matter), shuffled with
    ``default_rng(seed)``; valid and test get ``round(n * fraction)`` ids each, train the rest.
    Each list is returned in natural order.
    """
    ids = _natural_order(set(episode_ids))
    if len(fractions) != 3 or any(f < 0 for f in fractions) or not np.isclose(sum(fractions), 1.0):
        raise ValueError(f"fractions must be 3 non-negative numbers summing to 1, got {fractions}")
    n = len(ids)
    perm = np.random.default_rng(int(seed)).permutation(n)
    n_valid = int(round(n * fractions[1]))
    n_test = min(n - n_valid, int(round(n * fractions[2])))
    valid_idx, test_idx, train_idx = (
        perm[:n_valid],
        perm[n_valid : n_valid + n_test],
        perm[n_valid + n_test :],
    )
    pick = lambda idx: [ids[i] for i in np.sort(idx)]
    return {"train": pick(train_idx), "valid": pick(valid_idx), "test": pick(test_idx)}


# --------------------------------------------------------------------------- manifest


def _utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds").replace("+00:00", "Z")


def _dataset_sha256(shards: Sequence[Mapping[str, Any]]) -> str:
    h = hashlib.sha256()
    for s in shards:
        h.update(f"{s['file']} {s['sha256']}\n".encode())
    return h.hexdigest()


def _content_sha256(shards: Sequence[Mapping[str, Any]]) -> str | None:
    """Hash over the shards' content hashes (None when a shard has none: an entry from an older manifest)."""
    if any(not s.get("content_sha256") for s in shards):
        return None
    h = hashlib.sha256()
    for s in shards:
        h.update(f"{s['file']} {s['content_sha256']}\n".encode())
    return h.hexdigest()


def _manifest_text(manifest: Mapping[str, Any]) -> str:
    """The manifest as JSON, one top-level key, shard or split per line: readable, and written by json's C
    encoder (an indented dump of 200k episode ids took seconds in the pure-Python one)."""
    def value(k: str, v: Any) -> str:
        if k == "shards":
            return "[\n" + ",\n".join("  " + json.dumps(s) for s in v) + "\n ]"
        if k == "splits":
            return "{\n" + ",\n".join(f"  {json.dumps(n)}: {json.dumps(ids)}" for n, ids in v.items()) + "\n }"
        return json.dumps(v)

    return "{\n" + ",\n".join(f" {json.dumps(k)}: {value(k, v)}" for k, v in manifest.items()) + "\n}\n"


def write_manifest(
    directory: str | os.PathLike,
    *,
    name: str,
    root_seed: int | None,
    episodes_per_shard: int,
    config_sha256: str,
    shards: Sequence[Mapping[str, Any]],
    splits: Mapping[str, Sequence[str]],
    extra: Mapping[str, Any] | None = None,
    summary: Mapping[str, Any] | None = None,
) -> Path:
    """Write ``<directory>/manifest.json`` atomically (tmp file + os.replace); returns its path. summary: the
    dataset's (`sensors.data.recording.merge_summaries` of its shards'), written as "summary" where given."""
    directory = Path(directory)
    if set(splits) != set(SPLIT_NAMES):
        raise ValueError(f"splits must have exactly the keys {SPLIT_NAMES}, got {sorted(splits)}")
    known = {episode_key(s["file"], ep) for s in shards for ep in s["episodes"]}
    seen: set[str] = set()
    for split in SPLIT_NAMES:
        ids = set(splits[split])
        if ids & seen:
            raise ValueError(f"split {split!r} overlaps another split: {sorted(ids & seen)[:5]}")
        if ids - known:
            raise ValueError(f"split {split!r} names unknown episodes: {sorted(ids - known)[:5]}")
        seen |= ids
    shard_list = [dict(s) for s in shards]
    manifest = {
        "format": MANIFEST_FORMAT,
        "format_version": MANIFEST_VERSION,
        "name": name,
        "created_utc": _utc_now(),
        "root_seed": root_seed,
        "config_sha256": config_sha256,
        "n_shards": len(shard_list),
        "episodes_per_shard": episodes_per_shard,
        "total_episodes": sum(len(s["episodes"]) for s in shard_list),
        "dataset_sha256": _dataset_sha256(shard_list),
        "content_sha256": _content_sha256(shard_list),
        "shards": shard_list,
        "splits": {k: list(splits[k]) for k in SPLIT_NAMES},
    }
    if summary is not None:
        manifest["summary"] = dict(summary)
    if extra:
        clash = set(extra) & set(manifest)
        if clash:
            raise ValueError(f"extra may not override {sorted(clash)}")
        manifest.update(extra)
    directory.mkdir(parents=True, exist_ok=True)
    final = directory / MANIFEST_NAME
    tmp = final.with_name(final.name + ".tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(_manifest_text(manifest))
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, final)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return final


def read_manifest(directory: str | os.PathLike) -> dict[str, Any]:
    path = Path(directory)
    if path.is_dir():
        path = path / MANIFEST_NAME
    try:
        m = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ManifestError(f"{path}: no manifest (dataset incomplete or not a dataset dir)") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ManifestError(f"{path}: not valid JSON ({e})") from None
    if not isinstance(m, dict) or m.get("format") != MANIFEST_FORMAT:
        got = m.get("format") if isinstance(m, dict) else type(m).__name__
        raise ManifestError(f"{path}: format is {got!r}, not {MANIFEST_FORMAT!r}")
    if m.get("format_version", 0) > MANIFEST_VERSION:
        raise ManifestError(f"{path}: manifest version {m['format_version']} is newer than supported")
    return m


def build_manifest(
    directory: str | os.PathLike,
    *,
    name: str,
    n_shards: int,
    episodes_per_shard: int,
    config_sha256: str,
    root_seed: int | None,
    split_seed: int | None = None,
    fractions: Sequence[float] = (0.8, 0.1, 0.1),
    extra: Mapping[str, Any] | None = None,
    described: Mapping[int, dict[str, Any]] | None = None,
) -> Path:
    """Describe shards 0..n_shards-1 (all must be complete), split their episodes, write manifest.
    described: entries already made by the processes that wrote those shards (`shard_entry`), used where
    the file still has the size they recorded; such a shard (of this config, with episodes) is not opened
    again to check that it is complete: its writer made it whole (temporary file, then rename) in this run.
    The others are checked (`is_shard_complete`) and described from the file."""
    described = described or {}

    def vouched(i: int) -> dict[str, Any] | None:
        d = described.get(i)
        if d is None or not d.get("content_sha256") or not d.get("episodes"):
            return None
        if config_sha256 is not None and d.get("config_sha256") != config_sha256:
            return None
        try:
            return d if shard_path(directory, i).stat().st_size == d["bytes"] else None
        except OSError:
            return None

    known = {i: d for i in range(n_shards) if (d := vouched(i)) is not None}
    # opening every shard to check it costs ~2.5 ms each (3.1 s of a 1024-shard GPU run's manifest, H100 host)
    missing = [i for i in range(n_shards)
               if i not in known and not is_shard_complete(shard_path(directory, i), config_sha256)]
    if missing:
        raise ValueError(f"{directory}: shards {missing[:10]} are missing or incomplete")
    shards = [dict(known[i]) if i in known else describe_shard(shard_path(directory, i)) for i in range(n_shards)]
    parts = [s.pop("summary", None) for s in shards]
    ids = [episode_key(s["file"], ep) for s in shards for ep in s["episodes"]]
    seed = split_seed if split_seed is not None else (root_seed or 0)
    return write_manifest(
        directory,
        name=name,
        root_seed=root_seed,
        episodes_per_shard=episodes_per_shard,
        config_sha256=config_sha256,
        shards=shards,
        splits=make_splits(ids, seed, fractions),
        extra=extra,
        # the shards' stored summaries merged (no dataset read); none where a shard was written without one
        summary=merge_summaries(parts) if parts and all(p is not None for p in parts) else None,
    )


def verify_manifest(directory: str | os.PathLike) -> list[str]:
    """Problems found comparing the shards on disk with the manifest (empty list: all good)."""
    directory = Path(directory)
    m = read_manifest(directory)
    problems = []
    for s in m["shards"]:
        p = directory / s["file"]
        if not p.is_file():
            problems.append(f"{s['file']}: missing")
        elif p.stat().st_size != s["bytes"]:
            problems.append(f"{s['file']}: size {p.stat().st_size} != {s['bytes']}")
        elif file_sha256(p) != s["sha256"]:
            problems.append(f"{s['file']}: sha256 mismatch")
    return problems


def shard_files(directory: str | os.PathLike) -> list[Path]:
    """Shard files of a dataset dir: from the manifest when there is one, else shard-*.h5 on disk."""
    directory = Path(directory)
    if (directory / MANIFEST_NAME).is_file():
        return [directory / s["file"] for s in read_manifest(directory)["shards"]]
    pat = re.compile(r"^shard-\d+\.h5$")
    return sorted((p for p in directory.iterdir() if pat.match(p.name)), key=lambda p: _natural_key(p.name))
