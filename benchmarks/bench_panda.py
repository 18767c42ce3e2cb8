#!/usr/bin/env python
"""The Panda in MotionBenchMaker's 7 scenes (problem 1 of each): correctness and speed.

``check``: validity against coal on ``--configs`` configurations and the certified
motion check against a dense discretised check on ``--motions`` motions per scene (the
protocols: ``benchmarks/panda_reference.py``). One JSON per scene in ``--out``
(``results/panda_checks/check_<scene>.json``), skipped when it exists with the same
sizes and seeds (resumable; ``--force`` redoes it), and ``check_summary.json`` over all
of them. Exit code 1 when any count that must be 0 is not.

``speed``: per scene, medians of ``--reps`` repeats of

* ``Env.is_valid`` on ``--states`` uniform configurations (a device array);
* ``Env.steer_to(check="certified")`` and the discretised ``Env.steer_to`` on
  ``--speed-motions`` motions of each kind ``pair`` (two uniform valid states) and
  ``short`` (a valid state to a valid one ``U(0.02, 0.5)`` rad away); the discretised
  check's checked states are those it must look at (all ``n + 1`` of a free motion, up
  to the first invalid state in its coarse-to-fine order for a blocked one), also timed
  on the free motions alone;

with wall seconds, CPU seconds (``time.process_time``: the figure to trust on a shared
machine) and the ratios against VAMP's stated figures (quoted, not measured: VAMP
cannot be built here), and the certified program's compile CPU seconds. Written to
``--out``/``speed_<scene>.json`` (resumable as above) and ``speed_summary.json``.

``vamp``: per scene, VAMP's own C++ checks beside the package's on the same inputs:
the discretised motion check at 1/32 rad (VAMP's ``validate_motion<Panda, rake, 32>``,
the check its planners run; its Python ``validate_motion`` checks at resolution 1, one
rake of states per radian, so it is not used) on the ``pair`` and ``short`` motions of
``speed``, and validity of ``--states`` uniform states (VAMP's ``fkcc`` on blocks of
``rake`` states, against ``Env.is_valid``); VAMP's side runs in
``benchmarks/vamp_harness.cpp`` (built here with ``g++ -O3 -march=native`` from the
folders given by ``--vamp-include``: the vamp-planner sdist's ``src/impl``, Eigen 3.4's
``include/eigen3`` and pdqsort), with no Python in its timed loops; the package's in
this process; medians of ``--reps`` passes (VAMP: wall seconds of its single-threaded
loops; ours: CPU seconds), the answers' agreement (the two checks test different
states along a motion, so near-contact motions may differ) and how many of each
side's free motions the certified check proves. -> ``--out``/``vamp_<scene>.json``,
``vamp_summary.json``.

    taskset -c 0 python benchmarks/bench_panda.py check
    taskset -c 0 python benchmarks/bench_panda.py speed --reps 5
    taskset -c 0 python benchmarks/bench_panda.py speed --scene cage --force
    taskset -c 0 python benchmarks/bench_panda.py vamp --reps 5 --states 65536 \
        --vamp-include <sdist>/src/impl --vamp-include <eigen3> --vamp-include <pdqsort>
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
import panda_reference as ref
from common import interleaved, load_json, loadavg, machine

ROOT = Path(__file__).resolve().parent.parent
SCENES = (
    "bookshelf_small",
    "bookshelf_tall",
    "bookshelf_thin",
    "box",
    "cage",
    "table_pick",
    "table_under_pick",
)
#: VAMP's stated figures (Thomason, Kingston, Kavraki, "Motions in Microseconds via
#: Vectorized Sampling-Based Planning", ICRA 2024, as quoted in issue 48): 44-59 ns per
#: checked Panda state on one core of this kind of machine, ~2e7 states per second.
VAMP_NS_PER_STATE = (44.0, 59.0)
GOALS = {"is_valid_per_s_2_cores": 1e6, "certified_motions_per_s": 1e4}


def _write(path: Path, data: dict) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    os.replace(tmp, path)


def _fresh(path: Path, key: dict, force: bool) -> dict | None:
    old = load_json(path)
    return old if (old and old.get("key") == key and not force) else None


# ---------------------------------------------------------------------------
# check
# ---------------------------------------------------------------------------


def check_scene(scene: str, args) -> dict:
    import ntq_jax as nj

    env = nj.make_env(f"panda/{scene}/1")
    c0, t0 = time.process_time(), time.perf_counter()
    q = ref.sample_configs(env, args.seed, args.configs)
    validity = ref.compare_validity(env, q)
    c1, t1 = time.process_time(), time.perf_counter()
    a, b, kind = ref.sample_motions(env, args.seed + 1, args.motions)
    certified = ref.compare_certified(env, a, b, kind)
    c2, t2 = time.process_time(), time.perf_counter()
    return {
        "validity": validity,
        "certified": certified,
        "padding": env.padding,
        "obstacles": {
            k: int(getattr(env.world, k).shape[0]) for k in ("spheres", "cuboids", "capsules")
        },
        "seconds": {
            "validity_wall": round(t1 - t0, 1),
            "validity_cpu": round(c1 - c0, 1),
            "certified_wall": round(t2 - t1, 1),
            "certified_cpu": round(c2 - c1, 1),
        },
    }


def must_be_zero(rec: dict) -> dict:
    """The counts that must be 0: disagreements outside the band, certified false frees."""
    v, c = rec["validity"], rec["certified"]["all"]
    return {
        "validity_disagree": v["valid"]["disagree"],
        "obstacle_disagree": v["obstacle_free"]["disagree"],
        "self_disagree": v["self_free"]["disagree"],
        "certified_false_free": c["certified_false_free"],
    }


def run_check(args) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    key = {
        "configs": args.configs,
        "motions": args.motions,
        "seed": args.seed,
        "band": ref.BAND,
        "near": ref.NEAR,
        "dense_step": ref.DENSE_STEP,
    }
    rows = {}
    for scene in args.scene or SCENES:
        path = out / f"check_{scene}.json"
        rec = _fresh(path, key, args.force)
        if rec is None:
            print(
                f"{scene}: checking {args.configs} configurations, {args.motions} motions",
                flush=True,
            )
            rec = {
                "key": key,
                "scene": scene,
                "problem": 1,
                **check_scene(scene, args),
                "machine": machine(),
                "loadavg": loadavg(),
            }
            _write(path, rec)
        rows[scene] = rec
        v, c = rec["validity"], rec["certified"]["all"]
        print(
            f"{scene:17s} valid {v['valid']['reference_true']:6d}/{v['configs']} "
            f"disagree {must_be_zero(rec)} in-band {v['valid']['in_band']} | certified free "
            f"{c['certified_free']}/{c['motions']} dense free {c['dense_free']} "
            f"conservative {c['certified_blocked_dense_free']} | discretized false free "
            f"{c['discretized_false_free']}",
            flush=True,
        )
    if not args.scene:
        total = {
            k: sum(must_be_zero(r)[k] for r in rows.values())
            for k in must_be_zero(next(iter(rows.values())))
        }
        _write(
            out / "check_summary.json",
            {
                "key": key,
                "scenes": list(rows),
                "must_be_zero": total,
                "per_scene": {
                    s: {
                        **must_be_zero(r),
                        "configs": r["validity"]["configs"],
                        "motions": r["certified"]["motions"],
                        "in_band": r["validity"]["valid"]["in_band"],
                        "certified_free": r["certified"]["all"]["certified_free"],
                        "dense_free": r["certified"]["all"]["dense_free"],
                        "discretized_false_free": r["certified"]["all"]["discretized_false_free"],
                    }
                    for s, r in rows.items()
                },
            },
        )
        print("must be zero:", total)
        return int(any(total.values()))
    return int(any(any(must_be_zero(r).values()) for r in rows.values()))


# ---------------------------------------------------------------------------
# speed
# ---------------------------------------------------------------------------


def speed_motions(env, seed: int, n: int) -> dict:
    """``{"pair": (a, b), "short": (a, b)}``, ``n`` motions each (see the module docstring)."""
    rng = np.random.default_rng(seed)
    p = ref._valid_uniform(env, rng, 2 * n)
    a0 = ref._valid_uniform(env, rng, n)
    return {"pair": (p[:n], p[n:]), "short": (a0, ref._valid_steps(env, rng, a0, 0.02, 0.5))}


def checked_states(env, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per motion: the states the discretised check must look at, and whether it is free."""
    import jax.numpy as jnp

    from ntq_jax.robots.base import _check_index

    res = env.robot.resolution
    n = np.maximum(np.ceil(np.linalg.norm(b - a, axis=1) / np.float32(res)), 1).astype(np.int64)
    owner = np.repeat(np.arange(len(a)), n + 1)
    c = np.arange(owner.size) - np.repeat(np.cumsum(n + 1) - (n + 1), n + 1)
    k = np.asarray(_check_index(jnp.asarray(c, jnp.int32), jnp.asarray(n[owner], jnp.int32)))
    t = (k.astype(np.float32) / n[owner].astype(np.float32))[:, None]
    ok = ref._valid(env, a[owner] + t * (b[owner] - a[owner]))
    first_bad = np.full(len(a), -1)
    bad = np.flatnonzero(~ok)[::-1]  # the last write per motion is its first bad position
    first_bad[owner[bad]] = c[bad]
    free = first_bad < 0
    return np.where(free, n + 1, first_bad + 1), free


def _rate(n: float, wall: float, cpu: float) -> dict:
    return {"per_s_wall": n / wall, "per_cpu_s": n / cpu, "cores": cpu / wall}


def time_scene(scene: str, args) -> dict:
    import jax.numpy as jnp

    import ntq_jax as nj

    env = nj.make_env(f"panda/{scene}/1")
    rng = np.random.default_rng(args.seed)
    q = jnp.asarray(ref._uniform(env, rng, args.states))
    cases = {"is_valid": lambda: env.is_valid(q)}
    motions = speed_motions(env, args.seed + 1, args.speed_motions)
    work = {"is_valid": args.states}
    for kind, (a, b) in motions.items():
        states, free = checked_states(env, a, b)
        ja, jb = jnp.asarray(a), jnp.asarray(b)
        fa, fb = jnp.asarray(a[free]), jnp.asarray(b[free])
        cases[f"certified_{kind}"] = lambda ja=ja, jb=jb: env.steer_to(ja, jb, check="certified")
        cases[f"discretized_{kind}"] = lambda ja=ja, jb=jb: env.steer_to(ja, jb)
        cases[f"discretized_{kind}_free"] = lambda fa=fa, fb=fb: env.steer_to(fa, fb)
        work.update(
            {
                f"certified_{kind}": len(a),
                f"discretized_{kind}": len(a),
                f"discretized_{kind}_free": int(free.sum()),
                f"states_{kind}": int(states.sum()),
                f"states_{kind}_free": int(states[free].sum()),
            }
        )
    med = interleaved(cases, args.reps)
    cores = interleaved.cores
    out = {"work": work, "seconds": med, "cores": cores, "rates": {}}
    for name, sec in med.items():
        out["rates"][name] = _rate(work[name], sec, sec * cores[name])
        if name.startswith("discretized"):
            skey = "states" + name[len("discretized") :]
            out["rates"][name + "_states"] = _rate(work[skey], sec, sec * cores[name])
    out["certified_compile_cpu_s"] = compile_cpu(env)
    return out


def compile_cpu(env) -> float:
    """CPU seconds to trace, lower and compile the certified program of one chunk."""
    import jax
    import jax.numpy as jnp

    from ntq_jax.geometry import KERNEL_COMPILER_OPTIONS
    from ntq_jax.robots.batch import CERTIFIED_CHUNK, steer_to_cm

    robot, pad = env.robot, env.padding
    fn = jax.jit(
        lambda w, x, y: steer_to_cm(robot, w, x, y, pad, check="certified"),
        compiler_options=KERNEL_COMPILER_OPTIONS,
    )
    x = jnp.zeros((robot.dim, CERTIFIED_CHUNK), jnp.float32)
    c0 = time.process_time()
    fn.trace(env.world, x, x).lower().compile()
    return round(time.process_time() - c0, 2)


def _speed_line(scene: str, r: dict) -> str:
    rt = r["rates"]
    ns = 1e9 / rt["discretized_pair_free_states"]["per_cpu_s"]
    vamp = " / ".join(f"{ns / v:.1f}x" for v in VAMP_NS_PER_STATE)
    return (
        f"{scene:17s} is_valid {rt['is_valid']['per_cpu_s']:.3g}/cpu-s "
        f"({rt['is_valid']['per_s_wall']:.3g}/s wall) | certified pair "
        f"{rt['certified_pair']['per_cpu_s']:.3g} short {rt['certified_short']['per_cpu_s']:.3g}"
        f" motions/cpu-s | discretized pair {rt['discretized_pair']['per_cpu_s']:.3g} "
        f"motions/cpu-s, free states {rt['discretized_pair_free_states']['per_cpu_s']:.3g}"
        f"/cpu-s = {ns:.0f} ns/state ({vamp} VAMP's 44/59 ns) | certified compile "
        f"{r['certified_compile_cpu_s']} cpu-s"
    )


def _scenes(args, stem: str, key: dict, measure, line, extra: dict | None = None) -> dict:
    """Per scene (``--scene``, default all): ``<out>/<stem>_<scene>.json`` holding
    ``measure(scene, args)``, the machine and its load (kept, not measured again, when it
    holds the same ``key``: resumable), printed with ``line``; the records by scene."""
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = {}
    for scene in args.scene or SCENES:
        path = out / f"{stem}_{scene}.json"
        rec = _fresh(path, key, args.force)
        if rec is None:
            rec = {
                "key": key,
                "scene": scene,
                **measure(scene, args),
                "machine": machine(),
                "loadavg": loadavg(),
                **(extra or {}),
            }
            _write(path, rec)
        rows[scene] = rec
        print(line(scene, rec), flush=True)
    return rows


def _key(args, **more) -> dict:
    """What a per-scene record of ``speed`` / ``vamp`` was measured with (see :func:`_fresh`)."""
    return {
        "states": args.states,
        "speed_motions": args.speed_motions,
        "reps": args.reps,
        "seed": args.seed,
        **more,
    }


def run_speed(args) -> int:
    out = Path(args.out)
    key = _key(args)
    extra = {"vamp_ns_per_state_quoted": VAMP_NS_PER_STATE, "goals": GOALS}
    rows = _scenes(args, "speed", key, time_scene, _speed_line, extra)
    if not args.scene:
        _write(
            out / "speed_summary.json",
            {
                "key": key,
                "goals": GOALS,
                "vamp_ns_per_state_quoted": VAMP_NS_PER_STATE,
                "per_cpu_s": {
                    s: {k: round(v["per_cpu_s"]) for k, v in r["rates"].items()}
                    for s, r in rows.items()
                },
                "certified_compile_cpu_s": {
                    s: r["certified_compile_cpu_s"] for s, r in rows.items()
                },
            },
        )
    return 0


def _cpu_median(fn, reps: int) -> float:
    """Median process-CPU seconds of ``fn()`` over ``reps`` runs (after one warm-up)."""
    import jax

    jax.block_until_ready(fn())
    out = []
    for _ in range(reps):
        c0 = time.process_time()
        jax.block_until_ready(fn())
        out.append(time.process_time() - c0)
    return float(np.median(out))


HARNESS = Path(__file__).with_name("vamp_harness.cpp")


def build_harness(args) -> Path:
    """``benchmarks/vamp_harness.cpp`` compiled against VAMP's headers (``--vamp-include``:
    the vamp-planner sdist's ``src/impl``, Eigen 3.4's ``include/eigen3``, pdqsort), once
    per source change and flags, into the system's temporary folder."""
    import hashlib
    import subprocess
    import tempfile

    if not args.vamp_include:
        raise SystemExit(
            "error: the vamp command needs VAMP's C++ headers: --vamp-include <sdist>/src/impl "
            "--vamp-include <eigen3> --vamp-include <pdqsort> (see the module docstring)"
        )
    flags = ["-O3", "-march=native", "-std=c++17", "-DNDEBUG"]
    flags += [f"-I{d}" for d in args.vamp_include]
    tag = hashlib.sha256((HARNESS.read_text() + " ".join(flags)).encode()).hexdigest()[:12]
    exe = Path(tempfile.gettempdir()) / f"ntq_jax_vamp_harness_{tag}"
    if not exe.exists():
        cmd = ["g++", *flags, str(HARNESS), "-o", str(exe)]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode:
            raise SystemExit(f"error: building the harness failed: {done.stderr.strip()[-400:]}")
    return exe


def _vamp_input(env, a: np.ndarray, b: np.ndarray, q: np.ndarray) -> bytes:
    """The harness's input: the world in VAMP's shapes, the motions and the states."""
    from ntq_jax.planners import vamp_bridge

    w = env.world
    spheres = np.asarray(w.spheres, np.float32).reshape(-1, 4)
    cuboids = np.array(
        [
            [*c[:3], *vamp_bridge.cuboid_euler_xyz(c[6:15]), *c[3:6]]
            for c in np.asarray(w.cuboids, np.float64)
        ],
        np.float32,
    ).reshape(-1, 9)
    caps = []
    for c in np.asarray(w.capsules, np.float64):
        centre, euler, length = vamp_bridge.capsule_center_form(c[:3], c[3:6])
        caps.append([*centre, *euler, c[6], length])
    capsules = np.array(caps, np.float32).reshape(-1, 8)
    head = np.array([len(spheres), len(cuboids), len(capsules), len(a), len(q)], np.int32)
    parts = [head, spheres, cuboids, capsules, a, b, q]
    return b"".join(
        np.ascontiguousarray(x).astype(x.dtype.newbyteorder("<")).tobytes() for x in parts
    )


def _run_harness(exe: Path, data: bytes, n_motions: int, n_states: int, reps: int):
    """``(free (M,), valid (N,), seconds per pass over the motions, over the states)``."""
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "in.bin", Path(tmp) / "out.bin"
        src.write_bytes(data)
        done = subprocess.run([str(exe), str(src), str(dst), str(reps)], capture_output=True)
        if done.returncode:
            raise SystemExit(f"error: the harness failed: {done.stderr.decode().strip()}")
        raw = dst.read_bytes()
    free = np.frombuffer(raw[:n_motions], np.uint8).astype(bool)
    valid = np.frombuffer(raw[n_motions : n_motions + n_states], np.uint8).astype(bool)
    t_motion, t_state = np.frombuffer(raw[n_motions + n_states :], "<f8")
    return free, valid, float(t_motion), float(t_state)


def vamp_scene(scene: str, args) -> dict:
    """VAMP beside the package on one scene's motions and states (see the docstring)."""
    import jax.numpy as jnp

    import ntq_jax as nj

    exe = build_harness(args)
    env = nj.make_env(f"panda/{scene}/1")
    rng = np.random.default_rng(args.seed)
    q = np.ascontiguousarray(ref._uniform(env, rng, args.states), np.float32)
    jq = jnp.asarray(q)
    out = {"motions": {}}
    t_ours_states = _cpu_median(lambda: env.is_valid(jq), args.reps)
    valid_ours = np.asarray(env.is_valid(jq))
    for kind, (a, b) in speed_motions(env, args.seed + 1, args.speed_motions).items():
        a, b = np.ascontiguousarray(a, np.float32), np.ascontiguousarray(b, np.float32)
        ja, jb = jnp.asarray(a), jnp.asarray(b)
        free, valid, t_vamp, t_vamp_states = _run_harness(
            exe, _vamp_input(env, a, b, q), len(a), len(q), args.reps
        )
        ours = np.asarray(env.steer_to(ja, jb))
        cert = np.asarray(env.steer_to(ja, jb, check="certified"))
        t_ours = _cpu_median(lambda ja=ja, jb=jb: env.steer_to(ja, jb), args.reps)
        out["motions"][kind] = {
            "n": len(a),
            "vamp_free": int(free.sum()),
            "ours_free": int(ours.sum()),
            "agree": int((free == ours).sum()),
            "vamp_free_certified": int((free & cert).sum()),
            "ours_free_certified": int((ours & cert).sum()),
            "vamp_us_per_motion": round(t_vamp / len(a) * 1e6, 3),
            "ours_us_per_motion": round(t_ours / len(a) * 1e6, 3),
            "ours_over_vamp": round(t_ours / t_vamp, 2),
        }
    out["is_valid"] = {
        "n": len(q),
        "agree": int((valid == valid_ours).sum()),
        "vamp_ns_per_state": round(t_vamp_states / len(q) * 1e9, 2),
        "ours_ns_per_state": round(t_ours_states / len(q) * 1e9, 2),
        "ours_over_vamp": round(t_ours_states / t_vamp_states, 2),
    }
    return out


def _vamp_line(scene: str, r: dict) -> str:
    m, v = r["motions"], r["is_valid"]
    parts = [
        f"{k} {x['ours_us_per_motion']:.1f} vs {x['vamp_us_per_motion']:.1f} us/motion "
        f"({x['ours_over_vamp']:.1f}x), agree {x['agree']}/{x['n']}, VAMP-free certified "
        f"{x['vamp_free_certified']}/{x['vamp_free']}"
        for k, x in m.items()
    ]
    return (
        f"{scene:17s} " + " | ".join(parts) + f" | is_valid {v['ours_ns_per_state']:.0f} vs "
        f"{v['vamp_ns_per_state']:.1f} ns/state ({v['ours_over_vamp']:.0f}x), agree "
        f"{v['agree']}/{v['n']}"
    )


def run_vamp(args) -> int:
    out = Path(args.out)
    key = _key(args, harness=HARNESS.name)
    rows = _scenes(args, "vamp", key, vamp_scene, _vamp_line)
    if not args.scene:
        ratios = {
            k: [rows[s]["motions"][k]["ours_over_vamp"] for s in rows] for k in ("pair", "short")
        }
        ratios["is_valid"] = [rows[s]["is_valid"]["ours_over_vamp"] for s in rows]
        _write(
            out / "vamp_summary.json",
            {
                "key": key,
                "ours_over_vamp_median": {k: float(np.median(v)) for k, v in ratios.items()},
                "per_scene": {s: r["motions"] for s, r in rows.items()},
            },
        )
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("command", choices=("check", "speed", "vamp"))
    p.add_argument("--scene", action="append", choices=SCENES, help="repeatable; default all")
    p.add_argument("--configs", type=int, default=100_000)
    p.add_argument("--motions", type=int, default=10_000)
    p.add_argument("--states", type=int, default=1 << 20)
    p.add_argument("--speed-motions", type=int, default=4096)
    p.add_argument("--reps", type=int, default=5)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=str(ROOT / "results" / "panda_checks"))
    p.add_argument("--force", action="store_true")
    p.add_argument(
        "--vamp-include",
        action="append",
        default=[],
        help="vamp: a C++ include folder of VAMP's harness (repeatable; see the docstring)",
    )
    args = p.parse_args(argv)
    return {"check": run_check, "speed": run_speed, "vamp": run_vamp}[args.command](args)


if __name__ == "__main__":
    raise SystemExit(main())
