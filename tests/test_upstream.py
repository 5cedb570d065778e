"""The upstream internals hrgjax reaches (`hrgjax/_upstream.py`), against the installed JAX,
equinox and optimistix. A failure here names the upstream attribute that moved or changed
its behaviour: the function of `_upstream.py` that guards it needs a new way in."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

from hrgjax import _cache, _upstream


def _moved(attribute: str, what: str) -> str:
    return f"upstream internal {attribute} changed ({what}); see hrgjax/_upstream.py"


def test_equinox_checks_switch_to_their_nan_form_and_back():
    import equinox._errors as errors

    assert _upstream.CAN_SWITCH_ERRORS, _moved(
        "equinox._errors.EQX_ON_ERROR / branched_error_if_impl_jit", "no longer there"
    )
    before = errors.EQX_ON_ERROR, errors.branched_error_if_impl_jit

    def inside(x):
        return eqx.error_if(x, x > 0, "upstream-check")

    def outside(x):
        return eqx.error_if(x, x > 0, "upstream-check")

    with _upstream.errors_as_nan():
        out = jax.jit(inside)(jnp.asarray(1.0))
        jaxpr = str(jax.make_jaxpr(inside)(jnp.asarray(1.0)))
    assert np.isnan(out), _moved(
        "equinox._errors.EQX_ON_ERROR", "set to 'nan' at trace time, error_if still raises"
    )
    assert "callback" not in jaxpr, _moved(
        "equinox._errors.EQX_ON_ERROR", "error_if in its NaN form still calls back to Python"
    )
    assert (errors.EQX_ON_ERROR, errors.branched_error_if_impl_jit) == before
    with pytest.raises(Exception, match="upstream-check"):
        jax.jit(outside)(jnp.asarray(1.0)).block_until_ready()


def test_trace_state_clean_tells_a_trace_from_the_top_level():
    seen = []
    note = lambda: seen.append(_upstream.trace_state_clean())  # noqa: E731
    note()
    jax.jit(lambda: (note(), jnp.ones(()))[1])()  # a trace with no traced input
    jax.vmap(lambda x: (note(), x)[1])(jnp.ones(2))
    jax.grad(lambda x: (note(), x**2)[1])(1.0)
    assert seen == [True, False, False, False], _moved(
        "jax._src.core.trace_state_clean", f"top level, jit, vmap, grad gave {seen}"
    )


def test_concrete_value_unwraps_an_eager_tracer_only():
    x = jnp.arange(3.0)
    assert _upstream.concrete_value(x) is x
    seen = {}

    def loss(y):
        seen["grad"] = _upstream.concrete_value(y)
        return jnp.sum(y**2)

    jax.grad(loss)(x)
    jax.jit(lambda y: seen.setdefault("jit", _upstream.concrete_value(y)) or y)(x)
    what = "jax.extend.core.concrete_or_error"
    assert seen["grad"] is not None, _moved(what, "an eager grad's tracer gave no value")
    np.testing.assert_array_equal(np.asarray(seen["grad"]), np.asarray(x))
    assert seen["jit"] is None, _moved(what, "a jit tracer gave a value")


def test_compile_cache_entries_decompress_and_damage_is_refused():
    from jax._src import compilation_cache as cc

    blob = cc.compress_executable(b"hrgjax" * 20)
    assert _upstream.decompress_executable(blob) == b"hrgjax" * 20, _moved(
        "jax._src.compilation_cache.decompress_executable", "no longer inverts compress"
    )
    with pytest.raises(Exception):  # noqa: B017 - zstd and zlib raise their own types
        _upstream.decompress_executable(blob[: len(blob) // 2])


def test_the_compile_cache_writes_through_hrgjax_store():
    from jax._src import compilation_cache as cc

    folder = _cache.enabled_folder()
    assert folder is not None, "the tests' conftest enables the compile cache"
    store = cc._cache
    assert type(store).__module__ == "hrgjax._cache" and store.path == folder, _moved(
        "jax._src.compilation_cache._cache", "hrgjax's store is not the one JAX uses"
    )
    before = set(folder.glob("*-cache"))
    jax.jit(lambda x: jnp.cos(x) * 1.2345 + 6.789)(jnp.ones((13, 7))).block_until_ready()
    new = set(folder.glob("*-cache")) - before
    assert new, _moved("jax._src.compilation_cache._cache", "a compile wrote no entry")
    assert all(len(_upstream.decompress_executable(f.read_bytes())) > 4 for f in new)


def test_weakly_typed_sets_the_weak_type_only():
    def check(x):
        y = _upstream.weakly_typed(x)
        assert jax.typeof(y).weak_type, _moved(
            "jax._src.lax.lax._convert_element_type(weak_type=True)", "no weak type"
        )
        assert y.dtype == x.dtype
        return y

    x = jnp.arange(3.0)
    assert not jax.typeof(x).weak_type
    np.testing.assert_array_equal(jax.jit(check)(x), x)


@pytest.mark.parametrize("enumeration", [optx.RESULTS, diffrax.RESULTS])
def test_result_codes_agree_with_the_enumeration_comparisons(enumeration):
    failure = next(
        getattr(enumeration, n) for n in ("nonlinear_max_steps_reached", "max_steps_reached")
        if hasattr(enumeration, n)
    )  # fmt: skip
    pick = lambda ok: enumeration.where(ok, enumeration.successful, failure)  # noqa: E731
    batch = jax.vmap(pick)(jnp.asarray([True, False, True]))
    assert len(jax.tree.leaves(batch)) == 1, _moved(
        "equinox.EnumerationItem._value", "an item is no longer a pytree of one code array"
    )
    np.testing.assert_array_equal(
        _upstream.succeeded(batch, enumeration), np.asarray(batch == enumeration.successful)
    )
    assert _upstream.succeeded(enumeration.successful, enumeration)
    assert not _upstream.succeeded(failure, enumeration)
    member = _upstream.result_member(batch, 1)
    assert enumeration[member] == enumeration[failure], _moved(
        "equinox.Enumeration.__getitem__", "a member's message is not its item's"
    )
    assert enumeration[_upstream.result_member(batch, 0)] == enumeration[enumeration.successful]


def test_a_failed_check_in_a_compiled_program_is_told_by_its_message():
    def f(x):
        return eqx.error_if(x, x > 0, "upstream-check says x > 0")

    with pytest.raises(_upstream.RUNTIME_ERRORS) as err:
        jax.block_until_ready(jax.jit(f)(jnp.asarray(1.0)))
    assert _upstream.failed_check_message(err.value) == "upstream-check says x > 0", _moved(
        "the text of equinox's runtime error", "no 'EquinoxRuntimeError: <message>' in it"
    )
    assert _upstream.failed_check_message(RuntimeError("other")) is None


def test_a_failed_check_is_logged_by_jax_unless_quieted(caplog):
    f = jax.jit(lambda x: eqx.error_if(x, x > 0, "upstream-check logged"))
    for quiet in (False, True):
        caplog.clear()
        with caplog.at_level("ERROR"), pytest.raises(_upstream.RUNTIME_ERRORS):
            if quiet:
                with _upstream.quiet_failed_checks():
                    jax.block_until_ready(f(jnp.asarray(1.0)))
            else:
                jax.block_until_ready(f(jnp.asarray(1.0)))
        logged = [r for r in caplog.records if r.name == "jax._src.callback"]
        assert bool(logged) != quiet, _moved(
            "the logger jax._src.callback", "no longer logs a failed callback's traceback"
        )
