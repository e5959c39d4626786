"""The exported Q-network folded for fast NumPy inference (the outputs of policy.QPolicy up to
float32 rounding). The folding: docs/generation.md#speed.
"""

from __future__ import annotations

import math

import numpy as np

from jaxexo.physics import actions
from jaxexo.storage.policy_file import LAYER_NORM_EPS, QPolicy


class FoldedQNetwork:
    """``q(x)`` for x (..., D) like QPolicy.q_values; plus the pieces the single-step loop uses."""

    def __init__(self, policy: QPolicy):
        n = len(policy.kernels)
        self.layer_norm = bool(policy.norm_scales)
        self.eps = LAYER_NORM_EPS
        weights, shifts = [], []
        carry_rows = None  # per-unit factor |s| to apply to the next layer's rows
        carry_bias = None  # constant contribution of s = 0 units to the next layer's bias
        for i in range(n):
            w = policy.kernels[i].astype(np.float64)
            b = policy.biases[i].astype(np.float64)
            if carry_rows is not None:
                b = b + carry_bias @ w
                w = carry_rows[:, None] * w
            wa = np.vstack([w, b[None, :]])
            shift = None
            if self.layer_norm and i < n - 1:
                wa = wa - wa.mean(axis=1, keepdims=True)  # centring folded in
                s = policy.norm_scales[i].astype(np.float64)
                beta = policy.norm_biases[i].astype(np.float64)
                sign = np.where(s < 0.0, -1.0, 1.0)
                mag = np.abs(s)
                wa = wa * sign[None, :]
                shift = np.where(mag > 0.0, beta / np.where(mag > 0.0, mag, 1.0), 0.0)
                carry_rows = mag
                carry_bias = np.where(mag > 0.0, 0.0, np.maximum(beta, 0.0))
            weights.append(wa.astype(np.float32))
            shifts.append(None if shift is None else shift.astype(np.float32))
        self.weights = weights  # (in + 1, out) each
        self.shifts = shifts  # LayerNorm shift b/|s| per hidden layer (None without LN)
        self.hidden = [w.shape[1] for w in weights[:-1]]
        self.obs_dim = weights[0].shape[0] - 1
        self.num_actions = weights[-1].shape[1]

    def _hidden(self, i: int, pre: np.ndarray) -> np.ndarray:
        """Activation of hidden layer i from its (centred, if LayerNorm) pre-activation (..., H)."""
        if self.shifts[i] is not None:
            var = np.einsum("...h,...h->...", pre, pre)[..., None] * (1.0 / pre.shape[-1])
            pre = pre / np.sqrt(var + self.eps) + self.shifts[i]
        return np.maximum(pre, 0.0)

    def q(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=np.float32)
        if x.shape[-1] != self.obs_dim:
            raise ValueError(f"obs: expected last dimension {self.obs_dim}, got shape {x.shape}")
        for i, wa in enumerate(self.weights):
            x = x @ wa[:-1] + wa[-1]
            if i < len(self.weights) - 1:
                x = self._hidden(i, x)
        return x

    def first_layer_for(self, basis: np.ndarray) -> np.ndarray:
        """Layer 0 for an observation given as obs = c @ basis with c[-1] = 1: returns M (R, H) with
        layer 0's (folded) pre-activation = c @ M (the bias goes into the last row)."""
        w0 = self.weights[0].astype(np.float64)
        m = basis @ w0[:-1]
        m[-1] += w0[-1]
        return m.astype(np.float32)


class StepNetwork:
    """Greedy action for one observation given as affine coordinates, with preallocated buffers.

    The generator's observation is affine in c = (heel_y, heel_z, time, visited, 1) for a fixed scene
    (jaxexo.physics.actions.observation), so ``set_scene(basis)`` folds that map into layer 0 and each step
    costs one small matmul per layer and a handful of in-place operations."""

    def __init__(self, net: FoldedQNetwork):
        self.net = net
        self.m0 = None
        self.c = np.ones(5, np.float32)
        self.pre = [np.empty(h, np.float32) for h in net.hidden]
        self.bufs = [np.ones(h + 1, np.float32) for h in net.hidden]  # trailing 1 for the bias row
        self.outs = [b[:-1] for b in self.bufs]
        self.q = np.empty(net.num_actions, np.float32)
        # Per hidden layer: (weights, pre-activation buffer, output view, LayerNorm shift, 1/H).
        self._layers = None

    def set_scene(self, basis: np.ndarray) -> None:
        self.m0 = self.net.first_layer_for(basis)
        net = self.net
        self._layers = [
            (
                (self.m0 if i == 0 else net.weights[i]),
                self.pre[i],
                self.outs[i],
                net.shifts[i],
                1.0 / len(self.pre[i]),
            )
            for i in range(len(self.pre))
        ]

    def greedy(self, heel_y: float, heel_z: float, time: float, visited: float, mask=None) -> int:
        q = self.q_values(heel_y, heel_z, time, visited)
        if mask is not None:  # the shield's admissible moves (jaxexo.physics.actions.greedy_action)
            return int(actions.greedy_action(np, q, mask))
        return int(q.argmax())

    def q_values(self, heel_y: float, heel_z: float, time: float, visited: float) -> np.ndarray:
        """Q (NUM_ACTIONS,) float32 for one observation (a buffer, overwritten by the next call)."""
        c = self.c
        c[:4] = (heel_y, heel_z, time, visited)  # each rounded to float32, as one by one
        x = c
        eps = self.net.eps
        dot, multiply, maximum, f32, sqrt = np.dot, np.multiply, np.maximum, np.float32, math.sqrt
        zero = _ZERO
        for (w, pre, out, shift, inv_h), buf in zip(self._layers, self.bufs):
            dot(x, w, out=pre)
            if shift is not None:
                # a Python float scales a float32 array as that float rounded to float32 (NumPy's
                # weak scalars): the same product as ``pre *= scale``, without its conversion
                multiply(pre, f32(1.0 / sqrt(float(dot(pre, pre)) * inv_h + eps)), out=pre)
                pre += shift
            maximum(pre, zero, out=out)
            x = buf
        dot(x, self.net.weights[-1], out=self.q)
        return self.q


_ZERO = np.float32(0.0)  # ReLU's floor, converted once
