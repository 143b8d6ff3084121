"""Chunks of particles that threads can work on without write conflicts (opt-in threads).

The particles are cut into ``chunk_count`` contiguous index ranges. A spring (or face)
whose ends (corners) all lie in one chunk belongs to that chunk; the rest cross chunks.
A threaded kernel gives each chunk to one thread, which then writes only its own
particles' rows, and afterwards does the crossing springs and faces serially, so no two
threads ever add into the same row and the result does not depend on thread timing.
The partition keeps its own copies of the springs' and faces' arrays in chunk order, so
each thread reads a contiguous run: going through an index list instead made a chunk's
springs about 1.4x slower than the serial loop, which ate most of the second thread's
gain (measured on the 40,962-vertex ball).
Meshes from ``icosphere`` are numbered along a Morton curve, so few springs cross: 811 of
122,880 for a 40,962-vertex ball in two chunks. On other numberings the threaded
kernels stay correct but more of the work is serial.

The step kernels receive a partition packed into two flat arrays (``pack_partition``),
one of integers and one of reals, and take views of them (``spring_chunks``,
``face_chunks``): a ``Workspace`` that carried the ten arrays as a nested tuple made
every serial step of a 162-vertex ball about 40% slower, even with the threaded code
compiled out, while two more flat arrays cost nothing measurable (the likely cause:
every kernel that takes the workspace gets some 70 more arguments, which changes what
LLVM inlines; not confirmed).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit


class Partition(NamedTuple):
    """Chunks of a model's particles, springs and faces; T chunks, B bodies."""

    particle_start: np.ndarray  # (T + 1,) chunk c owns particles particle_start[c:c+2]
    spring_start: np.ndarray  # (T + 2,) chunk c's springs are spring_start[c:c+2]
    spring_indices: np.ndarray  # (S, 2) the model's springs in chunk order; chunk T: crossing
    spring_rest_length: np.ndarray  # (S,) [m], in the same order
    spring_stiffness: np.ndarray  # (S,) [N/m]
    spring_damping: np.ndarray  # (S,) [N s/m]
    tri_start: np.ndarray  # (T + 2,) chunk c's faces are tri_start[c:c+2]
    tri_indices: np.ndarray  # (F, 3) the model's faces in chunk order; chunk T: crossing
    tri_body: np.ndarray  # (F,) their bodies
    six_volume: np.ndarray  # (T + 1, B) scratch: each chunk's share of 6 x body volume

    @property
    def chunk_count(self) -> int:
        """Number of chunks (1: everything runs serially)."""
        return self.particle_start.shape[0] - 1


def _group(owner: np.ndarray, chunk_count: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR of element indices grouped by owner chunk (``chunk_count`` = crossing)."""
    order = np.argsort(owner, kind="stable").astype(np.int64)
    counts = np.bincount(owner, minlength=chunk_count + 1)
    start = np.zeros(chunk_count + 2, dtype=np.int64)
    np.cumsum(counts, out=start[1:])
    return start, order


def build_partition(model, chunk_count: int) -> Partition:
    """Cut a model's particles into ``chunk_count`` >= 1 equal contiguous ranges (1: one
    chunk, nothing crossing; ``pack_partition`` then keeps nothing, as the serial kernels
    read the model's arrays)."""
    if int(chunk_count) != chunk_count or chunk_count < 1:
        raise ValueError(f"chunk_count must be an integer >= 1, got {chunk_count!r}")
    chunk_count = int(chunk_count)
    m = model.data
    particle_count = model.particle_count
    particle_start = (np.arange(chunk_count + 1) * particle_count) // chunk_count
    particle_start = particle_start.astype(np.int64)
    chunk_of = np.repeat(np.arange(chunk_count), np.diff(particle_start))

    def owner(indices: np.ndarray) -> np.ndarray:
        if indices.shape[0] == 0:
            return np.zeros(0, dtype=np.int64)
        c = chunk_of[indices]
        same = np.all(c == c[:, :1], axis=1)
        return np.where(same, c[:, 0], chunk_count).astype(np.int64)

    spring_start, spring = _group(owner(m.spring_indices), chunk_count)
    tri_start, tri = _group(owner(m.tri_indices), chunk_count)
    return Partition(
        particle_start,
        spring_start,
        np.ascontiguousarray(m.spring_indices[spring]),
        m.spring_rest_length[spring],
        m.spring_stiffness[spring],
        m.spring_damping[spring],
        tri_start,
        np.ascontiguousarray(m.tri_indices[tri]),
        m.tri_body[tri],
        np.zeros((chunk_count + 1, model.body_count)),
    )


def pack_partition(part: Partition) -> tuple[np.ndarray, np.ndarray]:
    """The partition as (chunk_index int64, chunk_value float64) for the kernels.

    chunk_index = [T, particle_start (T + 1), spring_start (T + 2), tri_start (T + 2),
    spring_indices (2 S), tri_indices (3 F), tri_body (F)]; chunk_value = [rest length
    (S), stiffness (S), damping (S), six_volume ((T + 1) B)]. One chunk packs as [1] and
    nothing: the serial kernels read the model's arrays.
    """
    if part.chunk_count == 1:
        return np.ones(1, dtype=np.int64), np.zeros(0)
    index = np.concatenate(
        [
            [part.chunk_count],
            part.particle_start,
            part.spring_start,
            part.tri_start,
            part.spring_indices.ravel(),
            part.tri_indices.ravel(),
            part.tri_body,
        ]
    ).astype(np.int64)
    value = np.concatenate(
        [
            part.spring_rest_length,
            part.spring_stiffness,
            part.spring_damping,
            part.six_volume.ravel(),
        ]
    ).astype(np.float64)
    return index, value


@njit(cache=True)
def spring_chunks(chunk_index, chunk_value, spring_count):
    """Views (spring_start (T + 2,), spring_indices (S, 2), rest length, stiffness,
    damping (S,)) of a packed partition (``pack_partition``)."""
    t = chunk_index[0]
    a = 1 + (t + 1)
    spring_start = chunk_index[a : a + t + 2]
    a += 2 * (t + 2)
    indices = chunk_index[a : a + 2 * spring_count].reshape((spring_count, 2))
    s = spring_count
    return (
        spring_start,
        indices,
        chunk_value[0:s],
        chunk_value[s : 2 * s],
        chunk_value[2 * s : 3 * s],
    )


@njit(cache=True)
def face_chunks(chunk_index, chunk_value, spring_count, tri_count, body_count):
    """Views (particle_start (T + 1,), tri_start (T + 2,), tri_indices (F, 3), tri_body
    (F,), six_volume (T + 1, B)) of a packed partition (``pack_partition``)."""
    t = chunk_index[0]
    particle_start = chunk_index[1 : t + 2]
    a = 1 + (t + 1) + (t + 2)
    tri_start = chunk_index[a : a + t + 2]
    a += t + 2 + 2 * spring_count
    tri_indices = chunk_index[a : a + 3 * tri_count].reshape((tri_count, 3))
    a += 3 * tri_count
    tri_body = chunk_index[a : a + tri_count]
    b = 3 * spring_count
    six_volume = chunk_value[b : b + (t + 1) * body_count].reshape((t + 1, body_count))
    return particle_start, tri_start, tri_indices, tri_body, six_volume
