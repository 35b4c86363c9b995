"""The HDF5 recording format: one file per shard, same schema for simulated and real data.

Layout (docs/dataset.md)::

    /                      attrs: format, format_version, source, created_utc, generator,
                                  generator_version, generator_commit, config_json, config_sha256,
                                  version_<library>, root_seed, shard_index, + extra_attrs
    /sensor                attrs: family, taxel positions (m), sample rate, ADC, ... (sensor_attrs)
    /scene/mjcf            the compiled MJCF XML (string dataset), when given
    /episodes/<id>         attrs: seed, frequency_hz, n_samples, ... (episode_attrs)
    /episodes/<id>/<name>  one dataset per channel; attrs units, dim_names, description

Time series are chunked along time in blocks of whole frames of at most 1 MiB (the whole episode where it fits;
else a length that divides T where one is close to the cap, or T in equal parts); a taxel field (second axis named
"taxel") is also cut into blocks of TAXEL_BLOCK taxels where such a chunk holds >= 64 KiB. Compressed with lzf + shuffle by default (gzip level 1
+ shuffle, Blosc2 zstd / lz4 level 1 + shuffle, or none). Every chunked dataset carries HDF5's Fletcher-32
checksum per chunk: damaged data fails to read (RecordingError naming the file) instead of reading back as wrong
numbers. A chunk whose bytes are all zero is not written (`_write_rows`): HDF5 leaves it unallocated and every
reader gets the dataset's fill value, 0, back for it, so the data read are the same bytes; the filters (shuffle,
codec, checksum) then skip it. On the CPU path the shear field of a pad pressed along its normal (velostat,
cnt_pdms, fabric) is zero throughout: 48 / 33 / 10 % of those episodes' bytes; the taxel blocks a press never reaches
are zero in every field on both paths (bench/results/writer-episode-cpu.json, user-cli-h200-s18-*.json).

Storage (not schema): files are written with HDF5's 1.10 object formats (``libver=("v110", "latest")``: checksummed
object headers, a chunk index without a B-tree for one-chunk datasets), readable by HDF5 >= 1.10 (any h5py >= 2.8);
files written before (HDF5's earliest formats) read the same. Blosc2 runs one thread per writer (``BLOSC_NTHREADS=1``
unless the environment sets it): the writers are processes, one per core, and Blosc2's default threads cost more per
chunk than they save (bench/results/writer-episode-cpu.json).

Attribute values: numbers, strings, bools and numeric arrays are stored as HDF5 attributes; dicts,
lists of strings and other JSON-able values are stored as JSON strings and the attribute name is
listed in the group's ``_json_attrs`` attribute, so they read back as the same Python objects.
``None`` values are not stored (they read back as missing, i.e. ``None`` via ``.get``).

Writing is atomic: the file is written to ``<path>.tmp`` in the same directory and renamed with
``os.replace`` only once it is complete, so a crash never leaves a file at the final name.

Content hash. The root attribute ``content_sha256`` is a SHA-256 of what the recording says, not of its bytes:
every channel's data (dtype, shape, bytes) with its units, dim_names and description, every episode's
attributes, the sensor attributes, the MJCF and the root attributes except those that name the time and the
code that wrote it (``VOLATILE_ATTRS``: created_utc, generator*, version_*). Two runs that make the same data
have the same content hash even though their files differ (timestamps); `content_sha256` defines it,
`Recording.compute_content_sha256` recomputes it from the file.

Stored summary. The writer keeps what `Recording.summary` reports (per channel units, dims, dtype, frame shape,
samples, finite min and max; episodes' samples and duration) as it adds episodes, from the arrays in memory, and
stores it in the root attribute ``summary_json`` (left out of the content hash: it is derived from the hashed data).
`Recording.summary(from_data=False)` returns it without reading the data (the end of `piezotwin generate`);
`summary()` reads every dataset (`piezotwin inspect`, which also meets any damaged chunk). Files without it
(written before) are read.
"""

from __future__ import annotations

import datetime as _dt
import functools
import hashlib
import importlib.metadata
import itertools
import json
import math
import os
import re
import subprocess
import sys
import threading
from collections import OrderedDict
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import h5py
import numpy as np
from h5py import h5a, h5d, h5g, h5o, h5s, h5t

FORMAT = "piezotwin-recording"
FORMAT_VERSION = 1

_JSON_ATTRS = "_json_attrs"
_NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.\-]*$")
_CHUNK_MAX_BYTES = 1 << 20  # cap on one chunk (HDF5's default chunk cache per dataset); the whole episode where it fits
# HDF5 object formats of the files written: 1.10's (v2 object headers with checksums, single-chunk / fixed-array
# chunk indexes, compact link storage) halve the bytes of a short episode against the earliest formats (ntype's
# 20-sample episodes with lzf: 84 -> 43 kB, bench/results/writer-episode-cpu.json)
_LIBVER = ("v110", "latest")
_COMPRESSIONS = ("lzf", "gzip", "none", "zstd", "lz4")
# "zstd" / "lz4": Blosc2 (level 1, byte shuffle) through hdf5plugin; its filters register on import, so a
# reader needs hdf5plugin too (imported here when installed)
try:
    import hdf5plugin as _hdf5plugin
except ImportError:  # pragma: no cover - a dependency; only the Blosc2 options need it
    _hdf5plugin = None
# Blosc2 reads BLOSC_NTHREADS at every chunk and by default starts several threads for each: velostat's episodes
# took 27.8 ms of writer CPU with lz4 (data 22.6) before session 11, 8.3 (4.4) with one thread and the storage
# below (this 2-core host, bench/results/writer-episode-cpu.json; a larger host starts more threads per chunk).
# The writers (and readers) are processes: one thread each, unless the user set it
os.environ.setdefault("BLOSC_NTHREADS", "1")


def _blosc2(cname: str) -> dict[str, Any]:
    if _hdf5plugin is None:
        raise ValueError(f"compression '{cname}' needs the hdf5plugin package (pip install hdf5plugin)")
    return dict(_hdf5plugin.Blosc2(cname=cname, clevel=1, filters=_hdf5plugin.Blosc2.SHUFFLE))

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "VOLATILE_ATTRS",
    "Channel",
    "Recording",
    "RecordingError",
    "RecordingWriter",
    "SUMMARY_ATTR",
    "content_sha256",
    "generator_info",
    "merge_summaries",
    "read_recording_summary",
    "split_column",
    "write_recording",
]


class RecordingError(ValueError):
    """A file is not a readable piezotwin recording (wrong format, newer version, corrupt)."""


@dataclass
class Channel:
    """One named array of an episode, with its units and the names of its dimensions.

    ``dim_names[0] == "time"`` marks a time series (chunked along its first axis).
    """

    data: np.ndarray
    units: str
    dim_names: tuple[str, ...]
    description: str = ""
    # what the producer already knows of the data's zeros (the GPU feed: a field sent as its non-zero taxel blocks,
    # simulate.contact.field_blocks.BlockSparse): (block, mask), mask[k] False where entries [k * block, (k + 1) *
    # block) of axis 1 are all +0.0 over the whole episode. The writer then does not scan those blocks for zero
    # chunks, nor an all-zero field for the summary's min / max; the file and its content hash are the same (a
    # hint, not stored)
    nonzero_blocks: tuple[int, np.ndarray] | None = None

    def __post_init__(self) -> None:
        self.data = np.asarray(self.data)
        self.dim_names = tuple(self.dim_names)
        if self.nonzero_blocks is not None:
            self.nonzero_blocks = (int(self.nonzero_blocks[0]), np.asarray(self.nonzero_blocks[1], bool))
        self.validate()

    def validate(self, where: str = "channel") -> None:
        if not isinstance(self.units, str):
            raise ValueError(f"{where}: units must be a string, got {self.units!r}")
        if len(self.dim_names) != self.data.ndim:
            raise ValueError(
                f"{where}: dim_names {self.dim_names} has {len(self.dim_names)} names but the "
                f"data has {self.data.ndim} dimensions (shape {self.data.shape})"
            )
        if not all(isinstance(d, str) and d for d in self.dim_names):
            raise ValueError(f"{where}: dim_names must be non-empty strings, got {self.dim_names}")
        if self.data.dtype.kind not in "biufc":
            raise ValueError(f"{where}: data must be numeric or bool, got dtype {self.data.dtype}")
        if self.nonzero_blocks is not None:
            block, mask = self.nonzero_blocks
            n = -(-self.data.shape[1] // max(block, 1)) if self.data.ndim >= 2 else -1
            if block < 1 or mask.ndim != 1 or len(mask) != n:
                raise ValueError(f"{where}: nonzero_blocks needs a block >= 1 and one flag per block of axis 1 "
                                 f"({n} for shape {self.data.shape}), got block {block} and {mask.shape} flags")

    @property
    def is_time_series(self) -> bool:
        return self.data.ndim >= 1 and self.dim_names[0] == "time"


# --------------------------------------------------------------------------- provenance


@functools.lru_cache(maxsize=1)
def generator_info() -> dict[str, str]:
    """Package name, version and git commit of the code that writes (cached per process)."""
    try:
        version = importlib.metadata.version("piezotwin")
    except importlib.metadata.PackageNotFoundError:
        version = "0+unknown"
    commit = "unknown"
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            timeout=5,
        )
        if out.returncode == 0 and re.fullmatch(r"[0-9a-f]{40}", out.stdout.strip()):
            commit = out.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    return {"name": "piezotwin", "version": version, "commit": commit}


def _library_versions() -> dict[str, str]:
    """Versions of the libraries that shape the data; never imports mujoco or warp."""
    versions = {"numpy": np.__version__, "h5py": h5py.__version__, "hdf5": h5py.version.hdf5_version}
    for key, dist in (("mujoco", "mujoco"), ("mujoco_warp", "mujoco-warp"), ("warp", "warp-lang")):
        mod = sys.modules.get(key)
        v = getattr(mod, "__version__", None) if mod is not None else None
        if v is None:
            try:
                v = importlib.metadata.version(dist)
            except importlib.metadata.PackageNotFoundError:
                continue
        versions[key] = str(v)
    return versions


def _utc_now() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds").replace("+00:00", "Z")


# --------------------------------------------------------------------------- attributes


def _set_attrs(obj: h5py.HLObject, attrs: Mapping[str, Any], where: str) -> None:
    _write_attrs(obj, _encode_attrs(attrs, where))


def _encode_attrs(attrs: Mapping[str, Any], where: str) -> dict[str, tuple[Any, bool]]:
    """Check and encode attributes: name -> (stored value, is_json); ``None`` values are dropped."""
    out = {}
    for key, value in attrs.items():
        if not isinstance(key, str) or not key or key == _JSON_ATTRS:
            raise ValueError(f"{where}: bad attribute name {key!r}")
        if value is not None:
            out[key] = _encode_attr(value, f"{where}.{key}")
    return out


def _write_attrs(obj: h5py.HLObject, encoded: Mapping[str, tuple[Any, bool]]) -> None:
    json_keys = [str(k) for k in obj.attrs.get(_JSON_ATTRS, [])]
    for key, (stored, is_json) in encoded.items():
        obj.attrs[key] = stored
        if is_json:
            json_keys.append(key)
    if json_keys:
        obj.attrs[_JSON_ATTRS] = json.dumps(sorted(set(json_keys)))


def _encode_attr(value: Any, where: str) -> tuple[Any, bool]:
    if isinstance(value, str):
        return str(value), False  # np.str_ too, which h5py cannot store as it is
    if isinstance(value, (bool, np.bool_)):
        return value, False
    if isinstance(value, int) and not isinstance(value, bool):
        if -(2**63) <= value < 2**63:
            return np.int64(value), False
        if 0 <= value < 2**64:
            return np.uint64(value), False
        raise ValueError(f"{where}: integer {value} does not fit in 64 bits")
    if isinstance(value, (float, np.number)):
        return value, False
    if isinstance(value, np.ndarray) and value.dtype.kind in "biufc":
        return value, False
    if isinstance(value, (list, tuple)):
        arr = np.asarray(value) if len(value) else None
        if arr is not None and arr.dtype.kind in "biufc" and arr.dtype != object:
            return arr, False
    try:
        return json.dumps(value, sort_keys=True, default=_json_default), True
    except TypeError as e:
        raise ValueError(f"{where}: cannot store {type(value).__name__} as an attribute: {e}") from e


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serializable: {type(o).__name__}")


def _decode_value(v: Any) -> Any:
    if isinstance(v, bytes):
        return v.decode("utf-8")
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray) and v.dtype.kind in "OSU":
        return [_decode_value(x) for x in v.tolist()]
    return v


def _decoded_attrs(encoded: Mapping[str, tuple[Any, bool]]) -> dict[str, Any]:
    """The attributes as `_get_attrs` reads them back after `_write_attrs`, made from the encoded values in memory
    (HDF5 returns a scalar as a NumPy scalar, an array as an array of its dtype, a string as str)."""
    out = {}
    for key in sorted(encoded):
        stored, is_json = encoded[key]
        if is_json:
            out[key] = json.loads(stored)
            continue
        v = np.asarray(stored) if isinstance(stored, (np.ndarray, np.generic)) else stored
        if isinstance(v, np.ndarray) and v.ndim == 0:
            v = v[()]
        out[key] = _decode_value(v.copy() if isinstance(v, np.ndarray) else v)
    return out


def _get_attrs(obj: h5py.HLObject, keys: tuple[str, ...] | None = None) -> dict[str, Any]:
    """The attributes decoded (JSON ones parsed); ``keys``: only those named (the ones present), e.g. a file's
    provenance without decoding its config."""
    attrs = obj.attrs
    json_keys = set(json.loads(_decode_value(attrs.get(_JSON_ATTRS, "[]"))))
    names = sorted(k for k in attrs if k != _JSON_ATTRS) if keys is None else [k for k in keys if k in attrs]
    out = {}
    for key in names:
        v = _decode_value(attrs[key])
        out[key] = json.loads(v) if key in json_keys else v
    return out


# --------------------------------------------------------------------------- content hash

# root attributes left out of the content hash: when and by which code/library versions a file was written, and
# what the writer derived from the hashed data (the content hash itself, the channel ranges of SUMMARY_ATTR)
SUMMARY_ATTR = "summary_json"
VOLATILE_ATTRS = ("created_utc", "generator", "generator_version", "generator_commit", "content_sha256", SUMMARY_ATTR)
_VOLATILE_PREFIX = "version_"


def _canon_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return {"__ndarray__": o.dtype.str, "shape": list(o.shape), "values": o.tolist()}
    if isinstance(o, (complex, np.complexfloating)):
        return {"__complex__": [float(o.real), float(o.imag)]}
    if isinstance(o, np.generic):
        return o.item()
    return _json_default(o)


def _canon(attrs: Mapping[str, Any]) -> bytes:
    """Canonical JSON of decoded attributes (as `_get_attrs` returns them)."""
    return json.dumps(attrs, sort_keys=True, default=_canon_default, separators=(",", ":")).encode("utf-8")


def _put(h: hashlib._Hash, *parts: bytes | str) -> None:
    """Length-prefixed parts: no two different sequences of parts feed the same bytes."""
    for part in parts:
        b = part.encode("utf-8") if isinstance(part, str) else part
        h.update(len(b).to_bytes(8, "little"))
        h.update(b)


@functools.lru_cache(maxsize=1024)
def _channel_head(name: str, units: str, dim_names: tuple[str, ...], description: str, dtype: str,
                  shape: tuple[int, ...]) -> bytes:
    """The length-prefixed parts `_put` feeds before a channel's data (cached: the same for every episode of a layout)."""
    parts = ("channel", name, units, json.dumps(list(dim_names)), description, dtype, json.dumps(list(shape)))
    return b"".join(len(b).to_bytes(8, "little") + b for b in (p.encode("utf-8") for p in parts))


def _channel_hash(h: hashlib._Hash, name: str, data: np.ndarray, units: str, dim_names: tuple[str, ...],
                  description: str) -> None:
    a = np.ascontiguousarray(data)
    h.update(_channel_head(name, units, tuple(dim_names), description, a.dtype.str, a.shape))
    if a.size:
        h.update(memoryview(a.reshape(-1)).cast("B"))  # the bytes in place, no copy


def _episode_digest(ep_id: str, attrs: Mapping[str, Any], channels: Mapping[str, tuple]) -> bytes:
    """channels: name -> (data, units, dim_names, description)."""
    h = hashlib.sha256()
    _put(h, "episode", ep_id, _canon(attrs))
    for name in sorted(channels):
        _channel_hash(h, name, *channels[name])
    return h.digest()


_COLUMN_RE = re.compile(r"^(?P<base>.+)\[(?P<k>\d+)\]$")


def split_column(name: str) -> tuple[str, int | None]:
    """``"velostat[0]"`` -> ("velostat", 0); a plain channel name -> (name, None)."""
    m = _COLUMN_RE.match(name)
    return (m["base"], int(m["k"])) if m else (name, None)


def content_sha256(root_attrs: Mapping[str, Any], sensor_attrs: Mapping[str, Any], mjcf: str | None,
                   episode_digests: Mapping[str, bytes]) -> str:
    """The content hash of a recording from its decoded attributes and the digests of its episodes."""
    h = hashlib.sha256()
    root = {k: v for k, v in root_attrs.items() if k not in VOLATILE_ATTRS and not k.startswith(_VOLATILE_PREFIX)}
    _put(h, FORMAT, "root", _canon(root), "sensor", _canon(sensor_attrs), "mjcf", "" if mjcf is None else mjcf)
    for ep in _natural_sorted(episode_digests):
        _put(h, ep, episode_digests[ep])
    return h.hexdigest()


# --------------------------------------------------------------------------- writing


def _check_name(name: Any, what: str) -> str:
    if not isinstance(name, str) or not _NAME_RE.match(name) or name in (".", ".."):
        raise ValueError(
            f"invalid {what} {name!r}: use letters, digits, '_', '-', '.' (not starting with '.' "
            "or '-')"
        )
    return name


def _chunk_len(n_time: int, frame_bytes: int) -> int:
    """Frames per chunk: the whole series where it fits in 1 MiB, else <= 1 MiB: a length that divides ``n_time``
    where one is within half of the cap, else the series in equal parts (the last chunk short by < one frame per
    chunk: HDF5 stores a partial chunk at full size when uncompressed). A fixed cost per chunk: fabric_1's narrow
    frames made 294 chunks per episode at <= 256 frames."""
    target = max(1, min(n_time, _CHUNK_MAX_BYTES // max(1, frame_bytes)))
    for c in range(target, max(1, target // 2) - 1, -1):
        if n_time % c == 0:
            return c
    return -(-n_time // -(-n_time // target))


# Chunks of all-zero bytes are left unwritten (read back as the fill value 0: the same bytes). Off only to measure
# what it saves (bench): PIEZOTWIN_SKIP_ZERO_CHUNKS=0, read when this module is imported (the writer processes too)
SKIP_ZERO_CHUNKS = os.environ.get("PIEZOTWIN_SKIP_ZERO_CHUNKS", "1") == "1"
# Whether the writer takes a channel's `nonzero_blocks` hint (the same file either way). Off only for the bench's A/B:
# PIEZOTWIN_BLOCK_HINTS=0
USE_BLOCK_HINTS = os.environ.get("PIEZOTWIN_BLOCK_HINTS", "1") == "1"
# Taxels per chunk along a channel's "taxel" axis (its second): a press loads a few taxels of a large pad, so most
# blocks of a taxel field stay zero through an episode and are not written (velostat: a 10 mm tip on 144 taxels).
# 0: the whole frame in each chunk (the layout before session 18, and what the bench compares against:
# PIEZOTWIN_TAXEL_BLOCK=0) ...
TAXEL_BLOCK = int(os.environ.get("PIEZOTWIN_TAXEL_BLOCK", "16"))
TAXEL_BLOCK_MIN_BYTES = 1 << 16  # ... and where a block's chunk would hold less than this: HDF5's and the codec's
# cost per chunk then outweighs what the zero blocks save (ntype's 20-sample episodes: 5.9 -> 10.9 ms of writer CPU
# per episode with lz4, bench/results/writer-episode-cpu-s18-blocks.json)


def _chunk_shape(ch: Channel) -> tuple[int, ...] | None:
    """The chunk shape of a channel's dataset: None for one that is not a non-empty time series (h5py's guess, or
    no chunks); else whole frames of at most 1 MiB along time (`_chunk_len`), a taxel field cut into blocks of
    TAXEL_BLOCK taxels where a block's chunk holds at least TAXEL_BLOCK_MIN_BYTES (the time length then chosen for
    one block's frame)."""
    data = ch.data
    if not (data.ndim >= 1 and data.size > 0 and ch.is_time_series):
        return None
    frame = list(data.shape[1:])
    if TAXEL_BLOCK > 0 and data.ndim >= 2 and len(ch.dim_names) > 1 and ch.dim_names[1] == "taxel" and frame[0] > TAXEL_BLOCK:
        block = [TAXEL_BLOCK, *frame[1:]]
        block_bytes = int(np.prod(block, dtype=np.int64)) * data.dtype.itemsize
        if _chunk_len(data.shape[0], block_bytes) * block_bytes >= TAXEL_BLOCK_MIN_BYTES:
            frame = block
    frame_bytes = int(np.prod(frame, dtype=np.int64)) * data.dtype.itemsize
    return (_chunk_len(data.shape[0], frame_bytes), *frame)


def _nonzero_chunks(data: np.ndarray, chunks: tuple[int, ...]) -> np.ndarray:
    """Per chunk of a C-contiguous array laid out in `chunks` (split along its first two axes at most): whether any
    of its bytes is nonzero (-0.0 and NaN are nonzero bytes). Shape (chunks along axis 0, chunks along axis 1)."""
    n0 = data.shape[0]
    n1 = data.shape[1] if data.ndim >= 2 else 1
    c0 = chunks[0]
    c1 = chunks[1] if data.ndim >= 2 else 1
    raw = data.reshape(n0, n1, -1).view(np.uint8)  # (time, taxel, bytes of the rest)
    word = next(w for w in (8, 4, 2, 1) if raw.shape[2] % w == 0)
    words = raw.view(f"<u{word}")
    out = np.empty((-(-n0 // c0), -(-n1 // c1)), bool)
    for j in range(out.shape[1]):
        block = words[:, j * c1:(j + 1) * c1]
        full = n0 // c0
        if full:  # splitting the time axis of the (strided) block: a view, no copy
            out[:full, j] = block[: full * c0].reshape(full, c0, *block.shape[1:]).max(axis=(1, 2, 3)) != 0
        if out.shape[0] > full:
            out[full, j] = block[full * c0:].max() != 0
    return out


def _hinted_nonzero_chunks(data: np.ndarray, chunks: tuple[int, ...],
                           nonzero_blocks: tuple[int, np.ndarray]) -> np.ndarray | None:
    """`_nonzero_chunks` from a channel's `nonzero_blocks` where its blocks are the chunks' taxel columns: the
    columns it flags zero are not read, the others scanned only where a column holds several chunks along time;
    None where the blocks do not match the chunks (then everything is scanned)."""
    block, mask = nonzero_blocks
    if data.ndim < 2 or chunks[1] != block or len(mask) != -(-data.shape[1] // block):
        return None
    n_time = -(-data.shape[0] // chunks[0])
    nz = np.zeros((n_time, len(mask)), bool)
    for j in np.flatnonzero(mask):
        col = data[:, j * block:(j + 1) * block]
        nz[:, j] = True if n_time == 1 else _nonzero_chunks(np.ascontiguousarray(col), chunks)[:, 0]
    return nz


def _write_rows(dsid: h5d.DatasetID, data: np.ndarray, chunks: tuple[int, ...] | None,
                nonzero_blocks: tuple[int, np.ndarray] | None = None) -> None:
    """Write `data` into the chunked dataset `dsid` laid out in `chunks` (`_chunk_shape`; None: written whole),
    leaving its all-zero chunks unwritten (SKIP_ZERO_CHUNKS): a dataset with no zero chunk in one call, else each
    run of nonzero chunks along time (within one taxel block) as one hyperslab. `nonzero_blocks`: the channel's
    hint (`Channel.nonzero_blocks`), which spares the scan of the blocks it flags zero."""
    data = np.ascontiguousarray(data)
    if not SKIP_ZERO_CHUNKS or chunks is None or data.ndim == 0 or data.size == 0:
        dsid.write(h5s.ALL, h5s.ALL, data)
        return
    if data.shape[0] <= chunks[0] and (data.ndim < 2 or data.shape[1] <= chunks[1]):  # one chunk: one count (~2 us)
        if np.count_nonzero(data.reshape(-1).view(np.uint8)):
            dsid.write(h5s.ALL, h5s.ALL, data)
        return
    nz = _hinted_nonzero_chunks(data, chunks, nonzero_blocks) if USE_BLOCK_HINTS and nonzero_blocks is not None else None
    if nz is None:
        nz = _nonzero_chunks(data, chunks)
    if nz.all():
        dsid.write(h5s.ALL, h5s.ALL, data)
        return
    shape = data.shape
    c0 = chunks[0]
    c1 = chunks[1] if data.ndim >= 2 else None
    for j in range(nz.shape[1]):
        edges = np.flatnonzero(np.diff(np.concatenate([[False], nz[:, j], [False]]).astype(np.int8)))
        for a, b in zip(edges[::2], edges[1::2]):  # runs of nonzero chunks [a, b) along time
            start = [int(a) * c0] + [0] * (data.ndim - 1)
            count = [min(int(b) * c0, shape[0]) - start[0], *shape[1:]]
            if c1 is not None:
                start[1] = j * c1
                count[1] = min(c1, shape[1] - start[1])
            fspace = dsid.get_space()
            fspace.select_hyperslab(tuple(start), tuple(count))
            part = data[tuple(slice(s, s + c) for s, c in zip(start, count))]
            dsid.write(h5s.create_simple(tuple(count)), fspace, np.ascontiguousarray(part))


def _write_channel(
    group: h5py.Group, name: str, ch: Channel, compression: str, *, with_data: bool = True, checksum: bool = True
) -> h5py.Dataset:
    """Create the dataset of one channel, with its attributes; ``with_data=False``: no data written.
    ``checksum``: Fletcher-32 per chunk on chunked datasets. A time series is chunked by `_chunk_shape` and its
    all-zero chunks are not written (`_write_rows`)."""
    data = ch.data
    kwargs: dict[str, Any] = {}
    chunks = _chunk_shape(ch)
    if data.ndim >= 1 and data.size > 0:
        kwargs["chunks"] = chunks if chunks is not None else True
        if checksum:  # per-chunk checksum: a flipped byte is a read error, not a wrong number
            kwargs["fletcher32"] = True
        if compression == "lzf":
            kwargs.update(compression="lzf", shuffle=True)
        elif compression == "gzip":
            kwargs.update(compression="gzip", compression_opts=1, shuffle=True)
        elif compression in ("zstd", "lz4"):
            kwargs.update(_blosc2(compression))
    contents = {"data": data} if with_data and chunks is None else {"shape": data.shape, "dtype": data.dtype}
    ds = group.create_dataset(name, **contents, **kwargs)
    if with_data and chunks is not None:
        _write_rows(ds.id, data, chunks, ch.nonzero_blocks)
    ds.attrs["units"] = ch.units
    ds.attrs["dim_names"] = json.dumps(list(ch.dim_names))
    if ch.description:
        ds.attrs["description"] = ch.description
    return ds


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _check_episode(ep_id: str, channels: Mapping[str, Channel]) -> None:
    _check_name(ep_id, "episode id")
    if not channels:
        raise ValueError(f"episode {ep_id!r} has no channels")
    for name, ch in channels.items():
        _check_name(name, "channel name")
        if not isinstance(ch, Channel):
            raise ValueError(f"episode {ep_id!r} channel {name!r}: expected a Channel")
        ch.validate(f"episode {ep_id!r} channel {name!r}")


_TEMPLATES_PER_PROCESS = 16  # episode layouts kept (e.g. a few episode lengths, for a few families or codecs)
_template_names = itertools.count()
# the templates of this process, shared by its writers (a writer process of the GPU feed writes shard after shard of
# the same layouts: building them per shard cost 1.1-2.9 ms per episode of cnt_pdms, fabric_1 and velostat shards,
# "other" at 344a0a0 in bench/results/writer-episode-cpu.json), and the lock that keeps one thread's copy from a
# template another evicts
_TEMPLATES: OrderedDict[tuple, _Template] = OrderedDict()
_TEMPLATES_LOCK = threading.Lock()
_VLEN_STR = h5py.string_dtype()


def _attr_array(stored: Any) -> np.ndarray:
    """The array h5py writes for an encoded attribute value (a str is a variable-length UTF-8 string)."""
    if type(stored) is str:
        return np.array(stored, dtype=_VLEN_STR)
    return np.asarray(stored, order="C")


def _value_key(arr: np.ndarray) -> Any:
    return arr.item() if arr.dtype.kind == "O" else arr.tobytes()  # bytes: tells -0.0 from 0.0


class _Template:
    """An empty episode group (attributes, datasets with no data) in an in-memory HDF5 file.

    Creating HDF5 objects through h5py costs ~0.1-0.3 ms each; copying a whole prebuilt group with
    ``H5Ocopy`` and then writing the data and only the attributes whose values differ costs a fraction
    of that, and gives the same objects as building the group one call at a time.
    """

    def __init__(self, channels: Mapping[str, Channel], encoded: Mapping[str, tuple[Any, bool]],
                 arrays: Mapping[str, np.ndarray], compression: str, checksum: bool = True):
        self.file = h5py.File(f"piezotwin-template-{next(_template_names)}", "w", driver="core",
                              backing_store=False, libver=_LIBVER)
        try:
            g = self.file.create_group("ep")
            _write_attrs(g, encoded)
            for name, ch in channels.items():
                _write_channel(g, name, ch, compression, with_data=False, checksum=checksum)
        except BaseException:
            self.close()
            raise
        self.values = {key: _value_key(arr) for key, arr in arrays.items()}
        self.mtypes = {key: h5t.py_create(arr.dtype) for key, arr in arrays.items()}
        self.chunks = {name: _chunk_shape(ch) for name, ch in channels.items()}

    def write(self, dest: h5py.Group, ep_id: str, channels: Mapping[str, Channel],
              arrays: Mapping[str, np.ndarray]) -> None:
        h5o.copy(self.file.id, b"ep", dest.id, ep_id.encode())
        gid = h5g.open(dest.id, ep_id.encode())
        for key, arr in arrays.items():
            if _value_key(arr) != self.values[key]:
                h5a.open(gid, key.encode()).write(arr, mtype=self.mtypes[key])
        for name, ch in channels.items():
            _write_rows(h5d.open(gid, name.encode()), ch.data, self.chunks[name], ch.nonzero_blocks)

    def close(self) -> None:
        self.file.close()


class _SummaryAccumulator:
    """Episodes' samples and duration and per channel units, dims, dtype, frame shape, samples and finite min /
    max, accumulated episode by episode: the one code behind `Recording.summary` (reading the file) and the
    writer's stored summary (from the arrays it writes), so the two agree."""

    def __init__(self) -> None:
        self.n_samples = 0
        self.duration_s = 0.0
        self.channels: dict[str, dict[str, Any]] = {}

    def add_time(self, t: Any) -> None:
        """The episode's ``time`` channel (an array or an h5py dataset): its samples and n * mean(dt)."""
        if t.ndim >= 1:
            n = t.shape[0]
            self.n_samples += n
            if n >= 2:
                self.duration_s += float(t[n - 1] - t[0]) * n / (n - 1)

    def add_channel(self, name: str, units: str, dim_names: tuple[str, ...], dtype: np.dtype, shape: tuple[int, ...],
                    blocks: Iterator[np.ndarray]) -> None:
        c = self.channels.setdefault(name, {
            "units": units, "dim_names": tuple(dim_names), "dtype": str(dtype),
            "frame_shape": tuple(shape[1:]) if len(shape) else (), "n_samples": 0, "min": math.inf, "max": -math.inf,
        })
        c["n_samples"] += shape[0] if len(shape) else 1
        for block in blocks:
            b = np.asarray(block)
            if not b.size:
                continue
            if b.dtype.kind in "fc":
                b = b.real
            lo, hi = b.min(), b.max()  # one pass each; a masked copy only where a value is not finite
            if b.dtype.kind in "fc" and not (np.isfinite(lo) and np.isfinite(hi)):
                b = b[np.isfinite(b)]
                if not b.size:
                    continue
                lo, hi = b.min(), b.max()
            c["min"] = min(c["min"], lo.item())
            c["max"] = max(c["max"], hi.item())

    def add_episode(self, channels: Mapping[str, Channel]) -> None:
        """One episode from memory, as the writer holds it."""
        if "time" in channels:
            self.add_time(channels["time"].data)
        for name in sorted(channels):
            ch = channels[name]
            d = np.asarray(ch.data)
            # a field its producer flags all +0.0 (an unloaded shear field) is not read: its min and max are 0.0.
            # Only then: a min / max over a few strided blocks costs more than over the whole contiguous array
            hinted_zero = USE_BLOCK_HINTS and ch.nonzero_blocks is not None and not ch.nonzero_blocks[1].any()
            parts = (np.zeros(1 if d.size else 0, d.dtype),) if hinted_zero else (d,)
            self.add_channel(name, ch.units, ch.dim_names, d.dtype, d.shape, iter(parts))

    def result(self) -> dict[str, Any]:
        """{"n_samples", "duration_s", "channels"}: min / max None where a channel has no finite value."""
        chans = {}
        for name, c in self.channels.items():
            c = dict(c)
            if c["min"] == math.inf:
                c["min"] = c["max"] = None
            chans[name] = c
        return {"n_samples": self.n_samples, "duration_s": self.duration_s, "channels": chans}

    def to_json(self) -> str:
        return json.dumps(self.result())


def merge_summaries(parts: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """One summary ({"n_samples", "duration_s", "channels"}) of several recordings' (`Recording.summary` or the
    writers' stored ones), in their order: samples and durations summed, per channel its samples summed and the
    smallest min / largest max (None where no part has a finite value); units, dims, dtype and frame shape as the
    first part that has the channel gives them."""
    chans: dict[str, dict[str, Any]] = {}
    for part in parts:
        for name, c in part["channels"].items():
            d = chans.get(name)
            if d is None:
                chans[name] = dict(c)
                continue
            d["n_samples"] = d.get("n_samples", 0) + c.get("n_samples", 0)
            for key, pick in (("min", min), ("max", max)):
                vals = [v for v in (d[key], c[key]) if v is not None]
                d[key] = pick(vals) if vals else None
    return {"n_samples": sum(p["n_samples"] for p in parts), "duration_s": sum(p["duration_s"] for p in parts),
            "channels": chans}


def _summary_from_json(text: str) -> dict[str, Any]:
    d = json.loads(text)
    for c in d["channels"].values():
        c["dim_names"] = tuple(c["dim_names"])
        c["frame_shape"] = tuple(c["frame_shape"])
    return d


class RecordingWriter:
    """Write one recording episode by episode, atomically (what `write_recording` does in one call).

    ::

        with RecordingWriter(path, source="sim", config_json=..., root_seed=0, shard_index=3,
                             sensor_attrs={...}) as w:
            w.add_episode("ep-000000", channels, attrs)     # may be called from another thread
        # renamed into place here; on an exception (or no episode) nothing appears at `path`

    The file is built at ``<path>.tmp``; episodes must be added in the order they should be stored.
    Lets a producer simulate the next episodes while this writes (and compresses) the previous ones.
    An episode whose layout was seen before (by any writer of this process) is copied from a cached `_Template`,
    then filled in.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        source: Literal["sim", "real"],
        config_json: str,
        root_seed: int | None,
        shard_index: int | None,
        sensor_attrs: Mapping[str, Any],
        mjcf: str | None = None,
        extra_attrs: Mapping[str, Any] | None = None,
        compression: Literal["lzf", "gzip", "none", "zstd", "lz4"] = "lzf",
        checksum: bool = True,
        _fast: bool = True,  # tests only: False writes every episode object by object
    ):
        if source not in ("sim", "real"):
            raise ValueError(f"source must be 'sim' or 'real', got {source!r}")
        if compression not in _COMPRESSIONS:
            raise ValueError(f"compression must be one of {_COMPRESSIONS}, got {compression!r}")
        if not isinstance(config_json, str):
            raise ValueError("config_json must be a JSON string")
        try:
            json.loads(config_json)
        except json.JSONDecodeError as e:
            raise ValueError(f"config_json is not valid JSON: {e}") from e
        reserved = {"format", "format_version", "source", "config_json", "config_sha256", "content_sha256"}
        if extra_attrs and reserved & set(extra_attrs):
            raise ValueError(f"extra_attrs may not override {sorted(reserved & set(extra_attrs))}")
        self.path = Path(path)
        self.compression = compression
        self.checksum = checksum
        gen = generator_info()
        self._root: dict[str, Any] = {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "source": source,
            "created_utc": _utc_now(),
            "generator": f"{gen['name']} {gen['version']} (git {gen['commit']})",
            "generator_version": gen["version"],
            "generator_commit": gen["commit"],
            "config_json": config_json,
            "config_sha256": hashlib.sha256(config_json.encode("utf-8")).hexdigest(),
            "root_seed": root_seed,
            "shard_index": shard_index,
        }
        self._root.update({f"version_{k}": v for k, v in _library_versions().items()})
        self._root.update(extra_attrs or {})
        self._sensor_attrs = dict(sensor_attrs)
        self._mjcf = mjcf
        self._f: h5py.File | None = None
        self._eps: h5py.Group | None = None
        self._fast = _fast
        self._layouts: set[tuple] = set()  # the episode layouts this writer has written through templates
        self._digests: dict[str, bytes] = {}
        self._summary = _SummaryAccumulator()  # stored as SUMMARY_ATTR at the end
        self.content_sha256: str | None = None  # set when the file is complete
        self.summary: dict[str, Any] | None = None  # set when the file is complete: the stored summary as a dict
        self.n_episodes = 0
        self.tmp = self.path.with_name(self.path.name + ".tmp")

    def __enter__(self) -> RecordingWriter:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._f = h5py.File(self.tmp, "w", track_order=True, libver=_LIBVER)
            _set_attrs(self._f, self._root, "root")
            _set_attrs(self._f.create_group("sensor"), self._sensor_attrs, "sensor")
            if self._mjcf is not None:
                self._f.create_group("scene").create_dataset("mjcf", data=self._mjcf, dtype=h5py.string_dtype())
            self._eps = self._f.create_group("episodes")
        except BaseException:
            self._abort()
            raise
        return self

    def add_episode(self, ep_id: str, channels: Mapping[str, Channel], attrs: Mapping[str, Any] | None = None) -> None:
        if self._eps is None:
            raise RuntimeError("RecordingWriter: add_episode outside the with block")
        _check_episode(ep_id, channels)
        encoded = _encode_attrs(dict(attrs or {}), f"episode {ep_id}")
        if self._fast and all(ch.data.ndim >= 1 and ch.data.size > 0 for ch in channels.values()):
            arrays = {key: _attr_array(stored) for key, (stored, _) in encoded.items()}
            with _TEMPLATES_LOCK:
                self._template(channels, encoded, arrays).write(self._eps, ep_id, channels, arrays)
        else:
            g = self._eps.create_group(ep_id)
            _write_attrs(g, encoded)
            for name, ch in channels.items():
                _write_channel(g, name, ch, self.compression, checksum=self.checksum)
        # the attributes as a reader decodes them (`_decoded_attrs`, equal to reading them back, which cost about a
        # third of a small episode's write), the data from memory
        self._digests[ep_id] = _episode_digest(
            ep_id, _decoded_attrs(encoded),
            {name: (ch.data, ch.units, ch.dim_names, ch.description) for name, ch in channels.items()})
        self._summary.add_episode(channels)
        self.n_episodes += 1

    def _template(self, channels: Mapping[str, Channel], encoded: Mapping[str, tuple[Any, bool]],
                  arrays: Mapping[str, np.ndarray]) -> _Template:
        """The process's cached template of this episode layout (channels, attribute types, compression), built if
        new (call with _TEMPLATES_LOCK held)."""
        key = (
            tuple((name, ch.data.dtype.str, ch.data.shape, ch.units, ch.dim_names, ch.description)
                  for name, ch in channels.items()),
            tuple((k, encoded[k][1], arr.dtype.str, arr.shape) for k, arr in arrays.items()),
            self.compression, self.checksum,
        )
        self._layouts.add(key)
        tmpl = _TEMPLATES.get(key)
        if tmpl is None:
            tmpl = _TEMPLATES[key] = _Template(channels, encoded, arrays, self.compression, self.checksum)
            if len(_TEMPLATES) > _TEMPLATES_PER_PROCESS:
                _TEMPLATES.popitem(last=False)[1].close()
        _TEMPLATES.move_to_end(key)
        return tmpl

    def _abort(self) -> None:
        if self._f is not None:
            try:
                self._f.close()
            except Exception:  # noqa: BLE001 - the file is being thrown away
                pass
            self._f = self._eps = None
        try:
            self.tmp.unlink()
        except FileNotFoundError:
            pass

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None and self.n_episodes == 0:
            self._abort()
            raise ValueError("episodes is empty: a recording needs at least one episode")
        if exc_type is not None:
            self._abort()
            return
        try:
            self.content_sha256 = content_sha256(_get_attrs(self._f), _get_attrs(self._f["sensor"]), self._mjcf,
                                                 self._digests)
            self._f.attrs["content_sha256"] = self.content_sha256
            stored = self._summary.to_json()
            self._f.attrs[SUMMARY_ATTR] = stored
            self._f.close()
            self._f = self._eps = None
            _fsync(self.tmp)
            os.replace(self.tmp, self.path)
        except BaseException:
            self._abort()
            raise
        self.summary = _summary_from_json(stored)  # what a reader of the file gets, JSON round trip included
        try:  # make the rename durable; best effort (not every filesystem allows it)
            _fsync(self.path.parent)
        except OSError:
            pass


def write_recording(
    path: str | os.PathLike,
    episodes: Mapping[str, Mapping[str, Channel]],
    *,
    source: Literal["sim", "real"],
    config_json: str,
    root_seed: int | None,
    shard_index: int | None,
    sensor_attrs: Mapping[str, Any],
    mjcf: str | None = None,
    episode_attrs: Mapping[str, Mapping[str, Any]] | None = None,
    extra_attrs: Mapping[str, Any] | None = None,
    compression: Literal["lzf", "gzip", "none", "zstd", "lz4"] = "lzf",
    checksum: bool = True,
) -> Path:
    """Write one recording (shard) atomically and return its final path.

    The file is built at ``<path>.tmp`` and renamed to ``path`` when complete; on any exception
    the temporary file is removed and nothing appears at ``path``. Episodes are stored in natural
    order of their ids. (`RecordingWriter` does the same episode by episode.)
    """
    writer = RecordingWriter(
        path, source=source, config_json=config_json, root_seed=root_seed, shard_index=shard_index,
        sensor_attrs=sensor_attrs, mjcf=mjcf, extra_attrs=extra_attrs, compression=compression, checksum=checksum,
    )
    if not episodes:
        raise ValueError("episodes is empty: a recording needs at least one episode")
    episode_attrs = dict(episode_attrs or {})
    for ep_id, channels in episodes.items():
        _check_episode(ep_id, channels)
    unknown = set(episode_attrs) - set(episodes)
    if unknown:
        raise ValueError(f"episode_attrs for unknown episodes: {sorted(unknown)}")
    with writer as w:
        for ep_id in _natural_sorted(episodes):
            w.add_episode(ep_id, episodes[ep_id], episode_attrs.get(ep_id, {}))
    return writer.path


# --------------------------------------------------------------------------- reading


def _natural_key(s: str) -> list:
    return [(0, int(t), "") if t.isdigit() else (1, 0, t) for t in re.split(r"(\d+)", s) if t]


def _natural_sorted(names) -> list[str]:
    return sorted(names, key=_natural_key)


def _first_line(e: BaseException) -> str:
    return (str(e).splitlines() or [type(e).__name__])[0]


def _damage_is_error(fn):
    """HDF5 errors while reading (OSError, RuntimeError: a damaged B-tree, a failed checksum or decompression)
    -> RecordingError naming the file, one line."""

    @functools.wraps(fn)
    def wrapper(self: Recording, *args: Any, **kwargs: Any) -> Any:
        try:
            return fn(self, *args, **kwargs)
        except FileNotFoundError:
            raise
        except (OSError, RuntimeError) as e:
            raise RecordingError(f"{self.path}: damaged recording, HDF5 cannot read it ({_first_line(e)})") from None

    return wrapper


class Recording:
    """Read access to one recording file; use as a context manager or call ``close()``.

    A damaged file (unreadable HDF5 structure, a chunk that fails its Fletcher-32 checksum or does not
    decompress) raises RecordingError naming the file, from the open or from the read that meets the damage.
    """

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        try:
            self._f = h5py.File(self.path, "r")
        except FileNotFoundError:
            raise
        except (OSError, RuntimeError) as e:
            raise RecordingError(f"{self.path}: not a readable HDF5 file ({_first_line(e)})") from None
        try:
            self._validate()
        except BaseException:
            self._f.close()
            raise

    @_damage_is_error
    def _validate(self) -> None:
        fmt = _decode_value(self._f.attrs.get("format"))
        if fmt is None:
            groups = ", ".join(sorted(self._f.keys())[:8]) or "none"
            raise RecordingError(
                f"{self.path}: not a {FORMAT} file (an HDF5 file with no 'format' attribute; "
                f"top-level entries: {groups})"
            )
        if fmt != FORMAT:
            raise RecordingError(f"{self.path}: format is {fmt!r}, not {FORMAT!r}")
        version = _decode_value(self._f.attrs.get("format_version"))
        if not isinstance(version, int) or version < 1:
            raise RecordingError(f"{self.path}: bad format_version {version!r}")
        if version > FORMAT_VERSION:
            raise RecordingError(
                f"{self.path}: format_version {version} is newer than this piezotwin supports "
                f"({FORMAT_VERSION}); upgrade piezotwin"
            )
        if "episodes" not in self._f:
            raise RecordingError(f"{self.path}: recording has no /episodes group")

    # context manager
    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._f.id.valid:
            self._f.close()

    def __repr__(self) -> str:
        return f"Recording({str(self.path)!r})"

    # metadata
    @functools.cached_property
    @_damage_is_error
    def attrs(self) -> dict[str, Any]:
        return _get_attrs(self._f)

    @property
    def config(self) -> dict[str, Any]:
        return json.loads(self.attrs["config_json"])

    @property
    def config_sha256(self) -> str:
        if "attrs" in self.__dict__:
            return self.attrs["config_sha256"]
        # this attribute alone (a shard check reads nothing else: decoding every attribute of each shard cost the
        # GPU feed's driver 2.4 s over fabric_1's 1024 shards, bench/results/logs/profile-fabric_1-h200-s17.txt)
        return self._attrs_named("config_sha256")["config_sha256"]

    @_damage_is_error
    def _attrs_named(self, *keys: str) -> dict[str, Any]:
        """Only these attributes, decoded (those present)."""
        return _get_attrs(self._f, keys)

    @property
    def content_sha256(self) -> str:
        """The content hash stored when the file was written (computed from the file for older recordings)."""
        return self.attrs.get("content_sha256") or self.compute_content_sha256()

    @_damage_is_error
    def compute_content_sha256(self) -> str:
        """The content hash recomputed from what the file holds (reads every channel)."""
        digests = {}
        for ep in self.episode_ids:
            g = self._group(ep)
            chans = {}
            for name in g.keys():
                ds = g[name]
                chans[name] = (np.asarray(ds[()]), self.units(ep, name), self.dim_names(ep, name),
                               self.description(ep, name))
            digests[ep] = _episode_digest(ep, self.episode_attrs(ep), chans)
        return content_sha256(self.attrs, self.sensor_attrs, self.mjcf, digests)

    @functools.cached_property
    @_damage_is_error
    def sensor_attrs(self) -> dict[str, Any]:
        return _get_attrs(self._f["sensor"]) if "sensor" in self._f else {}

    @property
    @_damage_is_error
    def mjcf(self) -> str | None:
        if "scene" in self._f and "mjcf" in self._f["scene"]:
            return _decode_value(self._f["scene/mjcf"][()])
        return None

    @functools.cached_property
    @_damage_is_error
    def episode_ids(self) -> list[str]:
        return _natural_sorted(self._f["episodes"].keys())

    @_damage_is_error
    def _group(self, ep_id: str) -> h5py.Group:
        try:
            return self._f["episodes"][ep_id]
        except KeyError as e:
            if ep_id in self.episode_ids:  # listed but cannot be opened: damaged
                raise RecordingError(f"{self.path}: damaged recording, HDF5 cannot open episode {ep_id!r} "
                                     f"({_first_line(e)})") from None
            raise KeyError(f"{self.path}: no episode {ep_id!r}") from None

    @_damage_is_error
    def _ds(self, ep_id: str, name: str) -> h5py.Dataset:
        g = self._group(ep_id)
        if name not in g:
            raise KeyError(
                f"{self.path}: episode {ep_id!r} has no channel {name!r} (has {sorted(g.keys())})"
            )
        return g[name]

    @_damage_is_error
    def channels(self, ep_id: str) -> list[str]:
        return sorted(self._group(ep_id).keys())

    @_damage_is_error
    def episode_attrs(self, ep_id: str) -> dict[str, Any]:
        return _get_attrs(self._group(ep_id))

    @_damage_is_error
    def units(self, ep_id: str, name: str) -> str:
        return _decode_value(self._ds(ep_id, name).attrs["units"])

    @_damage_is_error
    def dim_names(self, ep_id: str, name: str) -> tuple[str, ...]:
        return tuple(json.loads(_decode_value(self._ds(ep_id, name).attrs["dim_names"])))

    @_damage_is_error
    def description(self, ep_id: str, name: str) -> str:
        return _decode_value(self._ds(ep_id, name).attrs.get("description", ""))

    @_damage_is_error
    def shape(self, ep_id: str, name: str) -> tuple[int, ...]:
        return tuple(self._ds(ep_id, name).shape)

    @_damage_is_error
    def read(self, ep_id: str, name: str, sl: Any = slice(None)) -> np.ndarray:
        ds = self._ds(ep_id, name)
        if ds.ndim == 0:
            return np.asarray(ds[()])
        return np.asarray(ds[sl])

    def read_column(self, ep_id: str, name: str) -> np.ndarray:
        """A channel by name, or one column of it as ``name[k]`` (a board stream of several values per sample, e.g.
        a capture's ``velostat[0]``): [T] for a column; KeyError naming the channel or the column range."""
        base, k = split_column(name)
        a = self.read(ep_id, base)
        if k is None:
            return a
        a = a.reshape(len(a), -1)
        if k >= a.shape[1]:
            raise KeyError(f"{self.path}: episode {ep_id!r}: channel {base!r} has {a.shape[1]} column(s); {name!r} "
                           f"asks for column {k} (allowed 0-{a.shape[1] - 1})")
        return a[:, k]

    def channel(self, ep_id: str, name: str) -> Channel:
        return Channel(
            self.read(ep_id, name),
            self.units(ep_id, name),
            self.dim_names(ep_id, name),
            self.description(ep_id, name),
        )

    def _blocks(self, ds: h5py.Dataset, max_bytes: int = 32 << 20) -> Iterator[np.ndarray]:
        if ds.ndim == 0 or ds.shape[0] == 0:
            yield np.asarray(ds[()])
            return
        row = max(1, ds.size // ds.shape[0] * ds.dtype.itemsize)
        step = max(1, max_bytes // row)
        if ds.chunks:
            step = max(ds.chunks[0], step // ds.chunks[0] * ds.chunks[0])
        for i in range(0, ds.shape[0], step):
            yield ds[i : i + step]

    @property
    def has_stored_summary(self) -> bool:
        """Whether the writer stored its summary (SUMMARY_ATTR; files written before do not have it)."""
        return SUMMARY_ATTR in self._f.attrs

    @_damage_is_error
    def summary(self, from_data: bool = True) -> dict[str, Any]:
        """Episodes, total duration (s) and per channel units, dims, shapes, min and max.

        The duration of an episode is n * mean(dt) of its ``time`` channel (its span plus one
        sample period), so n samples at f Hz last n/f seconds. from_data=False: the summary the writer stored
        (SUMMARY_ATTR, equal to reading; no dataset is read), where the file has one.
        """
        keys = ("format_version", "source", "created_utc", "generator", "config_sha256", "content_sha256",
                "root_seed", "shard_index")
        # the stored summary with the root attributes it reports, read one by one (not the config and versions)
        a = {} if from_data else _get_attrs(self._f, (SUMMARY_ATTR, *keys))
        if a.get(SUMMARY_ATTR) is not None:
            d = _summary_from_json(a[SUMMARY_ATTR])
            n_episodes = len(self._f["episodes"])
        else:
            a = self.attrs
            n_episodes = len(self.episode_ids)
            acc = _SummaryAccumulator()
            for ep in self.episode_ids:
                g = self._group(ep)
                if "time" in g:
                    acc.add_time(g["time"])
                for name in sorted(g.keys()):
                    ds = g[name]
                    acc.add_channel(name, self.units(ep, name), self.dim_names(ep, name), ds.dtype, ds.shape,
                                    self._blocks(ds))
            d = acc.result()
        n_samples, duration, chans = d["n_samples"], d["duration_s"], d["channels"]
        return {
            "path": str(self.path),
            "format_version": a["format_version"],
            "source": a["source"],
            "created_utc": a.get("created_utc"),
            "generator": a.get("generator"),
            "config_sha256": a.get("config_sha256"),
            "content_sha256": a.get("content_sha256") or self.content_sha256,
            "root_seed": a.get("root_seed"),
            "shard_index": a.get("shard_index"),
            "n_episodes": n_episodes,
            "n_samples": n_samples,
            "duration_s": duration,
            "channels": chans,
        }


def read_recording_summary(path: str | os.PathLike, from_data: bool = True) -> dict[str, Any]:
    with Recording(path) as rec:
        return rec.summary(from_data=from_data)
