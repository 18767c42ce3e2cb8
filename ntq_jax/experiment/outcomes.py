"""Per-query outcomes of a run, small enough to commit, and the counts recomputed from them.

A summary (:mod:`ntq_jax.experiment.summaries`) keeps a map's counts (successes,
McNemar's discordant pairs, cost ratios); the per-query arrays they come from live
in the run folder's paths files, which are not committed. ``outcomes.npz``, written
beside ``summary.json``, keeps those arrays compactly so that a reader can recompute
every count, and any comparison the summary does not hold (e.g. PNet_4 - PNet_2, or
one model across training seeds on the same queries)::

    format                  "ntq-outcomes-1"
    env, train_seed         the map and the training seed
    kinds                   the query kinds ("uniform", "nontrivial")
    models__<kind>__<steer>     (M,) the models planned on that kind with/without steerTo
    success__<kind>__<steer>    (M, ceil(K/8)) uint8: success bits (np.packbits, axis 1)
    cost__<kind>__<steer>       (M, K) float32: path cost (inf/NaN where no path)
    cause__<kind>__<steer>      (M, K) uint8: the outcome (ntq_jax.types.PlanCause; 0 success)
    ref_cost__<kind>            (K,) float32: the reference planner's cost
    ref_status__<kind>          (K,) int8: the reference planner's status (0 solved)
    in_band__<kind>             (ceil(K/8),) uint8: both ends valid at the data padding
    queries_sha256__<kind>      the test queries' digest (equal over a map's seeds)
    k__<kind>                   K

``<steer>`` is ``steer`` or ``nosteer``. About 30-60 kB per map.

Command line (the one-liner of ``docs/guide/reproducing-the-paper.md``)::

    python -m ntq_jax.experiment.outcomes results/paper results/factors

recomputes from each ``outcomes.npz`` every count its ``summary.json`` holds (each
row's successes, success ratio, cost ratio, failures by cause and in/out of band;
each comparison's discordant pairs, difference and McNemar p) and lists the
summaries made before outcomes were stored; exit 1 on a mismatch.
``--pack RUN --env NAME --out DIR`` writes ``DIR/outcomes.npz`` from a run folder
that still exists (a summary written before this file was).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from ntq_jax import artifacts

__all__ = ["FILE", "FORMAT", "pack", "write", "load", "recount", "main"]

FILE = "outcomes.npz"
FORMAT = "ntq-outcomes-1"
KINDS = ("uniform", "nontrivial")


def _steer(steer: bool) -> str:
    return "steer" if steer else "nosteer"


def pack(run, env_name: str, env=None, train_seed=None) -> dict[str, np.ndarray]:
    """The outcome arrays of ``env_name`` in the finished run folder ``run``.

    ``env``: its :class:`ntq_jax.Env`, for the in-band mask (None: no ``in_band__*``).
    Raises FileNotFoundError / KeyError when the run lacks its results or paths files.
    """
    run = Path(run)
    res = json.loads((run / "results.json").read_text())
    rows = [r for r in res["rows"] if r["env"] == env_name]
    if not rows:
        raise KeyError(f"{run}: no result rows of {env_name}")
    slug = rows[0]["env_slug"]
    out: dict[str, np.ndarray] = {
        "format": np.array(FORMAT),
        "env": np.array(env_name),
        "train_seed": np.array(-1 if train_seed is None else train_seed),
    }
    qs = np.load(run / "eval" / slug / "queries.npz")
    kinds = [k for k in KINDS if any(r["query_kind"] == k for r in rows)]
    out["kinds"] = np.array(kinds)
    for kind in kinds:
        groups: dict[bool, list] = {}
        for r in rows:
            if r["query_kind"] == kind:
                groups.setdefault(bool(r.get("steer", True)), []).append(r)
        ref = None
        for steer, rs in sorted(groups.items(), reverse=True):
            arrays = [np.load(run / r["paths_file"]) for r in rs]
            tag = f"{kind}__{_steer(steer)}"
            out[f"models__{tag}"] = np.array([r["model"] for r in rs])
            out[f"success__{tag}"] = np.packbits(
                np.stack([np.asarray(a["success"], bool) for a in arrays]), axis=1
            )
            out[f"cost__{tag}"] = np.stack([np.asarray(a["costs"], np.float32) for a in arrays])
            out[f"cause__{tag}"] = np.stack([np.asarray(a["cause"], np.uint8) for a in arrays])
            ref = ref or arrays[0]
        out[f"ref_cost__{kind}"] = np.asarray(ref["ref_costs"], np.float32)
        out[f"ref_status__{kind}"] = np.asarray(ref["ref_status"], np.int8)
        q = np.asarray(qs[kind])
        out[f"k__{kind}"] = np.array(len(q))
        out[f"queries_sha256__{kind}"] = np.array(artifacts.npy_sha256(q))
        if env is not None:
            from ntq_jax.experiment.metrics import in_band

            out[f"in_band__{kind}"] = np.packbits(np.asarray(in_band(env, q), bool))
    return out


def write(run, env_name: str, out_dir, env=None, train_seed=None) -> Path:
    """Writes ``<out_dir>/outcomes.npz`` (compressed, atomically) and returns its path."""
    path = Path(out_dir) / FILE
    arrays = pack(run, env_name, env, train_seed)
    artifacts.write_with(path, lambda f: np.savez_compressed(f, **arrays))
    return path


def load(path) -> dict:
    """``{(model, kind, steer): {"success", "cost", "cause", "ref_cost", "ref_status",
    "in_band"}}`` (bool / float32 / uint8 / ... arrays of K queries; ``in_band`` None when
    not stored), plus ``"meta"``: env, train_seed, queries digests."""
    z = np.load(Path(path))
    if str(z["format"]) != FORMAT:
        raise ValueError(f"{path}: format {z['format']!s}, expected {FORMAT}")
    out: dict = {
        "meta": {"env": str(z["env"]), "train_seed": int(z["train_seed"]), "queries_sha256": {}}
    }
    for kind in (str(k) for k in z["kinds"]):
        k = int(z[f"k__{kind}"])
        out["meta"]["queries_sha256"][kind] = str(z[f"queries_sha256__{kind}"])
        band = (
            np.unpackbits(z[f"in_band__{kind}"])[:k].astype(bool)
            if f"in_band__{kind}" in z.files
            else None
        )
        for steer in (True, False):
            tag = f"{kind}__{_steer(steer)}"
            if f"models__{tag}" not in z.files:
                continue
            success = np.unpackbits(z[f"success__{tag}"], axis=1)[:, :k].astype(bool)
            for i, m in enumerate(str(x) for x in z[f"models__{tag}"]):
                out[(m, kind, steer)] = {
                    "success": success[i],
                    "cost": z[f"cost__{tag}"][i],
                    "cause": z[f"cause__{tag}"][i],
                    "ref_cost": z[f"ref_cost__{kind}"],
                    "ref_status": z[f"ref_status__{kind}"],
                    "in_band": band,
                }
    return out


def _row_counts(o: dict) -> dict:
    """A summary row's counts from one model's outcomes (as ``metrics.metrics`` makes them)."""
    from ntq_jax.types import CAUSE_NAMES, PlanCause

    s, k = o["success"], len(o["success"])
    ref = o["ref_cost"].astype(np.float64)
    ok = (o["ref_status"] == 0) & np.isfinite(ref) & (ref > 0)
    both = s & ok
    got = {
        "k_test": k,
        "successes": int(s.sum()),
        "success_ratio": s.sum() / k,
        "cost_ratio": float(np.mean(o["cost"][both].astype(np.float64) / ref[both]))
        if both.any()
        else None,
        "cost_ratio_n": int(both.sum()),
        "failures": {
            CAUSE_NAMES[c]: int(np.sum(o["cause"] == c))
            for c in PlanCause
            if c != PlanCause.SUCCESS
        },
    }
    if o["in_band"] is not None:
        b = o["in_band"]
        got.update(
            n_in_band=int(b.sum()),
            n_out_band=int((~b).sum()),
            successes_in_band=int((s & b).sum()),
            successes_out_band=int((s & ~b).sum()),
        )
    return got


def recount(summary_dir) -> tuple[int, list[str]]:
    """Every count of ``<summary_dir>/summary.json`` recomputed from its ``outcomes.npz``:
    ``(numbers checked, mismatches)`` (one line each)."""
    from ntq_jax.stats import mcnemar_exact

    d = Path(summary_dir)
    summary = json.loads((d / "summary.json").read_text())
    got = load(d / FILE)
    checked, bad = 0, []

    def same(where, name, want, have, tol=0.0):
        nonlocal checked
        checked += 1
        if want is None or have is None:
            ok = want is None and have is None
        elif isinstance(want, dict):
            ok = want == have
        else:
            ok = abs(float(want) - float(have)) <= tol * max(1.0, abs(float(want)))
        if not ok:
            bad.append(f"{d}: {where} {name}: summary {want}, outcomes {have}")

    for r in summary.get("rows", []):
        key = (r["model"], r["query_kind"], bool(r.get("steer", True)))
        where = f"{key[0]} {key[1]}{'' if key[2] else ' without steerTo'}"
        if key not in got:
            bad.append(f"{d}: {where}: no outcomes")
            continue
        c = _row_counts(got[key])
        for name in (
            "k_test",
            "successes",
            "cost_ratio_n",
            "n_in_band",
            "n_out_band",
            "successes_in_band",
            "successes_out_band",
        ):
            if name in c and name in r:
                same(where, name, r[name], c[name])
        same(where, "success_ratio", r["success_ratio"], c["success_ratio"], 1e-12)
        same(where, "cost_ratio", r.get("cost_ratio"), c["cost_ratio"], 1e-6)
        if "failures" in r:
            same(where, "failures", r["failures"], c["failures"])
    for cmp_ in summary.get("comparisons", []):
        steer = bool(cmp_.get("steer", True))
        a, b = (got.get((m, cmp_["query_kind"], steer)) for m in (cmp_["model"], cmp_["baseline"]))
        where = f"{cmp_['model']} vs {cmp_['baseline']} {cmp_['query_kind']}" + (
            "" if steer else " without steerTo"
        )
        if a is None or b is None:
            bad.append(f"{d}: {where}: no outcomes")
            continue
        sa, sb = a["success"], b["success"]
        counts = {
            "n": len(sa),
            "both": int((sa & sb).sum()),
            "only_a": int((sa & ~sb).sum()),
            "only_b": int((~sa & sb).sum()),
            "neither": int((~sa & ~sb).sum()),
        }
        for name, v in counts.items():
            same(where, name, cmp_[name], v)
        same(
            where,
            "success_diff",
            cmp_["success_diff"],
            (counts["only_a"] - counts["only_b"]) / counts["n"],
            1e-12,
        )
        same(
            where,
            "mcnemar_p",
            cmp_["mcnemar_p"],
            mcnemar_exact(counts["only_a"], counts["only_b"]),
            1e-12,
        )
    return checked, bad


def _summaries(roots) -> list[Path]:
    return sorted({f.parent for r in roots for f in Path(r).rglob("summary.json")})


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m ntq_jax.experiment.outcomes",
        description="Recompute every count of the committed summaries "
        "from their per-query outcomes.",
    )
    ap.add_argument("roots", nargs="*", default=["results/paper", "results/factors"])
    ap.add_argument("--pack", metavar="RUN", help="write outcomes.npz from this run folder")
    ap.add_argument("--env", help="with --pack: the map (e.g. rigid/1)")
    ap.add_argument("--out", help="with --pack: the summary folder to write it to")
    ap.add_argument("--train-seed", type=int, default=None)
    args = ap.parse_args(argv)
    if args.pack:
        if not (args.env and args.out):
            print("error: --pack needs --env and --out", file=sys.stderr)
            return 2
        from ntq_jax import make_env

        print(write(args.pack, args.env, args.out, make_env(args.env), args.train_seed))
        return 0
    dirs = _summaries(args.roots)
    have = [d for d in dirs if (d / FILE).is_file()]
    lack = [d for d in dirs if d not in have]
    total, bad = 0, []
    for d in have:
        n, b = recount(d)
        total += n
        bad += b
    for line in bad:
        print(line)
    print(
        f"{len(have)} summaries with outcomes: {total} counts recomputed, "
        f"{len(bad)} mismatches; {len(lack)} summaries without outcomes (made before they "
        "were stored):"
    )
    for d in lack:
        print(f"  {d}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
