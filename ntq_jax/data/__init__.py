"""Training data: dataset generation (Alg. 2), includeData (Alg. 4), the on-disk format.

* :mod:`ntq_jax.data.generate`: :func:`generate_datasets`, D0..D3 of one environment.
* :mod:`ntq_jax.data.options`: :class:`DataOptions`, its settings.
* :mod:`ntq_jax.data.pools`: the shared query pools and the mixing bits.
* :mod:`ntq_jax.data.include`: :func:`include_data` (Alg. 4).
* :mod:`ntq_jax.data.format`: :class:`Dataset`, :func:`load_dataset`, :func:`load_datasets`.
* :mod:`ntq_jax.data.synthetic`: :func:`straight_line_rows` for tests and benchmarks.
"""

from ntq_jax.data.format import (
    ARRAY_SPECS,
    FORMAT,
    FORMAT_VERSION,
    Dataset,
    DatasetError,
    dataset_names,
    load_dataset,
    load_datasets,
    plot_environment,
)
from ntq_jax.data.generate import generate_datasets
from ntq_jax.data.include import include_data
from ntq_jax.data.options import PAPER_DATASETS, DataOptions, DatasetSpec
from ntq_jax.data.pools import mixing_bits, run_keys
from ntq_jax.data.synthetic import straight_line_rows

__all__ = [
    "Dataset",
    "DatasetError",
    "ARRAY_SPECS",
    "FORMAT",
    "FORMAT_VERSION",
    "dataset_names",
    "load_dataset",
    "load_datasets",
    "plot_environment",
    "generate_datasets",
    "DataOptions",
    "DatasetSpec",
    "PAPER_DATASETS",
    "include_data",
    "mixing_bits",
    "run_keys",
    "straight_line_rows",
]
