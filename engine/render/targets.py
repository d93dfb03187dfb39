"""Everything a frame of one image size needs, as Taichi ndarrays: the kernels take them as
arguments, so a new render size allocates arrays and compiles nothing (fields passed as
``ti.template()`` would re-specialise every kernel).

Per pixel (H·W,), flat in row-major order: ``bgc`` vec4 (background RGB, coverage 0) and ``depth`` f32 (m) — kept while the
camera, colliders and size stay; ``bg_packed`` ((H·W + 1) // 2,) u64, the background tone-mapped,
two pixels to an element (what an untouched tile shows; in host memory, a numpy array, on the
CPU: ``untouched_tiles``). The splat arrays hold the full level's W·H pixels, then the reduced level's
Wl·Hl texels (Hl, Wl = ceil(scale · (H, W))), then the coarse level's Wc·Hc texels (at half the
reduced scale; engine.render.composite): ``depth`` (the reduced parts: the farthest depth under
each texel), ``accA``/``accB`` vec4 splat accumulators (engine.render.splat), written only in tiles
that hold sprites (the full part tile by tile, each tile one contiguous run:
``composite.tile_rows``; the reduced part ends as the layer (RGB, T), the coarse one keeps its sums);
``touched_lo`` (T1,) reduced tiles drawn (their own sprites or the coarse level's under them;
non-zero: drawn — the GPU's schedule keeps in bit 1 whether the coarse level was mixed in),
``touched_co`` (T2,) coarse tiles holding sprites. Tiles (full, reduced, coarse: T0 + T1 + T2 =
T in one index space): ``hist``
(chunks, T) i32, ``tile_count``/``tile_start`` (T,), ``block_sum``, ``pairs`` (grows). Soft bodies:
``vis`` i64 visibility buffer, ``lines`` line sums (two packed i64 a pixel: engine.render.mesh), ``fbg``/``fdep`` the frame's background
with the bodies drawn in, ``dirty``/``dirty_prev`` (T0,) tiles the bodies touch. ``edges`` (T0,) the composite's cache of
which tiles' upsample is bilateral somewhere (engine.render.composite).
"""
from __future__ import annotations

import math
import sys

import numpy as np
import taichi as ti

from .binning import SCAN_BLOCK, vec16
from .sprites import TILE

vec4 = ti.types.vector(4, ti.f32)


def tiles_for(W: int, H: int):
    return (W + TILE - 1) // TILE, (H + TILE - 1) // TILE


def reduced_size(W: int, H: int, scale: float):
    return max(1, math.ceil(W * scale)), max(1, math.ceil(H * scale))


class FrameTargets:
    def __init__(self, W: int, H: int, scale: float, chunks: int, *, alpha: bool, mesh: bool,
                 pairs: int = 1 << 16, host: bool = False, rows: bool = False):
        self.W, self.H, self.scale = int(W), int(H), float(scale)
        self.TX, self.TY = tiles_for(W, H)
        self.T0 = self.TX * self.TY
        self.has_lo = scale < 1.0
        self.Wl, self.Hl = reduced_size(W, H, scale) if self.has_lo else (1, 1)
        self.TXl, self.TYl = tiles_for(self.Wl, self.Hl) if self.has_lo else (1, 1)
        self.T1 = self.TXl * self.TYl if self.has_lo else 0
        # the coarse level, with the reduced one: half its scale (engine.render.composite)
        self.Wc, self.Hc = reduced_size(W, H, 0.5 * scale) if self.has_lo else (1, 1)
        self.TXc, self.TYc = tiles_for(self.Wc, self.Hc) if self.has_lo else (1, 1)
        self.T2 = self.TXc * self.TYc if self.has_lo else 0
        self.T = self.T0 + self.T1 + self.T2
        self.NB = (self.T + SCAN_BLOCK - 1) // SCAN_BLOCK
        px = H * W  # pixel arrays are flat: (H·W,), indexed y·W + x
        self.LO = px  # where the reduced level starts in the splat arrays, and the coarse one
        self.LC = px + self.Wl * self.Hl
        both = self.LC + self.Wc * self.Hc  # splat arrays: every level (1×1 ones unused)
        self.bgc = ti.ndarray(vec4, shape=px)
        self.depth = ti.ndarray(ti.f32, shape=both)
        # two pixels to an element; on the CPU a numpy array (the kernels take it all the same,
        # without a copy) so that the frame can start as one memcpy of it (``untouched_tiles``)
        self.bg_packed = (np.zeros((px + 1) // 2, np.uint64) if host
                          else ti.ndarray(ti.u64, shape=(px + 1) // 2))
        self.accA = ti.ndarray(vec4, shape=both)
        self.accA.fill(ti.Vector([0.0, 0.0, 0.0, 1.0]))  # the empty layer (see composite.splat_tiles)
        self.accB = ti.ndarray(vec4, shape=both if alpha else 1)
        # the reduced rows interpolated along x (the per-pixel schedule's: upsample.lo_rows)
        self.lo_rows = ti.ndarray(vec4, shape=self.Hl * W if self.has_lo and rows else 1)
        self.touched_lo = ti.ndarray(ti.i32, shape=max(1, self.T1))
        self.touched_lo.fill(0)
        self.touched_co = ti.ndarray(ti.i32, shape=max(1, self.T2))
        self.touched_co.fill(0)
        # per full-level tile: the rows its sprites may have drawn in (a mask; splat_tiles)
        self.full_rows = ti.ndarray(ti.i32, shape=max(1, self.T0))
        # every touched_lo and touched_co is 0 (the renderer's empty frames skip the splat)
        self.lo_clear = True
        self.hist = ti.ndarray(ti.i32, shape=(chunks, self.T))
        self.tile_count = ti.ndarray(ti.i32, shape=self.T)
        self.tile_count.fill(0)  # (a scene without particles never bins: every tile stays empty)
        self.tile_start = ti.ndarray(ti.i32, shape=self.T)
        self.block_sum = ti.ndarray(ti.i32, shape=self.NB)
        self.dirty = ti.ndarray(ti.i32, shape=self.T0)
        self.dirty.fill(0)
        self.edges = ti.ndarray(ti.i32, shape=self.T0)
        self.edges.fill(-1)  # per tile: is the upsample bilateral anywhere (-1: not yet known)
        self.edge_rows = ti.ndarray(ti.i32, shape=self.T0 * TILE)  # and where: a mask per pixel row
        self.pairs = None
        self.grow_pairs(pairs)
        self.mesh = mesh
        if mesh:
            self.vis = ti.ndarray(ti.i64, shape=px)
            self.lines = ti.ndarray(ti.types.vector(2, ti.i64), shape=px)
            self.fbg = ti.ndarray(vec4, shape=px)
            self.fdep = ti.ndarray(ti.f32, shape=both)
            self.dirty_prev = ti.ndarray(ti.i32, shape=self.T0)
            self.dirty_prev.fill(0)
            self.mesh_clean = False  # vis and lines not yet emptied (the first draw empties them whole)
        self.bg_key = None  # the view (camera, show) the background arrays were drawn for
        self.bg_shapes = None  # the shown colliders' poses they were drawn with (Renderer._background_rect)
        self.packed_key = None  # (exposure, mode) of bg_packed (redrawn with the background)

    def grow_pairs(self, n: int) -> None:
        self.pairs = ti.ndarray(vec16, shape=max(1, int(n)))
        self.pair_capacity = max(1, int(n))

    def new_image(self) -> np.ndarray:
        return np.empty((self.H, self.W, 4), np.uint8)


def packed_view(image: np.ndarray, W: int, H: int, name: str = "out") -> np.ndarray:
    """The flat (H·W,) uint32 view of an (H, W, 4) uint8 RGBA array the kernels write into."""
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.shape != (H, W, 4):
        got = f"{getattr(image, 'dtype', type(image).__name__)} {getattr(image, 'shape', '')}"
        raise ValueError(f"{name}: need a uint8 array of shape ({H}, {W}, 4), got {got}")
    if not image.flags.c_contiguous:
        raise ValueError(f"{name}: need a C-contiguous array (np.empty((H, W, 4), np.uint8))")
    return image.view(np.uint32).reshape(H * W)


_NO_WIDE = np.zeros(1, np.uint64)


def untouched_tiles(t: FrameTargets, image: np.ndarray, packed: np.ndarray):
    """How the composite shows the tiles nothing touches: its ``(out64, copy)`` arguments.

    Where ``t.bg_packed`` lives in host memory and its u32 halves are in pixel order
    (little-endian), the flat (H·W,) u32 image ``packed`` is filled with it here in one memcpy and
    the composite leaves those tiles alone (copy 2): numpy copies the 3.7 MB of a 1280×720 frame
    in ~0.17 ms on this 2-core machine, the composite's own per-tile copy took 0.7–1.7 ms (short
    runs of 8 elements a row, each store making the next load re-read its array's address).
    Elsewhere the composite copies them itself, two pixels an element where ``wide_view`` allows
    (copy 1), else pixel by pixel (copy 0)."""
    if isinstance(t.bg_packed, np.ndarray) and sys.byteorder == "little":
        np.copyto(packed, t.bg_packed.view(np.uint32)[: packed.shape[0]])
        return _NO_WIDE, 2
    return wide_view(image)


def wide_view(image: np.ndarray):
    """The flat u64 view of a packed image (two pixels an element) and whether the kernels may
    use it: its width even (a tile row starts on an element), its memory 8-byte aligned (a
    caller's array may be a view at any offset) and the machine little-endian (an element's low
    half is its first pixel); else a 1-element stand-in and 0."""
    H, W = image.shape[:2]
    if W % 2 == 0 and image.ctypes.data % 8 == 0 and sys.byteorder == "little":
        return image.reshape(H * W * 4).view(np.uint64), 1
    return _NO_WIDE, 0
