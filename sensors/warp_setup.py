"""One place that initialises Warp quietly and resolves the device name ("cpu", "cuda", "cuda:0", "auto")."""

from __future__ import annotations

import logging

import warp as wp

_done = False


def init_warp() -> None:
    global _done
    if not _done:
        wp.config.log_level = logging.WARNING
        wp.init()
        _done = True


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
