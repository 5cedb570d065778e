import jax


def require_x64(where: str) -> None:
    """Raise a clear error when JAX runs in float32 mode.

    Simulation, navigation and physical fits need float64: the drift rates of interest are
    ~1e-6 rad/s against carrier phases of ~1e4 rad.
    """
    if not jax.config.read("jax_enable_x64"):
        raise RuntimeError(
            f"{where} needs float64 but JAX is in float32 mode. Turn it on before any JAX "
            "work with `jax.config.update('jax_enable_x64', True)` (or set the environment "
            "variable JAX_ENABLE_X64=1)."
        )
