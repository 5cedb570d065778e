"""`hrgjax discover`: name the effect missing from the nominal model (DISCOVERY.md)."""

from __future__ import annotations

import contextlib

from ..units import K_E_NOMINAL
from ._common import (
    K_E,
    PLOT_EXTENSIONS,
    UsageError,
    allow_extra_option,
    finish,
    load_data,
    start,
    usage_errors,
)
from .calibrate import cli_words
from .ins import ticker


def cmd_discover(args) -> int:
    """`hrgjax discover DATA`: name the effect missing from the nominal model."""
    if args.nominal != "base":
        raise UsageError(f"unknown --nominal {args.nominal!r}; choose 'base'")
    start(args, [args.data], json=(".json",), plot=PLOT_EXTENSIONS)
    from ..discovery import NOMINAL, discover

    data = load_data(args.data, args.allow_extra)
    what = ("discovering: the nominal fit, then the catalogue's effects screened round by "
            "round (a minute or more for a bench session)")  # fmt: skip
    with usage_errors(args.data), cli_words(DISCOVER_WORDS), contextlib.closing(ticker(what)):
        found = discover(data, nominal=NOMINAL, k_e=args.k_e, shape=args.shape)
    print(f"hrgjax discover: {args.data} ({found.shape} data)")
    print(f"  verdict: {found.verdict}; missing effect: {found.missing_effect}")
    if found.ambiguous_with:
        print(f"  hard to tell apart from: {', '.join(found.ambiguous_with)}")
    if found.accepted[1:]:
        print(f"  also accepted: {', '.join(found.accepted[1:])}")
    if found.structure_left or found.verdict == "unexplained":
        shapes = found.uncertainty.get("shapes") or []
        why = f" (a leftover shape: {', '.join(shapes)})" if shapes else ""
        print(f"  structure is left that no catalogue effect explains{why}")
    print("  fitted model:")
    print("\n".join("    " + line for line in found.equations().splitlines()[1:]))
    print(
        "  screening, first round — each candidate against the nominal model alone (score, p, "
        "ΔBIC, aliasing; a shape that outshines it there):"
    )
    for r in found.screening[:6]:
        outshone = f"  outshone by {r['outshone_by']}" if r.get("outshone_by") else ""
        if r.get("accepted_in_round"):
            round_ = r["accepted_in_round"]
            outshone = "  accepted" + (f" (round {round_})" if round_ > 1 else "")
        print(
            f"    {r['effect']:>32} {r['score']:12.4g} {r['p_value']:9.2g} "
            f"{r['delta_bic']:10.4g} {r['aliasing']:6.2f}{outshone}"
        )
    return finish((args.json, found.write_json), (args.plot, found.plot))


DISCOVER_WORDS = (
    (r"; add static runs or pass noise=hrgjax\.Noise\(\.\.\.\)$",
     "; add static runs or pass noise="),
    (r";? or pass noise=hrgjax\.Noise\(\.\.\.\)", ""),
    (r"; add static runs or pass noise=$",
     "; add static runs or holds (the command line takes no noise model; in Python, "
     "hrgjax.discovery.discover(..., noise=hrgjax.Noise(...)) does)"),
)  # fmt: skip
"""`discover`'s `cli_words`: the library's way out that the command line has no option for
(`noise=`), said so."""


def _discover_parser(sub):
    """`hrgjax discover`'s parser."""
    p = sub.add_parser("discover", help="name the effect missing from the nominal model")
    p.add_argument("data", help="dwell-grid or continuous data in the MeasuredData contract")
    p.add_argument("--nominal", default="base", help="nominal model (base)")
    p.add_argument(
        "--shape",
        default="auto",
        choices=("auto", "dwell", "continuous", "mixed"),
        help="data shape (auto: dwell when every run holds its rate and temperature, mixed "
        "when some do: those as dwell windows, jointly with the continuous records)",
    )
    p.add_argument("--json", default=None, help="write the report here (JSON)")
    p.add_argument("--plot", default=None, help="write the report figure here (PNG)")
    p.add_argument(
        "--k-e",
        type=K_E,
        default=K_E_NOMINAL,
        help="nominal electrical angular gain k_e = 2K, in (0, 1] (default 0.554)",
    )
    allow_extra_option(p)
    return p


PARSERS = {"discover": _discover_parser}
"""Command → the function that adds its parser to the subparsers (`hrgjax.cli`)."""
