"""The experiment layer: the paper's experiment as an application built on the core.

* :mod:`~ntq_jax.experiment.config` (+ :mod:`~ntq_jax.experiment.sections`): typed,
  frozen YAML configs with overrides;
* :mod:`~ntq_jax.experiment.pipeline`: data -> training -> evaluation -> report, resumable;
* :mod:`~ntq_jax.experiment.evaluate` (+ :mod:`~ntq_jax.experiment.references`,
  :mod:`~ntq_jax.experiment.metrics`): the neural planner on test queries, against
  their reference plans, success and cost ratios;
* :mod:`~ntq_jax.experiment.report` (+ :mod:`~ntq_jax.experiment.paired`,
  :mod:`~ntq_jax.experiment.formatting`): tables and figures of a run, the paired
  comparisons between its models;
* :mod:`~ntq_jax.experiment.summaries`, :mod:`~ntq_jax.experiment.reproduction`
  (+ :mod:`~ntq_jax.experiment.paper`, :mod:`~ntq_jax.experiment.verdict_tables`,
  :mod:`~ntq_jax.experiment.seed_tables`): committed per-map summaries and
  ``REPRODUCTION.md``;
* :mod:`~ntq_jax.experiment.claims` (+ :mod:`~ntq_jax.experiment.quantities`,
  :mod:`~ntq_jax.experiment.claim_lines`, :mod:`~ntq_jax.experiment.verdicts`): the
  paper's claims, the training seed a random effect, Holm's correction and the verdicts;
* :mod:`~ntq_jax.experiment.curve`: the data-efficiency curve;
* :mod:`~ntq_jax.experiment.cli`: the scripts' shared options and one-line errors.

The core (every other module of :mod:`ntq_jax`) never imports this layer.
"""
