"""What every `hrgjax` command shares: argument types, the start (output paths checked before
any work, an existing file refused unless `--force`; x64, compile cache), bad input as a
one-line usage error, and the end (each output written, atomically, and said where)."""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import tempfile
import time
import warnings

PRESETS = ("tvg3", "ideal")
DATA_EXTENSIONS = (".csv", ".nc")
PLOT_EXTENSIONS = (".png", ".pdf", ".svg")
EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_INTERRUPTED = 2, 1, 130
"""Exit statuses: bad input (a file, a column, an option), a failure during the work,
Ctrl-C."""


class UsageError(Exception):
    """The command's input is bad; `main` prints the message and exits with status 2."""


def positive(kind, what):
    """An argparse type: `kind(text)`, finite and > 0, else a message naming `what`."""

    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}; got {text!r}") from None
        if not value > 0 or value != value or value in (float("inf"),):
            raise argparse.ArgumentTypeError(f"expected {what} > 0; got {text}")
        return value

    return parse


POSITIVE_SECONDS = positive(float, "a number of seconds")
POSITIVE_INT = positive(int, "a whole number")
POSITIVE_FLOAT = positive(float, "a number")


def NONNEGATIVE_INT(text):  # noqa: N802 (an argparse type, named like the others)
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number ≥ 0; got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number ≥ 0; got {text}")
    return value


def NONNEGATIVE_FLOAT(text):  # noqa: N802 (an argparse type, named like the others)
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number ≥ 0; got {text!r}") from None
    if not (0 <= value < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number ≥ 0; got {text}")
    return value


OUTPUT_OPTIONS = ("out", "plot", "json", "write_sections", "csv", "kalibr")
"""Argument names (dests) that name files a command writes."""
TOOL_FOLDER = "out"
"""hrgjax's own folder, in the current one: every command's default outputs, `make demo`'s
and the docs' examples' go there. An output there that exists is replaced; a file named
anywhere else that exists is refused unless `--force` (`refuse_existing`)."""


def option_name(dest: str) -> str:
    """The option as the user typed it: `DATA` for a positional file, else `--json-name`."""
    return dest.upper() if dest in ("data", "log", "imu_log") else "--" + dest.replace("_", "-")


def check_output(option: str, path, extensions=(), inputs=()) -> None:
    """Refuse an output path before any work: wrong extension, a folder, an input file, or a
    place that cannot be written."""
    if path is None:
        return
    from .._io import same_file

    ext = os.path.splitext(path)[1].lower()
    if extensions and ext not in extensions:
        raise UsageError(f"{option} {path}: the file name must end in {' or '.join(extensions)}")
    if os.path.isdir(path):
        raise UsageError(f"{option} {path} is a folder; give a file name")
    for source in inputs:
        if source and same_file(path, source):
            raise UsageError(
                f"{option} {path} is the input file {source}; write to another file "
                "(hrgjax never overwrites its input)"
            )
    check_folder(f"{option} {path}", os.path.dirname(os.path.abspath(path)))


def check_folder(option: str, folder: str) -> None:
    """The folder exists or can be made, and can be written."""
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise UsageError(f"{option}: {folder} is a file, not a folder")
    d = folder
    while not os.path.exists(d):
        d = os.path.dirname(d)
    if not os.path.isdir(d):
        raise UsageError(f"{option}: cannot make the folder {folder}: {d} is a file")
    if not os.access(d, os.W_OK | os.X_OK):
        raise UsageError(f"{option}: cannot write in {d} (permission denied)")
    try:  # a file made and dropped: root passes os.access anywhere, /proc and read-only mounts
        with tempfile.TemporaryFile(dir=d):  # refuse a file (it failed after the work)
            pass
    except OSError as err:
        raise UsageError(
            f"{option}: cannot write in {d} ({err.strerror or one_line(err)})"
        ) from None


def one_line(err: BaseException) -> str:
    """The error's message on one line (its type's name when it has none)."""
    text = " ".join(str(err).split())
    return text or type(err).__name__


_python_warning = warnings.formatwarning


def setup():
    """float64 on, and the persistent compile cache (hrgjax.enable_cache: $HRGJAX_CACHE_DIR,
    else $XDG_CACHE_HOME/hrgjax, else ~/.cache/hrgjax; HRGJAX_NO_CACHE=1 switches it off),
    so a second run loads what the first compiled."""
    import jax

    from .._cache import enable_cache

    jax.config.update("jax_enable_x64", True)
    # hrgjax's own warnings (a cache it cannot use, a damaged entry) as one line each
    warnings.formatwarning = _one_line_warning
    enable_cache()
    return jax


def _one_line_warning(message, category, filename, lineno, line=None) -> str:
    text = str(message)
    return f"{text}\n" if text.startswith("hrgjax") else _python_warning(
        message, category, filename, lineno, line)  # fmt: skip


def start(args, inputs=(), **outputs) -> None:
    """The start of every command: each output option checked before any work, then `setup`.

    `outputs` maps an output option's dest (`out`, `json`, `plot`, `write_sections`) to the
    file name endings it takes; its path is `args.<dest>` (None: not asked for), checked by
    `check_output` against the `inputs` (paths the command reads), then by
    `refuse_existing`."""
    for dest, extensions in outputs.items():
        check_output(option_name(dest), getattr(args, dest, None), extensions, inputs)
    refuse_existing(args, outputs)
    setup()


def force_option(parser) -> None:
    """`--force`: replace output files that exist (`refuse_existing`). Every command that
    writes files the user names takes it (`hrgjax.cli.build_parser` adds it)."""
    parser.add_argument(
        "--force", action="store_true",
        help=f"replace output files that exist (without it, a file outside {TOOL_FOLDER}/ "
        "that exists is refused, before any work)",
    )  # fmt: skip


def in_tool_folder(path) -> bool:
    """Whether `path` lies inside `TOOL_FOLDER` of the current folder (links resolved: a
    link there to a file elsewhere is not inside)."""
    folder = os.path.realpath(TOOL_FOLDER)
    real = os.path.realpath(path)
    try:
        return real != folder and os.path.commonpath([folder, real]) == folder
    except ValueError:  # another drive (Windows)
        return False


def refuse_existing(args, dests) -> None:
    """Refuse, before any work, to replace a file that exists: an output the user named (each
    of `dests` given in `args`), or one written beside it (`beside`), unless `args.force`
    (`--force`) or the file lies in hrgjax's own folder (`TOOL_FOLDER`: every default output
    goes there). The user's data is never replaced unasked.

    **Raises:** `UsageError` naming the option, the file and `--force`."""
    if getattr(args, "force", False):
        return
    derived = getattr(args, "derived", {})
    for dest in dests:
        path = getattr(args, dest, None)
        if not path or not os.path.lexists(path) or in_tool_folder(path):
            continue
        option = option_name(dest)
        if dest in derived:
            of = derived[dest]
            raise UsageError(
                f"{option} {path} (written beside {option_name(of)} {getattr(args, of)}) "
                f"exists; give {option} another path, or --force to replace it"
            )
        raise UsageError(f"{option} {path} exists; give another path, or --force to replace it")


def beside(args, dest: str, of: str, ext: str) -> None:
    """`args.<dest>`, when not given, is `args.<of>` with the extension `ext` (calibrate's
    JSON export beside its `.eqx`): a file the user did not name, kept as the one named
    (`refuse_existing` names both)."""
    if getattr(args, dest) is None:
        setattr(args, dest, os.path.splitext(getattr(args, of))[0] + ext)
        args.derived = {**getattr(args, "derived", {}), dest: of}


@contextlib.contextmanager
def usage_errors(prefix: str | None = None, errors=(ValueError,), missing: str | None = None):
    """Bad input found inside the block becomes a one-line `UsageError` (exit status 2).

    **Arguments:**

    - `prefix`: what the message starts with (a file, an option), before `: `.
    - `errors`: the exception types that mean bad input (default `ValueError`).
    - `missing`: with it, a `FileNotFoundError` becomes this message.
    """
    caught = tuple(errors) + ((FileNotFoundError,) if missing is not None else ())
    try:
        yield
    except caught as err:
        if missing is not None and isinstance(err, FileNotFoundError):
            raise UsageError(missing) from None
        raise UsageError(_prefixed(prefix, err)) from None


def _prefixed(prefix, err) -> str:
    return one_line(err) if prefix is None else f"{prefix}: {one_line(err)}"


def write_json(obj: dict, path: str) -> str:
    """Write `obj` as indented, strict JSON at `path` (folders made; NaN and ±inf, which
    strict JSON has no word for, as null); returns the path."""
    import json

    from .._io import atomic_write

    with atomic_write(path, "w") as fh:
        fh.write(json.dumps(_strict(obj), indent=2, allow_nan=False))
    return str(path)


def _strict(x):
    """`x` with every NaN or infinite float as None (null)."""
    if isinstance(x, dict):
        return {k: _strict(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_strict(v) for v in x]
    return None if isinstance(x, float) and not math.isfinite(x) else x


def figure(name: str):
    """`hrgjax.plots.<name>`, imported when a figure is asked for (matplotlib is optional)."""
    from .. import plots

    return getattr(plots, name)


def finish(*outputs) -> int:
    """The end of every command: write each asked-for output and say where; returns 0.

    Each output is a pair `(path, write)`; `path` None (the option not given) skips it.
    `write` is a dict (written as JSON) or `write(path)`, which writes the file (atomically)
    and returns what follows "wrote " (the path, or a sentence ending in it)."""
    for path, write in outputs:
        if not path:
            continue
        try:
            done = write_json(write, path) if isinstance(write, dict) else write(path)
        except OSError as err:  # it named the temporary file beside `path`, not `path`
            raise OSError(f"cannot write {path}: {err.strerror or one_line(err)}") from err
        print(f"wrote {done}")
    return 0


def say(t0):
    """A progress line printer: `[seconds since t0] message`."""
    return lambda msg: print(f"  [{time.perf_counter() - t0:6.1f} s] {msg}", flush=True)


def preset_gyro(name: str, noise: bool = True):
    """The `--preset` / `--plant` gyro by name."""
    import hrgjax as hg

    if name == "tvg3":
        return hg.presets.tvg3_like(noise=noise)
    if name == "ideal":
        return hg.presets.ideal(hg.presets.tvg3_like(temperature_laws=False).resonator)
    raise UsageError(f"unknown --preset {name!r}; choose from {PRESETS}")


def allow_extra_option(parser) -> None:
    """`--allow-extra`: what `load_data` reads as `allow_extra` (every command that reads
    a data file offers it)."""
    parser.add_argument("--allow-extra", action="store_true", help="keep unknown data columns")


def load_data(path, allow_extra):
    """Measured data from `path`, or a one-line usage error naming the file."""
    import hrgjax as hg

    try:
        return hg.load(path, allow_extra=allow_extra)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except (OSError, ValueError) as err:
        raise UsageError(f"cannot read {path}: {one_line(err)}") from None


def K_E(text):  # noqa: N802 (an argparse type, named like the others)
    """`--k-e`: the electrical angular gain 2K of the data, a number in (0, 1]."""
    from ..units import K_E_WANTED, k_e_problem

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {K_E_WANTED}; got {text!r}") from None
    problem = k_e_problem(value)
    if problem:
        raise argparse.ArgumentTypeError(f"expected {problem}")
    return value
