"""The `hrgjax` command."""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import signal
import sys
import threading

from . import allan, calibrate, discover, ins, navigate, simulate
from ._common import DATA_EXTENSIONS as DATA_EXTENSIONS
from ._common import EXIT_BAD_INPUT as EXIT_BAD_INPUT
from ._common import EXIT_FAILURE as EXIT_FAILURE
from ._common import EXIT_INTERRUPTED as EXIT_INTERRUPTED
from ._common import NONNEGATIVE_INT as NONNEGATIVE_INT
from ._common import OUTPUT_OPTIONS as OUTPUT_OPTIONS
from ._common import PLOT_EXTENSIONS as PLOT_EXTENSIONS
from ._common import POSITIVE_FLOAT as POSITIVE_FLOAT
from ._common import POSITIVE_INT as POSITIVE_INT
from ._common import POSITIVE_SECONDS as POSITIVE_SECONDS
from ._common import PRESETS as PRESETS
from ._common import UsageError as UsageError
from ._common import force_option, one_line, option_name
from .allan import cmd_allan as cmd_allan
from .calibrate import COMPENSATORS as COMPENSATORS
from .calibrate import METHODS as METHODS
from .calibrate import cmd_calibrate as cmd_calibrate
from .calibrate import cmd_compare as cmd_compare
from .calibrate import cmd_correct as cmd_correct
from .calibrate import cmd_self_calibrate as cmd_self_calibrate
from .discover import cmd_discover as cmd_discover
from .ins import ACCEL_UNIT_NAMES as ACCEL_UNIT_NAMES
from .ins import DIAGNOSIS_METHODS as DIAGNOSIS_METHODS
from .ins import GYRO_UNIT_NAMES as GYRO_UNIT_NAMES
from .ins import cmd_align as cmd_align
from .ins import cmd_diagnose as cmd_diagnose
from .ins import cmd_imu_calibrate as cmd_imu_calibrate
from .ins import cmd_vibration as cmd_vibration
from .navigate import cmd_navigate as cmd_navigate
from .simulate import cmd_demo as cmd_demo
from .simulate import cmd_design as cmd_design
from .simulate import cmd_simulate as cmd_simulate

COMMANDS = ("demo", "calibrate", "self-calibrate", "correct", "compare", "discover", "align",
            "diagnose", "vibration", "navigate", "simulate", "design", "imu-calibrate",
            "allan")  # fmt: skip
"""The subcommands, in the order `hrgjax --help` lists them; `hrgjax NAME` runs this
module's `cmd_NAME` (dashes as underscores)."""
EXAMPLES = {
    "demo": "hrgjax demo --quick --out out/demo",
    "simulate": "hrgjax simulate --preset tvg3 --plan seed --quick --out out/bench.csv",
    "calibrate": "hrgjax calibrate out/bench.csv --method fourier --out out/model.eqx "
    "(bench.csv from the simulate example)",
    "self-calibrate": "hrgjax self-calibrate out/sweeps.csv --out out/self_cal.eqx (sweeps.csv "
    "from hrgjax simulate --plan precession --quick --out out/sweeps.csv)",
    "correct": "hrgjax correct out/test.csv --model out/model.eqx --out out/corrected.csv "
    "--plot out/corrected.png (test.csv: a second session, e.g. the simulate example with "
    "--seed 1)",
    "compare": "hrgjax compare out/test.csv --models out/model.eqx out/mlp.eqx --json "
    "out/compare.json --plot out/compare.png (models from calibrate on out/bench.csv, "
    "test.csv from the simulate example with --seed 1: another switch-on)",
    "discover": "hrgjax discover out/bench.csv --json out/report.json --plot out/report.png",
    "align": "hrgjax align psins_lasergyro.imu --json out/align.json --plot out/align.png",
    "diagnose": "hrgjax diagnose --scenario stationary --runs 3 --methods filter_bank,pnn_direct",
    "vibration": "hrgjax vibration --quick --json out/vib.json --plot out/vib.png",
    "navigate": "hrgjax navigate example --imu tactical --outage 1400:1460 --runs 20 --json "
    "out/nav.json --plot out/nav.png (or a gnss-ins-sim motion CSV instead of 'example')",
    "design": "hrgjax design --budget-h 4 --out out/plan.json --plot out/plan.png",
    "allan": "hrgjax allan gyro.csv --column rate --unit deg/h --rate-hz 10 --fit --plot "
    "out/allan.png --kalibr out/imu.yaml (a CSV with a header row and a rate column)",
    "imu-calibrate": "hrgjax imu-calibrate session.csv --sections sections.json --rate-hz 102.4 "
    "--gyro-unit deg/s --accel-unit m/s^2 --turn-deg -360 --json out/imu_cal.json --plot "
    "out/imu.png (a session with imucal's columns gyr_x … acc_z and its section-list JSON)",
}
"""One runnable example per command, shown at the end of `hrgjax CMD --help`."""
_PARSERS = {**simulate.PARSERS, **calibrate.PARSERS, **discover.PARSERS, **ins.PARSERS,
            **allan.PARSERS, **navigate.PARSERS}  # fmt: skip


def main(argv=None) -> int:
    """Entry point of the `hrgjax` command; `argv` defaults to `sys.argv[1:]`."""
    from .._threads import widen_cpu_thread_pool

    widen_cpu_thread_pool()  # before any JAX work: XLA:CPU's pool cannot wedge (hrgjax._threads)
    args = build_parser().parse_args(argv)
    if getattr(args, "quiet", False):
        os.environ["HRGJAX_QUIET"] = "1"
    return _run(args)


class _OneLineParser(argparse.ArgumentParser):
    """argparse's parser with its usage errors in one line, as every other error of the
    command: `hrgjax calibrate: error: argument --window: … (hrgjax calibrate --help: the
    options)`, exit status 2. argparse printed its usage block (6–10 lines) first. The
    subcommands' parsers are of this class too (argparse makes them of their parent's)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} ({self.prog} --help: the options)\n")


def build_parser() -> argparse.ArgumentParser:
    """The `hrgjax` argument parser (every option with its help and default)."""

    parser = _OneLineParser(
        prog="hrgjax",
        description=__doc__,
        parents=[_common(_RELAX_BEFORE)],
        formatter_class=HelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True)
    add_parser, common = sub.add_parser, _common("relax")
    sub.add_parser = lambda name, **k: add_parser(
        name,
        parents=[common],
        formatter_class=HelpFormatter,
        epilog=f"example: {EXAMPLES[name]}",
        **k,
    )
    here = globals()  # looked up now, so that a replaced cmd_NAME (a test's) is the one run
    for name in COMMANDS:
        p = _PARSERS[name](sub)
        p.set_defaults(func=here["cmd_" + name.replace("-", "_")])
        force_option(p)
    return parser


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Defaults shown, once: argparse's "(default: X)" is left out where the help says its
    default itself ("(default 0.5) (default: None)" showed two, the second wrong) or there
    is none to say (None: the option not given); the description and the example kept as
    written."""

    def _get_help_string(self, action):
        text = action.help or ""
        if action.default is None or "default" in text.lower():
            return text
        return super()._get_help_string(action)


_RELAX_BEFORE = "relax_before_command"
"""The dest of `--relax` given before the command: argparse's subcommand writes its own
`relax` list over the parent's, so the two are kept apart and merged in `_run`."""


def _common(relax_dest: str) -> argparse.ArgumentParser:
    """The options taken before or after the command; `--relax` appends to `relax_dest`."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--quiet",
        action="store_true",
        default=argparse.SUPPRESS,  # before or after the command; neither overrides the other
        help="no progress bars (they are off without a terminal)",
    )
    common.add_argument(
        "--relax",
        action="append",
        type=_relaxation,
        default=argparse.SUPPRESS,
        metavar="QUANTITY=LOW,HIGH",
        dest=relax_dest,
        help="widen a plausibility range for this run (hrgjax.plausible.RANGES, in the "
        "quantity's own unit), e.g. --relax specific_force_g=-40,40 for a centrifuge; "
        "repeatable",
    )
    common.add_argument(
        "--debug",
        action="store_true",
        default=argparse.SUPPRESS,
        help="show the full traceback of an error (otherwise one line)",
    )
    return common


INPUT_OPTIONS = ("data", "log", "imu_log", "sections", "model", "models", "plan_file",
                 "offset_from", "motion")  # fmt: skip
"""Argument names (dests) that name files a command reads."""


def check_distinct_paths(args) -> None:
    """Every output path differs from every input and from every other output, in every
    command: a `--plot` or `--json` naming the input file would overwrite the user's data.
    Inputs count where they are files (`--model` of `design` is a word, not a file).

    **Raises:** `UsageError` naming the two options and the path."""
    seen: dict[str, str] = {}
    for dest in INPUT_OPTIONS:
        value = getattr(args, dest, None)
        for v in value if isinstance(value, list) else [value]:
            if isinstance(v, str) and os.path.isfile(v):
                seen.setdefault(os.path.realpath(v), option_name(dest))
    inputs = dict(seen)
    for dest in OUTPUT_OPTIONS:
        v = getattr(args, dest, None)
        if not isinstance(v, str):
            continue
        real = os.path.realpath(v)
        if real in seen:
            what = "the input" if real in inputs else "the output"
            raise UsageError(f"{option_name(dest)} {v} is also {what} {seen[real]}; writing it "
                             "would overwrite that file: give another path")  # fmt: skip
        seen[real] = option_name(dest)


# Commands whose work is a wide batch (a plan's runs, a design's points vmapped): they stay on
# JAX's default backend. Every other command fits or follows one trajectory at a time.
BATCH_COMMANDS = frozenset({"simulate", "design"})


def _placement(command):
    """Where a command runs: beside an accelerator, a command that is not a wide batch runs on
    the CPU, as an eager `hg.simulate` does (`hrgjax._compiled.single_run_device`). Its
    programs are sequential loops of small kernels: on an NVIDIA H200 the demo, a
    calibration fit and discovery each took over 180 s (the per-test limit of
    `benchmarks/on_gpu.sh`), where a 2-core CPU takes about a minute."""
    import contextlib

    if command in BATCH_COMMANDS:
        return contextlib.nullcontext()
    from .._compiled import single_run_device

    device = single_run_device()
    if device is None:
        return contextlib.nullcontext()
    import jax

    return jax.default_device(device)


def _relaxation(text: str) -> tuple[str, tuple[float, float]]:
    """`QUANTITY=LOW,HIGH` of `--relax`, checked against `hrgjax.plausible.RANGES`."""
    from .. import plausible

    name, eq, bounds = text.partition("=")
    parts = bounds.split(",")
    try:
        low, high = (float(v) for v in parts) if len(parts) == 2 else (None, None)
    except ValueError:
        low = high = None
    if not eq or low is None or not low < high:
        raise argparse.ArgumentTypeError(f"{text!r}: give QUANTITY=LOW,HIGH with LOW < HIGH, "
                                         "e.g. specific_force_g=-40,40")  # fmt: skip
    if name not in plausible.RANGES:
        raise argparse.ArgumentTypeError(f"{name!r} is not a plausibility range; known: "
                                         f"{', '.join(sorted(plausible.RANGES))}")  # fmt: skip
    return name, (low, high)


def _run(args) -> int:
    """Run the command: a one-line error and exit status 2 for bad input, 1 for a failure
    during the work, 130 on Ctrl-C (files are written atomically, so none is left half
    written); `--debug` shows the traceback instead."""
    name, debug = f"hrgjax {args.command}", getattr(args, "debug", False)
    try:
        check_distinct_paths(args)
        from ..plausible import relaxed

        given = [*getattr(args, _RELAX_BEFORE, ()), *getattr(args, "relax", ())]  # in order
        with interruptible(), _placement(args.command), relaxed(**dict(given)):
            return args.func(args)
    except KeyboardInterrupt:
        if debug:
            raise
        print(f"\n{name}: interrupted (no partial output files are left)", file=sys.stderr)
        raise SystemExit(EXIT_INTERRUPTED) from None
    except (UsageError, ValueError, TypeError, OSError) as err:
        if debug:
            raise
        if isinstance(err, TypeError) and not raised_by_hrgjax(err):
            print(f"{name}: internal error: TypeError: {one_line(err)} (a bug: please report "
                  "it with the command line; --debug shows the traceback)", file=sys.stderr)  # fmt: skip
            raise SystemExit(EXIT_FAILURE) from None
        # a plausibility range's way out, as the command line spells it
        line = re.sub(r"hrgjax\.plausible\.relaxed\((\w+)=…\)", r"--relax \1=LOW,HIGH",
                      one_line(err))  # fmt: skip
        print(f"{name}: error: {line}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT) from None
    except Exception as err:
        if debug:
            raise
        print(f"{name}: failed: {one_line(err)} (--debug shows the traceback)", file=sys.stderr)
        raise SystemExit(EXIT_FAILURE) from None


def raised_by_hrgjax(err: BaseException) -> bool:
    """Whether `err` was raised by a `raise` statement in hrgjax's own code (its checks'
    one-line refusals: bad input), not by Python or a library under it (a `TypeError` such
    as "unsupported operand type(s)" is a bug, not the user's input)."""
    import linecache
    import traceback

    frames = traceback.extract_tb(err.__traceback__)
    if not frames:
        return False
    last = frames[-1]
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    try:
        if os.path.commonpath([package, os.path.abspath(last.filename)]) != package:
            return False
    except ValueError:  # another drive (Windows)
        return False
    line = linecache.getline(last.filename, last.lineno).strip()
    return line.startswith("raise ")


SWALLOWING_FRAMES = ("_xla_gc_callback", "__del__")
"""Names of functions whose exceptions Python prints ("Exception ignored in: …") and drops:
JAX's garbage-collector callback (run at any allocation) and finalizers. A Ctrl-C raised in
one was lost: the command went on, wrote its file and exited 0 (2 of 8 tries 5–6 s into
`simulate --duration 1200`)."""
REDELIVER_S = 0.01
"""Seconds after which a Ctrl-C that landed in such a function is delivered again."""


def swallows_exceptions(frame) -> bool:
    """Whether `frame` (or a frame that called it) is one whose exceptions are dropped: a
    garbage-collector callback (`gc.callbacks`) or a function named in
    `SWALLOWING_FRAMES`."""
    import gc

    callbacks = {getattr(c, "__code__", None) for c in gc.callbacks}
    while frame is not None:
        if frame.f_code in callbacks or frame.f_code.co_name in SWALLOWING_FRAMES:
            return True
        frame = frame.f_back
    return False


class Interrupts:
    """The command's SIGINT handler: `KeyboardInterrupt` as Python's own raises it, but a
    Ctrl-C that lands where an exception would be dropped (`swallows_exceptions`, or any
    place whose exception reaches `sys.unraisablehook`: a weakref callback, a finalizer) is
    raised again `REDELIVER_S` later, outside it (`redeliver`)."""

    def __init__(self):
        self.timer = None

    def __call__(self, signum, frame):
        if not swallows_exceptions(frame):
            raise KeyboardInterrupt
        self.redeliver()

    def redeliver(self) -> None:
        """SIGINT again in `REDELIVER_S` s (once, however many Ctrl-C came meanwhile)."""
        if self.timer is None or not self.timer.is_alive():
            self.timer = threading.Timer(REDELIVER_S, signal.raise_signal, (signal.SIGINT,))
            self.timer.daemon = True
            self.timer.start()

    def pending(self) -> bool:
        """Whether a Ctrl-C waits to be delivered again."""
        return self.timer is not None and self.timer.is_alive()


@contextlib.contextmanager
def interruptible():
    """`Interrupts` as the SIGINT handler inside the block, and a `sys.unraisablehook` that
    hands it a `KeyboardInterrupt` Python would print as "Exception ignored" and drop; both
    restored after. A Ctrl-C still waiting to be delivered when the block ends is raised
    there (the command must not finish with exit 0). Nothing changed off the main thread or
    where Ctrl-C is ignored (SIG_IGN)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGINT)
    if previous in (signal.SIG_IGN, None):
        yield
        return
    handler, hook = Interrupts(), sys.unraisablehook

    def unraisable(info):
        if isinstance(info.exc_value, KeyboardInterrupt):
            handler.redeliver()
        else:
            hook(info)

    signal.signal(signal.SIGINT, handler)
    sys.unraisablehook = unraisable
    try:
        yield
    finally:
        # Restore everything, then raise: a re-delivery firing meanwhile must not cut the
        # restoring short (it did: a timer that fired after the handler was restored raised
        # before the hook was, and `sys.unraisablehook` stayed replaced; 1 test run in ~20).
        # The timer is stopped (or waited for, if it is firing) while our handler is still in
        # place; `signal.signal` runs a pending handler first, so a Ctrl-C caught here is only
        # recorded, and the restoring is done again (each step is idempotent).
        interrupted = waiting = False
        while True:
            try:
                sys.unraisablehook = hook
                waiting = waiting or handler.pending()
                if handler.timer is not None:
                    handler.timer.cancel()
                    handler.timer.join()
                signal.signal(signal.SIGINT, previous)
                break
            except KeyboardInterrupt:
                interrupted = True
        if waiting or interrupted:
            raise KeyboardInterrupt
