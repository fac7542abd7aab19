"""The world model's Flax modules: the RSSM cell, the observation encoder and decoder, the reward and continue
heads (DreamerV3's layout: LayerNorm and SiLU after every hidden layer, zero-initialised reward output).

Shapes: ``deter`` D, ``stoch`` S categorical variables of ``classes`` K; features ``D + S K``. Every module
takes any leading batch axes.

``dtype`` is the compute dtype of the matrix products and activations (``jnp.bfloat16`` as DreamerV3 trains);
parameters stay float32, LayerNorm statistics are computed in float32, and every module's outputs (the GRU's state,
logits, embeddings, reconstructions) are float32.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
from flax import struct

from jarena_agents.world_model import distributions as dist


@struct.dataclass
class Latent:
    """A model state: ``deter`` float32 (*, D), the GRU's; ``stoch`` float32 (*, S, K), one-hot samples."""

    deter: jax.Array
    stoch: jax.Array

    def features(self) -> jax.Array:
        """``concat(deter, flattened stoch)``: float32 (*, D + S K), what the heads read."""
        return jnp.concatenate([self.deter, self.stoch.reshape(self.stoch.shape[:-2] + (-1,))], axis=-1)


class NormDense(nn.Module):
    """Dense, LayerNorm, SiLU, in ``dtype``."""

    features: int
    dtype: Any = jnp.float32

    @nn.compact
    def __call__(self, x):
        return nn.silu(nn.LayerNorm(dtype=self.dtype)(nn.Dense(self.features, use_bias=False, dtype=self.dtype)(x)))


class NormGRU(nn.Module):
    """The GRU of Dreamer's RSSM (DreamerV2 on): one Dense of ``[inputs, h]`` to reset, candidate and update
    gates, LayerNorm over them, ``update = sigmoid(u - 1)`` (biased towards keeping ``h``)."""

    features: int
    dtype: Any = jnp.float32

    @nn.compact
    def __call__(self, inputs, h):
        gates = nn.Dense(3 * self.features, use_bias=False, dtype=self.dtype)(jnp.concatenate([inputs, h], -1))
        parts = nn.LayerNorm(dtype=self.dtype)(gates)
        reset, candidate, update = jnp.split(parts, 3, axis=-1)
        candidate = jnp.tanh(jax.nn.sigmoid(reset) * candidate)
        update = jax.nn.sigmoid(update - 1.0)
        return (update * candidate + (1 - update) * h).astype(h.dtype)


class RSSMCell(nn.Module):
    """One step of the recurrent state-space model.

    ``img_step(latent, action, key)``: ``h' = GRU(h, [z, a])``, prior ``p(z' | h')``; returns the prior latent
    (a sample, or the mode when ``key`` is None) and the prior's probabilities (*, S, K).
    ``obs_step(latent, action, embed, key)``: the same ``h'``, then the posterior ``q(z' | h', embed)``;
    returns ``(posterior latent, posterior probs, prior probs)``; ``posterior_step`` the same without the prior,
    ``prior(deter)`` the prior alone.
    """

    deter: int
    stoch: int
    classes: int
    hidden: int
    unimix: float = dist.UNIMIX
    dtype: Any = jnp.float32

    def setup(self):
        self.gru_input = NormDense(self.hidden, self.dtype)
        self.gru = NormGRU(self.deter, self.dtype)
        self.prior_hidden = NormDense(self.hidden, self.dtype)
        self.prior_logits = nn.Dense(self.stoch * self.classes, dtype=self.dtype)
        self.posterior_hidden = NormDense(self.hidden, self.dtype)
        self.posterior_logits = nn.Dense(self.stoch * self.classes, dtype=self.dtype)

    def _probs(self, logits):
        logits = logits.astype(jnp.float32).reshape(logits.shape[:-1] + (self.stoch, self.classes))
        return dist.categorical_probs(logits, self.unimix)

    def _draw(self, probs, key):
        return dist.mode_one_hot(probs) if key is None else dist.sample_one_hot(key, probs)

    def _deter(self, latent: Latent, action):
        flat = latent.stoch.reshape(latent.stoch.shape[:-2] + (-1,))
        return self.gru(self.gru_input(jnp.concatenate([flat, action], -1)), latent.deter)

    def img_step(self, latent: Latent, action, key):
        deter = self._deter(latent, action)
        prior = self._probs(self.prior_logits(self.prior_hidden(deter)))
        return Latent(deter, self._draw(prior, key)), prior

    def prior(self, deter):
        """The prior's probabilities (*, S, K) given ``deter`` (*, D)."""
        return self._probs(self.prior_logits(self.prior_hidden(deter)))

    def posterior_step(self, latent: Latent, action, embed, key):
        """``obs_step`` without the prior: ``(posterior latent, posterior probs)``. A filter over a sequence runs
        this in its loop and the prior on all the steps' ``deter`` at once after it (fewer sequential ops)."""
        deter = self._deter(latent, action)
        posterior = self._probs(self.posterior_logits(self.posterior_hidden(jnp.concatenate([deter, embed], -1))))
        return Latent(deter, self._draw(posterior, key)), posterior

    def obs_step(self, latent: Latent, action, embed, key):
        following, posterior = self.posterior_step(latent, action, embed, key)
        return following, posterior, self.prior(following.deter)

    def __call__(self, latent, action, embed, key):
        return self.obs_step(latent, action, embed, key)


def _conv_norm(x, features, name, dtype):
    x = nn.Conv(features, (4, 4), (2, 2), padding="SAME", use_bias=False, dtype=dtype, name=name)(x)
    return nn.silu(nn.LayerNorm(dtype=dtype, name=f"{name}_norm")(x))


class Encoder(nn.Module):
    """Observations to one embedding (*, E): ``symlog`` of the vector through ``layers`` NormDense, and each
    uint8 image (scaled to [-0.5, 0.5]) through ``cnn_layers`` stride-2 4 x 4 convolutions of
    ``cnn_depth * 2^i`` channels, flattened; concatenated."""

    hidden: int
    layers: int
    cnn_depth: int
    cnn_layers: int
    dtype: Any = jnp.float32

    @nn.compact
    def __call__(self, vector, images: dict):
        parts = []
        if vector.shape[-1]:
            x = dist.symlog(vector)
            for i in range(self.layers):
                x = NormDense(self.hidden, self.dtype, name=f"vector_{i}")(x)
            parts.append(x.astype(jnp.float32))
        for key in sorted(images):
            x = images[key]
            batch = x.shape[:-3]
            x = x.reshape((-1,) + x.shape[-3:]).astype(jnp.float32) / 255.0 - 0.5
            for i in range(self.cnn_layers):
                x = _conv_norm(x, self.cnn_depth * 2 ** i, f"{key}_conv{i}", self.dtype)
            parts.append(x.reshape(batch + (-1,)).astype(jnp.float32))
        return jnp.concatenate(parts, axis=-1)


class Decoder(nn.Module):
    """Features to observations: the vector in symlog space (*, vector_size), and each image (*, H, W, C) in
    [-0.5, 0.5], from a Dense to (H / 2^n, W / 2^n, depth 2^(n-1)) then n stride-2 transposed convolutions."""

    vector_size: int
    image_shapes: Sequence[tuple[str, tuple[int, int, int]]]
    hidden: int
    layers: int
    cnn_depth: int
    cnn_layers: int
    dtype: Any = jnp.float32

    @nn.compact
    def __call__(self, features):
        vector = None
        if self.vector_size:
            x = features
            for i in range(self.layers):
                x = NormDense(self.hidden, self.dtype, name=f"vector_{i}")(x)
            vector = nn.Dense(self.vector_size, dtype=self.dtype, name="vector_out")(x).astype(jnp.float32)
        images = {}
        n = self.cnn_layers
        for key, (height, width, channels) in self.image_shapes:
            batch = features.shape[:-1]
            depth = self.cnn_depth * 2 ** (n - 1)
            x = nn.Dense((height >> n) * (width >> n) * depth, dtype=self.dtype, name=f"{key}_in")(features)
            x = x.reshape((-1, height >> n, width >> n, depth))
            for i in reversed(range(n)):
                last = i == 0
                x = nn.ConvTranspose(channels if last else self.cnn_depth * 2 ** (i - 1), (4, 4), (2, 2),
                                     padding="SAME", use_bias=last, dtype=self.dtype, name=f"{key}_deconv{i}")(x)
                if not last:
                    x = nn.silu(nn.LayerNorm(dtype=self.dtype, name=f"{key}_deconv{i}_norm")(x))
            images[key] = x.reshape(batch + (height, width, channels)).astype(jnp.float32)
        return vector, images


class Head(nn.Module):
    """``layers`` NormDense then a Dense to ``outputs`` (zero-initialised with ``zero_init``, as DreamerV3's
    reward head, so the first predictions are the bins' centre)."""

    outputs: int
    hidden: int
    layers: int
    zero_init: bool = False
    dtype: Any = jnp.float32

    @nn.compact
    def __call__(self, x):
        for i in range(self.layers):
            x = NormDense(self.hidden, self.dtype, name=f"hidden_{i}")(x)
        init = nn.initializers.zeros if self.zero_init else nn.initializers.lecun_normal()
        return nn.Dense(self.outputs, kernel_init=init, dtype=self.dtype, name="out")(x).astype(jnp.float32)
