#!/usr/bin/env python
"""Benchmark PNet ensemble training: four members together vs four sequential
trainings vs the same MLP in PyTorch (CPU), same architecture, data and batch size.

    python scripts/bench_train.py                       # quick widths 256-256-128-64
    python scripts/bench_train.py --hidden 1280,1024,896,768,512,384,256,256,128,64,32
    python scripts/bench_train.py --data runs/x/data/point_0   # real D0..D3 (data.py)

Data: by default four synthetic datasets of straight-line paths in the point/0
workspace (rows ``(current, goal) -> next``) with ``--rows`` rows each, the
last one 60 % the size (D3 is the smallest in the paper). Every variant runs
``--epochs`` epochs with batch ``--batch``, Adagrad lr 0.01, dropout 0.5 after
the first ``--dropout-layers`` layers. Compilation is excluded from the JAX
timings (a warm-up call with the same shapes) and reported separately.
Throughput is member-steps per second (one member-step = one optimizer step
of one PNet on one minibatch).

PyTorch runs only if ``import torch`` works (install it into the venv for the
benchmark only: ``pip install torch==2.13.0+cpu``); otherwise that column is
skipped with a message.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np


def straight_paths(n_rows: int, seed: int, lo, hi, step: float = 1.0):
    """About ``n_rows`` rows of straight paths between uniform random points."""
    rng = np.random.default_rng(seed)
    xs, ys, pis, p = [], [], [], 0
    while len(xs) < n_rows:
        a, b = rng.uniform(lo, hi), rng.uniform(lo, hi)
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        pts = a + (b - a) * (np.arange(n + 1) / n)[:, None]
        for k in range(n):
            xs.append(np.concatenate([pts[k], b]))
            ys.append(pts[k + 1])
            pis.append(p)
        p += 1
    return (np.array(xs[:n_rows], np.float32), np.array(ys[:n_rows], np.float32),
            np.array(pis[:n_rows], np.int32))


def bench_jax(datasets, env, model_cfg, train_cfg, seed, together_only=False):
    from ntq_jax import train as T

    def run(ds, ids):
        t = time.perf_counter()  # warm-up with the same shapes: compiles, runs one chunk
        T.train_ensemble(ds, env, model_cfg, train_cfg, seed=seed, member_ids=ids,
                         progress=False, stop_after=train_cfg.steps_per_call)
        compile_s = time.perf_counter() - t
        t = time.perf_counter()
        ens, hist = T.train_ensemble(ds, env, model_cfg, train_cfg, seed=seed, member_ids=ids,
                                     progress=False)
        return time.perf_counter() - t, compile_s, hist

    members = [T.prepare_member(d, train_cfg.val_fraction, seed, i) for i, d in enumerate(datasets)]
    sched = T.Schedule(tuple(len(md.train_x) for md in members), train_cfg.batch_size,
                       train_cfg.epochs)
    member_steps = sum(sched.member_steps)
    together, together_compile, hist = run(datasets, list(range(len(datasets))))
    if together_only:
        return {"member_steps": member_steps, "together_s": together,
                "together_compile_s": together_compile}
    seq, seq_compile = 0.0, 0.0
    for i, d in enumerate(datasets):
        s, c, _ = run([d], [i])
        seq += s
        seq_compile += c
    return {"member_steps": member_steps, "together_s": together, "together_compile_s":
            together_compile, "sequential_s": seq, "sequential_compile_s": seq_compile,
            "final_train_loss": [float(v) for v in hist.train_loss[-1]],
            "members": members, "schedule": sched}


def bench_torch(members, spec, train_cfg, seed, threads):
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
    for m, md in enumerate(members):
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
                idx = perm[b:b + train_cfg.batch_size]
                opt.zero_grad(set_to_none=True)
                loss = ((net(x[idx]) - y[idx]) ** 2).mean()
                loss.backward()
                opt.step()
                steps += 1
        total_s += time.perf_counter() - t
    return {"member_steps": steps, "sequential_s": total_s, "threads": torch.get_num_threads(),
            "version": torch.__version__}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hidden", default="256,256,128,64", help="hidden widths (comma-separated)")
    ap.add_argument("--dropout-layers", type=int, default=2)
    ap.add_argument("--rows", type=int, default=5000, help="rows of the largest dataset")
    ap.add_argument("--epochs", type=int, default=2)
    ap.add_argument("--batch", type=int, default=100)
    ap.add_argument("--steps-per-call", type=int, default=50)
    ap.add_argument("--data", type=Path, default=None,
                    help="a real environment data folder instead of synthetic paths")
    ap.add_argument("--torch-threads", type=int, default=0, help="0 = PyTorch's default")
    ap.add_argument("--no-torch", action="store_true")
    ap.add_argument("--sharded-devices", type=int, default=4,
                    help="also time the ensemble with the member axis sharded over this many "
                         "forced host CPU devices (a child process); 0 = skip")
    ap.add_argument("--child-together", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, default=None, help="also write the figures as JSON")
    args = ap.parse_args(argv)

    import jax

    from ntq_jax import make_env, models
    from ntq_jax.config import ModelConfig, TrainConfig

    hidden = tuple(int(h) for h in args.hidden.split(","))
    model_cfg = ModelConfig(hidden=hidden, dropout=0.5, dropout_layers=args.dropout_layers)
    train_cfg = TrainConfig(epochs=args.epochs, batch_size=args.batch, optimizer="adagrad",
                            learning_rate=0.01, val_fraction=0.1,
                            steps_per_call=args.steps_per_call, eval_every=10**9)
    if args.data is not None:
        from ntq_jax import data as data_mod
        env = make_env(args.data / "env.json")
        datasets = data_mod.load_datasets(args.data)
        source = str(args.data)
    else:
        env = make_env("point/0")
        lo, hi = (np.asarray(a) for a in env.robot.config_bounds(env.world))
        sizes = [args.rows, args.rows, args.rows, int(0.6 * args.rows)]
        datasets = [straight_paths(n, 10 + i, lo, hi) for i, n in enumerate(sizes)]
        source = f"synthetic straight paths on point/0, rows {sizes}"
    spec = models.ModelSpec.from_env(env, model_cfg)

    if args.child_together:  # run by the parent with XLA_FLAGS forcing host devices
        r = bench_jax(datasets, env, model_cfg, train_cfg, args.seed, together_only=True)
        print("CHILD " + json.dumps(r))
        return 0
    print(f"data: {source}\nPNet {hidden}, batch {args.batch}, {args.epochs} epochs, "
          f"Adagrad 0.01; JAX {jax.__version__} on {len(jax.devices())} "
          f"{jax.default_backend()} device(s), {os.cpu_count()} CPU cores", flush=True)
    res = bench_jax(datasets, env, model_cfg, train_cfg, args.seed)
    rows = [("JAX, 4 members together (vmap, 1 jit)", res["member_steps"], res["together_s"],
             res["together_compile_s"]),
            ("JAX, 4 sequential single-model trainings", res["member_steps"], res["sequential_s"],
             res["sequential_compile_s"])]
    if args.sharded_devices:
        import subprocess
        child_env = dict(os.environ, XLA_FLAGS=(os.environ.get("XLA_FLAGS", "") + " "
                         f"--xla_force_host_platform_device_count={args.sharded_devices}"))
        argv_child = [a for a in (argv if argv is not None else sys.argv[1:])
                      if a != "--child-together"]
        proc = subprocess.run([sys.executable, __file__, *argv_child, "--child-together"],
                              env=child_env, capture_output=True, text=True)
        line = [ln for ln in proc.stdout.splitlines() if ln.startswith("CHILD ")]
        if proc.returncode != 0 or not line:
            print(f"sharded run failed:\n{proc.stderr[-2000:]}")
        else:
            r = json.loads(line[0][6:])
            rows.insert(1, (f"JAX, 4 members together, member axis sharded over "
                            f"{args.sharded_devices} host CPU devices", r["member_steps"],
                            r["together_s"], r["together_compile_s"]))
    torch_res = None
    if not args.no_torch:
        try:
            import torch  # noqa: F401
        except ImportError:
            print("PyTorch not installed: skipping the PyTorch comparison "
                  "(pip install torch==2.13.0+cpu into the venv to include it)")
        else:
            torch_res = bench_torch(res["members"], spec, train_cfg, args.seed, args.torch_threads)
            rows.append((f"PyTorch {torch_res['version']} CPU ({torch_res['threads']} threads), "
                         "4 sequential", torch_res["member_steps"], torch_res["sequential_s"],
                         None))
    print("\n| variant | member-steps | seconds | member-steps/s | compile s |")
    print("|---|---:|---:|---:|---:|")
    for name, steps, s, c in rows:
        print(f"| {name} | {steps} | {s:.2f} | {steps / s:.0f} | "
              f"{'-' if c is None else f'{c:.1f}'} |")
    speed = res["sequential_s"] / res["together_s"]
    print(f"\ntogether vs sequential: {speed:.2f}x faster (goal >= 2x)")
    if torch_res is not None:
        ratio = (res["member_steps"] / res["together_s"]) / (torch_res["member_steps"]
                                                              / torch_res["sequential_s"])
        ratio_seq = (res["member_steps"] / res["sequential_s"]) / (
            torch_res["member_steps"] / torch_res["sequential_s"])
        print(f"JAX together vs PyTorch: {ratio:.2f}x the member-steps/s (goal >= 1x); "
              f"JAX single-model vs PyTorch: {ratio_seq:.2f}x")
    if args.json:
        out = {"hidden": hidden, "batch": args.batch, "epochs": args.epochs, "source": source,
               "rows": [{"variant": n, "member_steps": st, "seconds": s, "compile_s": c}
                        for n, st, s, c in rows]}
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
