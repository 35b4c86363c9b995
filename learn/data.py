"""Episodes of a dataset as in-memory sequences, and splits for learning.

A `Sequence` is one episode: inputs ``x`` [T, n_in] and targets ``y`` [T, n_out] in physical units
(channels flattened per frame and concatenated in the order named), plus ``meta`` (the episode's
attrs, its key ``shard/episode``) and optional extra channels (e.g. the drive, for loop analysis).
Episodes are short (seconds at 100 Hz), so training reads them whole instead of window by window.
"""

from __future__ import annotations

import hashlib
import json
from collections import defaultdict
from collections.abc import Callable, Iterable
from collections.abc import Sequence as Seq
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sensors.data.manifest import episode_key, read_manifest, shard_files
from sensors.data.recording import Recording

__all__ = ["Sequence", "dataset_fingerprint", "group_by", "load_sequences", "stratified_split"]


@dataclass
class Sequence:
    x: np.ndarray  # [T, n_in] float64, physical units
    y: np.ndarray  # [T, n_out] float64, physical units
    inputs: list[str]
    targets: list[str]
    units: dict[str, str]
    meta: dict[str, Any] = field(default_factory=dict)
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.x.shape[0])

    @property
    def key(self) -> str:
        return str(self.meta.get("key", ""))


def _flat(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).reshape(a.shape[0], -1)


def load_sequences(
    directory: str | Path,
    inputs: Seq[str],
    targets: Seq[str],
    extra: Seq[str] = (),
    keys: Iterable[str] | None = None,
) -> list[Sequence]:
    """Every episode of a dataset folder (or only ``keys``, ``"shard/episode"``), in natural order."""
    want = None if keys is None else set(keys)
    out: list[Sequence] = []
    for f in shard_files(directory):
        with Recording(f) as rec:
            for ep in rec.episode_ids:
                key = episode_key(f, ep)
                if want is not None and key not in want:
                    continue
                units = {c: rec.units(ep, c) for c in [*inputs, *targets, *extra]}
                x = np.concatenate([_flat(rec.read(ep, c)) for c in inputs], axis=1)
                y = np.concatenate([_flat(rec.read(ep, c)) for c in targets], axis=1)
                meta = dict(rec.episode_attrs(ep))
                meta["key"] = key
                ex = {c: np.asarray(rec.read(ep, c)) for c in extra}
                out.append(Sequence(x, y, list(inputs), list(targets), units, meta, ex))
    if want is not None and len(out) != len(want):
        found = {s.key for s in out}
        raise ValueError(f"episodes not in {directory}: {sorted(want - found)[:5]}")
    return out


def group_by(seqs: Seq[Sequence], attr: str | Callable[[Sequence], Any]) -> dict[Any, list[Sequence]]:
    get = attr if callable(attr) else (lambda s: s.meta.get(attr))
    groups: dict[Any, list[Sequence]] = defaultdict(list)
    for s in seqs:
        groups[get(s)].append(s)
    return dict(sorted(groups.items(), key=lambda kv: (str(type(kv[0])), kv[0])))


def stratified_split(
    seqs: Seq[Sequence],
    by: str,
    seed: int,
    fractions: tuple[float, float, float] = (0.7, 0.1, 0.2),
) -> dict[str, list[Sequence]]:
    """Disjoint train/valid/test episode lists, split within each value of ``meta[by]`` so that every
    loading condition (e.g. frequency) appears in test, and in valid where it has >= 3 episodes.

    Within a group of n episodes (deterministic permutation from ``default_rng(seed)``):
    test gets max(1, round(n f_test)) if n >= 2, valid max(1, round(n f_valid)) if n >= 3, train the rest.
    """
    if len(fractions) != 3 or not np.isclose(sum(fractions), 1.0):
        raise ValueError(f"fractions must be 3 numbers summing to 1, got {fractions}")
    rng = np.random.default_rng(int(seed))
    out: dict[str, list[Sequence]] = {"train": [], "valid": [], "test": []}
    for _, group in group_by(seqs, by).items():
        group = sorted(group, key=lambda s: s.key)
        n = len(group)
        perm = rng.permutation(n)
        n_test = max(1, int(round(n * fractions[2]))) if n >= 2 else 0
        n_valid = max(1, int(round(n * fractions[1]))) if n >= 3 else 0
        n_test = min(n_test, n - 1) if n >= 2 else 0
        n_valid = min(n_valid, n - n_test - 1) if n >= 3 else 0
        out["test"] += [group[i] for i in perm[:n_test]]
        out["valid"] += [group[i] for i in perm[n_test : n_test + n_valid]]
        out["train"] += [group[i] for i in perm[n_test + n_valid :]]
    for k in out:
        out[k].sort(key=lambda s: s.key)
    return out


def dataset_fingerprint(directory: str | Path) -> dict[str, Any]:
    """What a checkpoint records about its data: the manifest's own sha256, its dataset_sha256
    (over the shard files' sha256), content_sha256 (over the shards' data) and config_sha256."""
    directory = Path(directory)
    raw = (directory / "manifest.json").read_bytes()
    m = read_manifest(directory)
    return {
        "path": str(directory),
        "manifest_sha256": hashlib.sha256(raw).hexdigest(),
        "dataset_sha256": m.get("dataset_sha256"),
        "content_sha256": m.get("content_sha256"),  # equal for equal data (dataset_sha256 covers timestamps)
        "config_sha256": m.get("config_sha256"),
        "name": m.get("name"),
        "total_episodes": m.get("total_episodes"),
    }


def to_jsonable(o: Any) -> Any:
    if isinstance(o, dict):
        return {str(k): to_jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [to_jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    return o


def dumps(o: Any) -> str:
    return json.dumps(to_jsonable(o), indent=2, allow_nan=True)
