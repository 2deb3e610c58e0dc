"""The shipped PPO policies evaluated the same way on every CPU: their features' elementary
functions and their network, in float64 from the trained weights.

Why: torch's float32 kernels, and numpy's vector kernels for ``sin``, ``cos`` and ``tanh`` (SVML on
AVX-512, others on AVX2), round differently from one CPU to the next, and a closed loop carries a
last-bit difference in an action into the second decimal of Table II. What makes this evaluation
independent of the CPU:

- the network's sums run in one fixed pairwise order written here (:func:`fixed_order_dot`), as
  numpy elementwise additions and multiplications: IEEE 754 rounds each such operation exactly, so
  the vector width of the kernel that performs it cannot change the result; no BLAS (whose dot and
  matrix kernels, chosen per CPU, sum in their own orders) and no torch;
- the elementary functions (``sin``, ``cos``, ``hypot``, ``tanh``) are Python's ``math`` functions
  applied entry by entry (:func:`scalar_map`, :data:`LIBM`): the C library's scalar code, the very
  functions the single env's step (:data:`risk_env.models.ops.MATH`) uses, so the policy is exactly as
  CPU-independent as the env it drives (glibc picks one build of each for every x86-64 CPU with
  FMA and AVX2);
- the float32 weights are widened to float64 exactly.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from risk_env.models.ops import MATH, NUMPY, Ops


def scalar_map(fn: Callable[..., float], *arrays: Any) -> np.ndarray:
    """``fn`` (a ``math`` function of Python floats) applied entry by entry to the broadcast
    float64 ``arrays``: the C library's scalar result, the same whichever vector units the CPU has."""
    if len(arrays) == 1:  # the common case, without broadcasting's cost
        parts = [np.asarray(arrays[0], dtype=float)]
    else:
        parts = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in arrays))
    shape = parts[0].shape
    values = map(fn, *(p.ravel().tolist() for p in parts))
    return np.fromiter(values, dtype=float, count=math.prod(shape)).reshape(shape)


@dataclass(frozen=True)
class _ScalarOps(Ops):
    """:data:`risk_env.models.ops.NUMPY` with ``sin``, ``cos`` and ``sinc`` taken entry by entry from
    :data:`risk_env.models.ops.MATH` (``sinc`` is the single env's own formula)."""

    def sinc(self, a: Any) -> Any:
        return scalar_map(MATH.sinc, a)


LIBM = _ScalarOps(
    **{
        **NUMPY.__dict__,
        "name": "numpy-libm",
        "sin": lambda a: scalar_map(math.sin, a),
        "cos": lambda a: scalar_map(math.cos, a),
        "hypot": lambda x, y: scalar_map(math.hypot, x, y),
    }
)
"""The numpy face for the policies' features, with its elementary functions from ``math``."""


def fixed_order_dot(x: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """``x @ weight.T``, ``(B, n) x (m, n) -> (B, m)`` float64, summed pairwise in an order fixed
    by n alone: the products, then halves added (entry i to entry i + n/2; an odd last one carried),
    until one term is left."""
    terms = x[:, None, :] * weight[None, :, :]
    while terms.shape[-1] > 1:
        half = terms.shape[-1] // 2
        paired = terms[..., :half] + terms[..., half : 2 * half]
        terms = paired if terms.shape[-1] % 2 == 0 else np.concatenate((paired, terms[..., -1:]), axis=-1)
    return terms[..., 0]


ACTIVATIONS: dict[str, Callable[[float], float]] = {"Tanh": math.tanh, "ReLU": lambda z: max(z, 0.0)}
"""The hidden layers' activations this evaluation knows, by torch module name."""


@dataclass(frozen=True)
class PolicyNet:
    """The deterministic action of an SB3 ``ActorCriticPolicy`` (an MLP on a flat Box observation,
    a diagonal Gaussian's mean): hidden layers ``a(W h + b)``, then the action layer ``W h + b``."""

    weights: tuple[np.ndarray, ...]
    """``(n_out, n_in)`` float64 per layer, the action layer last."""
    biases: tuple[np.ndarray, ...]
    """``(n_out,)`` float64 per layer."""
    activations: tuple[str, ...]
    """A name of :data:`ACTIVATIONS` per hidden layer (one fewer than the layers)."""

    @classmethod
    def from_sb3(cls, policy: Any) -> PolicyNet:
        """The float64 copy of a loaded SB3 policy (``model.policy``); ``ValueError`` for a policy
        whose deterministic action is not an MLP of :data:`ACTIVATIONS` on flat features."""
        from stable_baselines3.common.distributions import DiagGaussianDistribution
        from stable_baselines3.common.torch_layers import FlattenExtractor
        from torch import nn

        def refuse(what: str) -> ValueError:
            return ValueError(
                "the float64 evaluation takes an MLP (Linear layers with Tanh or ReLU between them)"
                f" on flat features, acting by a diagonal Gaussian's mean; {what}"
            )

        extractor = policy.pi_features_extractor
        if not isinstance(extractor, FlattenExtractor):
            raise refuse(f"this policy extracts its features with {type(extractor).__name__}")
        if not isinstance(policy.action_dist, DiagGaussianDistribution) or policy.squash_output:
            raise refuse(
                f"this policy acts by {type(policy.action_dist).__name__} (squash_output"
                f" {policy.squash_output})"
            )
        layers = [*policy.mlp_extractor.policy_net, policy.action_net]
        weights: list[np.ndarray] = []
        biases: list[np.ndarray] = []
        activations: list[str] = []
        for i, layer in enumerate(layers):
            name = type(layer).__name__
            if isinstance(layer, nn.Linear) and len(weights) == len(activations):
                weights.append(layer.weight.detach().cpu().double().numpy().copy())
                bias = layer.bias
                zero = np.zeros(layer.out_features)
                biases.append(zero if bias is None else bias.detach().cpu().double().numpy().copy())
            elif name in ACTIVATIONS and len(weights) == len(activations) + 1 and i < len(layers) - 1:
                activations.append(name)
            else:
                raise refuse(f"its layer {i} is {layer}")
        return cls(tuple(weights), tuple(biases), tuple(activations))

    @property
    def size(self) -> int:
        """Length of the feature vector the policy reads."""
        return self.weights[0].shape[1]

    def __call__(self, features: np.ndarray) -> np.ndarray:
        """Actions ``(B, n_actions)`` float64 (before any clipping) of features ``(B, size)``."""
        h = np.asarray(features, dtype=float)
        for i, (weight, bias) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = fixed_order_dot(h, weight) + bias
            if i < len(self.activations):
                h = scalar_map(ACTIVATIONS[self.activations[i]], h)
        return h


def load_model(zip_path: Path) -> Any:
    """The stable-baselines3 PPO model saved at ``zip_path``, on the CPU. Loading first builds the
    network with fresh weights (an orthogonal initialisation: a QR per layer), which the saved ones
    then replace: built with one torch thread, as a QR this small is over 100 times slower on two
    threads than on one (their synchronisation); the caller's thread count is restored after."""
    import torch
    from stable_baselines3 import PPO

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return PPO.load(zip_path, device="cpu")
    finally:
        torch.set_num_threads(threads)
