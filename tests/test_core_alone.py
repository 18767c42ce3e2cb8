"""The core stands alone (issue 51): with ``ntq_jax.experiment`` unimportable, the
package imports, generates a tiny dataset and trains one epoch through the core API
(:class:`ntq_jax.data.DataOptions`, :func:`ntq_jax.training.train_from_folder`)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

_CHILD = textwrap.dedent("""
    import importlib.abc, json, sys
    from pathlib import Path

    class NoExperiment(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name == "ntq_jax.experiment" or name.startswith("ntq_jax.experiment."):
                raise ImportError(f"{name} is made unimportable by the test")
            return None

    sys.meta_path.insert(0, NoExperiment())

    import ntq_jax as nj
    from ntq_jax import data, training
    from ntq_jax.models import ModelConfig

    out = Path(sys.argv[1])
    env = nj.make_env("point/0")
    opts = data.DataOptions(seed=0, k_train=20, chunk=20, gamma_queries=2000,
                            gamma_eval=False)
    summary = data.generate_datasets(env, opts, out / "data", progress=False, figure=False)
    datasets = data.load_datasets(summary["env_dir"])
    ens, hist = training.train_from_folder(
        summary["env_dir"], out / "models", model=ModelConfig(hidden=(16, 16)),
        train=training.TrainConfig(epochs=1, batch_size=10), seed=0, progress=False)
    loaded = training.load_ensemble(out / "models")
    print("RESULT" + json.dumps({
        "datasets": [len(d.inputs) for d in datasets], "members": loaded.num_members,
        "epochs": int(hist.train_loss.shape[0]) if hist.train_loss.ndim else 0,
        "experiment": [m for m in sys.modules if m.startswith("ntq_jax.experiment")]}))
""")


def test_core_runs_without_the_experiment_layer(tmp_path):
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join([str(REPO), *filter(None, [os.environ.get("PYTHONPATH")])]),
    )
    r = subprocess.run(
        [sys.executable, "-c", _CHILD, str(tmp_path)],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    line = next(ln for ln in r.stdout.splitlines() if ln.startswith("RESULT"))
    res = json.loads(line[len("RESULT") :])
    assert res["experiment"] == []
    assert len(res["datasets"]) == 4 and all(n > 0 for n in res["datasets"][:3])
    assert res["members"] == 4
    assert (tmp_path / "data" / "point_0" / "config.yaml").is_file()
    assert (tmp_path / "models" / "ensemble").is_dir()
    # the default record: these options (no experiment config), written as YAML
    meta = json.loads((tmp_path / "data" / "point_0" / "D0" / "meta.json").read_text())
    assert meta["k_train"] == 20 and meta["config_hash"]
