"""``ectskin bound OUT``: the physical limit, Cramér–Rao bound maps of the finger's point and force
over the skins (:mod:`ectskin.twin.bound`; ``docs/bound.md``).

Thin wrapper: parses the states and nuisances, opens the Dask runner of
:mod:`ectskin.design.cluster` and calls :func:`~ectskin.twin.bound.bound_maps`. The library is
imported inside :func:`run`: ``ectskin --help`` imports every command module.
"""

from __future__ import annotations

import argparse
import itertools
import logging
from pathlib import Path

from ectskin._check import EctskinError, check_option, parse_floats
from ectskin.commands._options import (
    add_figure_options,
    add_out,
    add_overwrite,
    integer,
    number,
    resolve_out,
)

HELP = "the physical limit: Cramér-Rao bound maps of the finger's point and force over the skins"
EXAMPLES = """\
  ectskin bound limits/                     # states (0,0,0) and (20,20,20), 10-mm grid, coarse mesh
  ectskin bound limits/ --levels 0,20       # the 8 states of levels 0 and 20 ml per chamber
  ectskin bound limits/ --states "0,10,20" --spacing-mm 5 --mesh default --workers 4
  ectskin bound limits/ --nuisance push --priors none --hover-mm 5 --overwrite
  ectskin bound limits/ --nuisance push,inflation,finger,modulus   # + the pulp's modulus
  ectskin bound limits/ --scheduler tcp://10.0.0.5:8786
"""
# (twin.bound.NUISANCE_NAMES and NUISANCES: not imported at start-up)
NUISANCE_NAMES = ("push", "inflation", "finger", "modulus")
DEFAULT_NUISANCES = NUISANCE_NAMES[:3]
N_CHAMBERS = 3  # the paper's body; another body's count would come with its config
log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_out(p, help="folder for bound.json and bound.png", positional=True)
    p.add_argument(
        "--states",
        default=None,
        metavar="P1,P2,P3;...",
        help='inflation states, ml per chamber, separated by ";" (default "0,0,0;20,20,20")',
    )
    p.add_argument(
        "--levels",
        default=None,
        metavar="L,...",
        help="instead of --states: every combination of these levels (ml) over the chambers",
    )
    p.add_argument(
        "--spacing-mm",
        type=number(0, above=True),
        default=10.0,
        help="grid spacing over each skin, mm (default 10)",
    )
    p.add_argument(
        "--nuisance",
        default=",".join(DEFAULT_NUISANCES),
        help="nuisances, comma-separated, or 'none': push, inflation, finger (its radius), "
        "modulus (ln of its pulp's modulus) (default push,inflation,finger)",
    )
    p.add_argument(
        "--priors",
        default="inflation=1,finger=1,modulus=0.4",
        metavar="NAME=SD,...",
        help="prior standard deviations of nuisances in their units (ml, mm, ln E; the push in "
        "N); a nuisance not named is unknown; 'none' for none (default "
        "inflation=1,finger=1,modulus=0.4)",
    )
    p.add_argument(
        "--force-n", type=number(0.05, above=True), default=1.0, help="finger force, N (default 1)"
    )
    p.add_argument(
        "--hover-mm",
        type=number(0.25, above=True),
        default=None,
        help="also map a finger hovering this high (its point and height)",
    )
    p.add_argument("--faces", default=None, help="faces, comma-separated (default: every skin's)")
    p.add_argument(
        "--mesh",
        default="coarse",
        help="method-of-moments mesh: coarse (default, quick maps) or default (the twin's)",
    )
    p.add_argument("--layout", help="layout JSON file (default: the paper's layout)")
    p.add_argument(
        "--workers",
        type=integer(0),
        default=2,
        help="Dask LocalCluster worker processes (default 2; 0: in this process)",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        help="a running Dask scheduler, tcp://HOST:PORT (default: a local cluster)",
    )
    add_figure_options(p)
    add_overwrite(p)
    p.add_argument("--no-progress", action="store_true")


def parse_states(states: str | None, levels: str | None) -> list[tuple[float, ...]]:
    """The inflation states of ``--states`` ("p1,p2,p3;...") or ``--levels`` (all combinations)."""
    if states is not None and levels is not None:
        raise EctskinError("give --states or --levels, not both")
    if levels is not None:
        values = parse_floats("--levels", levels)
        return [tuple(p) for p in itertools.product(values, repeat=N_CHAMBERS)]
    parts = [s for s in (states or "0,0,0;20,20,20").split(";") if s.strip()]
    if not parts:
        raise EctskinError(f"--states must hold at least one state, got {states!r}")
    return [tuple(parse_floats("--states", s, N_CHAMBERS)) for s in parts]


def parse_nuisances(text: str) -> tuple[str, ...]:
    if text.strip() == "none":
        return ()
    names = [s.strip() for s in text.split(",") if s.strip()]
    for n in names:
        check_option("--nuisance", n, NUISANCE_NAMES)
    if len(set(names)) != len(names):
        raise EctskinError(f"--nuisance names a nuisance twice: {text!r}")
    return tuple(names)


def parse_priors(text: str) -> dict[str, float]:
    if text.strip() == "none":
        return {}
    out = {}
    for part in (s.strip() for s in text.split(",") if s.strip()):
        name, _, value = part.partition("=")
        check_option("--priors", name.strip(), NUISANCE_NAMES)
        sd = parse_floats(f"--priors {name.strip()}", value, 1)[0]
        if not sd >= 0:
            raise EctskinError(f"--priors: {name.strip()} needs a standard deviation >= 0, got {sd}")
        out[name.strip()] = sd
    return out


def run(args: argparse.Namespace) -> int:
    # imported here: the twin, dask and matplotlib take seconds to import
    from ectskin._files import save_figure_atomic, write_json_atomic
    from ectskin.design.cluster import open_runner
    from ectskin.layout import default_layout, load_layout
    from ectskin.twin.bound import COARSE, TwinResponse, bound_maps
    from ectskin.twin.sensor import SensorModel
    from ectskin.viz import check_figure_options, figure_file
    from ectskin.viz.bound import plot_bound_maps

    out = Path(resolve_out(args, "an output folder"))
    fmt, dpi = check_figure_options(args.figure_format, args.dpi)
    states = parse_states(args.states, args.levels)
    nuisances = parse_nuisances(args.nuisance)
    priors = parse_priors(args.priors)
    check_option("--mesh", args.mesh, ("coarse", "default"))
    layout = load_layout(args.layout) if args.layout else default_layout()
    faces = None
    if args.faces is not None:
        faces = [f.strip() for f in args.faces.split(",") if f.strip()]
        for f in faces:
            check_option("--faces", f, sorted({s.surface for s in layout.skins}))
    modes = ["contact"] + ([] if args.hover_mm is None else ["hover"])
    files = {"json": out / "bound.json"} | {
        m: out / figure_file("bound" if m == "contact" else "bound_hover", fmt) for m in modes
    }
    there = [str(f) for f in files.values() if f.exists()]
    if there and not args.overwrite:
        raise EctskinError(f"{there[0]}: file exists; use --overwrite to replace it")
    sensor = SensorModel(layout, discretisation=COARSE if args.mesh == "coarse" else None)
    providers = {s: TwinResponse(sensor, s) for s in states}  # checks each state
    with open_runner(args.workers, args.scheduler) as runner:
        log.info("bound maps of %d state(s) on %s", len(states), runner.address)
        maps = bound_maps(
            providers,
            layout,
            faces=faces,
            spacing_mm=args.spacing_mm,
            force_n=args.force_n,
            hover_mm=args.hover_mm,
            nuisances=nuisances,
            prior_sd=priors,
            runner=runner,
            progress=not args.no_progress,
        )
    maps["settings"]["mesh"] = args.mesh
    write_json_atomic(files["json"], maps)
    shown = list(dict.fromkeys([maps["cases"][0], maps["cases"][-1]]))
    for m in modes:
        save_figure_atomic(plot_bound_maps(maps, mode=m, cases=shown), files[m], dpi=dpi)
    for m in modes:
        for case, s in maps["summary"][m].items():
            third = "force_n" if m == "contact" else "height_mm"
            log.info(
                "%s %-9s position median %.3g mm (p95 %.3g), %s median %.3g (p95 %.3g)%s",
                m, case, s["position_mm"]["median"], s["position_mm"]["p95"], third,
                s[third]["median"], s[third]["p95"],
                f", force observable on {s['force_observable_share']:.0%}" if m == "contact" else "",
            )
    log.info("wrote %s", ", ".join(str(f) for f in files.values()))
    return 0
