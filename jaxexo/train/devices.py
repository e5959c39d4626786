"""CPU cores as JAX devices.

XLA runs one fused loop per CPU device on one thread, so a vmapped environment batch uses a single
core. Exposing each core as a host device and splitting the batch across them (shard_map) uses them
all. The flag must be set before JAX is first imported: the CLI calls ``use_all_cpu_cores()`` first.
"""

from __future__ import annotations

import os
import sys
import warnings

_FLAG = "--xla_force_host_platform_device_count"


def use_all_cpu_cores(count: int | None = None) -> int:
    """Ask XLA for one host device per CPU core (or ``count``). Returns the count asked for.

    Has no effect if JAX was already imported (a warning says so) or if XLA_FLAGS already sets it."""
    n = count or (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))
    flags = os.environ.get("XLA_FLAGS", "")
    if _FLAG in flags:
        return n
    if "jax" in sys.modules:
        warnings.warn("jaxexo.train.devices.use_all_cpu_cores() called after JAX was imported; using the "
                      "devices JAX already has", stacklevel=2)
        return n
    os.environ["XLA_FLAGS"] = f"{flags} {_FLAG}={n}".strip()
    return n
