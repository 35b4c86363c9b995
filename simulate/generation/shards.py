"""What the shard executors and the GPU feed share: the failure they raise, the check of a written shard,
and the fault injection the resume tests use (PIEZOTWIN_FAULT_SHARD / _MARKER / _MODE)."""

from __future__ import annotations

import os
from pathlib import Path

from sensors.data.manifest import is_shard_complete, shard_path


class ShardFailedError(RuntimeError):
    """A shard still failed after its retries (the message names it and the last error)."""


def maybe_inject_fault(shard: int) -> None:
    k = os.environ.get("PIEZOTWIN_FAULT_SHARD")
    marker = os.environ.get("PIEZOTWIN_FAULT_MARKER")
    if k is None or marker is None or int(k) != shard:
        return
    try:
        fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)  # only the first attempt gets here
    except FileExistsError:
        return
    os.write(fd, f"shard {shard} pid {os.getpid()}\n".encode())
    os.close(fd)
    if os.environ.get("PIEZOTWIN_FAULT_MODE", "exit") == "raise":
        raise RuntimeError(f"injected fault in shard {shard}")
    os._exit(17)  # a killed worker: no cleanup, no exception reaches the driver


def check_written(out: Path, shard: int, sha: str) -> None:
    if not is_shard_complete(shard_path(out, shard), sha):
        raise RuntimeError(f"worker reported shard {shard} done but {shard_path(out, shard).name} is not a complete recording")
