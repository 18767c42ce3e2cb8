import os
import tempfile
from pathlib import Path

# Tests run on the CPU; keep XLA from grabbing every core's worth of threads twice.
os.environ.setdefault("JAX_PLATFORMS", "cpu")

# One persistent compilation cache for the whole suite: both xdist workers, the scripts the
# tests run in subprocesses and the Ray workers (they inherit the environment) reuse each
# other's compiled programs instead of compiling the same kernels again. A cached program is
# the program XLA would compile (same HLO, same flags), so no result changes.
# NTQ_TEST_COMPILE_CACHE=0 turns it off.
if os.environ.get("NTQ_TEST_COMPILE_CACHE", "1") != "0":
    _cache = Path(tempfile.gettempdir()) / f"ntq_jax-test-jax-cache-{os.getuid()}"
    os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(_cache))
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")


def pytest_configure(config):
    """Turns the cache on in this process too (JAX reads the variables at import)."""
    if os.environ.get("NTQ_TEST_COMPILE_CACHE", "1") == "0":
        return
    import jax
    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update("jax_persistent_cache_min_compile_time_secs",
                      float(os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"]))
