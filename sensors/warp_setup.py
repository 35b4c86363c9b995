"""One place that initialises Warp quietly, resolves the device name ("cpu", "cuda", "cuda:0", "auto") and copies
results back from the GPU (`to_host`, into reused page-locked buffers inside `host_staging`)."""

from __future__ import annotations

import logging
import threading
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Iterator

import numpy as np
import warp as wp

_done = False

# Freed device memory each process's CUDA pool keeps for its next allocations instead of handing it back to the
# driver at every synchronize (CUDA's default threshold is 0): the sensor chain allocates its smaller arrays per
# call. Set in session 7 while looking for the fused chain's slowdown, which it did not remove (that was the
# stores into per-call arrays: `scratch` below); all of that session's H100 figures ran with it, no gain of its
# own is claimed. estimate: 8 GiB, 10 % of an 80 GB GPU, so the feed's driver and its two physics processes
# together hold back at most ~a third of it; capped at a quarter of a smaller device's memory.
MEMPOOL_KEEP_BYTES = 8 * 1024**3


NO_DRIVER_WARNING = "Could not find or load the NVIDIA CUDA driver"


def init_warp() -> None:
    """wp.init() once, quietly: on a machine without CUDA, Warp's native code prints "Warp CUDA warning: Could
    not find or load the NVIDIA CUDA driver" to the process's stderr on every command; that line is dropped
    (CPU is what such a machine has; asking for a CUDA device still says there is none). Anything else
    wp.init() prints is passed on."""
    global _done
    if not _done:
        wp.config.log_level = logging.WARNING
        _init_without_driver_warning()
        _done = True
        for dev in wp.get_cuda_devices():
            if wp.is_mempool_supported(dev):
                wp.set_mempool_release_threshold(dev, int(min(MEMPOOL_KEEP_BYTES, dev.total_memory // 4)))


def _init_without_driver_warning() -> None:
    import os
    import sys
    import tempfile

    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no file descriptor 2 to redirect: plain init
        wp.init()
        return
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            wp.init()
        finally:
            try:
                sys.stderr.flush()
            except (OSError, ValueError):
                pass
            os.dup2(saved, 2)
            os.close(saved)
        tmp.seek(0)
        text = tmp.read().decode("utf-8", errors="replace")
    rest = "".join(line for line in text.splitlines(keepends=True) if NO_DRIVER_WARNING not in line)
    if rest:
        sys.stderr.write(rest)
        sys.stderr.flush()


def resolve_device(device: str) -> str:
    """'auto' -> 'cuda:0' when a CUDA device is present, else 'cpu'; 'cuda' -> 'cuda:0'."""
    init_warp()
    if device == "auto":
        return "cuda:0" if wp.get_cuda_device_count() > 0 else "cpu"
    if device == "cuda":
        device = "cuda:0"
    if device.startswith("cuda") and wp.get_cuda_device_count() == 0:
        raise ValueError(f"device '{device}' requested but no CUDA device is available (allowed here: cpu, auto)")
    if device.startswith("cuda:"):
        n = wp.get_cuda_device_count()
        idx = device.split(":", 1)[1]
        if not idx.isdigit() or int(idx) >= n:
            allowed = ", ".join(["cpu", "cuda", "auto"] + [f"cuda:{i}" for i in range(n)])
            raise ValueError(f"device '{device}' does not exist here (allowed: {allowed})")
    return device


# host_staging / to_host: copies back from the GPU into reused page-locked buffers where the caller allows it
_STAGING: ContextVar[bool] = ContextVar("piezotwin_host_staging", default=False)
_PINNED: dict[tuple, wp.array] = {}  # (site, slot) -> flat page-locked host buffer (uint64), grow-only: a
# call site's copies take views of it, so a group's last, shorter slice reuses the full slice's buffer
# which set of staging buffers the copies go into: a consumer that still holds one slice's views while the next
# slice is copied back (the GPU feed packs slice i while slice i + 1 runs) alternates slots (`staging_slot`)
_SLOT: ContextVar[int] = ContextVar("piezotwin_staging_slot", default=0)
# inside `staging_log`: (site, slot) -> the most bytes a copy asked for (a probe's, for `reserve_staging`)
_LOG: ContextVar[dict | None] = ContextVar("piezotwin_staging_log", default=None)


@contextmanager
def host_staging() -> Iterator[None]:
    """Inside, `to_host` returns views of page-locked host buffers that the next copy from the same call site (in
    the same `staging_slot`) overwrites: for a consumer that copies each slice's outputs away before asking for
    the next (the GPU feed packs them into shared memory). A fresh pageable array per copy ran at ~1.4 GB/s on the H100
    host (page faults, staging); page-locked memory that stays mapped takes the DMA directly."""
    token = _STAGING.set(True)
    try:
        yield
    finally:
        _STAGING.reset(token)


@contextmanager
def staging_slot(slot: int) -> Iterator[None]:
    """Inside, `to_host` copies into the page-locked buffers of `slot` (one set per slot and call site): views
    handed out under another slot stay valid."""
    token = _SLOT.set(slot)
    try:
        yield
    finally:
        _SLOT.reset(token)


def to_host(arr: wp.array, site: str) -> np.ndarray:
    """arr on the host: `arr.numpy()` (a new array, or arr's own memory on the CPU), or inside `host_staging`
    for a CUDA array, a view of the reused page-locked buffer of `site` (valid until its next copy)."""
    _note(arr, site)
    if not _STAGING.get() or not arr.device.is_cuda:
        return arr.numpy()
    buf = _pinned_buffer(arr, site)
    wp.copy(buf, arr)
    wp.synchronize_device(arr.device)  # a copy into page-locked memory is asynchronous
    return buf.numpy()


def _pinned_buffer(arr: wp.array, site: str) -> wp.array:
    """A page-locked host array of arr's shape and dtype: a view of the grow-only buffer of `site` in the current
    `staging_slot` (made, or made larger, here: page-locking costs ~0.35 s per GB on the H200 host, so the GPU feed
    makes them ahead with `reserve_staging` while its first batch steps)."""
    key = (site, _SLOT.get())
    flat = _grow_pinned(key, arr.size * wp.types.type_size_in_bytes(arr.dtype))
    view = wp.array(ptr=flat.ptr, dtype=arr.dtype, shape=arr.shape, capacity=flat.capacity, device="cpu", pinned=True)
    view._ref = flat  # a view handed out keeps its buffer (and values) past `release_staging`
    return view


def _note(arr: wp.array, site: str) -> None:
    """Inside `staging_log` and `host_staging`: note the bytes this copy of `site` asks for (on any device, so a
    plan can be made and checked without CUDA)."""
    log = _LOG.get()
    if log is not None and _STAGING.get():
        key = (site, _SLOT.get())
        log[key] = max(log.get(key, 0), arr.size * wp.types.type_size_in_bytes(arr.dtype))


def _grow_pinned(key: tuple, nbytes: int) -> wp.array:
    flat = _PINNED.get(key)
    if flat is None or flat.capacity < nbytes:
        _PINNED.pop(key, None)  # unpinned before the larger one is made
        # 8-byte words: a Warp dimension holds < 2**31 elements, and a slice's fields reach 3.6 GB
        flat = _PINNED[key] = wp.empty(max(1, -(-nbytes // 8)), dtype=wp.uint64, device="cpu", pinned=True)
    return flat


@contextmanager
def staging_log() -> Iterator[dict]:
    """Inside, every `to_host` copy into a staging buffer notes its (site, slot) and bytes in the dict yielded
    (the largest per key): a probe's, scaled to a batch's slices, is the plan of `reserve_staging`."""
    log: dict = {}
    token = _LOG.set(log)
    try:
        yield log
    finally:
        _LOG.reset(token)


def reserve_staging(plan: dict[tuple, int]) -> int:
    """Make the staging buffers of `plan` ((site, slot) -> bytes) at least that large now, for a caller with idle
    time before its copies (the GPU feed, while its first batch steps); returns the bytes page-locked here."""
    made = 0
    for key, nbytes in plan.items():
        before = _PINNED.get(key)
        flat = _grow_pinned(key, int(nbytes))
        made += flat.capacity if flat is not before else 0
    return made


def release_staging() -> int:
    """Free the page-locked staging buffers of `host_staging` (they are made again on the next use); returns the
    bytes freed. For a caller done with the GPU's copies that still has other work to wait for (the GPU feed, while
    its writers finish): unpinning gigabytes takes ~1-2 s, which the process would otherwise pay at exit."""
    freed = sum(b.capacity for b in _PINNED.values())
    _PINNED.clear()
    return freed


def to_host_many(arrs: list[wp.array], sites: list[str]) -> list[np.ndarray]:
    """`to_host` of each array, with one synchronisation for all the copies into page-locked buffers (inside
    `host_staging`, CUDA) instead of one per copy; elsewhere as `to_host` one by one."""
    if not _STAGING.get() or not arrs or not all(a.device.is_cuda for a in arrs):
        return [to_host(a, s) for a, s in zip(arrs, sites)]
    bufs = []
    for arr, site in zip(arrs, sites):
        _note(arr, site)
        buf = _pinned_buffer(arr, site)
        wp.copy(buf, arr)
        bufs.append(buf)
    for dev in {str(a.device) for a in arrs}:
        wp.synchronize_device(dev)  # copies into page-locked memory are asynchronous
    return [b.numpy() for b in bufs]


# Device buffers reused across calls: the sensor chain's per-taxel outputs on CUDA. The taxel kernel's strided
# stores into arrays freshly allocated per call ran ~3x slower on the H100 than into buffers kept from an
# earlier call (fused kernel 27.7 vs 10.1 ms, plain kernel 34.0 vs 8.7 ms, bench/results/transduction-h100-s7.json),
# while a plain sequential fill of fresh arrays costs no more than of kept ones (alloc-cost-h100-s7.json). One grow-only
# buffer per (thread, device, name); a smaller request gets a view of it. Only for results that are copied off
# the device before the same thread asks for the same name again.
_SCRATCH: dict[tuple, wp.array] = {}


def scratch(name: str, n: int, dtype, device: str) -> wp.array:
    """A flat device array of n elements for `name`, reused across calls on a CUDA device (fresh on the CPU)."""
    dev = wp.get_device(device)
    if not dev.is_cuda:
        return wp.empty(n, dtype=dtype, device=device)
    key = (threading.get_ident(), str(dev), name)
    buf = _SCRATCH.get(key)
    if buf is None or buf.shape[0] < n or buf.dtype != dtype:
        _SCRATCH.pop(key, None)  # freed before the larger one is made
        buf = _SCRATCH[key] = wp.empty(max(n, 1), dtype=dtype, device=device)
    return buf[:n]
