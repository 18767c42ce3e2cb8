"""Configuration: typed loading, overrides, and one clear error per bad input."""

from pathlib import Path

import numpy as np
import pytest

from ntq_jax.experiment import config
from ntq_jax.experiment.config import ConfigError

CONFIGS = sorted(Path(__file__).resolve().parents[1].joinpath("configs").glob("*.yaml"))


def test_every_shipped_config_loads():
    assert len(CONFIGS) >= 6
    for path in CONFIGS:
        cfg = config.load(path)
        assert cfg.envs and cfg.data.k_train >= 1


def test_defaults_are_the_papers_datasets():
    cfg = config.load()
    assert [(d.p_nt, d.prune) for d in cfg.data.datasets] == [
        (0.0, False),
        (0.5, False),
        (1.0, False),
        (1.0, True),
    ]
    assert cfg.train.optimizer == "adagrad" and cfg.train.learning_rate == 0.01


def test_numbers_without_a_dot_are_numbers_in_files_and_overrides(tmp_path):
    """PyYAML (YAML 1.1) read 5e-2, 1e-9 and 1e9 as strings ("expected a finite number,
    got '5e-2'"): configs and --set read them as numbers, whole ones for integer keys."""
    f = tmp_path / "c.yaml"
    f.write_text("planner:\n  data_paths: 5e-2\n  time_budget: 3e0\ndata:\n  gamma_queries: 1e5\n")
    cfg = config.load(f, ["sampling.n_max=1e3", "data.prune_padding=+1E-1", "eval.k_test=2e2"])
    assert cfg.planner.data_paths == 0.05 and cfg.planner.time_budget == 3.0
    assert cfg.data.gamma_queries == 100000 and isinstance(cfg.data.gamma_queries, int)
    assert cfg.sampling.n_max == 1000 and cfg.data.prune_padding == 0.1 and cfg.eval.k_test == 200
    assert (
        cfg.hash()
        == config.load(
            None,
            [
                "planner.data_paths=0.05",
                "planner.time_budget=3.0",
                "data.gamma_queries=100000",
                "sampling.n_max=1000",
                "data.prune_padding=0.1",
                "eval.k_test=200",
            ],
        ).hash()
    )
    with pytest.raises(ConfigError, match=r"data\.gamma_queries: expected an integer, got 1\.5"):
        config.load(None, ["data.gamma_queries=1.5e0"])
    assert config.load(None, ["out_dir='1e3'"]).out_dir == "1e3"  # quoted: a string


def test_config_is_frozen_and_hash_is_stable():
    a, b = config.load(CONFIGS[0]), config.load(CONFIGS[0])
    assert a == b and a.hash() == b.hash()
    with pytest.raises(Exception):
        a.seed = 3  # type: ignore[misc]
    c = config.load(CONFIGS[0], ["seed=1"])
    assert c.hash() != a.hash() and c.seed == 1


def test_overrides_parse_yaml_values():
    cfg = config.load(None, ["data.k_train=7", "eval.steer=[true, false]", "model.hidden=[8, 4]"])
    assert cfg.data.k_train == 7 and cfg.eval.steer == (True, False) and cfg.model.hidden == (8, 4)


@pytest.mark.parametrize(
    "text, key",
    [
        ("data:\n  k_trian: 5\n", "data.k_trian"),
        ("smapling: {}\n", "smapling"),
        ("data:\n  k_train: -3\n", "data.k_train"),
        ("data:\n  k_train: 2.5\n", "data.k_train"),
        ("data:\n  datasets: [{p_nt: 1.5}]\n", "data.datasets[0].p_nt"),
        ("data:\n  datasets: [{p_nt: -0.1, prune: true}]\n", "data.datasets[0].p_nt"),
        ("data:\n  datasets: [{p_nt: 0.5, prune: 3}]\n", "data.datasets[0].prune"),
        ("planner:\n  name: rrt\n", "planner.name"),
        ("train:\n  learning_rate: '0.1'\n", "train.learning_rate"),
        ("model:\n  hidden: []\n", "model.hidden"),
        ("eval:\n  k_test: 0\n", "eval.k_test"),
        ("envs: point/0\n", "envs"),
    ],
)
def test_bad_values_name_the_key_and_the_file(tmp_path, text, key):
    f = tmp_path / "bad.yaml"
    f.write_text(text)
    with pytest.raises(ConfigError) as e:
        config.load(f)
    msg = str(e.value)
    assert str(f) in msg and key in msg


def test_misspelled_key_suggests_the_right_one(tmp_path):
    f = tmp_path / "typo.yaml"
    f.write_text("train:\n  batch_sise: 10\n")
    with pytest.raises(ConfigError, match="did you mean 'batch_size'"):
        config.load(f)


def test_missing_and_unparsable_files(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        config.load(tmp_path / "nope.yaml")
    f = tmp_path / "broken.yaml"
    f.write_text("data: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        config.load(f)
    with pytest.raises(ConfigError, match="KEY=VALUE"):
        config.load(None, ["data.k_train"])


def test_per_env_planner_and_training_seed():
    from ntq_jax import make_env
    from ntq_jax.experiment.evaluate import task_of
    from ntq_jax.experiment.pipeline import load_config

    cfg = load_config(None, [])  # the embedded default: four point maps and rigid/0
    assert cfg.envs[-1] == "rigid/0"
    assert [cfg.planner.name_for(e) for e in cfg.envs] == ["astar"] * 4 + ["roadmap"]
    assert [task_of(make_env(e)) for e in ("point/1", "rigid/0", "nlink/4")] == [
        "point",
        "rigid",
        "nlink",
    ]
    # a per-map planner that does not exist is one error naming the key
    with pytest.raises(ConfigError, match=r"planner\.per_env\[0\]\.name"):
        load_config(None, ["planner.per_env=[{env: rigid/0, name: rrt}]"])
    # no name: the config's planner, and the key stays out of the hash
    plain = config.load(None, ["planner.per_env=[{env: rigid/0, time_budget: 1.0}]"])
    assert plain.planner.name_for("rigid/0") == plain.planner.name
    assert "name" not in plain.to_dict()["planner"]["per_env"][0]
    # train.seed: null is the run's seed (and hashes as before); a value retrains
    assert cfg.train.seed is None and cfg.train.seed_for(cfg.seed) == cfg.seed
    assert "seed" not in cfg.to_dict()["train"]
    other = load_config(None, ["train.seed=2"])
    assert other.train.seed_for(other.seed) == 2 and other.hash() != cfg.hash()
    with pytest.raises(ConfigError, match=r"train\.seed"):
        load_config(None, ["train.seed=-1"])


def test_smooth_data_reaches_the_data_planner_only():
    """planner.smooth_data: null keeps the hash and the planners' default (shortcut paths);
    false reaches astar/roadmap data generation, never the evaluation reference."""
    from ntq_jax import make_env
    from ntq_jax.experiment.pipeline import load_config
    from ntq_jax.planners import plan
    from ntq_jax.planners.jobs import planner_options

    cfg = load_config(None, [])
    assert "smooth_data" not in cfg.to_dict()["planner"]
    assert "smooth" not in planner_options(config.planner_settings(cfg, "point/0"))
    # the embedded default resamples rigid/0's (shortcut) roadmap paths: data_paths 0.6
    assert planner_options(config.planner_settings(cfg, "rigid/0"))["smooth"] is True
    raw = load_config(None, ["planner.smooth_data=false", "planner.per_env=[]"])
    assert raw.hash() != cfg.hash()
    assert planner_options(config.planner_settings(raw, "rigid/0"))["smooth"] is False
    assert planner_options(config.planner_settings(raw, "point/0"))["smooth"] is False
    assert "smooth" not in planner_options(config.planner_settings(raw, "rigid/0"), evaluation=True)
    with pytest.raises(ConfigError, match=r"planner\.smooth_data"):
        load_config(None, ["planner.smooth_data=maybe"])
    # the option changes the paths: raw grid paths keep their many cell centres
    env = make_env("point/0")
    rng = np.random.default_rng(0)
    lo, hi = np.asarray(env.world.bounds)[:, 0], np.asarray(env.world.bounds)[:, 1]
    q = rng.uniform(lo, hi, (40, 2, 2)).astype(np.float32)
    kw = planner_options(config.planner_settings(raw, "point/0"))
    smooth = plan(env, q, "astar", padding=env.padding, resolution=kw["resolution"])
    rough = plan(env, q, "astar", padding=env.padding, **kw)
    both = (smooth.lengths >= 2) & (rough.lengths >= 2)
    assert both.sum() >= 10
    assert np.all(rough.lengths[both] >= smooth.lengths[both])
    assert np.mean(rough.lengths[both]) > 3 * np.mean(smooth.lengths[both])


def test_the_embedded_default_is_one_yaml_shipped_with_the_package():
    """``train_all.py`` without --config reads ``ntq_jax/experiment/default.yaml`` (package
    data, so a non-editable install has it); its keys are checked like any config file's."""
    import importlib.resources
    import tomllib
    from pathlib import Path

    from ntq_jax.experiment import pipeline

    res = importlib.resources.files("ntq_jax.experiment") / "default.yaml"
    assert res.is_file() and pipeline.DEFAULT["envs"][-1] == "rigid/0"
    pyproject = tomllib.loads(
        (Path(__file__).resolve().parent.parent / "pyproject.toml").read_text()
    )
    assert "default.yaml" in pyproject["tool"]["setuptools"]["package-data"]["ntq_jax.experiment"]
    cfg = pipeline.load_config(None, [])
    assert cfg.planner.name_for("rigid/0") == "roadmap" and cfg.data.k_train == 600


def test_the_config_maps_onto_the_cores_options():
    """Issue 51: the core's option dataclasses default to what a config without keys
    says, and a config's per-env settings reach them."""
    from ntq_jax.data import DataOptions
    from ntq_jax.models import ModelConfig
    from ntq_jax.neural import PlannerOptions
    from ntq_jax.training import TrainConfig

    base = config.load(None)
    assert config.data_options(base, "point/0") == DataOptions()
    assert config.neural_options(base.eval) == PlannerOptions()
    args = config.train_args(base)
    assert (args["model"], args["train"], args["seed"]) == (ModelConfig(), TrainConfig(), 0)
    cfg = config.load(
        None,
        [
            "seed=3",
            "data.per_env=[{env: point/1, k_train: 7}]",
            "planner.per_env=[{env: point/1, name: visgraph}]",
        ],
    )
    o = config.data_options(cfg, "point/1")
    assert (o.seed, o.k_train, o.planner.name, o.planner.roadmap_seed) == (3, 7, "visgraph", 3)
    assert o.recorded() == cfg.to_dict() and o.recorded_hash() == cfg.hash()
    assert config.data_options(cfg, "point/0").k_train == cfg.data.k_train
