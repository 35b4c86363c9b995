"""Taxel fields sent off the device as their non-zero taxel blocks (the GPU feed): the host side, numpy only.

A press loads a few taxels of a pad: velostat's 10 mm tip on its 144 taxels leaves 93-100 % of the deformation and
pressure fields zero, and its shear field is all zero on a normal press (bench/README.md, session 20). Copying
those fields whole cost the GPU feed 3.5 MB per episode through the device-to-host copy, the page-locked staging
and the pack into shared memory (28.6 GB per 8192-episode batch). Here each field is rounded to float32 on the
device, its blocks of FIELD_BLOCK consecutive taxels that hold a
non-zero byte anywhere in an episode are flagged and gathered on the device, and only those come back, with
their (episode, block) index: a `BlockSparse` (the kernels: `load_field_kernels.fields_f32_blocks_to_host`). Its episode rows read back as the dense float32 arrays, byte for
byte (a block left out holds only +0.0), so the files and their content hashes do not change.
"""

from __future__ import annotations

import os

import numpy as np

FIELD_BLOCK = 16  # taxels per block (the writers' TAXEL_BLOCK, so a block sent maps onto one chunk column there)
SPARSE_MAX_SHARE = 0.5  # a field with more of its blocks non-zero than this goes whole (a gather then saves little);
# PIEZOTWIN_FIELD_BLOCKS=0 sends every field whole, as before (the bench's A/B)
if os.environ.get("PIEZOTWIN_FIELD_BLOCKS", "1") == "0":
    SPARSE_MAX_SHARE = -1.0


class BlockSparse:
    """A float32 taxel field of shape (E, T, N, ...) held as its non-zero taxel blocks.

    blocks: (M, T, FIELD_BLOCK, ...) float32, block m = taxels [b * B, b * B + B) of episode row r over all its
    samples (a last block past N padded with zeros); index: (M, 2) int32 rows (r, b), sorted by r then b. Every
    block not listed is all +0.0. Indexing by an int gives that episode's dense array (T, N, ...); by a slice or a
    list of rows, a BlockSparse of those rows; `np.asarray` the whole dense field."""

    on_host = True  # held in host memory (`sensors.base.LoadBatch.fields_on_device` is False for it)

    def __init__(self, blocks: np.ndarray, index: np.ndarray, shape: tuple[int, ...], block: int = FIELD_BLOCK):
        self.blocks, self.index, self.shape, self.block = blocks, index, tuple(int(s) for s in shape), int(block)
        self.dtype = np.dtype(np.float32)

    @property
    def ndim(self) -> int:
        return len(self.shape)

    @property
    def nbytes(self) -> int:
        """Bytes of the dense field it stands for."""
        return int(np.prod(self.shape, dtype=np.int64)) * self.dtype.itemsize

    @property
    def stored_nbytes(self) -> int:
        """Bytes it holds (blocks and index)."""
        return self.blocks.nbytes + self.index.nbytes

    def __len__(self) -> int:
        return self.shape[0]

    def _span(self, r: int) -> tuple[int, int]:
        rows = self.index[:, 0]
        return int(np.searchsorted(rows, r, "left")), int(np.searchsorted(rows, r, "right"))

    def episode(self, r: int) -> np.ndarray:
        """Row r as its dense float32 array (T, N, ...)."""
        out = np.zeros(self.shape[1:], np.float32)
        a, b = self._span(r)
        n, B = self.shape[2], self.block
        for m in range(a, b):
            k = int(self.index[m, 1]) * B
            w = min(B, n - k)
            out[:, k:k + w] = self.blocks[m, :, :w]
        return out

    def nonzero_blocks(self, r: int) -> tuple[int, np.ndarray]:
        """Row r's blocks as `sensors.data.recording.Channel.nonzero_blocks` takes them: (block, flags), a flag per
        block of the taxel axis, False where the block is not listed (all +0.0)."""
        a, b = self._span(r)
        mask = np.zeros(-(-self.shape[2] // self.block), bool)
        mask[self.index[a:b, 1]] = True
        return self.block, mask

    def __getitem__(self, key):
        if isinstance(key, (int, np.integer)):
            r = int(key) + (self.shape[0] if key < 0 else 0)
            if not 0 <= r < self.shape[0]:
                raise IndexError(f"row {key} of {self.shape[0]}")
            return self.episode(r)
        if isinstance(key, slice) and key.step in (None, 1):  # a run of rows: views of its blocks, no copy
            lo, hi, _ = key.indices(self.shape[0])
            hi = max(lo, hi)
            a, b = int(np.searchsorted(self.index[:, 0], lo, "left")), int(np.searchsorted(self.index[:, 0], hi, "left"))
            index = self.index[a:b] - np.array([lo, 0], np.int32) if lo else self.index[a:b]
            return BlockSparse(self.blocks[a:b], index, (hi - lo, *self.shape[1:]), self.block)
        rows = np.arange(self.shape[0])[key]
        if rows.ndim != 1:
            raise TypeError(f"BlockSparse rows: an int, a slice or a list of rows, not {key!r}")
        new = np.full(self.shape[0], -1, np.int64)
        new[rows] = np.arange(len(rows))
        keep = new[self.index[:, 0]] >= 0
        index = np.stack([new[self.index[keep, 0]], self.index[keep, 1]], axis=1).astype(np.int32)
        order = np.lexsort((index[:, 1], index[:, 0]))
        return BlockSparse(self.blocks[np.flatnonzero(keep)[order]], index[order], (len(rows), *self.shape[1:]), self.block)

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        out = np.stack([self.episode(r) for r in range(self.shape[0])]) if self.shape[0] else np.zeros(self.shape, np.float32)
        return out if dtype is None else out.astype(dtype)

    def copy(self) -> BlockSparse:
        return BlockSparse(np.array(self.blocks), np.array(self.index), self.shape, self.block)


def blocks_of(dense: np.ndarray, block: int = FIELD_BLOCK) -> BlockSparse:
    """The numpy reference of the device's flag and gather kernels (`load_field_kernels.fields_f32_blocks_to_host`,
    tested equal): the `BlockSparse` of a float32 field (E, T, N, ...), a block kept where any of its bytes is
    non-zero."""
    E, T, N = dense.shape[:3]
    block = max(1, min(block, N))  # a narrow field: one block of its own width
    nb = -(-N // block)
    pad = np.zeros((E, T, nb * block, *dense.shape[3:]), np.float32)
    pad[:, :, :N] = dense
    per = pad.reshape(E, T, nb, block, int(np.prod(dense.shape[3:], dtype=np.int64)))
    hit = (per.view(np.uint32) != 0).any(axis=(1, 3, 4))  # (E, nb)
    r, b = np.nonzero(hit)  # row-major: sorted by row, then block
    blocks = per.transpose(0, 2, 1, 3, 4)[r, b].reshape(len(r), T, block, *dense.shape[3:])
    return BlockSparse(np.ascontiguousarray(blocks), np.stack([r, b], axis=1).astype(np.int32), dense.shape, block)
