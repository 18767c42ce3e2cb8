"""Where the ensemble runs: CPU devices, the member mesh, and placement of stacked arrays.

With ``D >= 2`` devices that can hold equal shares of the ``M`` members (GPUs,
or CPU devices from :func:`use_cpu_devices`, the ``jax_num_cpu_devices``
option or ``XLA_FLAGS=--xla_force_host_platform_device_count``), the member
axis of every stacked array is sharded over the largest such ``D`` with a
``NamedSharding`` (:func:`member_mesh`, :func:`place`): 4 members on 4 devices
one each, on 2 devices two each. Otherwise everything runs on one device.
The measured effect on a CPU is in BENCHMARKS.md (``benchmarks/bench_train.py``).
"""

from __future__ import annotations

import os
import re

import jax
import numpy as np

__all__ = ["use_cpu_devices", "mesh_size", "member_mesh", "place"]


def use_cpu_devices(count: int | None = None) -> int:
    """Exposes the host's cores as ``count`` JAX CPU devices (call right after ``import jax``).

    On a CPU, :func:`ntq_jax.training.train_ensemble` then shards the member axis
    over these devices (:func:`member_mesh`): each device runs its members on its
    own core instead of every small matmul being split over all cores. Results differ from a
    one-device run at float level, hence
    the scripts' default of one device. Other computations keep running on
    device 0 with all cores.

    Nothing is changed when ``XLA_FLAGS`` already forces a host device count, or when
    ``count`` is 1.

    Args:
        count: devices to create; None = ``min(os.cpu_count(), 4)`` (the ensemble's size).

    Returns:
        The number of CPU devices requested (or already forced).

    Raises:
        RuntimeError: JAX has already run a computation in this process (the device
            count is fixed then); call this before any JAX operation.
    """
    forced = re.search(
        r"--xla_force_host_platform_device_count=(\d+)", os.environ.get("XLA_FLAGS", "")
    )
    if forced:
        return int(forced.group(1))
    count = min(os.cpu_count() or 1, 4) if count is None else int(count)
    if count < 1:
        raise ValueError(f"use_cpu_devices: count must be >= 1, got {count}")
    if count > 1:
        try:
            jax.config.update("jax_num_cpu_devices", count)
        except RuntimeError as e:
            raise RuntimeError(
                "use_cpu_devices must be called before any JAX operation "
                f"(right after `import jax`): {e}"
            ) from None
    return count


def mesh_size(num_members: int, num_devices: int) -> int:
    """The largest device count ``<= num_devices`` that divides ``num_members`` (>= 1)."""
    return max(d for d in range(1, min(num_devices, num_members) + 1) if num_members % d == 0)


def member_mesh(num_members: int, shard: bool | None = None):
    """A 1-D mesh ``("member",)`` to shard the member axis over, or None to run on one device.

    The mesh has the largest number of devices ``D <= len(jax.devices())`` that
    divides ``M`` (each device then holds ``M / D`` members): 4 members on 4
    devices one each, on 2 devices two each.

    Args:
        num_members: ``M``.
        shard: True requires a mesh of >= 2 devices, False never shards, None shards
            whenever such a mesh exists.
    """
    devices = jax.devices()
    size = mesh_size(num_members, len(devices))
    if shard is False or (shard is None and size < 2):
        return None
    if size < 2:
        raise ValueError(
            f"shard=True needs >= 2 devices and a member count they divide; "
            f"found {len(devices)} device(s) for {num_members} members"
        )
    return jax.sharding.Mesh(np.array(devices[:size]), ("member",))


def place(tree, mesh, axis: int = 0):
    """``tree`` on device 0 (``mesh`` None), or sharded over ``mesh`` along its ``axis``."""
    if mesh is None:
        return jax.device_put(tree, jax.devices()[0])
    spec = [None] * axis + ["member"]
    sh = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec(*spec))
    return jax.device_put(tree, sh)
