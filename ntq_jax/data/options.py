"""The settings of one environment's dataset generation: :class:`DataOptions`.

Usage::

    from ntq_jax import data, make_env
    opts = data.DataOptions(seed=0, k_train=400, gamma_queries=200_000)
    summary = data.generate_datasets(make_env("point/0"), opts, "runs/data")

The defaults are the paper's (D0..D3, the A* planner). The experiment layer maps
its YAML config onto these options (``ntq_jax.experiment.config.data_options``).
"""

from __future__ import annotations

import dataclasses
import json
from typing import NamedTuple, Optional, Union

from ntq_jax import artifacts
from ntq_jax.planners.jobs import PlannerSettings

__all__ = ["DatasetSpec", "PAPER_DATASETS", "DataOptions"]


class DatasetSpec(NamedTuple):
    """One dataset of Alg. 2: the non-trivial probability and Alg. 4's pruning.

    ``prune``: ``False`` keeps every sample; ``True`` drops every sample whose
    ``steer_to(pi_i, pi_end)`` is free (the paper's D3); a number ``p`` in [0, 1]
    drops each such sample with probability ``p``; ``"gamma"``: ``p`` = the map's
    gamma_nt at the data-generation padding; ``"keep_last"``: like ``True``, but
    each path keeps its step into the goal (:mod:`ntq_jax.data.include`).
    """

    p_nt: float
    prune: Union[bool, float, str] = False


#: The paper's D0..D3: ``p_nt`` 0, 0.5 and 1, and D3 = D2 pruned.
PAPER_DATASETS = (
    DatasetSpec(0.0, False),
    DatasetSpec(0.5, False),
    DatasetSpec(1.0, False),
    DatasetSpec(1.0, True),
)


@dataclasses.dataclass(frozen=True)
class DataOptions:
    """What :func:`ntq_jax.data.generate_datasets` follows for one environment.

    Attributes:
        seed: master seed (query pools, mixing bits, pruning, gamma_nt, planner seeds).
        k_train: queries per dataset.
        datasets: the datasets, named ``D0``, ``D1``, ... by position
            (:class:`DatasetSpec` s, or any objects with ``p_nt`` and ``prune``).
        n_max: attempts of the non-trivial sampler before it returns a trivial query.
        prune_padding: padding of the pruning steer_to (None: the environment's).
        chunk: queries per planning chunk written to disk (the resumable unit).
        gamma_queries: uniform queries of the gamma_nt estimates in the metadata.
        gamma_eval: also estimate gamma_nt at padding 0 (the evaluation geometry).
        paths_from: a folder of recorded data paths of this map
            (``scripts/record_paths.py``), taken instead of planning them.
        planner: the data planner and its settings (:class:`~ntq_jax.planners.jobs.PlannerSettings`).
        record: what ``<env_dir>/config.yaml`` records and ``meta.json``'s
            ``config_hash`` hashes (a plain dict; None: these options). The experiment
            layer passes its whole resolved config here.
        record_hash: ``config_hash`` (None: the fingerprint of ``record``).
    """

    seed: int = 0
    k_train: int = 3000
    datasets: tuple = PAPER_DATASETS
    n_max: int = 10_000
    prune_padding: Optional[float] = None
    chunk: int = 500
    gamma_queries: int = 1_000_000
    gamma_eval: bool = True
    paths_from: Optional[str] = None
    planner: PlannerSettings = dataclasses.field(default_factory=PlannerSettings)
    record: Optional[dict] = dataclasses.field(default=None, compare=False)
    record_hash: Optional[str] = dataclasses.field(default=None, compare=False)

    def recorded(self) -> dict:
        """The plain dict written to ``config.yaml`` (``record``, or these options)."""
        if self.record is not None:
            return self.record
        plain = dataclasses.asdict(dataclasses.replace(self, record=None, record_hash=None))
        del plain["record"], plain["record_hash"]
        plain["datasets"] = [[s.p_nt, s.prune] for s in self.datasets]
        return json.loads(json.dumps(plain, default=artifacts.json_default))  # YAML-ready

    def recorded_hash(self) -> str:
        """``meta.json``'s ``config_hash``: ``record_hash``, or the fingerprint of :meth:`recorded`."""
        if self.record_hash is not None:
            return self.record_hash
        return artifacts.fingerprint(self.recorded(), default=artifacts.json_default)
