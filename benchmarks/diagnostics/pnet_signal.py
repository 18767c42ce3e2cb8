#!/usr/bin/env python
"""Signal against dropout noise in a freshly initialised PNet (MPNet's released width vs ours).

For random normalised inputs, the variance of the expected output over inputs (what the
network can learn from) against the variance over dropout masks for one input (noise
the training loss sees), per architecture; and the activation scale per layer.

    python benchmarks/diagnostics/pnet_signal.py
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp

from ntq_jax import make_env, models
from ntq_jax.models import ModelConfig

MPNET = (1280, 1024, 896, 768, 512, 384, 256, 256, 128, 64, 32)
NETS = (
    ("MPNet's released, dropout after 10 layers", MPNET, 10),
    ("MPNet's width, dropout after 2 layers", MPNET, 2),
    ("ours (512-...-64), dropout after 2 layers", (512, 512, 256, 256, 128, 64), 2),
)


def main(argv=None) -> None:
    argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    ).parse_args(argv)
    env = make_env("point/0")
    x = jax.random.uniform(jax.random.key(1), (256, 2 * env.dim), minval=-1, maxval=1)
    for name, hidden, layers in NETS:
        spec = models.ModelSpec.from_env(
            env, ModelConfig(hidden=hidden, dropout=0.5, dropout_layers=layers)
        )
        net = models.init_pnet(spec, jax.random.key(0))
        outs = jnp.stack([net.net(x, jax.random.key(k), False) for k in range(64)])
        signal = float(outs.mean(0).var(0).mean())
        noise = float(outs.var(0).mean())
        h, scale = x, []
        for lin, act in zip(net.layers, net.acts):
            h = act(lin(h))
            scale.append(float(h.std()))
        print(
            f"{name}: input-driven variance {signal:.2e}, mask-driven {noise:.2e}, "
            f"signal/noise {signal / noise:.3f}; activation std first/last hidden "
            f"{scale[0]:.2f}/{scale[-1]:.3f}"
        )


if __name__ == "__main__":
    main()
