"""The process's JAX setup for training: CPU cores as JAX devices, and the compilation cache.

XLA runs one fused loop per CPU device on one thread, so a vmapped environment batch uses a single
core. Exposing each core as a host device and splitting the batch across them (shard_map) uses them
all. The flag must be set before JAX is first imported: the CLI calls ``use_all_cpu_cores()`` first.
``use_compilation_cache()`` keeps compiled programs on disk for the next run (``train``, ``sweep``,
``reproduce``).
"""

from __future__ import annotations

import os
import sys
import warnings

_FLAG = "--xla_force_host_platform_device_count"


def use_all_cpu_cores(count: int | None = None) -> int:
    """Ask XLA for one host device per CPU core (or ``count``). Returns the count asked for.

    Has no effect if JAX was already imported (a warning says so) or if XLA_FLAGS already sets it."""
    n = count or (
        len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    )
    flags = os.environ.get("XLA_FLAGS", "")
    if _FLAG in flags:
        return n
    if "jax" in sys.modules:
        warnings.warn(
            "jaxexo.train.devices.use_all_cpu_cores() called after JAX was imported; using the "
            "devices JAX already has",
            stacklevel=2,
        )
        return n
    os.environ["XLA_FLAGS"] = f"{flags} {_FLAG}={n}".strip()
    return n


CACHE_ENV = "JAXEXO_COMPILATION_CACHE"
# Compiled programs are small (docs/training.md); the cap only stops a long history of sweeps
# filling the disk (JAX evicts the least recently used entries beyond it).
CACHE_MAX_BYTES = 1 << 30


def _cache_folder_problem(path: str) -> str | None:
    """Why ``path`` cannot be the cache folder, or None. JAX writes its files into it: never through a
    symbolic link jaxexo did not make, at any component the user named below ``$HOME`` or the
    cache root (a link higher up, such as /home -> /data/home, is the machine's own layout); and a
    file where a folder is needed is said so."""
    home = os.path.expanduser("~")
    q = path
    while q != os.path.dirname(q):
        if os.path.islink(q) and not os.path.commonpath([home, q]) == q:
            return f"{q} is a symbolic link; jaxexo writes nothing through a link it did not make"
        if os.path.exists(q) and not os.path.isdir(q):
            return f"{q} is a file, not a folder (for {path})"
        q = os.path.dirname(q)
    return None


def use_compilation_cache() -> str | None:
    """Keep compiled programs on disk (JAX's persistent compilation cache), so that a later run with
    the same static settings (any seed, any pytree-leaf hyperparameter: learning rate, gamma, reward
    weights...) loads its training, validation and evaluation programs instead of compiling them
    (what that saves: docs/training.md). A loaded program is the compiled program itself, so results
    are bit for bit those of a run that compiled.

    The directory: ``$JAXEXO_COMPILATION_CACHE`` ("off" disables it), else JAX's own setting
    (``JAX_COMPILATION_CACHE_DIR``), else ``$XDG_CACHE_HOME/jaxexo/xla`` (``~/.cache/jaxexo/xla``).
    Returns the directory used, or None. The CLI calls it for ``train``, ``sweep`` and ``reproduce``
    (not for benchmarks, whose compile times it would hide)."""
    import jax

    setting = os.environ.get(CACHE_ENV, "").strip()
    if setting.lower() in ("off", "0", "false", "no", "none"):
        return None
    if not setting and jax.config.jax_compilation_cache_dir:
        return jax.config.jax_compilation_cache_dir
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    path = os.path.abspath(os.path.expanduser(setting or os.path.join(base, "jaxexo", "xla")))
    problem = _cache_folder_problem(path)
    if problem is None:
        try:
            os.makedirs(path, exist_ok=True)
        except OSError as e:
            problem = f"cannot use {path} as the compilation cache ({e.strerror})"
    if problem is not None:
        warnings.warn(
            f"{CACHE_ENV}: {problem}; compiling every program (point {CACHE_ENV} at a real folder, or "
            "set it to off)",
            stacklevel=2,
        )
        return None
    jax.config.update("jax_compilation_cache_dir", path)
    if jax.config.jax_compilation_cache_max_size < 0:
        jax.config.update("jax_compilation_cache_max_size", CACHE_MAX_BYTES)
    return path
