"""The exported policy file (policy.npz): written by the trainer, read with NumPy only.

A plain ``.npz`` (no pickle) of the Q-network's arrays and a JSON ``metadata`` with everything
inference needs, checksummed (``sha256``) and verified on load; loading type-checks every field and
refuses format version 1 (docs/reliability.md, docs/training.md).
"""

from __future__ import annotations

import hashlib
import io
import json
import numbers
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jaxexo.config.input_files import MAX_POLICY_BYTES, InputFileError, check_path_type, read_input
from jaxexo.storage.atomic import atomic_write

FORMAT = "jaxexo-policy"
FORMAT_VERSION = 2  # 2: sha256 checksum in the metadata, every network field required
ACTIVATIONS = ("relu",)
LAYER_NORM_EPS = 1e-6  # flax.linen.LayerNorm's default epsilon


class PolicyFileError(ValueError):
    """A policy file that is missing, truncated, corrupt, or of another format or version."""


@dataclass(frozen=True)
class QPolicy:
    """A Q-network as NumPy arrays: ``q_values(obs)`` for one observation (D,) or a batch (..., D)."""

    kernels: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    norm_scales: tuple[np.ndarray, ...]
    norm_biases: tuple[np.ndarray, ...]
    metadata: dict

    @property
    def obs_dim(self) -> int:
        return self.kernels[0].shape[0]

    @property
    def num_actions(self) -> int:
        return self.kernels[-1].shape[1]

    def q_values(self, obs) -> np.ndarray:
        x = np.asarray(obs, dtype=np.float32)
        if x.shape[-1] != self.obs_dim:
            raise ValueError(f"obs: expected last dimension {self.obs_dim}, got shape {x.shape}")
        for i, (w, b) in enumerate(zip(self.kernels[:-1], self.biases[:-1])):
            x = x @ w + b
            if self.norm_scales:
                mu = x.mean(axis=-1, keepdims=True)
                var = ((x - mu) ** 2).mean(axis=-1, keepdims=True)
                x = (x - mu) / np.sqrt(var + LAYER_NORM_EPS) * self.norm_scales[
                    i
                ] + self.norm_biases[i]
            x = np.maximum(x, 0.0)
        return x @ self.kernels[-1] + self.biases[-1]

    def greedy_action(self, obs) -> np.ndarray:
        return np.argmax(self.q_values(obs), axis=-1)


def policy_checksum(arrays: dict, metadata: dict) -> str:
    """SHA-256 over the metadata (canonical JSON, without its ``sha256`` field) and every array's name,
    dtype, shape and bytes, in name order."""
    h = hashlib.sha256()
    h.update(
        json.dumps({k: v for k, v in metadata.items() if k != "sha256"}, sort_keys=True).encode()
    )
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"\n{name} {a.dtype.str} {a.shape}\n".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _as_float32(name: str, a, path) -> np.ndarray:
    """``a`` as float32 if it is a real floating-point array that stays finite in float32."""
    a = np.asarray(a)
    if not np.issubdtype(a.dtype, np.floating):
        raise PolicyFileError(
            f"{path}: array {name!r} has dtype {a.dtype}; weights must be real floating point"
        )
    with np.errstate(over="ignore", invalid="ignore"):
        f = a.astype(np.float32)
    if not np.all(np.isfinite(f)):
        raise PolicyFileError(
            f"{path}: array {name!r} holds NaN or inf"
            + (
                ""
                if not np.all(np.isfinite(a))
                else " after the cast to float32 (values beyond float32's range)"
            )
        )
    return f


def save_policy(
    path: str | Path, kernels, biases, norm_scales, norm_biases, metadata: dict
) -> Path:
    """Write policy.npz atomically (a partial file never replaces a good one). Refuses arrays that are
    not finite in float32: a diverged training must not export a policy."""
    path = Path(path)
    meta = {"format": FORMAT, "format_version": FORMAT_VERSION, **metadata}
    arrays = {}
    for i, (w, b) in enumerate(zip(kernels, biases)):
        arrays[f"dense_{i}_kernel"] = _as_float32(f"dense_{i}_kernel", w, path)
        arrays[f"dense_{i}_bias"] = _as_float32(f"dense_{i}_bias", b, path)
    for i, (s, b) in enumerate(zip(norm_scales, norm_biases)):
        arrays[f"norm_{i}_scale"] = _as_float32(f"norm_{i}_scale", s, path)
        arrays[f"norm_{i}_bias"] = _as_float32(f"norm_{i}_bias", b, path)
    meta["sha256"] = policy_checksum(arrays, meta)
    buf = io.BytesIO()
    np.savez(buf, metadata=np.array(json.dumps(meta, sort_keys=True)), **arrays)
    atomic_write(path, buf.getvalue())
    return path


# Metadata fields the network and the generator need: name -> (check, what it must be).
def _is_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _is_num(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool) and np.isfinite(x)


REQUIRED = {
    "obs_mode": (lambda x: isinstance(x, str), "a string"),
    "obs_dim": (lambda x: _is_int(x) and x > 0, "a positive integer"),
    "num_actions": (lambda x: _is_int(x) and x > 0, "a positive integer"),
    "layers": (
        lambda x: isinstance(x, list) and len(x) >= 2 and all(_is_int(v) and v > 0 for v in x),
        "a list of at least two positive integers (the layer sizes)",
    ),
    "layer_norm": (lambda x: isinstance(x, bool), "true or false"),
    "activation": (lambda x: x in ACTIVATIONS, f"one of {list(ACTIVATIONS)}"),
    "action_angles_rad": (
        lambda x: isinstance(x, list) and all(_is_num(v) for v in x),
        "a list of angles (rad)",
    ),
    "length_scale": (lambda x: _is_num(x) and x > 0, "a positive number (m)"),
    "thesis_obs_center": (
        lambda x: isinstance(x, list) and all(_is_num(v) for v in x),
        "a list of numbers",
    ),
    "config_toml": (lambda x: isinstance(x, str), "the training config as TOML text"),
    "sha256": (lambda x: isinstance(x, str) and len(x) == 64, "a 64-digit hex checksum"),
}


# The largest array a policy may hold (a Q-network of 65,536-unit layers is far below it).
MAX_ARRAY_BYTES = 2**31


def _check_archive(data: bytes, path: Path) -> None:
    """Before NumPy reads anything: the file is a zip archive (np.load would try a non-archive as a
    pickle and suggest allow_pickle), no member name appears twice (a reader would take one of
    them), and no member's header claims more data than the member holds (a crafted shape of 10^12
    would be allocated before the read fails)."""
    if not zipfile.is_zipfile(io.BytesIO(data)):
        raise PolicyFileError(
            f"{path}: not a jaxexo policy: not a readable policy file (truncated or corrupt, "
            "or not the zip archive of arrays that policy.npz is)"
        )
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            names = [info.filename for info in zf.infolist()]
            twice = sorted({n for n in names if names.count(n) > 1})
            if twice:
                raise PolicyFileError(
                    f"{path}: the archive holds the member {twice[0]!r} more than once; not a "
                    "policy that jaxexo wrote (it writes each array once)"
                )
            for info in zf.infolist():
                with zf.open(info) as f:
                    version = np.lib.format.read_magic(f)
                    if version == (1, 0):
                        shape, _, dtype = np.lib.format.read_array_header_1_0(f)
                    else:
                        shape, _, dtype = np.lib.format.read_array_header_2_0(f)
                count = 1
                for n in shape:
                    count *= int(n)
                nbytes = count * dtype.itemsize
                if nbytes > min(info.file_size, MAX_ARRAY_BYTES):
                    raise PolicyFileError(
                        f"{path}: array {info.filename!r} claims shape {tuple(shape)} "
                        f"({nbytes} bytes) but holds {info.file_size} bytes; not a valid policy"
                    )
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, RuntimeError) as e:
        if isinstance(e, PolicyFileError):
            raise
        raise PolicyFileError(
            f"{path}: not a readable jaxexo policy (truncated or corrupt: {e})"
        ) from None


# Fields declared after policies had been trained, with the value that means what those policies were
# trained with: a file that lacks one reads it (env.floor_clearance: 0, the shield without the floor
# rule).
FORMER_MEANING = {("env", "floor_clearance"): 0.0}


def policy_config(meta: dict, path):
    """The policy's training config from ``metadata.config_toml``: the complete resolved config that
    ``jaxexo train`` writes (every field stated, so that no default fills a gap), agreeing with every
    metadata field that it also states (obs_mode, layer_norm, the hidden layers). PolicyFileError
    naming the field otherwise."""
    import tomllib

    from jaxexo.config import (
        SECTION_CLASSES,
        SECTIONS,
        ConfigError,
        config_from_dict,
        declared_fields,
    )

    text = meta.get("config_toml")
    if not isinstance(text, str):
        raise PolicyFileError(
            f"{path}: metadata.config_toml is missing; cannot rebuild the environment"
        )
    if not text.strip():
        raise PolicyFileError(
            f"{path}: metadata.config_toml is empty; the policy's training config is needed "
            "to rebuild its environment"
        )
    try:
        raw = tomllib.loads(text)
        for section in SECTIONS:
            for name, spec in declared_fields(SECTION_CLASSES[section]):
                # The [device] section describes the drives a swing is timed for, not the training:
                # a setting added after a policy was trained takes its default.
                if section == "device" and spec.role == "setting":
                    continue
                if (section, name) in FORMER_MEANING and isinstance(raw.get(section), dict):
                    raw[section].setdefault(name, FORMER_MEANING[section, name])
                if spec.omit_default and isinstance(raw.get(section), dict):
                    continue  # left out at its default (off) by the writer
                if not isinstance(raw.get(section), dict) or name not in raw[section]:
                    raise ConfigError(
                        f"{section}.{name} is not stated: not the resolved training config that "
                        "this jaxexo's train writes (a policy trained by an older jaxexo, before "
                        "the field existed, must be retrained)"
                    )
        config = config_from_dict(raw)
    except (tomllib.TOMLDecodeError, ConfigError) as e:
        raise PolicyFileError(
            f"{path}: metadata.config_toml is not a valid jaxexo config ({e})"
        ) from None
    for key, field_, value in (
        ("obs_mode", "env.obs_mode", config.env.obs_mode),
        ("layer_norm", "train.layer_norm", config.train.layer_norm),
        ("layers", "train.hidden", list(config.train.hidden)),
    ):
        have = meta.get(key)
        if key == "layers" and isinstance(have, list):
            have = have[1:-1]
        if have != value:
            raise PolicyFileError(
                f"{path}: metadata.{key} ({meta.get(key)!r}) contradicts its config_toml's "
                f"{field_} = {value!r}"
            )
    return config


def load_policy(path: str | Path) -> QPolicy:
    """Read and check policy.npz; raises PolicyFileError saying what is wrong."""
    path = check_path_type(path, "path")
    try:
        data = read_input(path, "policy file", MAX_POLICY_BYTES)
    except InputFileError as e:
        raise PolicyFileError(str(e)) from None
    _check_archive(data, path)
    try:
        z = np.load(io.BytesIO(data), allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise PolicyFileError(f"{path}: a single array, not a policy archive (.npz)")
        with z:
            files = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, OSError, EOFError, ValueError) as e:
        raise PolicyFileError(
            f"{path}: not a readable policy file (truncated or corrupt: {e})"
        ) from None
    if "metadata" not in files:
        raise PolicyFileError(f"{path}: no 'metadata' entry; not a jaxexo policy file")
    try:
        meta = json.loads(str(files.pop("metadata")))
    except json.JSONDecodeError as e:
        raise PolicyFileError(f"{path}: metadata is not valid JSON ({e})") from None
    if not isinstance(meta, dict):
        raise PolicyFileError(f"{path}: metadata must be a JSON object, got {type(meta).__name__}")
    if meta.get("format") != FORMAT:
        raise PolicyFileError(f"{path}: format is {meta.get('format')!r}, expected {FORMAT!r}")
    if meta.get("format_version") == 1:
        raise PolicyFileError(
            f"{path}: format_version 1 (written by an older jaxexo, without a checksum) is no "
            f"longer read: its weights cannot be verified. Train the policy again with this jaxexo"
        )
    if meta.get("format_version") != FORMAT_VERSION:
        raise PolicyFileError(
            f"{path}: format_version {meta.get('format_version')!r} is not supported "
            f"(this jaxexo reads version {FORMAT_VERSION})"
        )
    for key, (ok, what) in REQUIRED.items():
        if meta.get(key) is None:
            raise PolicyFileError(f"{path}: metadata.{key} is missing (it must be {what})")
        if not ok(meta[key]):
            raise PolicyFileError(f"{path}: metadata.{key} must be {what}, got {meta[key]!r:.80}")
    if policy_checksum(files, meta) != meta["sha256"]:
        raise PolicyFileError(
            f"{path}: checksum mismatch: the arrays or the metadata were changed or corrupted "
            "after export (metadata.sha256 does not match the content)"
        )
    layers = meta["layers"]
    if layers[0] != meta["obs_dim"]:
        raise PolicyFileError(
            f"{path}: metadata.obs_dim is {meta['obs_dim']} but the network (metadata.layers) "
            f"has {layers[0]} inputs"
        )
    n_norm = len(layers) - 2 if meta["layer_norm"] else 0
    expected = {f"dense_{i}_{p}" for i in range(len(layers) - 1) for p in ("kernel", "bias")}
    expected |= {f"norm_{i}_{p}" for i in range(n_norm) for p in ("scale", "bias")}
    for name in sorted(expected):
        if name not in files:
            raise PolicyFileError(f"{path}: missing array {name!r}")
    extra = sorted(set(files) - expected)
    if extra:
        raise PolicyFileError(
            f"{path}: unexpected arrays {extra} for metadata.layers {layers} and "
            f"metadata.layer_norm {meta['layer_norm']}"
        )
    kernels, biases, scales, nbiases = [], [], [], []
    for i in range(len(layers) - 1):
        w, b = files[f"dense_{i}_kernel"], files[f"dense_{i}_bias"]
        if w.shape != (layers[i], layers[i + 1]) or b.shape != (layers[i + 1],):
            raise PolicyFileError(
                f"{path}: dense_{i} has shapes {w.shape}, {b.shape}; metadata.layers "
                f"says ({layers[i]}, {layers[i + 1]})"
            )
        kernels.append(_as_float32(f"dense_{i}_kernel", w, path))
        biases.append(_as_float32(f"dense_{i}_bias", b, path))
        if i < n_norm:
            s, nb = files[f"norm_{i}_scale"], files[f"norm_{i}_bias"]
            if s.shape != (layers[i + 1],) or nb.shape != (layers[i + 1],):
                raise PolicyFileError(
                    f"{path}: misshaped norm_{i} arrays {s.shape}, {nb.shape}; expected "
                    f"({layers[i + 1]},)"
                )
            scales.append(_as_float32(f"norm_{i}_scale", s, path))
            nbiases.append(_as_float32(f"norm_{i}_bias", nb, path))
    if meta["num_actions"] != layers[-1]:
        raise PolicyFileError(
            f"{path}: metadata.num_actions {meta['num_actions']!r} does not match "
            f"the output layer ({layers[-1]})"
        )
    if len(meta["action_angles_rad"]) != meta["num_actions"]:
        raise PolicyFileError(
            f"{path}: metadata.action_angles_rad lists {len(meta['action_angles_rad'])} "
            f"angles for {meta['num_actions']} actions"
        )
    return QPolicy(tuple(kernels), tuple(biases), tuple(scales), tuple(nbiases), meta)
