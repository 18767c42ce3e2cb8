"""The sections of an experiment config: ``sampling``, ``data``, ``planner`` and ``eval``.

Each section is a frozen dataclass whose fields are the section's keys, with
their defaults; ``validate(prefix)`` raises :class:`~ntq_jax.errors.ConfigError`
naming the key. ``model`` and ``train`` are the core's own
:class:`~ntq_jax.models.ModelConfig` and :class:`~ntq_jax.training.config.TrainConfig`.
:mod:`ntq_jax.experiment.config` assembles them into a :class:`Config` and loads YAML.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from typing import Optional

from ntq_jax.errors import check_config as _check
from ntq_jax.neural.options import NOSTEER_CHECKS

__all__ = [
    "SamplingConfig",
    "PRUNE_GAMMA",
    "PRUNE_KEEP_LAST",
    "DatasetSpec",
    "DataEnvOverride",
    "DataConfig",
    "PlannerEnvOverride",
    "PLANNERS",
    "DATA_PATH_MODES",
    "validate_mode",
    "PlannerConfig",
    "ENSEMBLE_ROWS",
    "EvalConfig",
]


@dataclasses.dataclass(frozen=True)
class SamplingConfig:
    """Query sampling (Alg. 3).

    Attributes:
        n_max: attempts of the non-trivial sampler before it returns a trivial query.
    """

    n_max: int = 10_000

    def validate(self, p: str):
        _check(self.n_max >= 1, f"{p}.n_max", f"must be >= 1, got {self.n_max}")


PRUNE_GAMMA = "gamma"
PRUNE_KEEP_LAST = "keep_last"  #: Alg. 4's pruning, keeping each path's last step


@dataclasses.dataclass(frozen=True)
class DatasetSpec:
    """One dataset of Alg. 2: the non-trivial probability and the pruning setting.

    Datasets are named by their position in ``data.datasets``: ``D0``, ``D1``, ...

    Attributes:
        p_nt: probability that a query is non-trivial (Alg. 2).
        prune: Alg. 4's pruning. ``false``: keep every sample; ``true``: drop
            every sample whose ``steer_to(pi_i, pi_end)`` is free (the
            "trivial remainder"; the paper's D3). A number ``p`` in [0, 1]:
            drop each trivial-remainder sample with probability ``p``
            (probabilistic pruning, the paper's Sec. VI; ``0`` gives the same
            arrays as ``false``, ``1`` the same as ``true``). ``gamma``: ``p`` =
            the map's gamma_nt estimated at the data-generation padding (the
            ``gamma_nt`` of the dataset metadata). Non-trivial samples are never
            dropped. Which samples are dropped follows from the run's seed, the
            environment and the dataset's name only (:func:`ntq_jax.data.include.prune_rng`).
            ``keep_last``: like ``true``, but each path keeps its last sample, the
            step into the goal (beyond the paper; :mod:`ntq_jax.data.include`).
        name: optional; when given it must be the dataset's positional name
            (e.g. ``D4`` for the fifth entry), a check against a misordered list.
    """

    p_nt: float
    prune: typing.Union[bool, float, str] = False
    name: Optional[str] = None

    # left out of to_dict (and so of the config hash) when None: unnamed specs hash as before
    _OMIT_NONE = ("name",)

    def validate(self, p: str):
        _check(0.0 <= self.p_nt <= 1.0, f"{p}.p_nt", f"must be in [0, 1], got {self.p_nt}")
        pr = self.prune
        if isinstance(pr, str):
            _check(
                pr in (PRUNE_GAMMA, PRUNE_KEEP_LAST),
                f"{p}.prune",
                f"must be true, false, a probability in [0, 1], {PRUNE_GAMMA!r} or "
                f"{PRUNE_KEEP_LAST!r}; got {pr!r}",
            )
        elif not isinstance(pr, bool):
            _check(
                0.0 <= pr <= 1.0, f"{p}.prune", f"a pruning probability must be in [0, 1], got {pr}"
            )

    @property
    def prunes(self) -> bool:
        """Whether any sample may be pruned (``false`` and ``0`` never prune)."""
        return (
            self.prune is True
            or isinstance(self.prune, str)
            or (not isinstance(self.prune, bool) and self.prune > 0.0)
        )


def _paper_datasets() -> tuple[DatasetSpec, ...]:
    return (
        DatasetSpec(0.0, False),
        DatasetSpec(0.5, False),
        DatasetSpec(1.0, False),
        DatasetSpec(1.0, True),
    )


@dataclasses.dataclass(frozen=True)
class DataEnvOverride:
    """Per-environment data settings (e.g. the paper's 3000/4000/5000 queries for 2/4/6 links).

    Attributes:
        env: the environment name exactly as listed in ``envs``.
        k_train: queries per dataset for this environment (``None`` = ``data.k_train``).
        paths_from: a folder of recorded data paths of this map
            (``scripts/record_paths.py``: ``record.json``, ``U/`` and ``N/`` chunk
            files, e.g. ``results/data_paths/bitstar/rigid_0``): the pools' queries
            it holds are taken from it instead of being planned (their queries must
            be this run's, byte for byte); the rest are planned as usual.
    """

    env: str
    k_train: Optional[int] = None
    paths_from: Optional[str] = None
    _OMIT_NONE = ("paths_from",)

    def validate(self, p: str):
        _check(bool(self.env), f"{p}.env", "must name an environment")
        _check(
            self.k_train is None or self.k_train >= 1,
            f"{p}.k_train",
            f"must be >= 1 or null, got {self.k_train}",
        )


@dataclasses.dataclass(frozen=True)
class DataConfig:
    """Dataset generation (Alg. 2 and 4).

    Attributes:
        k_train: queries per dataset.
        datasets: D0..D3 (the paper's four by default): :class:`DatasetSpec` s,
            named ``D0``, ``D1``, ... by position; list more to train more
            ensemble members, e.g. the probabilistic-pruning ``D4``::

                datasets: [{p_nt: 0.0}, {p_nt: 0.5}, {p_nt: 1.0}, {p_nt: 1.0, prune: true},
                           {name: D4, p_nt: 1.0, prune: gamma}]   # or prune: 0.3
        prune_padding: padding of the pruning steer_to; ``None`` = the environment's
            (the paper prunes on the data-generation geometry).
        chunk: queries per chunk written to disk (resumable unit).
        gamma_queries: uniform queries used to estimate gamma_nt for the metadata
            (at the data-generation padding, and at padding 0 when ``gamma_eval``).
        gamma_eval: also estimate gamma_nt on the evaluation geometry (padding 0).
        per_env: per-environment overrides (:class:`DataEnvOverride`).
    """

    k_train: int = 3000
    datasets: tuple[DatasetSpec, ...] = dataclasses.field(default_factory=_paper_datasets)
    prune_padding: Optional[float] = None
    chunk: int = 500
    gamma_queries: int = 1_000_000
    gamma_eval: bool = True
    per_env: tuple[DataEnvOverride, ...] = ()

    def validate(self, p: str):
        _check(self.k_train >= 1, f"{p}.k_train", f"must be >= 1, got {self.k_train}")
        _check(len(self.datasets) >= 1, f"{p}.datasets", "must list at least one dataset")
        for i, d in enumerate(self.datasets):
            d.validate(f"{p}.datasets[{i}]")
            _check(
                d.name is None or d.name == f"D{i}",
                f"{p}.datasets[{i}].name",
                f"datasets are named by position: entry {i} is D{i}, got {d.name!r}",
            )
        _check(
            self.prune_padding is None or self.prune_padding >= 0,
            f"{p}.prune_padding",
            f"must be >= 0 or null, got {self.prune_padding}",
        )
        _check(self.chunk >= 1, f"{p}.chunk", f"must be >= 1, got {self.chunk}")
        _check(
            self.gamma_queries >= 1, f"{p}.gamma_queries", f"must be >= 1, got {self.gamma_queries}"
        )
        for i, o in enumerate(self.per_env):
            o.validate(f"{p}.per_env[{i}]")
        names = [o.env for o in self.per_env]
        _check(
            len(set(names)) == len(names), f"{p}.per_env", f"lists an environment twice: {names}"
        )

    def paths_from_for(self, env: str) -> str | None:
        """The recorded data paths of ``env`` (its override's ``paths_from``), or None."""
        return next((o.paths_from for o in self.per_env if o.env == env), None)

    def k_train_for(self, env: str) -> int:
        """Queries per dataset for ``env`` (its override, else ``k_train``)."""
        for o in self.per_env:
            if o.env == env and o.k_train is not None:
                return o.k_train
        return self.k_train


@dataclasses.dataclass(frozen=True)
class PlannerEnvOverride:
    """Per-environment planner settings (the paper: BIT* 2/4/6 s data, 1/2/4 s eval for
    2/4/6 links; or another planner for one map, e.g. the roadmap for a rigid-body map
    in a config of grid-A* point maps).

    Attributes:
        env: the environment name exactly as listed in ``envs``.
        time_budget: BIT* seconds per query for data (``None`` = ``planner.time_budget``).
        eval_time_budget: BIT* seconds at evaluation (``None`` = ``planner.eval_time_budget``).
        name: the planner of this environment (``None`` = ``planner.name``).
        data_paths: the data paths of this environment (``None`` = ``planner.data_paths``).
    """

    env: str
    time_budget: Optional[float] = None
    eval_time_budget: Optional[float] = None
    name: Optional[str] = None
    data_paths: typing.Union[float, str, None] = None

    # left out of to_dict (and so of the config hash) when None: configs hash as before
    _OMIT_NONE = ("name", "data_paths")

    def validate(self, p: str):
        _check(bool(self.env), f"{p}.env", "must name an environment")
        _check(
            self.name is None or self.name in PLANNERS,
            f"{p}.name",
            f"must be one of {', '.join(PLANNERS)} or null; got {self.name!r}",
        )
        for k in ("time_budget", "eval_time_budget"):
            v = getattr(self, k)
            _check(v is None or v > 0, f"{p}.{k}", f"must be > 0 or null, got {v}")
        why = validate_mode(self.data_paths)
        _check(why is None, f"{p}.data_paths", why or "")


PLANNERS = ("astar", "visgraph", "bitstar", "roadmap")
DATA_PATH_MODES = ("raw", "shortcut")  # or a number: the resampling spacing


def validate_mode(mode) -> str | None:
    """Why ``mode`` is not a ``data_paths`` value (:mod:`ntq_jax.planners.path_modes`), or None."""
    if mode is None or mode in DATA_PATH_MODES:
        return None
    if isinstance(mode, (int, float)) and not isinstance(mode, bool):
        return None if math.isfinite(mode) and mode > 0 else f"a spacing must be > 0, got {mode}"
    return f"must be raw, shortcut, a spacing > 0 or null; got {mode!r}"


@dataclasses.dataclass(frozen=True)
class PlannerConfig:
    """Classical planner used to solve training queries and as the evaluation reference.

    Attributes:
        name: ``astar`` (grid A* + smoothing), ``visgraph``, ``bitstar`` or ``roadmap``.
        resolution: grid resolution of A* (workspace units per cell).
        milestones: roadmap size (``roadmap``; doubled on each growth round).
        neighbors: roadmap neighbours per milestone (``null``: PRM*'s rule).
        grow_rounds: roadmap growth rounds for unconnected queries.
        time_budget: BIT* seconds per query during data generation.
        eval_time_budget: BIT* seconds per query at evaluation.
        workers: BIT* worker processes (0 = number of cores).
        data_paths: the data planner's output before includeData
            (:mod:`ntq_jax.planners.path_modes`): ``raw`` (the planner's own
            waypoints: grid cells, roadmap nodes, BIT*'s vertices; pruning drops
            every waypoint that sees the goal), ``shortcut`` (a few corners;
            pruning drops only the step into the goal), a number ``s`` (the
            shortcut resampled to at most ``s`` between waypoints, robot metric:
            BIT*-like density) or null (the planner's default: shortcut for
            ``astar``/``roadmap``, raw for ``bitstar``/``visgraph``; left out of the
            config hash). The evaluation reference is always the default.
        data_check: the motion check every data path passes (``discretized``, the
            paper's steerTo at its resolution, or ``certified``: every segment proven
            free); null = ``discretized``, left out of the config hash. The planner
            plans and verifies with it; the blocked-ness of a query and includeData's
            pruning stay the discretised steerTo, as in the paper.
        smooth_data: the earlier spelling of ``data_paths`` (``false`` = ``raw``,
            ``true`` = ``shortcut``); kept so that older configs load and hash as
            they did. Not together with ``data_paths``.
        per_env: per-environment planners and budgets (:class:`PlannerEnvOverride`);
            read them with :meth:`name_for`, :meth:`time_budget_for` and
            :meth:`eval_time_budget_for`.
    """

    name: str = "astar"
    resolution: float = 0.1
    milestones: int = 20_000
    neighbors: Optional[int] = None
    grow_rounds: int = 2
    time_budget: float = 3.0
    eval_time_budget: float = 2.0
    workers: int = 0
    data_paths: typing.Union[float, str, None] = None
    data_check: Optional[str] = None
    smooth_data: Optional[bool] = None
    per_env: tuple[PlannerEnvOverride, ...] = ()
    _OMIT_NONE = ("data_paths", "data_check", "smooth_data")

    def validate(self, p: str):
        _check(
            self.name in PLANNERS,
            f"{p}.name",
            f"must be one of {', '.join(PLANNERS)}; got {self.name!r}",
        )
        _check(self.milestones >= 2, f"{p}.milestones", f"must be >= 2, got {self.milestones}")
        _check(
            self.neighbors is None or self.neighbors >= 1,
            f"{p}.neighbors",
            f"must be >= 1 or null, got {self.neighbors}",
        )
        _check(
            0 <= self.grow_rounds <= 8,
            f"{p}.grow_rounds",
            f"must be in [0, 8], got {self.grow_rounds}",
        )
        _check(self.resolution > 0, f"{p}.resolution", f"must be > 0, got {self.resolution}")
        _check(self.time_budget > 0, f"{p}.time_budget", f"must be > 0, got {self.time_budget}")
        _check(
            self.eval_time_budget > 0,
            f"{p}.eval_time_budget",
            f"must be > 0, got {self.eval_time_budget}",
        )
        _check(self.workers >= 0, f"{p}.workers", f"must be >= 0, got {self.workers}")
        why = validate_mode(self.data_paths)
        _check(why is None, f"{p}.data_paths", why or "")
        _check(
            self.data_check in (None, "discretized", "certified"),
            f"{p}.data_check",
            f"must be certified, discretized or null; got {self.data_check!r}",
        )
        _check(
            self.data_paths is None or self.smooth_data is None,
            f"{p}.smooth_data",
            "is the earlier spelling of data_paths; set only data_paths "
            "(raw for false, shortcut for true)",
        )
        for i, o in enumerate(self.per_env):
            o.validate(f"{p}.per_env[{i}]")
        names = [o.env for o in self.per_env]
        _check(
            len(set(names)) == len(names), f"{p}.per_env", f"lists an environment twice: {names}"
        )

    def _for(self, env: str, key: str) -> float:
        for o in self.per_env:
            if o.env == env and getattr(o, key) is not None:
                return getattr(o, key)
        return getattr(self, key)

    def name_for(self, env: str) -> str:
        """The planner of ``env``: its ``per_env`` name, else ``name``."""
        return self._for(env, "name")

    def time_budget_for(self, env: str) -> float:
        """BIT* data-generation seconds per query for ``env``."""
        return self._for(env, "time_budget")

    def eval_time_budget_for(self, env: str) -> float:
        """BIT* evaluation seconds per query for ``env``."""
        return self._for(env, "eval_time_budget")

    def data_paths_for(self, env: str):
        """The data paths of ``env`` (:mod:`ntq_jax.planners.path_modes`; None: the planner's default)."""
        mode = self._for(env, "data_paths")
        if mode is None and self.smooth_data is not None:
            return "shortcut" if self.smooth_data else "raw"
        return mode


#: The ensemble rows ``eval.ensemble`` can ask for (all of them by default).
ENSEMBLE_ROWS = ("ens", "best", "cascade")


@dataclasses.dataclass(frozen=True)
class EvalConfig:
    """Neural planner evaluation.

    Attributes:
        k_test: test queries of each kind (uniform and non-trivial).
        n_plan: PNet steps per plan (Alg. 1).
        steer: evaluate with steerTo (True) and/or without (False).
        delta: goal tolerance of the variant without steerTo, in the robot's cost
            metric (Euclidean for the point robot and the arm's joints;
            ``||dp|| + angle_weight * |dtheta|`` on the shortest arc for the rigid
            body); a start already within it is reached with a path of one state.
        delta_norm: the distance of that goal test: null or ``robot`` (the robot's
            metric, above) or ``l2`` (``||pi_end - x_g||_2`` on the raw state
            vector, angles not wrapped: the paper's text). Left out of the hash when null.
        nosteer_check: without steerTo, success needs every segment collision-free
            (null or true, ours); false is the paper's "only executing the lines 8
            and 9" of Alg. 1 (success once the goal test passes, the path's
            segments not checked); ``states``: every state of the path valid, its
            segments not checked; ``replan``: the goal test replaces only line 4's
            steerTo, the goal is appended once it passes and lines 10-14 run as with
            steerTo (contraction, every segment checked, neural replanning). Left out
            of the hash when null.
        replan_rounds: neural replanning rounds.
        replan_steps: PNet predictions per repaired segment in a replanning round.
        bidirectional: MPNet's bidirectional coarse plan instead of Alg. 1's forward one.
        query_padding: padding at which test queries are sampled (valid and
            non-trivial); 0 = the evaluation geometry (default), null = the
            environment's. Training data lives at the environment's padding, so
            at 0 some test queries have an endpoint inside that band, where no
            training state lies: every result row also reports the success of the
            "in band" queries (both endpoints valid at the environment's padding)
            and of the "out of band" ones apart (``n_in_band``,
            ``success_in_band``, ``success_out_band`` and their intervals).
        gamma_queries: uniform queries for gamma_nt (padding 0) in the table
            headings when the dataset metadata has none.
        chunk: test queries per jitted planner call.
        motion_check: how the evaluation decides that a path is collision-free:
            ``certified`` (default: every configuration of every segment proven
            clear, so a success is a collision-free path) or ``discretized``
            (states the robot's ``resolution`` apart, what the paper does; it can
            miss a shallow clip between two checked states). Used for the neural
            planner's feasibility check (success) and to verify the reference
            planner's paths; the planner's own steerTo keeps the discretised check.
            The point robot's check is exact either way.
        ensemble: the ensemble rows evaluated beside the members' (needs at least two
            members): ``ens`` is the ensemble neural planner (``PNet_ens``: every
            member proposes each next state and a fixed rule picks one; see
            :mod:`ntq_jax.neural.driver`), ``best`` the best-of-N baseline
            (``PNet_best-of-<N>``: per query the cheapest successful path of the N
            members' own plans, computed from their saved results without
            replanning, timed as the sum of their planning times), ``cascade`` the
            members as fallbacks (``PNet_cascade``: the member with the best success
            on validation queries plans every query, the next the ones still
            unsolved, and so on; :func:`ntq_jax.neural.driver.plan_cascade`).
            ``null`` (default) is all three, ``[ens, best, cascade]``; ``[]``
            evaluates the members only. Left out of the config hash when null, so
            run folders made before the option existed are reopened (and get the
            rows) on a rerun.
    """

    k_test: int = 500
    n_plan: int = 50
    steer: tuple[bool, ...] = (True,)
    delta: float = 1.0
    delta_norm: Optional[str] = None
    nosteer_check: typing.Union[bool, str, None] = None
    replan_rounds: int = 5
    replan_steps: int = 20
    bidirectional: bool = False
    query_padding: Optional[float] = 0.0
    gamma_queries: int = 200_000
    chunk: int = 1024
    motion_check: str = "certified"
    ensemble: Optional[tuple[str, ...]] = None

    # left out of to_dict (and so of the config hash) when None: configs hash as before
    _OMIT_NONE = ("ensemble", "delta_norm", "nosteer_check")

    @property
    def ensemble_rows(self) -> tuple[str, ...]:
        """The ensemble rows to evaluate: ``ensemble``, or all of :data:`ENSEMBLE_ROWS` when null."""
        return ENSEMBLE_ROWS if self.ensemble is None else self.ensemble

    def validate(self, p: str):
        for i, e in enumerate(self.ensemble_rows):
            _check(
                e in ENSEMBLE_ROWS,
                f"{p}.ensemble[{i}]",
                f"must be one of {', '.join(ENSEMBLE_ROWS)}, got {e!r}",
            )
        _check(
            len(set(self.ensemble_rows)) == len(self.ensemble_rows),
            f"{p}.ensemble",
            f"lists a row twice: {list(self.ensemble_rows)}",
        )
        _check(
            self.motion_check in ("discretized", "certified"),
            f"{p}.motion_check",
            f"must be certified or discretized, got {self.motion_check!r}",
        )
        _check(self.k_test >= 1, f"{p}.k_test", f"must be >= 1, got {self.k_test}")
        _check(self.n_plan >= 1, f"{p}.n_plan", f"must be >= 1, got {self.n_plan}")
        _check(len(self.steer) >= 1, f"{p}.steer", "must list at least one of true, false")
        _check(self.delta > 0, f"{p}.delta", f"must be > 0, got {self.delta}")
        _check(
            self.delta_norm in (None, "robot", "l2"),
            f"{p}.delta_norm",
            f"must be robot, l2 or null, got {self.delta_norm!r}",
        )
        _check(
            self.nosteer_check in (None, *NOSTEER_CHECKS),
            f"{p}.nosteer_check",
            f"must be true, false, states, replan or null, got {self.nosteer_check!r}",
        )
        _check(
            self.replan_rounds >= 0, f"{p}.replan_rounds", f"must be >= 0, got {self.replan_rounds}"
        )
        _check(
            self.replan_steps >= 1, f"{p}.replan_steps", f"must be >= 1, got {self.replan_steps}"
        )
        _check(
            not (self.bidirectional and False in self.steer),
            f"{p}.bidirectional",
            "the bidirectional planner needs steerTo; remove false from eval.steer",
        )
        _check(
            self.query_padding is None or self.query_padding >= 0,
            f"{p}.query_padding",
            f"must be >= 0 or null, got {self.query_padding}",
        )
        _check(
            self.gamma_queries >= 1, f"{p}.gamma_queries", f"must be >= 1, got {self.gamma_queries}"
        )
        _check(self.chunk >= 1, f"{p}.chunk", f"must be >= 1, got {self.chunk}")
