"""A fast counter-based uniform generator for the streaming gamma_nt estimator.

``jax.random``'s default threefry-2x32 produced only ~80 M floats/s on the 2-core
CPU this package is developed on, which would dominate the fused estimator
(4-6 floats per candidate query). This module hashes ``(stream, counter)`` with
Wellons' *triple32* integer hash (three xorshift-multiply rounds; a bijection on
32-bit words with near-ideal avalanche, bias ~0.021 in his measurements) on
top of a per-stream bijection of the counter, and keeps the top 24 bits as a float32 in ``[0, 1)``.

Quality is checked in ``tests/test_prng.py`` (uniformity of each coordinate and
of pairs, serial correlation, independence of streams, and gamma_nt agreement
with threefry). It is NOT a cryptographic generator. It is used in two places, both keyed by
``jax.random`` keys (a key is turned into two 32-bit seed words with one small
threefry call): the streaming gamma_nt estimator (:func:`stream_seeds`) and
PNet's dropout masks (:func:`uniform_array`; vmapped threefry draws of the masks
halved the ensemble's training steps/s on the CPU). Everything else in the
package uses ``jax.random`` directly; :func:`uniform_prefix` draws the host-side
``jax.random.uniform(key, (n,))`` of any ``n`` with few compiled programs.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

Array = jax.Array


def triple32(x: Array) -> Array:
    """Wellons' triple32 hash of uint32 words."""
    x = x.astype(jnp.uint32)
    x = x ^ (x >> 17)
    x = x * jnp.uint32(0xED5AD4BB)
    x = x ^ (x >> 11)
    x = x * jnp.uint32(0xAC4C1B51)
    x = x ^ (x >> 15)
    x = x * jnp.uint32(0x31848BAB)
    x = x ^ (x >> 14)
    return x


def typed_key(key: Array) -> Array:
    """``key`` as a typed ``jax.random`` key (``jax.random.key``): a raw ``uint32[2]`` key
    (``jax.random.PRNGKey``) is wrapped with the default implementation, which draws the
    same bits from it, so jitted code that takes keys compiles once for both kinds."""
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        return key
    return jax.random.wrap_key_data(key)


def stream_seeds(key: Array, index: Array | int) -> Array:
    """The two uint32 seed words of stream ``index``, derived from a ``jax.random`` key."""
    return jax.random.bits(jax.random.fold_in(key, index), (2,), jnp.uint32)


def to_unit(x: Array) -> Array:
    """Top 24 bits of uint32 words as float32 in ``[0, 1)``."""
    return (x >> 8).astype(jnp.float32) * jnp.float32(1.0 / (1 << 24))


def uniform(seeds: Array, counter: Array) -> Array:
    """Uniform float32 in ``[0, 1)`` for each uint32 ``counter`` of the stream ``seeds``.

    ``seeds`` is a pair of uint32 words (from :func:`stream_seeds`). The counter is
    first mapped through the stream's own bijection ``(c ^ s1) * (s2 | 1)``, so
    two streams do not share runs of inputs (a plain ``c + s`` offset would make
    streams overlapping shifts of one sequence), then hashed.
    """
    s1, s2 = seeds[0], seeds[1] | jnp.uint32(1)
    return to_unit(triple32((counter.astype(jnp.uint32) ^ s1) * s2))


def uniform_array(key: Array, shape: tuple[int, ...]) -> Array:
    """Uniform float32 in ``[0, 1)`` of ``shape`` from a ``jax.random`` key.

    A drop-in for ``jax.random.uniform(key, shape)`` (a different but equally
    distributed draw, see the module docstring): two seed words from ``key``,
    then :func:`uniform` over the counters ``0 .. prod(shape) - 1`` in row-major
    order. Jittable and vmappable over ``key``.

    Raises:
        ValueError: ``shape`` has more than ``2**32`` elements (the counter is 32-bit).
    """
    n = math.prod(shape)
    if n > 2**32:
        raise ValueError(
            f"uniform_array: {n} draws exceed the 2**32 counters of one key; split the batch"
        )
    seeds = jax.random.bits(key, (2,), jnp.uint32)
    return uniform(seeds, jnp.arange(n, dtype=jnp.uint32).reshape(shape))


def uniform_prefix(key: Array, n: int) -> np.ndarray:
    """``np.asarray(jax.random.uniform(key, (n,)))``, bit for bit, as a host array.

    ``jax.random`` compiles one program per shape. With ``jax_threefry_partitionable``
    (JAX's default) element ``i`` of a 1-D draw depends only on the key and ``i``, so the
    first ``n`` of a draw of ``2**ceil(log2 n)`` values are the draw of ``n``: every ``n``
    of one power-of-two bucket shares one program. Without that flag the draw of ``n``
    itself is taken.
    """
    n = int(n)
    if n <= 0:
        return np.zeros((0,), np.float32)
    size = 1 << (n - 1).bit_length() if jax.config.jax_threefry_partitionable else n
    return np.asarray(jax.random.uniform(key, (size,)))[:n]
