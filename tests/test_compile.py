"""sorjax._compile: per-program XLA options, the on-disk cache switched on at the first
compilation, and traced programs stored (jax.export) so that a new process skips tracing."""

from __future__ import annotations

import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sorjax import _compile as C

TRACES: list[tuple] = []


class _Out(eqx.Module):
    value: jax.Array
    pair: tuple
    label: str = eqx.field(static=True)


def _program(x, y, scale, n=None):
    """A small program with a pytree in and out, a static argument and a None default."""
    TRACES.append((x.shape, scale))
    z = jnp.sin(x) * scale + jnp.linalg.solve(y, jnp.ones(y.shape[0])).sum()  # LAPACK: a custom call
    return _Out(value=z, pair=(z.sum(), jnp.int32(x.shape[0])), label=f"scale {scale}")


def _args(n=5):
    rng = np.random.default_rng(0)
    return rng.normal(size=n), np.eye(3) + 0.1 * rng.normal(size=(3, 3))


@pytest.fixture
def store(tmp_path, monkeypatch):
    monkeypatch.setenv("SORJAX_CACHE", str(tmp_path))
    monkeypatch.delenv("SORJAX_EXPORT", raising=False)
    TRACES.clear()
    return tmp_path


def _stored(root):
    d = root / "exported"
    return sorted(os.listdir(d)) if d.exists() else []


def test_stored_program_is_reused_without_tracing_and_gives_the_same_numbers(store):
    x, y = _args()
    ref = jax.jit(_program, static_argnames="scale")(x, y, scale=2.0)
    TRACES.clear()
    first = C.one_off_jit(_program, static_argnames=("scale",))(x, y, scale=2.0)
    assert len(TRACES) == 1 and len(_stored(store)) == 1
    # a new process: a new wrapper, nothing in memory; the program comes from the disk
    again = C.one_off_jit(_program, static_argnames=("scale",))
    out = again(x, y, scale=2.0)
    assert len(TRACES) == 1, "the stored program was traced again"
    assert isinstance(out, _Out) and out.label == "scale 2.0"
    for got in (first, out):
        np.testing.assert_allclose(got.value, ref.value, rtol=0, atol=1e-12)
        np.testing.assert_allclose(got.pair[0], ref.pair[0], rtol=0, atol=1e-12)
        assert int(got.pair[1]) == 5
    # positional static argument: the same key
    again(x, y, 2.0)
    assert len(TRACES) == 1


def test_a_new_static_value_or_shape_is_a_new_program(store):
    f = C.one_off_jit(_program, static_argnames=("scale",))
    x, y = _args()
    f(x, y, scale=2.0)
    f(x, y, scale=3.0)
    f(*_args(7), scale=2.0)
    assert len(TRACES) == 3 and len(_stored(store)) == 3
    f(x, y, scale=3.0)
    assert len(TRACES) == 3


def test_a_prepared_program_is_traced_once_compiled_aside_and_gives_the_same_numbers(store):
    """prepare() traces in the caller's thread, compiles in a host thread; the call with
    other values of the same structure waits for it and runs the compiled program (no
    second trace), with the numbers of jax.jit; another structure is another program."""
    x, y = _args()
    ref = jax.jit(_program, static_argnames="scale")(x, y, scale=2.0)
    TRACES.clear()
    f = C.one_off_jit(_program, static_argnames=("scale",))
    f.prepare(np.zeros_like(x), np.eye(3), scale=2.0)
    assert len(TRACES) == 1 and len(_stored(store)) == 1
    out = f(x, y, scale=2.0)
    assert len(TRACES) == 1 and not f._pending
    (program,) = f._programs.values()
    assert program[1] is not None  # the ahead-of-time compiled executable ran
    np.testing.assert_allclose(out.value, ref.value, rtol=0, atol=1e-12)
    assert out.label == "scale 2.0" and int(out.pair[1]) == 5
    f.prepare(x, y, scale=2.0)  # there already: nothing to do
    assert len(TRACES) == 1 and not f._pending
    out = f(*_args(7), scale=2.0)  # not prepared: traced at the call
    assert len(TRACES) == 2 and out.value.shape == (7,)


def test_opting_out_stores_nothing(store, monkeypatch):
    x, y = _args()
    monkeypatch.setenv("SORJAX_EXPORT", "0")
    out = C.one_off_jit(_program, static_argnames=("scale",))(x, y, scale=2.0)
    assert _stored(store) == [] and out.label == "scale 2.0"
    monkeypatch.delenv("SORJAX_EXPORT")
    monkeypatch.setenv("SORJAX_CACHE", "off")
    assert C.cache_dir() is None and not C.exports_enabled()
    out = C.one_off_jit(_program, static_argnames=("scale",))(x, y, scale=2.0)
    assert _stored(store) == [] and out.label == "scale 2.0"
    monkeypatch.setenv("SORJAX_CACHE", str(store))
    C.one_off_jit(_program, static_argnames=("scale",))(x, y, scale=2.0)
    assert len(_stored(store)) == 1  # the same call stores it when allowed


def test_a_damaged_stored_program_is_traced_again(store):
    x, y = _args()
    C.one_off_jit(_program, static_argnames=("scale",))(x, y, scale=2.0)
    (name,) = _stored(store)
    (store / "exported" / name).write_bytes(b"not a program")
    out = C.one_off_jit(_program, static_argnames=("scale",))(x, y, scale=2.0)
    assert len(TRACES) == 2 and out.label == "scale 2.0"
    assert C.one_off_jit(_program, static_argnames=("scale",))(x, y, scale=2.0).label == "scale 2.0"
    assert len(TRACES) == 2  # stored again, whole


def test_inside_a_transformation_it_is_the_jitted_function(store):
    f = C.one_off_jit(_program, static_argnames=("scale",))
    x, y = _args()
    g = jax.grad(lambda x: f(x, y, scale=2.0).pair[0])(x)
    np.testing.assert_allclose(g, 2.0 * np.cos(x), atol=1e-12)
    v = jax.vmap(lambda x: f(x, y, scale=2.0).pair[0])(np.stack([x, x + 1]))
    assert v.shape == (2,)
    assert _stored(store) == []  # tracers are never exported


def test_compiler_options_and_their_switches(monkeypatch):
    monkeypatch.delenv("SORJAX_FAST_COMPILE", raising=False)
    opts = C.compiler_options()
    assert opts and set(opts) <= set(C.ONE_OFF)
    assert opts["xla_backend_optimization_level"] == 0
    # the threshold of a short run, just inside and just outside
    assert C.options_for_runs(C.ONE_OFF_TRIALS - 1) == opts
    assert C.options_for_runs(C.ONE_OFF_TRIALS) is None
    monkeypatch.setenv("SORJAX_FAST_COMPILE", "0")
    assert C.compiler_options() is None
    # an option this jaxlib does not know is left out, not an abort
    monkeypatch.delenv("SORJAX_FAST_COMPILE")
    assert C.compiler_options({"xla_no_such_option_at_all": True}) is None
    assert C.compiler_options({"xla_no_such_option_at_all": True, "xla_backend_optimization_level": 0}) == {
        "xla_backend_optimization_level": 0}


def test_the_cache_is_switched_on_at_the_first_compile_unless_configured(tmp_path, monkeypatch):
    before = jax.config.jax_compilation_cache_dir
    try:
        jax.config.update("jax_compilation_cache_dir", None)
        monkeypatch.setattr(C, "_cache_done", False)
        monkeypatch.setenv("SORJAX_CACHE", str(tmp_path / "a"))
        C.ensure_cache()
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "a")
        # the caller's own setting wins
        jax.config.update("jax_compilation_cache_dir", str(tmp_path / "mine"))
        monkeypatch.setattr(C, "_cache_done", False)
        C.ensure_cache()
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "mine")
        # opted out
        jax.config.update("jax_compilation_cache_dir", None)
        monkeypatch.setattr(C, "_cache_done", False)
        monkeypatch.setenv("SORJAX_CACHE", "off")
        C.ensure_cache()
        assert jax.config.jax_compilation_cache_dir is None
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


def test_importing_sorjax_changes_no_jax_cache_setting():
    import subprocess
    import sys

    code = ("import jax; import sorjax; print(jax.config.jax_compilation_cache_dir)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                       env={k: v for k, v in os.environ.items() if k != "SORJAX_CACHE"})
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "None"
