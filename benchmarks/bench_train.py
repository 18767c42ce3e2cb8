#!/usr/bin/env python
"""Benchmark PNet ensemble training: four members together (on one device, and
sharded over one CPU device per core) vs four sequential single-model trainings
vs the same MLP in PyTorch (CPU), same architecture, data and batch size.

    python benchmarks/bench_train.py                       # quick widths 256-256-128-64
    python benchmarks/bench_train.py --hidden 1280,1024,896,768,512,384,256,256,128,64,32
    python benchmarks/bench_train.py --data runs/x/data/point_0   # real D0..D3 (data.py)

Data: by default four synthetic datasets of straight-line paths in the point/0
workspace (rows ``(current, goal) -> next``) with ``--rows`` rows each, the
last one 60 % the size (D3 is the smallest in the paper). Every variant runs
``--epochs`` epochs with batch ``--batch``, Adagrad lr 0.01, dropout 0.5 after
the first ``--dropout-layers`` layers; no validation passes by default
(``--val-fraction 0``), as the PyTorch loop has none.
Throughput is member-steps per second (one member-step = one optimizer step
of one PNet on one minibatch). Two measurements:

* steady state, in this process: every JAX variant is compiled first (a
  warm-up call with the same shapes, timed apart), then the variants run
  interleaved ``--repeats`` times; medians and the median of the per-repeat
  ratios are printed (the machine is shared: side by side is what counts);
* end to end, in fresh processes (no compile cache): the wall time of the
  training calls including compilation, what a user waits for. The four
  sequential trainings compile once per distinct dataset shape, as four
  separate single-model runs would.

PyTorch runs only if ``import torch`` works (install it into the venv for the
benchmark only: ``pip install torch==2.13.0+cpu``); otherwise that column is
skipped with a message.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
import time
from pathlib import Path

import numpy as np


def jax_training(
    datasets, env, model_cfg, train_cfg, seed, ids, stop_after=None, shard=False
) -> float:
    """Wall seconds of one ``train_ensemble`` call on ``datasets`` (members ``ids``)."""
    from ntq_jax import training as T

    t = time.perf_counter()
    T.train_ensemble(
        datasets,
        env,
        model_cfg,
        train_cfg,
        seed=seed,
        member_ids=ids,
        progress=False,
        stop_after=stop_after,
        shard=shard,
    )
    return time.perf_counter() - t


def together(datasets, env, model_cfg, train_cfg, seed, **kw) -> float:
    """The four members in one ensemble (one vmapped, jitted step) on one device."""
    return jax_training(
        datasets, env, model_cfg, train_cfg, seed, list(range(len(datasets))), shard=False, **kw
    )


def together_sharded(datasets, env, model_cfg, train_cfg, seed, **kw) -> float:
    """The same, the member axis sharded over the CPU devices (one per core)."""
    return jax_training(
        datasets, env, model_cfg, train_cfg, seed, list(range(len(datasets))), shard=True, **kw
    )


def sequential(datasets, env, model_cfg, train_cfg, seed, **kw) -> float:
    """Four single-model trainings, one after the other (the same code with one member)."""
    return sum(
        jax_training([d], env, model_cfg, train_cfg, seed, [i], **kw)
        for i, d in enumerate(datasets)
    )


VARIANTS = {"together": together, "together_sharded": together_sharded, "sequential": sequential}


def bench_torch(members, spec, train_cfg, seed, threads):
    """Four sequential PyTorch trainings of the same MLP on the same rows (MPNet's loop)."""
    import torch
    from torch import nn

    torch.manual_seed(seed)
    if threads:
        torch.set_num_threads(threads)
    lo, hi = np.array(spec.lo, np.float32), np.array(spec.hi, np.float32)

    def norm(q):
        return 2.0 * (q - lo) / (hi - lo) - 1.0

    def make():
        layers, w = [], 2 * spec.dim
        for i, h in enumerate(spec.hidden):
            layers += [nn.Linear(w, h), nn.PReLU()]
            if i < spec.dropout_layers:
                layers.append(nn.Dropout(spec.dropout))
            w = h
        layers.append(nn.Linear(w, spec.dim))
        return nn.Sequential(*layers)

    total_s, steps = 0.0, 0
    for md in members:
        d = spec.dim
        x = torch.from_numpy(np.concatenate([norm(md.train_x[:, :d]), norm(md.train_x[:, d:])], 1))
        y = torch.from_numpy(norm(md.train_y))
        net = make()
        opt = torch.optim.Adagrad(net.parameters(), lr=train_cfg.learning_rate)
        n = len(x)
        t = time.perf_counter()
        for epoch in range(train_cfg.epochs):
            perm = torch.randperm(n)
            for b in range(0, n, train_cfg.batch_size):
                idx = perm[b : b + train_cfg.batch_size]
                opt.zero_grad(set_to_none=True)
                loss = ((net(x[idx]) - y[idx]) ** 2).mean()
                loss.backward()
                opt.step()
                steps += 1
        total_s += time.perf_counter() - t
    return {
        "member_steps": steps,
        "seconds": total_s,
        "threads": torch.get_num_threads(),
        "version": torch.__version__,
    }


def run_child(argv, variant: str) -> dict | None:
    """Runs ``variant`` in a fresh process (no compile cache); returns its JSON line."""
    import subprocess

    env = dict(os.environ)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    proc = subprocess.run(
        [sys.executable, __file__, *argv, "--child", variant],
        env=env,
        capture_output=True,
        text=True,
    )
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("CHILD ")]
    if proc.returncode != 0 or not line:
        print(f"child run {variant!r} failed:\n{proc.stderr[-2000:]}")
        return None
    return json.loads(line[0][6:])


def parse_args(argv):
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--hidden", default="256,256,128,64", help="hidden widths (comma-separated)")
    ap.add_argument("--dropout-layers", type=int, default=2)
    ap.add_argument("--rows", type=int, default=5000, help="rows of the largest dataset")
    ap.add_argument("--epochs", type=int, default=2)
    ap.add_argument("--batch", type=int, default=100)
    ap.add_argument("--steps-per-call", type=int, default=50)
    ap.add_argument(
        "--val-fraction",
        type=float,
        default=0.0,
        help="validation split (default 0: no validation passes, like the PyTorch loop)",
    )
    ap.add_argument(
        "--repeats",
        type=int,
        default=3,
        help="interleaved repeats of the steady-state timings (medians reported)",
    )
    ap.add_argument(
        "--data",
        type=Path,
        default=None,
        help="a real environment data folder instead of synthetic paths",
    )
    ap.add_argument("--torch-threads", type=int, default=0, help="0 = PyTorch's default")
    ap.add_argument("--no-torch", action="store_true")
    ap.add_argument(
        "--no-end-to-end",
        action="store_true",
        help="skip the fresh-process runs that include compilation",
    )
    ap.add_argument(
        "--cpu-devices",
        type=int,
        default=None,
        help="JAX CPU devices (as scripts/train.py; default min(cores, 4)) for the "
        "sharded variant; 1 = skip that variant",
    )
    ap.add_argument("--child", choices=sorted(VARIANTS), help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=None, help="also write the figures as JSON")
    return ap.parse_args(argv)


def configs(args):
    """The hidden widths, the model and the training configurations of ``args``."""
    from ntq_jax.models import ModelConfig
    from ntq_jax.training.config import TrainConfig

    hidden = tuple(int(h) for h in args.hidden.split(","))
    model_cfg = ModelConfig(hidden=hidden, dropout=0.5, dropout_layers=args.dropout_layers)
    train_cfg = TrainConfig(
        epochs=args.epochs,
        batch_size=args.batch,
        optimizer="adagrad",
        learning_rate=0.01,
        val_fraction=args.val_fraction,
        steps_per_call=args.steps_per_call,
        eval_every=10**9,
    )
    return hidden, model_cfg, train_cfg


def load_data(args):
    """The environment, the four datasets and a line saying where they come from."""
    from ntq_jax import data as data_mod
    from ntq_jax import make_env

    if args.data is not None:
        env = make_env(args.data / "env.json")
        datasets = data_mod.load_datasets(args.data)
        source = str(args.data)
    else:
        env = make_env("point/0")
        lo, hi = (np.asarray(a) for a in env.robot.config_bounds(env.world))
        sizes = [args.rows, args.rows, args.rows, int(0.6 * args.rows)]
        datasets = [
            data_mod.straight_line_rows(10 + i, lo, hi, step=1.0, n_rows=n)
            for i, n in enumerate(sizes)
        ]
        source = f"synthetic straight paths on point/0, rows {sizes}"
    return env, datasets, source


def torch_available(args) -> bool:
    """Whether the PyTorch column runs (says why not when PyTorch is missing)."""
    have_torch = not args.no_torch
    if have_torch:
        import importlib.util

        if importlib.util.find_spec("torch") is None:
            have_torch = False
            print(
                "PyTorch not installed: skipping the PyTorch comparison "
                "(pip install torch==2.13.0+cpu into the venv to include it)"
            )
    return have_torch


def steady_state(args, run, variants, members, spec, train_cfg, member_steps):
    """Compiles every variant first (timed apart), then runs them interleaved ``--repeats`` times.

    Returns the compile seconds, the per-repeat seconds of each variant (and
    ``"torch"``) and the PyTorch run's details (None without PyTorch).
    """
    compile_s = {v: run(v, stop_after=train_cfg.steps_per_call) for v in variants}
    have_torch = torch_available(args)
    times = {v: [] for v in variants}
    times["torch"] = []
    torch_info = None
    for r in range(args.repeats):
        for v in variants:
            times[v].append(run(v))
        if have_torch:
            torch_info = bench_torch(members, spec, train_cfg, args.seed + r, args.torch_threads)
            times["torch"].append(torch_info["seconds"])
        print(
            f"repeat {r + 1}/{args.repeats}: "
            + ", ".join(f"{v} {member_steps / t[-1]:.1f}/s" for v, t in times.items() if t),
            flush=True,
        )
    return compile_s, times, torch_info


def end_to_end(args, argv_child, variants) -> dict:
    """Wall seconds of each variant in a fresh process, compilation included."""
    e2e = {}
    if not args.no_end_to_end:
        for v in variants:
            r = run_child(argv_child, v)
            if r is not None:
                e2e[v] = r["seconds"]
    return e2e


def variant_names(mesh, torch_info) -> dict:
    """The table's label of each variant."""
    return {
        "together": "JAX, 4 members together (vmap, one jit, one device)",
        "together_sharded": "JAX, 4 members together, member axis sharded over "
        f"{mesh.devices.size if mesh else 0} CPU devices",
        "sequential": "JAX, 4 sequential single-model trainings",
        "torch": (
            f"PyTorch {torch_info['version']} CPU ({torch_info['threads']} threads), 4 sequential"
        )
        if torch_info
        else "",
    }


def print_table(args, names, times, compile_s, e2e, member_steps) -> None:
    """The table of member-steps/s, compile and end-to-end seconds per variant."""
    med = {v: float(np.median(t)) for v, t in times.items() if t}
    print(
        "\n| variant | member-steps/s (median of %d) | compile s | end to end s (fresh "
        "process, incl. compile) |" % args.repeats
    )
    print("|---|---:|---:|---:|")
    for v, t in med.items():
        c = compile_s.get(v)
        print(
            f"| {names[v]} | {member_steps / t:.1f} | {'-' if c is None else f'{c:.1f}'} | "
            f"{f'{e2e[v]:.1f}' if v in e2e else '-'} |"
        )


def print_ratios(names, times, e2e) -> None:
    """The speed-ups of the ensemble variants over sequential trainings and PyTorch."""
    pair = lambda a, b: float(np.median(np.array(times[b]) / np.array(times[a])))  # noqa: E731
    print()
    for v in ("together", "together_sharded"):
        if v not in times:
            continue
        print(
            f"{names[v]} vs sequential: {pair(v, 'sequential'):.2f}x steady state "
            f"(goal >= 2x)"
            + (
                f", {e2e['sequential'] / e2e[v]:.2f}x end to end incl. compilation"
                if v in e2e and "sequential" in e2e
                else ""
            )
        )
        if times["torch"]:
            print(f"  vs PyTorch: {pair(v, 'torch'):.2f}x the member-steps/s (goal >= 1x)")
    if times["torch"]:
        print(f"JAX single-model vs PyTorch: {pair('sequential', 'torch'):.2f}x")


def main(argv=None) -> int:
    args = parse_args(argv)
    argv_child = [a for a in (argv if argv is not None else sys.argv[1:])]

    import jax

    from ntq_jax import models
    from ntq_jax import training as T

    T.use_cpu_devices(args.cpu_devices)  # before any JAX operation
    hidden, model_cfg, train_cfg = configs(args)
    env, datasets, source = load_data(args)
    spec = models.ModelSpec.from_env(env, model_cfg)
    run = functools.partial(
        lambda f, **kw: VARIANTS[f](datasets, env, model_cfg, train_cfg, args.seed, **kw)
    )

    if args.child:  # a fresh process: the first call compiles, as a user's run would
        wall = run(args.child)
        print("CHILD " + json.dumps({"seconds": wall, "devices": len(jax.devices())}))
        return 0

    members = [
        T.prepare_member(d, train_cfg.val_fraction, args.seed, i) for i, d in enumerate(datasets)
    ]
    sched = T.Schedule(
        tuple(len(md.train_x) for md in members), train_cfg.batch_size, train_cfg.epochs
    )
    member_steps = sum(sched.member_steps)
    print(
        f"data: {source}\nPNet {hidden}, batch {args.batch}, {args.epochs} epochs, "
        f"Adagrad 0.01, {member_steps} member-steps per variant; JAX {jax.__version__} on "
        f"{len(jax.devices())} {jax.default_backend()} device(s), {os.cpu_count()} CPU cores",
        flush=True,
    )

    mesh = T.member_mesh(len(datasets))
    variants = [v for v in VARIANTS if v != "together_sharded" or mesh is not None]
    compile_s, times, torch_info = steady_state(
        args, run, variants, members, spec, train_cfg, member_steps
    )
    e2e = end_to_end(args, argv_child, variants)
    names = variant_names(mesh, torch_info)
    print_table(args, names, times, compile_s, e2e, member_steps)
    out = {
        "hidden": hidden,
        "batch": args.batch,
        "epochs": args.epochs,
        "source": source,
        "member_steps": member_steps,
        "seconds": times,
        "compile_s": compile_s,
        "end_to_end_s": e2e,
    }
    print_ratios(names, times, e2e)
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
