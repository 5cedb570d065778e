"""Exported programs: a later process skips tracing and lowering of hrgjax's own programs.

JAX's persistent cache (`hrgjax._cache`) keeps the *compiled* form of a program, but a new
process must still trace the Python function and lower it before it can even ask the cache —
for the simulator that is most of a warm CLI call. `jax.export` serialises the traced and
lowered program (StableHLO); here each of hrgjax's compiled programs
([`program`][hrgjax._compiled.program]) is exported the first time it is called on concrete
inputs of a new signature and reloaded by later processes, which then only wrap the stored
module and fetch its compiled form from the compile cache.

A program is exported only when the stored form is sure to be the program the current code
would trace:

- the key holds the hrgjax source (a hash of every module), the versions of JAX, jaxlib,
  equinox, diffrax, optimistix, optax, lineax and NumPy, the backend and device kind, the
  JAX settings that change a trace (x64, PRNG implementation, promotion rules, matmul
  precision), the input tree with every static value, and the shape, dtype and weak type of
  every array;
- every pytree node type and every static value must come from hrgjax or those libraries
  (a user's own subclass or function is code the key cannot see: such calls trace as usual);
- a static value must have a stable text form (no memory addresses).

Entries are written atomically and carry a checksum; a damaged or unreadable entry is
dropped with a warning and exported again. Nothing is exported when the compile cache is
off (`HRGJAX_NO_CACHE=1`) or under `jax.disable_jit`.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import logging
import os
import pickle
import struct
import tempfile
import types
import warnings
from pathlib import Path

import jax
import numpy as np

from hrgjax import _upstream

_log = logging.getLogger("hrgjax.export")
_MAGIC = b"hrgjax-exported-program-v1\n"
_TRUSTED = (
    "hrgjax",
    "jax",
    "jaxlib",
    "equinox",
    "diffrax",
    "optimistix",
    "optax",
    "lineax",
    "numpy",
    "builtins",
    "collections",
)
_CONFIG = (
    "jax_enable_x64",
    "jax_default_prng_impl",
    "jax_threefry_partitionable",
    "jax_numpy_dtype_promotion",
    "jax_numpy_rank_promotion",
    "jax_default_matmul_precision",
    "jax_enable_custom_prng",
    "jax_legacy_prng_key",
)
_VERSIONS = ("jax", "jaxlib", "equinox", "diffrax", "optimistix", "optax", "lineax", "numpy")

_memo: dict[str, tuple] = {}  # key -> (runner, out_tree, dynamic positions, key impls)
_refused: set[str] = set()  # keys whose export failed in this process
_environment: str | None = None


def folder() -> Path | None:
    """The folder of exported programs (`export/` beside the compile cache's `xla/`), or
    None when the compile cache is off."""
    from hrgjax import _cache

    enabled = _cache.enabled_folder()
    if enabled is None or _cache.cache_disabled():
        return None
    return enabled.parent / "export"


def _source_hash() -> str:
    root = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        digest.update(str(f.relative_to(root)).encode())
        digest.update(f.read_bytes())
    return digest.hexdigest()


def _version(name: str) -> str:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return "-"


def environment() -> str:
    """The part of every key that is fixed for the process (source, versions, device)."""
    global _environment
    if _environment is None:
        device = jax.devices()[0]
        parts = [_source_hash(), jax.default_backend(), getattr(device, "device_kind", "")]
        parts += [f"{n}={_version(n)}" for n in _VERSIONS]
        _environment = "|".join(parts)
    settings = "|".join(f"{n}={getattr(jax.config, n, None)!r}" for n in _CONFIG)
    return _environment + "|" + settings


def _trusted_module(obj) -> bool:
    module = getattr(obj, "__module__", None) or ""
    return module.split(".")[0] in _TRUSTED


def _describe(treedef) -> str | None:
    """A text form of `treedef` with every node type and static value spelled out stably,
    or None when one comes from outside hrgjax and its libraries or has no stable form."""
    data = treedef.node_data() if treedef.num_nodes else None
    if data is None:
        return "*"
    kind, aux = data
    if not _trusted_module(kind):
        return None
    aux_text = _token(aux)
    children = [_describe(child) for child in treedef.children()]
    if aux_text is None or None in children:
        return None
    return f"{kind.__module__}.{kind.__qualname__}[{aux_text}]({','.join(children)})"


def _code_digest(code) -> str | None:
    """A hash of a code object: its byte code, names and constants (nested code too)."""
    digest = hashlib.sha256(code.co_code)
    digest.update(repr((code.co_names, code.co_firstlineno)).encode())
    for const in code.co_consts:
        text = _code_digest(const) if isinstance(const, types.CodeType) else repr(const)
        if text is None or "0x" in text:
            return None
        digest.update(text.encode())
    return digest.hexdigest()[:16]


def _function_token(fn, depth: int) -> str | None:
    """A function of hrgjax or its libraries: its name, its code and what its closure and
    defaults hold (a closure is as stable as the values it captured)."""
    if not _trusted_module(fn) or depth > 8:
        return None
    digest = _code_digest(fn.__code__)
    if digest is None:
        return None
    captured = [cell.cell_contents for cell in fn.__closure__ or ()]
    extra = _token((tuple(captured), fn.__defaults__, fn.__kwdefaults__), depth + 1)
    if extra is None:
        return None
    return f"fn:{fn.__module__}.{fn.__qualname__}:{digest}{extra}"


def _token(x, depth: int = 0) -> str | None:
    """A stable text form of a static value, or None."""
    if depth > 16:
        return None
    if x is None or isinstance(x, (bool, int, float, complex, str, bytes)):
        return f"{type(x).__name__}:{x!r}"
    if isinstance(x, (tuple, list, frozenset, set)):
        ordered = sorted(x, key=repr) if isinstance(x, (set, frozenset)) else x
        items = [_token(v, depth + 1) for v in ordered]
        return None if None in items else f"{type(x).__name__}({','.join(items)})"
    if isinstance(x, dict):
        items = [(_token(k, depth + 1), _token(v, depth + 1)) for k, v in x.items()]
        if any(k is None or v is None for k, v in items):
            return None
        return "dict(" + ",".join(f"{k}:{v}" for k, v in items) + ")"
    if isinstance(x, types.FunctionType):
        return _function_token(x, depth)
    if isinstance(x, type):
        return f"type:{x.__module__}.{x.__qualname__}" if _trusted_module(x) else None
    if isinstance(x, functools.partial):
        inner = _token((x.func, x.args, x.keywords), depth + 1)
        return None if inner is None else f"partial{inner}"
    if isinstance(x, (np.dtype, jax.ShapeDtypeStruct)) or isinstance(x, np.generic):
        return f"{type(x).__name__}:{x!r}"
    wrapped = getattr(x, "__wrapped__", None) or getattr(x, "fun", None)
    if wrapped is not None and _trusted_module(type(x)):
        # jax.jit'ed functions (jnp.tanh) and custom_jvp/vjp functions (jax.nn.relu).
        inner = _token(wrapped, depth + 1)
        return None if inner is None else f"{type(x).__name__}({inner})"
    text = repr(x)
    if _trusted_module(type(x)) and "0x" not in text and not callable(x):
        return f"{type(x).__module__}.{type(x).__qualname__}:{text}"
    return None


def _is_key(x) -> bool:
    return isinstance(x, jax.Array) and jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key)


def _signature(name: str, leaves, treedef):
    """(key, dynamic positions, key impls), or None when the call must trace as usual."""
    text = _describe(treedef)
    if text is None:
        _log.debug("%s: not exported (a node type or static field: %s)", name, treedef)
        return None
    parts, dynamic, impls = [name, environment(), text], [], []
    for i, x in enumerate(leaves):
        if _is_key(x):
            impl = jax.random.key_impl(x)
            parts.append(f"key:{impl}:{x.shape}")
            dynamic.append(i)
            impls.append(impl)
        elif isinstance(x, (jax.Array, np.ndarray, np.generic)):
            if isinstance(x, jax.core.Tracer):
                return None
            weak = bool(getattr(x, "weak_type", False))
            parts.append(f"{np.dtype(x.dtype).str}{tuple(x.shape)}{'w' if weak else ''}")
            dynamic.append(i)
            impls.append(None)
        else:
            token = _token(x)
            if token is None:
                _log.debug("%s: not exported (static argument %r)", name, x)
                return None
            parts.append(token)
    key = hashlib.sha256("\n".join(parts).encode()).hexdigest()[:40]
    return key, tuple(dynamic), tuple(impls)


def _default_platform() -> str:
    """The platform JAX lowers for by default ("cpu", "cuda", "rocm", "tpu"; not
    `jax.default_backend()`, which says "gpu")."""
    default = getattr(jax.export, "default_export_platform", None)
    return default() if default is not None else jax.default_backend()


def _platform() -> str | None:
    """The platform this call will run on: the default one, or "cpu" inside
    `jax.default_device(a CPU device)` (`hrgjax._compiled` runs single simulations there on an
    accelerator's machine); None inside `jax.default_device` of another device, whose call is
    traced rather than exported."""
    device = jax.config.jax_default_device
    if device is None:
        return _default_platform()
    name = device if isinstance(device, str) else device.platform
    return "cpu" if name == "cpu" else None


def _export(fn, leaves, treedef, dynamic, impls, platform):
    out_box = []

    def flat(*values):
        full = list(leaves)
        for i, impl, v in zip(dynamic, impls, values, strict=True):
            full[i] = v if impl is None else jax.random.wrap_key_data(v, impl=impl)
        args, kwargs = jax.tree_util.tree_unflatten(treedef, full)
        out_leaves, out_tree = jax.tree_util.tree_flatten(fn(*args, **kwargs))
        arrays = [o for o in out_leaves if isinstance(o, jax.Array)]
        # The output's structure, as the output itself with its arrays replaced by slots
        # (a pickled PyTreeDef does not survive equinox's sentinels); other leaves are
        # constants of the trace and are kept as they are.
        slots, n = [], 0
        for o in out_leaves:
            is_array = isinstance(o, jax.Array)
            slots.append(_Slot(n, bool(o.aval.weak_type)) if is_array else o)
            n += is_array
        out_box.append(jax.tree_util.tree_unflatten(out_tree, slots))
        return arrays

    specs = []
    for i, impl in zip(dynamic, impls, strict=True):
        x = leaves[i] if impl is None else jax.random.key_data(leaves[i])
        weak = bool(getattr(x, "weak_type", False))
        specs.append(jax.ShapeDtypeStruct(np.shape(x), x.dtype, weak_type=weak))
    # The key pins the exact jax and jaxlib versions, so custom calls (LAPACK's) need no
    # compatibility across versions: "ALL" lifts jax.export's check for them.
    # A lowering platform ("cuda" on a GPU, where `jax.default_backend()` says "gpu", which
    # the exported program's call then refuses).
    exported = jax.export.export(
        jax.jit(flat),
        platforms=[platform],
        disabled_checks=[jax.export.DisabledSafetyCheck.custom_call("ALL")],
    )(*specs)
    template = out_box[0]
    pickle.dumps(template)  # a leaf that cannot be stored: not exportable
    return exported, template


class _Slot:
    """The position of an array among an exported program's outputs, and whether the traced
    program gave it a weak type (serialisation drops weak types; they are restored, so that
    what a caller passes on has the same type as from the traced program)."""

    def __init__(self, index: int, weak: bool = False):
        self.index, self.weak = index, weak

    def __repr__(self):
        return f"_Slot({self.index}, weak={self.weak})"


def _runner(exported, slots):
    weak = {s.index for s in slots if s.weak}

    def run(*values):
        out = exported.call(*values)
        return [_upstream.weakly_typed(x) if i in weak else x for i, x in enumerate(out)]

    return jax.jit(run)


def _placed(values: list) -> list:
    """`values` committed to the one device `jax.jit` would run them on: that of the
    committed ones, else the default device. The runner's `jax.jit` keys its compiled form on
    which arguments are committed (`jax.device_put(x, device)`, or an exported program's own
    output) and which are not (`jnp.asarray`, NumPy): a simulation given a committed key after
    an uncommitted one compiled its exported program a second time (8–11 s in a cold cache,
    0.2–0.7 s read from a warm one). Committed on several devices, or sharded: left to
    `jax.jit` as they are."""
    committed = {tuple(v.devices()) for v in values if isinstance(v, jax.Array) and v.committed}
    if len(committed) > 1 or any(len(d) != 1 for d in committed):
        return values
    if committed:
        target = next(iter(committed))[0]
    else:
        default = jax.config.jax_default_device
        if default is None or isinstance(default, str):
            target = jax.local_devices(backend=default)[0]
        else:
            target = default
    move = [i for i, v in enumerate(values) if not (isinstance(v, jax.Array) and v.committed)]
    # a NumPy value is copied: on a CPU `device_put` shares its buffer, which the caller may
    # change while the program still reads it (`jax.jit` copied it)
    moved = [values[i] if isinstance(values[i], jax.Array) else np.array(values[i], copy=True)
             for i in move]  # fmt: skip
    placed = list(values)
    for i, v in zip(move, jax.device_put(moved, target), strict=True):
        placed[i] = v
    return placed


def _write(path: Path, exported, template) -> None:
    tree = pickle.dumps(template)
    body = struct.pack("<Q", len(tree)) + tree + bytes(exported.serialize())
    blob = _MAGIC + hashlib.sha256(body).digest() + body
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-")
    try:
        with os.fdopen(fd, "wb") as out:
            out.write(blob)
        os.replace(tmp, path)
    except OSError:
        try:
            os.unlink(tmp)
        except OSError:
            pass


def _read(path: Path):
    """(exported, output template) from `path`, or None when absent; a damaged entry is
    dropped."""
    try:
        blob = path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as err:
        warnings.warn(f"hrgjax: cannot read exported program {path.name} ({err})", stacklevel=3)
        return None
    try:
        if not blob.startswith(_MAGIC):
            raise ValueError("not an exported program")
        digest, body = blob[len(_MAGIC) : len(_MAGIC) + 32], blob[len(_MAGIC) + 32 :]
        if hashlib.sha256(body).digest() != digest:
            raise ValueError("checksum mismatch")
        (n,) = struct.unpack("<Q", body[:8])
        template = pickle.loads(body[8 : 8 + n])
        exported = jax.export.deserialize(bytearray(body[8 + n :]))
        return exported, template
    except Exception:
        warnings.warn(
            f"hrgjax: ignoring a damaged exported program {path.name} in {path.parent}; "
            "it is exported again",
            stacklevel=3,
        )
        try:
            path.unlink()
        except OSError:
            pass
        return None


_NONE = object()


def _can_serialise() -> bool:
    """jax.export's serialisation needs the `flatbuffers` package (in the `cli` extra)."""
    try:
        import flatbuffers  # noqa: F401
    except ImportError:
        return False
    return True


def call(name: str, fn, args, kwargs):
    """`fn(*args, **kwargs)` through its exported form, or `NONE` when this call cannot be
    exported (the caller then runs its usual compiled path). Call it inside the
    callback-free trace switch of `hrgjax._compiled`."""
    where = folder()
    if where is None or jax.config.jax_disable_jit or not _can_serialise():
        return _NONE
    platform = _platform()
    if platform is None:  # inside `jax.default_device(an accelerator)`: trace
        return _NONE
    if not _trusted_module(fn):  # code the source hash does not cover
        return _NONE
    leaves, treedef = jax.tree_util.tree_flatten((args, kwargs))
    signature = _signature(name, leaves, treedef)
    if signature is None:
        return _NONE
    key, dynamic, impls = signature
    if platform != _default_platform():  # the CPU of an accelerator's machine
        key = f"{key}-{platform}"
    if key in _refused:
        return _NONE
    entry = _memo.get(key)
    if entry is None:
        path = where / f"{key}.exported"
        refused = where / f"{key}.refused"
        if refused.exists():  # an earlier process found it cannot be exported
            _refused.add(key)
            return _NONE
        stored = _read(path)
        if stored is None:
            _log.debug("%s: exporting %s", name, key)
            try:
                stored = _export(fn, leaves, treedef, dynamic, impls, platform)
            except Exception as err:  # not exportable (an effect, a custom call): trace
                _log.debug("%s: not exported (%s: %s)", name, type(err).__name__, err)
                _refused.add(key)
                _write_refusal(refused, f"{type(err).__name__}: {err}")
                return _NONE
            _write(path, *stored)
            # Run what later processes will load (serialisation drops weak types, so the
            # program compiled from it differs from the in-memory one's): one compile, kept.
            stored = (jax.export.deserialize(bytearray(stored[0].serialize())), stored[1])
        exported, template = stored
        leaves_t, tree = jax.tree_util.tree_flatten(
            template, is_leaf=lambda x: isinstance(x, _Slot)
        )
        slots = [x for x in leaves_t if isinstance(x, _Slot)]
        entry = _memo[key] = (_runner(exported, slots), leaves_t, tree)
    runner, leaves_t, tree = entry
    values = [
        leaves[i] if impl is None else jax.random.key_data(leaves[i])
        for i, impl in zip(dynamic, impls, strict=True)
    ]
    arrays = runner(*_placed(values))
    out = [arrays[x.index] if isinstance(x, _Slot) else x for x in leaves_t]
    return jax.tree_util.tree_unflatten(tree, out)


def _write_refusal(path: Path, why: str) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-")
        with os.fdopen(fd, "w") as out:
            out.write(why[:2000])
        os.replace(tmp, path)
    except OSError:
        pass


NONE = _NONE
