import os

# The test process keeps no compile cache on disk (the cache tests run their own processes
# with their own folders); the CLI tests would otherwise fill the user's ~/.cache/hrgjax.
os.environ.setdefault("HRGJAX_NO_CACHE", "1")

import jax  # noqa: E402
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
jax.config.update("jax_numpy_rank_promotion", "raise")


@pytest.fixture(scope="session")
def key():
    return jax.random.key(0)
