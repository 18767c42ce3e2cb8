"""Every figure of the package (matplotlib, Agg backend); nothing else imports matplotlib.

* :func:`dataset_figure`: a dataset folder's map, start/goal distributions of D0
  and D2 and a few solved paths (``<env_dir>/figure.png``).
* :func:`curves_figure`: the training curves of an ensemble (``curves.png``).
* :func:`success_figure`, :func:`examples_figure`, :func:`queries_figure`: the
  report's success bars, neural paths beside the reference, test queries.
* :func:`query_figure`: one planned query (``scripts/plan.py``).
* :func:`learning_curve_figure`: success vs training rows and vs K_train per
  dataset (``scripts/learning_curve.py``).

Maps are drawn by :func:`draw_map` from the environment JSON: obstacles dark,
their padding light (optional); for the arm, the workspace with the arm along
a path (:func:`draw_arm`) or the joint space. A 3-D scene (the serial arm, e.g. the
Panda) is drawn by :func:`ntq_jax.scenes.viewer.draw_scene`, with the hand's trace
along each path (:func:`hand_trace`); its queries in joint space.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import Sequence

import jax
import numpy as np

from ntq_jax import artifacts
from ntq_jax.types import QUERY_KINDS, PlanStatus

__all__ = [
    "draw_map",
    "draw_arm",
    "is_scene",
    "hand_trace",
    "dataset_figure",
    "curves_figure",
    "success_figure",
    "examples_figure",
    "queries_figure",
    "query_figure",
    "learning_curve_figure",
]

#: maps with more boxes are drawn as one image of at most IMAGE_PIXELS a side, not one patch
#: per box (which grows with the box count in time and memory)
IMAGE_MAP_BOXES = 2000
IMAGE_PIXELS = 1600
KIND_TITLE = {"uniform": "Uniform Query", "nontrivial": "Non-trivial Query"}
#: robots whose maps are drawn in joint space (joints 1 and 2): the planar arm and the 3-D
#: serial arm (whose workspace is drawn in 3-D by :func:`_scene_axes`)
JOINT_SPACE_KINDS = ("nlink", "serial_arm")


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path, **kw) -> Path:
    plt = _plt()
    artifacts.save_figure(fig, path, dpi=110, **kw)
    plt.close(fig)
    return Path(path)


def _joint_axes(ax):
    ax.set_xlim(-math.pi, math.pi)
    ax.set_ylim(-math.pi, math.pi)
    ax.set_xlabel("joint 1 (rad)")
    ax.set_ylabel("joint 2 (rad)")


def draw_map(ax, spec: dict, padded: bool = False, joint_space: bool | None = None):
    """Draws the environment JSON ``spec`` on ``ax``.

    Obstacles are dark; with ``padded``, their padding (``spec["padding"]``) is
    drawn light around them. A map of more than :data:`IMAGE_MAP_BOXES` boxes
    is drawn as one image (:data:`IMAGE_PIXELS` a side; padding with square
    corners), so drawing time and memory do not grow with the box count. ``joint_space``
    (default: for an arm) sets up the
    ``[-pi, pi]^2`` axes of joints 1 and 2 instead (no obstacles there).
    """
    if joint_space is None:
        joint_space = spec["robot"]["kind"] in JOINT_SPACE_KINDS
    if joint_space:
        _joint_axes(ax)
        return
    if len(spec["bounds"]) != 2:
        raise ValueError(
            f"{spec.get('name')!r}: draw_map draws a planar map; a 3-D scene is "
            "drawn by ntq_jax.scenes.viewer.draw_scene"
        )
    from matplotlib.patches import Circle, FancyBboxPatch, Rectangle

    pad = float(spec.get("padding", 0.0))
    boxes = np.asarray(spec.get("boxes", []), np.float64).reshape(-1, 4)
    if len(boxes) > IMAGE_MAP_BOXES:
        _draw_boxes_image(ax, boxes, spec["bounds"], pad if padded else 0.0)
        boxes = boxes[:0]
    for cx, cy, hw, hh in boxes:
        if padded and pad > 0:
            ax.add_patch(
                FancyBboxPatch(
                    (cx - hw, cy - hh),
                    2 * hw,
                    2 * hh,
                    boxstyle=f"round,pad={pad}",
                    fc="0.85",
                    ec="none",
                )
            )
        ax.add_patch(Rectangle((cx - hw, cy - hh), 2 * hw, 2 * hh, fc="0.35", ec="none"))
    for cx, cy, r in spec.get("discs", []):
        if padded and pad > 0:
            ax.add_patch(Circle((cx, cy), r + pad, fc="0.85", ec="none"))
        ax.add_patch(Circle((cx, cy), r, fc="0.35", ec="none"))
    (x0, x1), (y0, y1) = spec["bounds"]
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")


def _draw_boxes_image(ax, boxes: np.ndarray, bounds, pad: float):
    """``boxes`` as one image of at most :data:`IMAGE_PIXELS` a side: a pixel is dark where its square
    meets a box, light where it meets a box grown by ``pad`` (square corners) and only that."""
    (x0, x1), (y0, y1) = (map(float, b) for b in bounds)
    scale = IMAGE_PIXELS / max(x1 - x0, y1 - y0)
    w, h = max(1, math.ceil((x1 - x0) * scale)), max(1, math.ceil((y1 - y0) * scale))
    img = np.ones((h, w), np.float32)
    for grow, shade in ((pad, 0.85), (0.0, 0.35)):
        if grow <= 0 and shade == 0.85:
            continue
        lo = np.floor((boxes[:, :2] - boxes[:, 2:] - grow - (x0, y0)) * scale).astype(np.int64)
        hi = np.ceil((boxes[:, :2] + boxes[:, 2:] + grow - (x0, y0)) * scale).astype(np.int64)
        lo, hi = np.clip(lo, 0, (w, h)), np.clip(hi, 0, (w, h))
        for (c0, r0), (c1, r1) in zip(lo.tolist(), hi.tolist()):
            img[r0 : max(r1, r0 + 1), c0 : max(c1, c0 + 1)] = shade
    ax.imshow(
        img,
        cmap="gray",
        vmin=0.0,
        vmax=1.0,
        origin="lower",
        extent=(x0, x1, y0, y1),
        interpolation="nearest",
    )


def draw_arm(ax, env, path: np.ndarray):
    """The arm of ``env`` at every state of ``path`` (start green, goal blue, between magenta)."""
    fk = jax.vmap(env.robot.forward_kinematics)(np.asarray(path, np.float32))
    n = len(path)
    for t, pts in enumerate(np.asarray(fk, np.float64)):
        c = "green" if t == 0 else "blue" if t == n - 1 else "magenta"
        ax.plot(pts[:, 0], pts[:, 1], "-o", color=c, ms=2, lw=1.5, alpha=0.9)


def is_scene(env) -> bool:
    """Whether ``env`` is a 3-D scene with an arm (drawn by :mod:`ntq_jax.scenes.viewer`)."""
    from ntq_jax.geometry import World3D

    return isinstance(env.world, World3D)


@functools.lru_cache(maxsize=8)
def _tip_jit(robot):
    return jax.jit(jax.vmap(lambda q: robot.tip_pose(q)[:3, 3]))


def hand_trace(env, path: np.ndarray, per_segment: int = 8) -> np.ndarray:
    """``(m, 3)``: the hand (the tip link's origin) of a 3-D arm along the joint-space
    polyline ``path`` (``per_segment`` states per segment, its ends included)."""
    p = np.asarray(path, np.float32)
    if len(p) < 2:
        return np.asarray(_tip_jit(env.robot)(p), np.float64)
    t = np.linspace(0.0, 1.0, per_segment, endpoint=False, dtype=np.float32)[None, :, None]
    dense = (p[:-1, None] + t * (p[1:, None] - p[:-1, None])).reshape(-1, p.shape[1])
    return np.asarray(_tip_jit(env.robot)(np.concatenate([dense, p[-1:]])), np.float64)


def _scene_panel(ax, env, states, title: str, path=None) -> None:
    """The obstacles of a 3-D scene and its arm at ``states`` (and along ``path``) on ``ax``."""
    from ntq_jax.scenes import viewer

    viewer.draw_scene(
        env,
        states=np.asarray(states, np.float64),
        path=path,
        ax=ax,
        labels=["start", "goal"],
        title=title,
        legend=False,
        limits="bounds",
        resolution=12,
        arm_resolution=6,
    )


def _workspace_panel(ax, env, spec: dict, d) -> None:
    """The first panel of :func:`dataset_figure` for an arm: one solved path of ``d``."""
    solved = len(d.path_lengths) > 0
    p = np.asarray(d.paths[0, : int(d.path_lengths[0])]) if solved else None
    title = f"{spec.get('name')}: workspace, one solved path"
    if is_scene(env):
        _scene_panel(
            ax, env, env.query if p is None else p[[0, -1]], title, None if p is None else p
        )
        return
    draw_map(ax, spec, padded=True, joint_space=False)
    if p is not None:
        draw_arm(ax, env, p)
    ax.set_title(title)


def dataset_figure(
    env, datasets: Sequence, out: Path, n_points: int = 400, n_paths: int = 6
) -> Path:
    """PNG of the map with the start/goal distributions of D0 and D2 and a few solved paths.

    Point robot and rigid body: (x, y) of starts (green) and goals (blue) and
    paths (magenta) over the obstacles (dark) and their padding (light). Arm:
    the workspace with the arm along a solved path (in 3-D for a 3-D scene), and the
    configuration space (joints 1 and 2; for the 2-link arm this is the whole
    C-space, with the colliding configurations shaded).

    Args:
        env: the :class:`ntq_jax.Env`.
        datasets: its loaded datasets (:func:`ntq_jax.data.load_datasets`).
        out: the PNG to write.
    """
    plt = _plt()
    spec = env.to_json()
    ds = datasets
    picks = [0, min(2, len(ds) - 1)]
    picks = [
        (i, f"D{i}: p_nt={ds[i].meta['p_nt']}" + (", pruned" if ds[i].meta["prune"] else ""))
        for i in picks
    ]
    arm = spec["robot"]["kind"] in JOINT_SPACE_KINDS
    rng = np.random.default_rng(0)
    ncol = len(picks) + (1 if arm else 0)
    fig = plt.figure(figsize=(5 * ncol, 5))
    axes = [
        fig.add_subplot(1, ncol, j + 1, projection="3d" if j == 0 and is_scene(env) else None)
        for j in range(ncol)
    ]
    if arm:
        _workspace_panel(axes[0], env, spec, ds[picks[-1][0]])
        axes = axes[1:]
    for (i, title), ax in zip(picks, axes):
        d = ds[i]
        q = np.asarray(d.queries)
        sel = rng.permutation(len(q))[:n_points]
        draw_map(ax, spec, padded=True)
        if arm and env.dim == 2:
            g = np.linspace(-np.pi, np.pi, 181, dtype=np.float32)
            A, B = np.meshgrid(g, g)
            ok = np.asarray(env.is_valid(np.stack([A.ravel(), B.ravel()], 1))).reshape(A.shape)
            ax.imshow(
                ~ok, origin="lower", extent=(-np.pi, np.pi, -np.pi, np.pi), cmap="Greys", alpha=0.5
            )
        ax.scatter(q[sel, 0, 0], q[sel, 0, 1], s=4, c="green", label="start")
        ax.scatter(q[sel, 1, 0], q[sel, 1, 1], s=4, c="blue", label="goal")
        for p in rng.permutation(len(d.path_lengths))[:n_paths]:
            L = int(d.path_lengths[p])
            ax.plot(d.paths[p, :L, 0], d.paths[p, :L, 1], "-", color="magenta", lw=1.2)
        st = d.meta["stats"]
        ax.set_title(
            f"{title}\n{st['solved']}/{st['queries']} solved, {st['samples']} samples", fontsize=9
        )
        ax.legend(loc="upper right", fontsize=7, markerscale=3)
    g = ds[0].meta.get("gamma_nt", {}) or {}
    if g.get("gamma") is not None:
        fig.suptitle(
            f"{spec.get('name')}  (gamma_nt = {g['gamma']:.3f} at padding {g['padding']})",
            fontsize=10,
        )
    fig.tight_layout()
    return _save(fig, out)


def curves_figure(history, labels: Sequence[str], out: Path) -> Path | None:
    """Training and validation loss per member against epochs (log scale).

    ``history`` is a :class:`ntq_jax.training.History`. Uses the object API with
    the Agg canvas (no pyplot state), as the training loop redraws it at checkpoints.
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:  # pragma: no cover
        return None
    h = history
    fig = Figure(figsize=(6.4, 4.0))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for m, lab in enumerate(labels):
        ok = np.isfinite(h.train_loss[:, m])
        (line,) = ax.plot(h.epoch[ok, m], h.train_loss[ok, m], "--", lw=1, label=f"{lab} train")
        okv = np.isfinite(h.val_loss[:, m])
        if okv.any():
            ax.plot(
                h.epoch[okv, m],
                h.val_loss[okv, m],
                "-",
                lw=1.5,
                color=line.get_color(),
                label=f"{lab} val",
            )
    ax.set_xlabel("epoch")
    ax.set_ylabel("loss (normalised MSE)")
    ax.set_yscale("log")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    artifacts.save_figure(fig, out, dpi=110)
    return Path(out)


def model_order(name: str) -> tuple:
    """Sort key of a result row's model: ``PNet_0..PNet_<M-1>`` by index, then the
    ensemble rows (``PNet_ens``, ``PNet_best-of-<N>``, ``PNet_cascade``), then anything
    else by name."""
    tail = name.split("_", 1)[-1]
    if tail.isdigit():
        return (0, int(tail), name)
    rank = {"ens": 1, "cascade": 3}.get(tail, 2 if tail.startswith("best-of-") else 4)
    return (rank, 0, name)


def _fmt(x, nd=2) -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{nd}f}"


def success_figure(rows, path: Path, steer: bool = True) -> Path | None:
    """Grouped bars: success ratio per environment and model, with 95% intervals."""
    plt = _plt()
    rows = [r for r in rows if r["steer"] == steer]
    if not rows:
        return None
    envs = list(dict.fromkeys(r["env"] for r in rows))
    models = sorted({r["model"] for r in rows}, key=model_order)
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), sharey=True)
    width = 0.8 / max(len(models), 1)
    for ax, kind in zip(axes, QUERY_KINDS):
        for j, m in enumerate(models):
            ys, lo, hi = [], [], []
            for e in envs:
                r = next(
                    (
                        r
                        for r in rows
                        if r["env"] == e and r["model"] == m and r["query_kind"] == kind
                    ),
                    None,
                )
                y = r["success_ratio"] if r else np.nan
                ci = r["success_ci95"] if r else (np.nan, np.nan)
                ys.append(y)
                lo.append(max(y - ci[0], 0.0))
                hi.append(max(ci[1] - y, 0.0))
            x = np.arange(len(envs)) + (j - (len(models) - 1) / 2) * width
            ax.bar(x, ys, width, yerr=[lo, hi], capsize=2, label=m)
        gam = {r["env"]: r.get("gamma_nt") for r in rows}
        ax.set_xticks(np.arange(len(envs)), [f"{e}\n$\\gamma_{{nt}}$={_fmt(gam[e])}" for e in envs])
        ax.set_title(KIND_TITLE[kind] + ("" if steer else " (no steerTo)"))
        ax.set_ylim(0, 1.05)
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_ylabel("success ratio (95% interval)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(
        handles,
        labels,
        loc="upper center",
        ncol=len(models),
        fontsize=8,
        bbox_to_anchor=(0.5, 1.06),
    )
    return _save(fig, path, bbox_inches="tight")


def examples_figure(
    env, reference: dict | None, saved: dict, path: Path, n_examples: int = 4
) -> Path | None:
    """Neural paths (each model) beside the reference paths on non-trivial test queries.

    Args:
        env: the :class:`ntq_jax.Env`.
        reference: the saved reference plans (``eval/<env>/reference.npz`` arrays).
        saved: ``{model name: saved paths file arrays}`` for the non-trivial queries.
        path: the PNG to write.
    """
    saved = {m: z for m, z in saved.items() if z is not None}
    if reference is None or not saved:
        return None
    ref = reference
    plt = _plt()
    pick = np.flatnonzero(ref["nontrivial_status"] == PlanStatus.SOLVED)[:n_examples]
    ej, scene = env.to_json(), is_scene(env)
    n, size = max(len(pick), 1), (4.6 if scene else 3.6)
    fig = plt.figure(figsize=(size * n, size + 0.2))
    axes = [fig.add_subplot(1, n, j + 1, projection="3d" if scene else None) for j in range(n)]
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, i in zip(axes, pick):
        rp = ref["nontrivial_paths"][i, : ref["nontrivial_lengths"][i]]
        title = f"{env.name}: non-trivial query {i}"
        if scene:  # the hand's trace along each path, the arm at the start and the goal
            _scene_panel(ax, env, rp[[0, -1]], title)
        else:
            draw_map(ax, ej)
            ax.set_title(title, fontsize=9)
        _path_line(
            ax,
            env,
            scene,
            rp,
            color="k",
            ls="--",
            lw=2,
            label=f"reference ({ref['nontrivial_costs'][i]:.2f})",
        )
        for j, (m, z) in enumerate(saved.items()):
            good = bool(z["success"][i])
            _path_line(
                ax,
                env,
                scene,
                z["paths"][i, : z["lengths"][i]],
                ls="-" if good else ":",
                color=colors[j % len(colors)],
                lw=1.3,
                **({} if scene else {"marker": ".", "ms": 4}),
                label=f"{m} ({z['costs'][i]:.2f})" if good else f"{m} (failed)",
            )
        if not scene:
            ax.plot(*rp[0, :2], "o", color="green", ms=7)
            ax.plot(*rp[-1, :2], "*", color="blue", ms=10)
        ax.legend(fontsize=6, loc="best")
    return _save(fig, path, bbox_inches="tight")


def _path_line(ax, env, scene: bool, p: np.ndarray, **kw) -> None:
    """A path on a map (its first two coordinates) or, in a 3-D scene, the hand's trace
    along it (:func:`hand_trace`)."""
    if scene:
        ax.plot(*hand_trace(env, p).T, **kw)
    else:
        ax.plot(p[:, 0], p[:, 1], **kw)


def queries_figure(env, queries: dict | None, path: Path) -> Path | None:
    """The test query distributions: starts (green) and goals (blue), per kind."""
    if queries is None:
        return None
    plt = _plt()
    ej = env.to_json()
    fig, axes = plt.subplots(1, 2, figsize=(8, 4))
    for ax, kind in zip(axes, QUERY_KINDS):
        draw_map(ax, ej)
        qq = queries[kind]
        ax.scatter(qq[:, 0, 0], qq[:, 0, 1], s=4, c="green", label="start")
        ax.scatter(qq[:, 1, 0], qq[:, 1, 1], s=4, c="blue", label="goal")
        ax.set_title(f"{env.name}: {KIND_TITLE[kind].lower()} test queries", fontsize=9)
    axes[0].legend(fontsize=7, loc="upper right")
    return _save(fig, path, bbox_inches="tight")


def query_figure(
    env,
    path: np.ndarray,
    success: bool,
    cost: float,
    label: str,
    start,
    goal,
    out: Path,
    optimum: tuple[np.ndarray, float] | None = None,
) -> Path:
    """One planned query: the path (solid if a success), the optimum if given, start and goal."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5, 5))
    draw_map(ax, env.to_json())
    if optimum is not None:
        p, c = optimum
        ax.plot(p[:, 0], p[:, 1], "k--", lw=2, label=f"optimum ({c:.3f})")
    ax.plot(
        path[:, 0],
        path[:, 1],
        "-" if success else ":",
        color="tab:red",
        marker=".",
        label=f"{label} ({cost:.3f})" if success else f"{label} (failed)",
    )
    ax.plot(*start[:2], "o", color="green", ms=8)
    ax.plot(*goal[:2], "*", color="blue", ms=12)
    ax.legend(fontsize=8)
    return _save(fig, out, bbox_inches="tight")


def learning_curve_figure(rows, path: Path, title: str = "") -> Path | None:
    """Success ratio vs training rows (top) and vs K_train (bottom), per dataset, with 95%
    intervals; non-trivial test queries left, uniform right.

    ``rows``: :func:`ntq_jax.experiment.curve.curve_rows`' dicts (``size``, ``dataset``, ``rows``,
    ``kind``, ``success``, ``ci95``). Returns None without rows.
    """
    if not rows:
        return None
    plt = _plt()
    names = sorted({r["dataset"] for r in rows}, key=lambda n: (len(n), n))
    kinds = [k for k in ("nontrivial", "uniform") if any(r["kind"] == k for r in rows)]
    fig, axes = plt.subplots(
        2, len(kinds), figsize=(5.2 * len(kinds), 7.2), squeeze=False, sharey=True
    )
    for col, kind in enumerate(kinds):
        for row, (xkey, xlabel) in enumerate(
            (("rows", "training rows (samples)"), ("size", "K_train (queries per dataset)"))
        ):
            ax = axes[row, col]
            for j, nm in enumerate(names):
                rr = sorted(
                    (r for r in rows if r["dataset"] == nm and r["kind"] == kind),
                    key=lambda r: r[xkey],
                )
                if not rr:
                    continue
                x = np.array([r[xkey] for r in rr], float)
                y = np.array([r["success"] for r in rr], float)
                lo = np.array([r["ci95"][0] for r in rr], float)
                hi = np.array([r["ci95"][1] for r in rr], float)
                c = f"C{j}"
                ax.plot(x, y, "o-", color=c, label=nm, ms=4)
                ax.fill_between(x, lo, hi, color=c, alpha=0.15, lw=0)
            ax.set_xlabel(xlabel)
            ax.set_ylim(0, 1.05)
            ax.grid(alpha=0.3)
            if row == 0:
                ax.set_title(KIND_TITLE[kind])
            if col == 0:
                ax.set_ylabel("success ratio (95% interval)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(
        handles, labels, loc="upper center", ncol=len(names), fontsize=9, bbox_to_anchor=(0.5, 1.0)
    )
    if title:
        fig.suptitle(title, y=1.04)
    fig.tight_layout(rect=(0, 0, 1, 0.96))
    return _save(fig, path, bbox_inches="tight")
