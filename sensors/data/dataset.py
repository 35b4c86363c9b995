"""Sliding windows over recordings, as a torch Dataset.

``WindowDataset`` indexes every window of ``window`` consecutive samples (step ``stride``) of
every selected episode. Item ``i`` is ``(x, y)``: ``x`` float32 ``(window, n_input_features)``,
the input channels over the window, each flattened per frame and concatenated in the order given;
``y`` float32 ``(n_target_features,)``, the target channels at the window's last step
(``horizon="last"``) or ``h`` steps after it (``horizon=h``, an int >= 0).

HDF5 files are only opened briefly at construction (to read lengths and shapes); reads open them
lazily in whichever process calls ``__getitem__`` (handles are cached per process id and never
pickled), so the dataset works with ``DataLoader(num_workers>0)``.
"""

from __future__ import annotations

import os
from collections import OrderedDict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import torch
from torch.utils.data import Dataset

from sensors.data.recording import Recording

__all__ = ["WindowDataset"]


class WindowDataset(Dataset):
    def __init__(
        self,
        paths: Sequence[str | os.PathLike] | str | os.PathLike,
        inputs: Sequence[str],
        targets: Sequence[str],
        window: int,
        stride: int = 1,
        episodes: Sequence[tuple[str | os.PathLike, str] | str] | None = None,
        horizon: str | int = "last",
        max_open_files: int = 32,
        max_open_datasets: int = 64,
    ):
        if isinstance(paths, (str, os.PathLike)) and Path(paths).is_dir():
            from sensors.data.manifest import shard_files

            files = shard_files(paths)
        elif isinstance(paths, (str, os.PathLike)):
            files = [Path(paths)]
        else:
            files = [Path(p) for p in paths]
        if not files:
            raise ValueError(f"no recording files in {paths}")
        if window < 1 or stride < 1:
            raise ValueError(f"window and stride must be >= 1 (got {window}, {stride})")
        if horizon == "last":
            self.horizon = 0
        elif isinstance(horizon, (int, np.integer)) and not isinstance(horizon, bool) and horizon >= 0:
            self.horizon = int(horizon)
        else:
            raise ValueError(f"horizon must be 'last' or an int >= 0, got {horizon!r}")
        if not inputs or not targets:
            raise ValueError("inputs and targets must each name at least one channel")
        self.files = [f.resolve() for f in files]
        self.inputs = list(inputs)
        self.targets = list(targets)
        self.window = int(window)
        self.stride = int(stride)
        self.max_open_files = int(max_open_files)
        self.max_open_datasets = max(1, int(max_open_datasets))

        wanted = self._select(files, episodes)
        names = list(dict.fromkeys(self.inputs + self.targets))
        frame_shapes: dict[str, tuple[int, ...]] = {}
        self.units: dict[str, str] = {}
        ep_file, ep_ids, ep_count = [], [], []
        for fi, f in enumerate(self.files):
            sel = wanted.get(fi)
            if sel is not None and not sel:
                continue
            with Recording(f) as rec:
                ids = rec.episode_ids if sel is None else sel
                for ep in ids:
                    length = None
                    have = rec.channels(ep)
                    for name in names:
                        if name not in have:
                            raise ValueError(f"{f}:{ep} has no channel {name!r} (has {have})")
                        shape = rec.shape(ep, name)
                        dims = rec.dim_names(ep, name)
                        if not dims or dims[0] != "time":
                            raise ValueError(f"{f}:{ep}/{name} is not a time series (dims {dims})")
                        fs = tuple(shape[1:])
                        if frame_shapes.setdefault(name, fs) != fs:
                            raise ValueError(
                                f"{f}:{ep}/{name} frame shape {fs} differs from {frame_shapes[name]}"
                            )
                        self.units.setdefault(name, rec.units(ep, name))
                        if length is None:
                            length = shape[0]
                        elif shape[0] != length:
                            raise ValueError(
                                f"{f}:{ep}: channels {names} differ in length ({shape[0]} vs {length})"
                            )
                    span = self.window + self.horizon
                    n = 0 if length < span else (length - span) // self.stride + 1
                    if n:
                        ep_file.append(fi)
                        ep_ids.append(ep)
                        ep_count.append(n)
        self._ep_file = np.asarray(ep_file, dtype=np.int64)
        self._ep_ids = ep_ids
        self._cum = np.concatenate([[0], np.cumsum(ep_count, dtype=np.int64)])
        self._sizes = {n: int(np.prod(s, dtype=np.int64)) for n, s in frame_shapes.items()}
        self.frame_shapes = frame_shapes
        self.input_slices = self._slices(self.inputs)
        self.target_slices = self._slices(self.targets)
        self.n_input_features = sum(self._sizes[n] for n in self.inputs)
        self.n_target_features = sum(self._sizes[n] for n in self.targets)
        self._pid: int | None = None
        self._handles: OrderedDict[int, h5py.File] = OrderedDict()
        self._dsets: OrderedDict[tuple[int, str], h5py.Dataset] = OrderedDict()

    # ------------------------------------------------------------------ construction helpers

    def _select(self, files, episodes) -> dict[int, list[str]]:
        """Map file index -> selected episode ids (files absent from the map: all episodes)."""
        if episodes is None:
            return {}
        by_path = {f.resolve(): i for i, f in enumerate(files)}
        by_stem: dict[str, int] = {}
        for i, f in enumerate(files):
            by_stem.setdefault(Path(f).stem, i)
        out: dict[int, list[str]] = {i: [] for i in range(len(files))}
        for e in episodes:
            if isinstance(e, str):
                stem, sep, ep = e.partition("/")
                if not sep or stem not in by_stem:
                    raise ValueError(f"episode {e!r}: expected 'shard/episode' naming one of the files")
                fi = by_stem[stem]
            else:
                p, ep = e
                fi = by_path.get(Path(p).resolve())
                if fi is None:
                    raise ValueError(f"episode {e!r}: file not among the dataset's paths")
            if ep not in out[fi]:
                out[fi].append(ep)
        return out

    def _slices(self, names: Sequence[str]) -> dict[str, slice]:
        out, i = {}, 0
        for n in names:
            out[n] = slice(i, i + self._sizes[n])
            i += self._sizes[n]
        return out

    # ------------------------------------------------------------------ lazy file handles

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_handles"] = OrderedDict()
        state["_dsets"] = OrderedDict()
        state["_pid"] = None
        return state

    def _file(self, fi: int) -> h5py.File:
        pid = os.getpid()
        if self._pid != pid:  # new process (e.g. a DataLoader worker): never reuse inherited handles
            self._handles = OrderedDict()
            self._dsets = OrderedDict()
            self._pid = pid
        f = self._handles.get(fi)
        if f is not None and not f.id.valid:
            f = None
        if f is None:
            f = h5py.File(self.files[fi], "r")
            self._handles[fi] = f
            while len(self._handles) > self.max_open_files:
                old_fi, old = self._handles.popitem(last=False)
                for key in [k for k in self._dsets if self._ep_file[k[0]] == old_fi]:
                    del self._dsets[key]
                old.close()
        else:
            self._handles.move_to_end(fi)
        return f

    def _dataset(self, e: int, name: str) -> h5py.Dataset:
        """Open dataset of episode ``e``, cached (an h5py chunk cache lives with the open dataset,
        so consecutive windows do not decompress the same chunk again)."""
        key = (e, name)
        if self._pid == os.getpid():
            ds = self._dsets.get(key)
            if ds is not None:
                self._dsets.move_to_end(key)
                return ds
        f = self._file(int(self._ep_file[e]))  # resets the caches in a new process
        ds = f["episodes"][self._ep_ids[e]][name]
        self._dsets[key] = ds
        while len(self._dsets) > self.max_open_datasets:
            self._dsets.popitem(last=False)
        return ds

    def close(self) -> None:
        if self._pid == os.getpid():
            for f in self._handles.values():
                f.close()
        self._handles = OrderedDict()
        self._dsets = OrderedDict()

    # ------------------------------------------------------------------ Dataset API

    def __len__(self) -> int:
        return int(self._cum[-1])

    def locate(self, index: int) -> tuple[Path, str, int]:
        """(file, episode id, start sample) of window ``index``."""
        n = len(self)
        if index < 0:
            index += n
        if not 0 <= index < n:
            raise IndexError(f"window index {index} out of range for {n} windows")
        e = int(np.searchsorted(self._cum, index, side="right") - 1)
        start = (index - int(self._cum[e])) * self.stride
        return self.files[self._ep_file[e]], self._ep_ids[e], start

    def __getitem__(self, index: int) -> tuple[torch.Tensor, torch.Tensor]:
        n = len(self)
        if index < 0:
            index += n
        if not 0 <= index < n:
            raise IndexError(f"window index {index} out of range for {n} windows")
        e = int(np.searchsorted(self._cum, index, side="right") - 1)
        start = (index - int(self._cum[e])) * self.stride
        stop = start + self.window
        x = np.concatenate(
            [
                np.asarray(self._dataset(e, c)[start:stop], dtype=np.float32).reshape(self.window, -1)
                for c in self.inputs
            ],
            axis=1,
        )
        t = stop - 1 + self.horizon
        y = np.concatenate([np.asarray(self._dataset(e, c)[t], dtype=np.float32).reshape(-1) for c in self.targets])
        return torch.from_numpy(x), torch.from_numpy(y)

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001
            pass
