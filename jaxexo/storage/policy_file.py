"""The exported policy file (policy.npz): writing is done by the trainer, reading needs NumPy only.

A policy file is a plain ``.npz`` (no pickle: loading never executes code) holding the Q-network's
arrays ``dense_{i}_kernel``, ``dense_{i}_bias`` (and ``norm_{i}_scale``, ``norm_{i}_bias`` with
LayerNorm), and ``metadata``: a JSON document with everything inference needs to rebuild the
observation and the actions: format version, observation mode and normalisation, action set, step
size, kinematic constants, layer sizes.
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jaxexo.storage.atomic import atomic_write

FORMAT = "jaxexo-policy"
FORMAT_VERSION = 1
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
                x = (x - mu) / np.sqrt(var + LAYER_NORM_EPS) * self.norm_scales[i] + self.norm_biases[i]
            x = np.maximum(x, 0.0)
        return x @ self.kernels[-1] + self.biases[-1]

    def greedy_action(self, obs) -> np.ndarray:
        return np.argmax(self.q_values(obs), axis=-1)


def save_policy(path: str | Path, kernels, biases, norm_scales, norm_biases, metadata: dict) -> Path:
    """Write policy.npz atomically (a partial file never replaces a good one)."""
    path = Path(path)
    meta = {"format": FORMAT, "format_version": FORMAT_VERSION, **metadata}
    arrays = {"metadata": np.array(json.dumps(meta, sort_keys=True))}
    for i, (w, b) in enumerate(zip(kernels, biases)):
        arrays[f"dense_{i}_kernel"] = np.asarray(w, np.float32)
        arrays[f"dense_{i}_bias"] = np.asarray(b, np.float32)
    for i, (s, b) in enumerate(zip(norm_scales, norm_biases)):
        arrays[f"norm_{i}_scale"] = np.asarray(s, np.float32)
        arrays[f"norm_{i}_bias"] = np.asarray(b, np.float32)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return atomic_write(path, buf.getvalue())


def load_policy(path: str | Path) -> QPolicy:
    """Read and check policy.npz; raises PolicyFileError saying what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise PolicyFileError(f"{path}: no such policy file")
    try:
        z = np.load(path, allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise PolicyFileError(f"{path}: a single array, not a policy archive (.npz)")
        with z:
            files = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, OSError, EOFError, ValueError) as e:
        raise PolicyFileError(f"{path}: not a readable policy file (truncated or corrupt: {e})") from None
    if "metadata" not in files:
        raise PolicyFileError(f"{path}: no 'metadata' entry; not a jaxexo policy file")
    try:
        meta = json.loads(str(files["metadata"]))
    except json.JSONDecodeError as e:
        raise PolicyFileError(f"{path}: metadata is not valid JSON ({e})") from None
    if not isinstance(meta, dict):
        raise PolicyFileError(f"{path}: metadata must be a JSON object, got {type(meta).__name__}")
    if meta.get("format") != FORMAT:
        raise PolicyFileError(f"{path}: format is {meta.get('format')!r}, expected {FORMAT!r}")
    if meta.get("format_version") != FORMAT_VERSION:
        raise PolicyFileError(f"{path}: format_version {meta.get('format_version')!r} is not supported "
                              f"(this jaxexo reads version {FORMAT_VERSION})")
    layers = meta.get("layers")
    if not isinstance(layers, list) or len(layers) < 2:
        raise PolicyFileError(f"{path}: metadata.layers must list the layer sizes, got {layers!r}")
    kernels, biases, scales, nbiases = [], [], [], []
    for i in range(len(layers) - 1):
        for name in (f"dense_{i}_kernel", f"dense_{i}_bias"):
            if name not in files:
                raise PolicyFileError(f"{path}: missing array {name!r}")
        w, b = files[f"dense_{i}_kernel"], files[f"dense_{i}_bias"]
        if w.shape != (layers[i], layers[i + 1]) or b.shape != (layers[i + 1],):
            raise PolicyFileError(f"{path}: dense_{i} has shapes {w.shape}, {b.shape}; metadata.layers "
                                  f"says ({layers[i]}, {layers[i + 1]})")
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
            raise PolicyFileError(f"{path}: dense_{i} holds NaN or inf")
        kernels.append(w.astype(np.float32))
        biases.append(b.astype(np.float32))
        if meta.get("layer_norm") and i < len(layers) - 2:
            s, nb = files.get(f"norm_{i}_scale"), files.get(f"norm_{i}_bias")
            if s is None or nb is None or s.shape != (layers[i + 1],) or nb.shape != (layers[i + 1],):
                raise PolicyFileError(f"{path}: missing or misshaped norm_{i} arrays")
            scales.append(s.astype(np.float32))
            nbiases.append(nb.astype(np.float32))
    if meta.get("num_actions") != layers[-1]:
        raise PolicyFileError(f"{path}: metadata.num_actions {meta.get('num_actions')!r} does not match "
                              f"the output layer ({layers[-1]})")
    return QPolicy(tuple(kernels), tuple(biases), tuple(scales), tuple(nbiases), meta)
