"""The world: obstacles as arrays (:class:`World`), and the compiler options of every kernel."""

from __future__ import annotations

import dataclasses
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ntq_jax import validation
from ntq_jax.broadphase import ObstacleIndex

Array = jax.Array


#: XLA options for the jitted kernels (``jax.jit(..., compiler_options=...)``): on CPU,
#: let LLVM vectorise with 512-bit registers where the CPU has them (AVX-512). A per-jit
#: preference, so it never changes other code in the process; on CPUs without AVX-512
#: and on other backends it has no effect. Results are bit-identical either way.
KERNEL_COMPILER_OPTIONS = {"xla_cpu_prefer_vector_width": 512}


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class World:
    """A planar workspace with obstacles (a pytree of arrays).

    Attributes:
        bounds: ``(2, 2)`` float32, ``[[xmin, xmax], [ymin, ymax]]``.
        boxes: ``(B, 4)`` float32, ``[cx, cy, half_w, half_h]`` per row.
        discs: ``(C, 3)`` float32, ``[cx, cy, r]`` per row.
        index: None, or a broad-phase :class:`ntq_jax.broadphase.ObstacleIndex` of
            ``boxes`` (:func:`ntq_jax.broadphase.with_index`; ``Env`` adds one to maps
            with more than ``UNROLL_MAX`` boxes). It changes the speed, never the answers.
    """

    bounds: Array
    boxes: Array
    discs: Array
    index: ObstacleIndex | None = None

    @staticmethod
    def create(bounds, boxes=(), discs=()) -> "World":
        """Builds a World from nested sequences (or 2-D arrays), validating shapes and values.

        Strict: ``bounds`` is exactly two rows ``[min, max]``, every box row is
        exactly ``[cx, cy, half_w, half_h]`` and every disc row exactly
        ``[cx, cy, r]``, all finite numbers (bools and strings are refused);
        nothing is reshaped. ``[]`` (or an empty array) means no obstacles.

        Raises:
            ValueError: one line naming the key, the row and the expected form.
        """
        b = validation.number_rows(bounds, "bounds", 2, "[min, max]")
        if b.shape != (2, 2):
            raise ValueError(
                f"bounds must be [[xmin, xmax], [ymin, ymax]] (two rows), got "
                f"{validation.short_repr(bounds)}"
            )
        for i, axis in enumerate("xy"):
            if not b[i, 1] > b[i, 0]:
                raise ValueError(
                    f"bounds[{i}] is {b[i].tolist()}: expected [{axis}min, {axis}max] "
                    f"with {axis}min < {axis}max"
                )
        bx = validation.number_rows(boxes, "boxes", 4, "[cx, cy, half_w, half_h]")
        dc = validation.number_rows(discs, "discs", 3, "[cx, cy, r]")
        for i in np.flatnonzero(np.any(bx[:, 2:] <= 0, axis=1))[:1]:
            raise ValueError(
                f"boxes[{i}] is {bx[i].tolist()}: half sizes must be > 0 "
                "(rows are [cx, cy, half_w, half_h])"
            )
        for i in np.flatnonzero(dc[:, 2] <= 0)[:1]:
            raise ValueError(
                f"discs[{i}] is {dc[i].tolist()}: radius must be > 0 (rows are [cx, cy, r])"
            )
        return World(
            jnp.asarray(b, jnp.float32), jnp.asarray(bx, jnp.float32), jnp.asarray(dc, jnp.float32)
        )

    @property
    def num_boxes(self) -> int:
        return int(self.boxes.shape[0])

    @property
    def num_discs(self) -> int:
        return int(self.discs.shape[0])


def as_sequence_of_floats(x) -> Sequence[float]:
    """``x`` (any array-like) flattened to a list of Python floats."""
    return [float(v) for v in np.asarray(x).ravel()]
