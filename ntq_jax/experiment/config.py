"""Typed, frozen configuration loaded from YAML, with command-line overrides.

A config file is a YAML mapping whose sections mirror the dataclasses of
:mod:`ntq_jax.experiment.sections` (``sampling``, ``data``, ``planner``, ``eval``),
:class:`~ntq_jax.models.ModelConfig` (``model``) and
:class:`~ntq_jax.training.config.TrainConfig` (``train``). Every key
is checked: an unknown or misspelled key, a wrong type or an impossible value
raises one :class:`ConfigError` naming the key and the file, e.g.::

    ConfigError: configs/point.yaml: data.k_trian: unknown key; did you mean 'k_train'?

Overrides use dotted keys with YAML values: ``--set data.k_train=100 --set
eval.steer=[true,false]`` (see :func:`apply_overrides`). Files and overrides read
``5e-2``, ``1e-9`` and ``1e9`` as numbers (YAML 1.2, as other YAML readers do;
PyYAML's YAML 1.1 needs a dot, ``5.0e-2``), and an integer key takes a whole
number written so (``gamma_queries: 1e9``).
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
import re
import types
import typing
from pathlib import Path
from typing import Optional

import yaml

from ntq_jax import artifacts
from ntq_jax.data.options import DataOptions
from ntq_jax.data.options import DatasetSpec as CoreDatasetSpec
from ntq_jax.errors import ConfigError
from ntq_jax.errors import check_config as _check
from ntq_jax.experiment.sections import (
    DATA_PATH_MODES,
    ENSEMBLE_ROWS,
    PLANNERS,
    PRUNE_GAMMA,
    DataConfig,
    DataEnvOverride,
    DatasetSpec,
    EvalConfig,
    PlannerConfig,
    PlannerEnvOverride,
    SamplingConfig,
    validate_mode,
)
from ntq_jax.models import ModelConfig
from ntq_jax.neural.options import PlannerOptions
from ntq_jax.planners.jobs import PlannerSettings
from ntq_jax.training.config import TrainConfig

__all__ = [
    "Config",
    "ConfigError",
    "load",
    "from_dict",
    "apply_overrides",
    "ModelConfig",
    "TrainConfig",
    "SamplingConfig",
    "DatasetSpec",
    "DataEnvOverride",
    "DataConfig",
    "PlannerEnvOverride",
    "PlannerConfig",
    "EvalConfig",
    "PLANNERS",
    "DATA_PATH_MODES",
    "PRUNE_GAMMA",
    "ENSEMBLE_ROWS",
    "validate_mode",
    "planner_settings",
    "data_options",
    "train_args",
    "neural_options",
]


#: the values of ``task`` (the run folder's name; ``panda``: the 7-DoF arm in 3-D scenes)
TASKS = ("point", "rigid", "nlink", "panda")


class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader reading ``5e-2`` and ``1e9`` as numbers (see the module docstring)."""


_Loader.yaml_implicit_resolvers = {
    k: list(v) for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def yaml_load(text: str):
    """``text`` parsed as YAML by the configs' rules (``5e-2`` a number)."""
    return yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass


@dataclasses.dataclass(frozen=True)
class Config:
    """A whole experiment: environments, then every stage of the pipeline.

    Attributes:
        task: ``point``, ``rigid``, ``nlink`` or ``panda`` (names the run folder; the robot,
            and so the table a map's rows go to, comes from each environment, so
            one config may mix robots).
        envs: preset names or JSON map paths.
        seed: master seed; every stage derives its keys from it.
        out_dir: where run folders are written.
        executor: where the host-side planning chunks run, ``local`` (null, the
            default: in this process) or ``ray`` (Ray tasks, :mod:`ntq_jax.executors`);
            the scripts' ``--executor`` overrides it.
        ray_address: the Ray cluster to join with ``executor: ray`` (``auto``: the
            one ``ray start`` made on this node; null: start a local instance);
            ``--ray-address`` overrides it.

    ``executor`` and ``ray_address`` say where the work runs, not what is
    computed: they are not part of :meth:`hash`, so a run folder made with one
    executor is resumed with the other.
    """

    task: str = "point"
    envs: tuple[str, ...] = ("point/0", "point/1", "point/2", "point/3")
    seed: int = 0
    out_dir: str = "runs"
    executor: Optional[str] = None
    ray_address: Optional[str] = None
    sampling: SamplingConfig = dataclasses.field(default_factory=SamplingConfig)
    data: DataConfig = dataclasses.field(default_factory=DataConfig)
    planner: PlannerConfig = dataclasses.field(default_factory=PlannerConfig)
    model: ModelConfig = dataclasses.field(default_factory=ModelConfig)
    train: TrainConfig = dataclasses.field(default_factory=TrainConfig)
    eval: EvalConfig = dataclasses.field(default_factory=EvalConfig)

    _OMIT_NONE = ("executor", "ray_address")
    #: keys that say where the work runs, not what it computes (left out of :meth:`hash`)
    RUNTIME_KEYS = ("executor", "ray_address")

    def validate(self, p: str = ""):
        pre = f"{p}." if p else ""
        _check(
            self.executor in (None, "local", "ray"),
            f"{pre}executor",
            f"must be local or ray (or null: local), got {self.executor!r}",
        )
        _check(
            self.ray_address is None or bool(self.ray_address.strip()),
            f"{pre}ray_address",
            "must be auto, <host>:<port> or null (start a local Ray instance)",
        )
        _check(
            self.task in TASKS,
            f"{pre}task",
            f"must be point, rigid, nlink or panda; got {self.task!r}",
        )
        _check(len(self.envs) >= 1, f"{pre}envs", "must list at least one environment")
        _check(self.seed >= 0, f"{pre}seed", f"must be >= 0, got {self.seed}")
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if dataclasses.is_dataclass(v):
                v.validate(f"{pre}{f.name}")

    def to_dict(self) -> dict:
        return _to_plain(self)

    def hash(self) -> str:
        """A short stable hash of the resolved config (for metadata and resume checks)."""
        plain = {k: v for k, v in self.to_dict().items() if k not in self.RUNTIME_KEYS}
        return artifacts.fingerprint(plain)


# ---------------------------------------------------------------------------
# Generic typed loading
# ---------------------------------------------------------------------------


def _to_plain(obj):
    if dataclasses.is_dataclass(obj):
        omit = getattr(obj, "_OMIT_NONE", ())
        return {
            f.name: _to_plain(getattr(obj, f.name))
            for f in dataclasses.fields(obj)
            if not (f.name in omit and getattr(obj, f.name) is None)
        }
    if isinstance(obj, tuple):
        return [_to_plain(v) for v in obj]
    return obj


def _type_name(tp) -> str:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) > 1:
            return " or ".join(_type_name(a) for a in args)
        return f"{_type_name(args[0])} or null"
    if origin is tuple:
        return f"list of {_type_name(typing.get_args(tp)[0])}"
    return getattr(tp, "__name__", str(tp))


def _coerce(value, tp, key: str):
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            if type(None) in typing.get_args(tp):
                return None
            raise ConfigError(f"{key}: expected {_type_name(tp)}, got null")
        if len(args) > 1:  # e.g. prune: bool, a number or a string, chosen by the value's type
            for a in args:
                if (
                    (a is bool and isinstance(value, bool))
                    or (
                        a is float
                        and isinstance(value, (int, float))
                        and not isinstance(value, bool)
                    )
                    or (a is str and isinstance(value, str))
                ):
                    return _coerce(value, a, key)
            raise ConfigError(f"{key}: expected {_type_name(tp)}, got {value!r}")
        return _coerce(value, args[0], key)
    if origin is tuple:
        (item,) = [a for a in typing.get_args(tp) if a is not Ellipsis]
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{key}: expected a list of {_type_name(item)}, got {value!r}")
        return tuple(_coerce(v, item, f"{key}[{i}]") for i, v in enumerate(value))
    if dataclasses.is_dataclass(tp):
        return _from_dict(tp, value, key)
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}: expected true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, float) and value.is_integer() and abs(value) < 2**63:
            value = int(value)  # 1e9
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key}: expected an integer, got {value!r}")
        return value
    if tp is float:
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
        ):
            raise ConfigError(f"{key}: expected a finite number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{key}: expected a string, got {value!r}")
        return value
    raise TypeError(f"unsupported config type {tp}")  # pragma: no cover (programming error)


def _from_dict(cls, data, prefix: str):
    if not isinstance(data, dict):
        raise ConfigError(f"{prefix or 'config'}: expected a mapping, got {data!r}")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    kwargs = {}
    for k, v in data.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        if k not in names:
            close = difflib.get_close_matches(str(k), names, n=1)
            hint = (
                f"; did you mean {close[0]!r}?" if close else f"; allowed keys: {', '.join(names)}"
            )
            raise ConfigError(f"{key}: unknown key{hint}")
        kwargs[k] = _coerce(v, hints[k], key)
    return cls(**kwargs)


def from_dict(data: dict, where: str = "config") -> Config:
    """Builds and validates a :class:`Config` from a plain dict."""
    try:
        cfg = _from_dict(Config, data or {}, "")
        cfg.validate()
    except ConfigError as e:
        raise ConfigError(f"{where}: {e}") from None
    return cfg


def _set_dotted(data: dict, dotted: str, value):
    parts = dotted.split(".")
    cur = data
    for p in parts[:-1]:
        nxt = cur.get(p)
        if nxt is None:
            nxt = cur[p] = {}
        if not isinstance(nxt, dict):
            raise ConfigError(f"override {dotted}: {p} is not a section")
        cur = nxt
    cur[parts[-1]] = value


def apply_overrides(data: dict, overrides: list[str] | None) -> dict:
    """Applies ``key.sub=value`` overrides (values parsed as YAML) to a plain dict."""
    data = json.loads(json.dumps(data or {}))
    for ov in overrides or []:
        if "=" not in ov:
            raise ConfigError(f"override {ov!r}: expected KEY=VALUE, e.g. data.k_train=100")
        k, v = ov.split("=", 1)
        try:
            value = yaml_load(v)
        except yaml.YAMLError as e:
            why = getattr(e, "problem", None) or type(e).__name__
            raise ConfigError(
                f"override {ov!r}: the value is not valid YAML ({why}); quote "
                "it in the shell, e.g. --set 'envs=[point/0, point/1]'"
            ) from None
        _set_dotted(data, k.strip(), value)
    return data


def load(path: str | Path | None = None, overrides: list[str] | None = None) -> Config:
    """Loads a YAML config (or the defaults when ``path`` is None) and applies overrides.

    Raises:
        ConfigError: missing or unparsable file, unknown key, wrong type or
            impossible value; the message names the file and the key.
    """
    where = str(path) if path is not None else "defaults"
    data: dict = {}
    if path is not None:
        p = Path(path)
        if not p.is_file():
            raise ConfigError(f"{where}: config file not found")
        try:
            data = yaml_load(p.read_text(encoding="utf-8")) or {}
        except UnicodeDecodeError:
            raise ConfigError(
                f"{where}: not a text (UTF-8) file; a config is YAML, e.g. configs/point.yaml"
            ) from None
        except yaml.YAMLError as e:
            raise ConfigError(f"{where}: not valid YAML: {e}") from None
    if overrides:
        where += " (with overrides " + ", ".join(overrides) + ")"
    return from_dict(apply_overrides(data, overrides), where)


# ---------------------------------------------------------------------------
# The core's options of a Config
# ---------------------------------------------------------------------------


def planner_settings(cfg: Config, env_name: str) -> PlannerSettings:
    """``cfg``'s planner settings for environment ``env_name`` (its ``per_env`` overrides
    applied; the roadmap's seed is the run's, the motion check the evaluation's)."""
    pc = cfg.planner
    return PlannerSettings(
        name=pc.name_for(env_name),
        resolution=pc.resolution,
        milestones=pc.milestones,
        neighbors=pc.neighbors,
        grow_rounds=pc.grow_rounds,
        roadmap_seed=cfg.seed,
        time_budget=pc.time_budget_for(env_name),
        eval_time_budget=pc.eval_time_budget_for(env_name),
        workers=pc.workers,
        data_paths=pc.data_paths_for(env_name),
        motion_check=cfg.eval.motion_check,
        data_check=pc.data_check or "discretized",
    )


def data_options(cfg: Config, env_name: str) -> DataOptions:
    """The :class:`~ntq_jax.data.DataOptions` of ``cfg`` for environment ``env_name``
    (``seed``, ``sampling``, ``data`` and ``planner``, per-env overrides applied);
    the datasets record the whole resolved config and its :meth:`Config.hash`."""
    dc = cfg.data
    return DataOptions(
        seed=cfg.seed,
        k_train=dc.k_train_for(env_name),
        datasets=tuple(CoreDatasetSpec(s.p_nt, s.prune) for s in dc.datasets),
        n_max=cfg.sampling.n_max,
        prune_padding=dc.prune_padding,
        chunk=dc.chunk,
        gamma_queries=dc.gamma_queries,
        gamma_eval=dc.gamma_eval,
        paths_from=dc.paths_from_for(env_name),
        planner=planner_settings(cfg, env_name),
        record=cfg.to_dict(),
        record_hash=cfg.hash(),
    )


def train_args(cfg: Config) -> dict:
    """The keyword arguments of :func:`ntq_jax.training.train_from_folder` for ``cfg``
    (``model``, ``train``, ``seed``; the checkpoints record the whole resolved config)."""
    return {"model": cfg.model, "train": cfg.train, "seed": cfg.seed, "record": cfg.to_dict()}


def neural_options(ev: EvalConfig, steer: bool | None = None) -> PlannerOptions:
    """The neural planner's :class:`~ntq_jax.neural.options.PlannerOptions` of ``ev``
    (``steer`` overrides its first entry)."""
    return PlannerOptions(
        n_plan=ev.n_plan,
        steer=ev.steer[0] if steer is None else bool(steer),
        delta=ev.delta,
        delta_norm=ev.delta_norm or "robot",
        nosteer_check=True if ev.nosteer_check is None else ev.nosteer_check,
        replan_rounds=ev.replan_rounds,
        replan_steps=ev.replan_steps,
        bidirectional=ev.bidirectional,
        eval_check=ev.motion_check,
    )
