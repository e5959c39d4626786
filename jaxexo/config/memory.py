"""How much memory a training run needs, estimated from its config before JAX allocates anything, so
that ``jaxexo train`` refuses a run the machine cannot hold naming the field to change. What the
estimate counts: docs/training.md#jaxexo-train-and-what-a-run-writes. NumPy-only.
"""

from __future__ import annotations

import functools
import os

from jaxexo.config.checks import ConfigError
from jaxexo.config.sections import Config
from jaxexo.physics import actions
from jaxexo.physics.actions import NUM_ACTIONS

FLOAT = 4  # bytes: float32 / int32
ENV_SCALARS = 24  # per-environment scalars of the env state and episode statistics (heel, time,
# scene numbers, flags, return): a generous count


def observation_size(cfg: Config) -> int:
    """The network's input size D (jaxexo.physics.actions.obs_dim, the one definition)."""
    return actions.obs_dim(cfg.env.obs_mode, cfg.env.shape_points)


def network_size(cfg: Config, obs_dim: int | None = None) -> int:
    """Parameters P of the Q-network D -> hidden... -> 36 (Dense kernels and biases, LayerNorm scale
    and bias after each hidden layer when layer_norm)."""
    d = observation_size(cfg) if obs_dim is None else obs_dim
    sizes = (d, *cfg.train.hidden, NUM_ACTIONS)
    dense = sum((a + 1) * b for a, b in zip(sizes[:-1], sizes[1:]))
    norm = 2 * sum(cfg.train.hidden) if cfg.train.layer_norm else 0
    return dense + norm


def memory_breakdown(cfg: Config) -> dict[str, int]:
    """Bytes by part (docs/training.md); ``estimate_memory_bytes`` is their sum."""
    t = cfg.train
    n, T = t.num_envs, t.rollout_steps
    d = observation_size(cfg)
    P = network_size(cfg, d)
    width = sum(t.hidden) + NUM_ACTIONS
    env_state = cfg.outline_vertices * 2 + cfg.env.shape_points + ENV_SCALARS + d
    parts = {
        "network": 5 * P * FLOAT,
        "env_state": n * env_state * FLOAT,
        "eval_envs": t.eval_episodes * env_state * FLOAT,
    }
    if t.trace == "forward":
        # per step: obs, action, reward, terminated, truncated, greedy, target (max_a or all of Q),
        # the lambda-return; activations and their gradients for one minibatch of T x N/M samples
        target = 1 if t.control == "off_policy" else NUM_ACTIONS
        parts["rollout_buffer"] = T * n * (d + 6 + target) * FLOAT
        parts["activations"] = 2 * T * (n // t.num_minibatches) * width * FLOAT
    else:
        parts["traces"] = 2 * n * P * FLOAT
        parts["activations"] = 2 * n * width * FLOAT
    return parts


def estimate_memory_bytes(cfg: Config) -> int:
    """A lower bound on the bytes a training run with this config keeps alive at once."""
    return int(sum(memory_breakdown(cfg).values()))


def machine_memory_bytes() -> int | None:
    """Physical memory of this machine (os.sysconf, else /proc/meminfo); None if unknown."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        pass
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def process_memory_limit() -> tuple[int | None, str]:
    """The memory this process can use at most (a ceiling, not what is free now: see
    ``process_memory_bytes``): this machine's, or less where the process's address-space or
    data limit (``ulimit -v``, ``-d``) or its control group's memory limit says so. (bytes, what sets
    them); (None, "") if nothing is known."""
    known = [(machine_memory_bytes(), "this machine's memory")]
    try:
        import resource
    except ImportError:  # not a Unix: the machine's memory only
        resource = None
    for name, ulimit in (("RLIMIT_AS", "ulimit -v"), ("RLIMIT_DATA", "ulimit -d")):
        if resource is not None and hasattr(resource, name):
            soft = resource.getrlimit(getattr(resource, name))[0]
            if soft != resource.RLIM_INFINITY:
                known.append((soft, f"the process's limit, {ulimit}"))
    known.append((_cgroup_memory()[0], "the control group's memory limit"))
    known = [(n, what) for n, what in known if n is not None]
    return min(known) if known else (None, "")


def _read(path: str) -> str | None:
    """A small file's text, None where it cannot be read: os.open and os.read, a third of open()'s
    cost (the sample guard reads /proc/meminfo and the cgroup's files for every timed swing)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        chunks = []
        while chunk := os.read(fd, 65536):
            chunks.append(chunk)
        return b"".join(chunks).decode()
    except (OSError, UnicodeDecodeError):
        return None
    finally:
        os.close(fd)


@functools.lru_cache(maxsize=1)
def _cgroup_files() -> tuple[tuple[str, str], ...]:
    """(limit file, usage file) of this process's control group and its ancestors where the limit
    file exists (cgroup v2 ``memory.max`` and ``memory.current``, v1 ``memory.limit_in_bytes`` and
    ``memory.usage_in_bytes``), the group first. Found once per process (its groups are set when it
    starts); their values are read afresh by ``_cgroup_memory``."""
    text = _read("/proc/self/cgroup")
    if text is None:
        return ()
    folders = []
    for line in text.splitlines():
        if line.count(":") < 2:
            continue
        _, controllers, path = line.split(":", 2)
        if controllers == "":  # v2: one hierarchy
            base, names = "/sys/fs/cgroup", ("memory.max", "memory.current")
        elif "memory" in controllers.split(","):
            base, names = (
                "/sys/fs/cgroup/memory",
                ("memory.limit_in_bytes", "memory.usage_in_bytes"),
            )
        else:
            continue
        parts = [x for x in path.split("/") if x]
        folders += [(os.path.join(base, *parts[:i]), names) for i in range(len(parts), -1, -1)]
    return tuple(
        (os.path.join(folder, limit), os.path.join(folder, usage))
        for folder, (limit, usage) in folders
        if os.path.exists(os.path.join(folder, limit))
    )


def _cgroup_memory() -> tuple[int | None, int]:
    """The smallest memory limit of this process's control group and its ancestors (cgroup v2
    ``memory.max``, v1 ``memory.limit_in_bytes``; "max" and v1's huge "unlimited" are no limit) and
    that group's usage (bytes; 0 where unknown); (None, 0) without a limit."""
    best = (None, 0)
    for limit, usage in _cgroup_files():
        cap = _read(limit)
        if cap is None:
            continue
        cap = cap.strip()
        if not (cap.isdigit() and int(cap) < 2**60) or (
            best[0] is not None and int(cap) >= best[0]
        ):
            continue
        try:
            used = int((_read(usage) or "").strip())
        except ValueError:
            used = 0
        best = (int(cap), used)
    return best


def check_memory(cfg: Config, available: int | None = None) -> int:
    """Refuse (ConfigError) a config whose estimate exceeds ``available`` bytes (default: this
    machine's memory); returns the estimate. The error names the field behind the largest part, or
    ``train.population`` when one agent fits but the population's K do not (every member's state and
    best parameters are alive at once: K times one agent's estimate, generous since the members'
    working sets are computed a few at a time)."""
    one = estimate_memory_bytes(cfg)
    k = cfg.train.population
    need = one * k
    have = machine_memory_bytes() if available is None else available
    if have is not None and k > 1 and one <= have < need:
        raise ConfigError(
            f"train.population: {k} members need at least {need / 2**30:.2f} GiB ({one / 2**30:.3f} "
            f"GiB each) but this machine has {have / 2**30:.2f} GiB of memory; at most "
            f"{have // one} members fit"
        )
    need = one
    if have is not None and need > have:
        parts = memory_breakdown(cfg)
        top = max(parts, key=parts.get)
        field = {
            "traces": "train.num_envs",
            "rollout_buffer": "train.num_envs",
            "activations": "train.num_envs",
            "env_state": "train.num_envs",
            "eval_envs": "train.eval_episodes",
            "network": "train.hidden",
        }[top]
        detail = ", ".join(
            f"{k} {v / 2**30:.2f}" for k, v in sorted(parts.items(), key=lambda kv: -kv[1])
        )
        raise ConfigError(
            f"{field}: the run needs at least {need / 2**30:.2f} GiB ({detail} GiB) but this machine "
            f"has {have / 2**30:.2f} GiB of memory; reduce {field}"
            + (" or train.rollout_steps" if top == "rollout_buffer" else "")
        )
    return one * k


def _meminfo(key: str) -> int | None:
    """A /proc/meminfo entry in bytes (None where there is none)."""
    for line in (_read("/proc/meminfo") or "").splitlines():
        if line.startswith(key + ":"):
            try:
                return int(line.split()[1]) * 1024
            except (ValueError, IndexError):
                return None
    return None


def _process_sizes() -> dict[str, int]:
    """This process's virtual size and data segment (VmSize, VmData) in bytes, where known."""
    out = {}
    try:
        with open("/proc/self/status") as f:
            for line in f:
                key, _, rest = line.partition(":")
                if key in ("VmSize", "VmData"):
                    out[key] = int(rest.split()[0]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return out


# What the size guards assume where no figure of this process's memory can be read.
UNKNOWN_MEMORY = 8 * 2**30


def process_memory_bytes() -> int:
    """The memory this process may still take (bytes): the least of the machine's available memory
    (MemAvailable; its total where that is unknown), what RLIMIT_AS and RLIMIT_DATA (``ulimit -v``,
    ``ulimit -d``) leave above the process's present size, and what its cgroup's limit leaves;
    UNKNOWN_MEMORY if none is known. A size guard counts this, not the machine: under a process
    limit the machine's memory is not the process's."""
    room = [_meminfo("MemAvailable") or machine_memory_bytes()]
    try:
        import resource
    except ImportError:  # not on this platform: the machine's figure alone
        resource = None
    if resource is not None:
        sizes = None  # read only under a limit (/proc/self/status: a third of this call's cost)
        for limit, used in ((resource.RLIMIT_AS, "VmSize"), (resource.RLIMIT_DATA, "VmData")):
            soft = resource.getrlimit(limit)[0]
            if soft != resource.RLIM_INFINITY and soft >= 0:
                sizes = _process_sizes() if sizes is None else sizes
                room.append(max(0, soft - sizes.get(used, 0)))
    cap, used = _cgroup_memory()
    room.append(None if cap is None else max(0, cap - used))
    known = [r for r in room if r is not None]
    return min(known) if known else UNKNOWN_MEMORY
