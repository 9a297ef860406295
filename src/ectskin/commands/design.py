"""``ectskin design score|search``: score electrode layouts in the twin, search the layout family.

Thin wrapper over :mod:`ectskin.design` (see ``docs/design.md``).
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import replace
from pathlib import Path

from ectskin._check import EctskinError, check_option, parse_floats
from ectskin.commands._options import add_seed, integer, number

HELP = "score electrode layouts in the twin, or search the layout family (Optuna on Dask)"
EXAMPLES = """\
  ectskin design score my_layout.json other.json --out scores   # + the paper's layout
  ectskin design score my_layout.json --out scores --workers 4
  ectskin design score my_layout.json --out scores --response solve   # solves per dwell
  ectskin design score my_layout.json --out scores --scheduler tcp://10.0.0.5:8786
  ectskin design search study                    # bound objective: 6 trials on 2 local workers
  ectskin design search study --trials 200 --scheduler tcp://10.0.0.5:8786
  ectskin design search study --objective fit       # the fit's worst-case error, not the bound
  ectskin design search study --objective trained   # train and evaluate every layout
  ectskin simulate --layout study/layouts/design-0003/layout.json -o rec.h5
"""
log = logging.getLogger(__name__)


def _pair(text: str, name: str) -> tuple[float, float]:
    v = parse_floats(name, text, 2)
    return float(v[0]), float(v[1])


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--workers",
        type=integer(0),
        default=2,
        help="Dask LocalCluster worker processes, one layout each at a time "
        "(default 2; 0: in this process, one after another)",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        help="a running Dask scheduler, tcp://HOST:PORT (default: a local cluster)",
    )
    add_seed(p, help="protocol, split and model seed (default 0)")
    p.add_argument(
        "--levels", default="0,20", help="inflation levels per chamber, ml (default 0,20: 8 states)"
    )
    p.add_argument(
        "--touch-trials",
        type=integer(0),
        default=None,
        help="touch trials per inflation state (default 12; 6 with --response solve)",
    )
    p.add_argument(
        "--duration",
        type=number(0, above=True),
        default=None,
        help="seconds per trial (default 15; 3 with --response solve)",
    )
    p.add_argument(
        "--response",
        default=None,
        help="trained score: how touch trials are read, field (default: from the states' "
        "response fields, built once per layout and cached, a new touch point every 0.5 s) or "
        "solve (method-of-moments solves per dwell)",
    )
    p.add_argument(
        "--field-grid",
        default="quick",
        help="with --response field: the fields' grid, quick (default) or fine",
    )
    p.add_argument(
        "--field-cache",
        default=None,
        help="with --response field: the field cache (default $ECTSKIN_CACHE/fields, else "
        "~/.cache/ectskin/fields)",
    )
    p.add_argument(
        "--epochs",
        default="15,6,3",
        help="quick-profile epochs of the touch, contact and track models (default 15,6,3)",
    )
    p.add_argument("--no-track", action="store_true", help="skip the tracking model")
    p.add_argument(
        "--mesh",
        default="coarse",
        help="trained score: the twin's mesh for the simulation, coarse (default: the "
        "information score's mesh, about 5x faster) or default (the twin's own)",
    )
    p.add_argument(
        "--min-width",
        type=float,
        default=0.5,
        help="manufacturing rule: narrowest wire, mm (default 0.5)",
    )
    p.add_argument(
        "--min-spacing",
        type=float,
        default=1.0,
        help="manufacturing rule: smallest gap between conductors, mm (default 1)",
    )
    p.add_argument(
        "--edge-margin",
        type=float,
        default=0.0,
        help="manufacturing rule: conductors this far inside the skin, mm (default 0)",
    )
    p.add_argument(
        "--bound-states",
        default="0/0/0,20/20/20",
        help="information score: inflation states, ml per chamber, '/' between chambers and ',' "
        "between states (default 0/0/0,20/20/20)",
    )
    p.add_argument(
        "--bound-spacing",
        type=number(0, above=True),
        default=15.0,
        help="information score: grid spacing on each face, mm (default 15)",
    )
    p.add_argument(
        "--bound-mesh",
        default="coarse",
        help="information score: mesh of the solves, coarse (default) or default",
    )


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="design_command", metavar="{score,search}")
    s = sub.add_parser("score", help="score layout files (and the paper's) in the twin")
    s.add_argument(
        "layouts",
        nargs="*",
        help="layout JSON files (each named after its file; a search's layouts/NAME/layout.json "
        "after NAME)",
    )
    s.add_argument("--out", required=True, help="folder for design.json, design.md/.html")
    _common(s)
    s.add_argument(
        "--no-bound", action="store_true", help="skip the information score (bound maps)"
    )
    s.add_argument(
        "--seeds",
        type=integer(1),
        default=3,
        help="train and evaluate every layout with this many seeds (--seed, --seed + 1, ...): "
        "means, 95 %% intervals and the paired comparison with the paper's layout (default 3)",
    )
    q = sub.add_parser(
        "search", help="Optuna study: worst-case bound (or trained error) vs electrodes and wire"
    )
    q.add_argument("out", help="folder of the study (resumed when it exists)")
    q.add_argument(
        "--objective",
        default="bound",
        help="bound (default: minimise the worst-case position bound, the electrode count and "
        "the total wire length), fit (the same with the worst-case error of a fit with one "
        "fingertip instead of the bound), fit-median (the same with that fit's median error) or "
        "trained (the mean localisation error and the electrode count)",
    )
    q.add_argument("--trials", type=integer(1), default=6, help="trials to finish (default 6)")
    q.add_argument("--sampler", default="tpe", help="tpe (default) or nsga2")
    q.add_argument("--min-wires", type=int, default=2, help="wires per face, at least (default 2)")
    q.add_argument("--max-wires", type=int, default=8, help="wires per face, at most (default 8)")
    q.add_argument("--length-mm", default="15,105", help="wire lengths, mm (default 15,105)")
    q.add_argument("--width-mm", default="0.5,2", help="wire widths, mm (default 0.5,2)")
    _common(q)


def _config(args):
    from ectskin.design.score import DEFAULT_RESPONSE, ScoreConfig, design_protocol

    epochs = [int(x) for x in parse_floats("--epochs", args.epochs, 3)]
    tasks = ("touch", "contact") if args.no_track else ("touch", "contact", "track")
    response = args.response or DEFAULT_RESPONSE
    check_option("--response", response, ("field", "solve"))
    given = {"touch_trials": args.touch_trials, "duration_s": args.duration}
    protocol = design_protocol(
        args.seed,
        response=response,
        levels_ml=tuple(parse_floats("--levels", args.levels)),
        **{k: v for k, v in given.items() if v is not None},
    )
    try:
        return ScoreConfig(
            protocol=protocol,
            epochs=dict(zip(("touch", "contact", "track"), epochs)),
            seed=args.seed,
            tasks=tasks,
            mesh=args.mesh,
            response=response,
            field_grid=args.field_grid,
            field_cache=args.field_cache,
        )
    except EctskinError as exc:
        raise EctskinError(f"--mesh / --field-grid / --field-cache: {exc}") from None


def _states(text: str) -> tuple[tuple[float, ...], ...]:
    """``0/0/0,20/20/20`` → ((0, 0, 0), (20, 20, 20)), each a volume per chamber of the twin."""
    from ectskin.twin.mechanics import Manipulator

    states = []
    for part in str(text).split(","):
        try:
            state = tuple(float(x) for x in part.split("/"))
        except ValueError:
            raise EctskinError(
                f"--bound-states: expected states like 0/0/0,20/20/20 (ml per chamber, '/' "
                f"between chambers), got {text!r}"
            ) from None
        try:
            Manipulator().check_inflation(state)
        except EctskinError as exc:
            raise EctskinError(f"--bound-states {part!r}: {exc}") from None
        states.append(state)
    return tuple(states)


def _information(args):
    from ectskin.design.information import InformationConfig

    states = _states(args.bound_states)
    try:
        return InformationConfig(
            states_ml=states, spacing_mm=args.bound_spacing, mesh=args.bound_mesh
        )
    except EctskinError as exc:  # the one left: --bound-mesh (states and spacing checked)
        raise EctskinError(f"--bound-mesh / --bound-states: {exc}") from None


def run(args: argparse.Namespace) -> int:
    # imported here: dask, optuna, torch and the twin take seconds to import
    from ectskin.design.family import ManufacturingRules
    from ectskin.layout import load_layout

    if args.design_command is None:
        raise EctskinError("design: choose a subcommand, score or search (ectskin design -h)")
    rules = ManufacturingRules(args.min_width, args.min_spacing, args.edge_margin)
    config = _config(args)
    information = _information(args)
    if args.design_command == "score":
        from ectskin._check import MAX_SEED
        from ectskin.design.sweep import score_layouts

        if args.seed + args.seeds - 1 > MAX_SEED:
            raise EctskinError(
                f"--seeds {args.seeds} from --seed {args.seed}: the seeds must stay <= {MAX_SEED}"
            )

        named = []
        for path in args.layouts:
            layout = load_layout(path)
            p = Path(path)  # a search's proposal, <study>/layouts/<name>/layout.json: <name>
            name = p.parent.name if p.stem == "layout" and p.parent.name else p.stem
            named.append((name, replace(layout, source=str(path))))
        design = score_layouts(
            named,
            args.out,
            config,
            n_workers=args.workers,
            scheduler=args.scheduler,
            rules=rules,
            information=None if args.no_bound else information,
            seeds=list(range(args.seed, args.seed + args.seeds)),
        )
        out = Path(args.out)
    else:
        from ectskin.design.search import SearchSpace, run_search

        space = SearchSpace(
            args.min_wires,
            args.max_wires,
            _pair(args.length_mm, "--length-mm"),
            _pair(args.width_mm, "--width-mm"),
        )
        design = run_search(
            args.out,
            n_trials=args.trials,
            space=space,
            objective=args.objective,
            config=config,
            information=information,
            rules=rules,
            sampler=args.sampler,
            seed=args.seed,
            n_workers=args.workers,
            scheduler=args.scheduler,
        )
        out = Path(args.out)
    for e in design["layouts"]:
        parts = [f"{e['name']:<14} {e['n_electrodes']:2d} electrodes"]
        if "loc_mm_mean" in e:
            parts.append(
                f"loc {_num(e['loc_mm_mean'], '.1f')} mm  region acc "
                f"{_num(e.get('region_accuracy'), '.3f')}  force {_num(e.get('force_mae_n'), '.3f')}"
                f" N  track {_num(e.get('track_ad_mm'), '.2f')} mm"
            )
        if "bound_mm_p95" in e:
            parts.append(
                f"bound mean {_num(e['bound_mm_mean'], '.3g')} p95 {_num(e['bound_mm_p95'], '.3g')}"
                f" mm  fit error mean {_num(e.get('fit_error_mm_mean'), '.3g')} p95 "
                f"{_num(e.get('fit_error_mm_p95'), '.3g')} mm  force share "
                f"{_num(e['force_observable_share'], '.2f')}  ambiguity "
                f"{_num(e['ambiguity_sigma'], '.3g')} sigma  wire {_num(e['wire_length_mm'], '.0f')}"
                f" mm"
            )
        log.info("  ".join(parts))
    log.info("wrote %s, %s", out / "design.json", out / "design.html")
    return 0


def _num(v, spec: str) -> str:
    return "n/a" if v is None else format(v, spec)
