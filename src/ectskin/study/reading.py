"""The ablation of the twin's reading of the paper's experiment (``ectskin study reading``).

The paper's TouchMLP, trained with the paper's recipe, reaches 99.88 % on the paper's data; on
the twin it reaches much less. The twin's reading of the experiment (paper §3, "we randomly
touch a sub-region of the robot and induce different deformations by changing the contact
force") holds choices the text does not pin down. Each row
(:data:`~ectskin.study.reading_rows.ROWS`) changes one of them from the default
``Protocol(seed=s)`` (the ``sliding`` row two fields that make one choice);
each cell simulates that protocol, trains and scores as the reproduction does
(:func:`ectskin.study.reading_eval.measure`) and writes its numbers to
``OUT/results/<row>_s<seed>.json``:

* the TouchMLP under the paper's recipe (the demo's ``quick`` profile): test accuracy, the
  epoch whose weights were kept, of how many;
* the same network under the ``robust`` recipe: test accuracy;
* the touch baselines (majority, logistic regression, random forest, k-NN) on the same split,
  the strongest named;
* the seconds the simulation, the two trainings and the evaluations took.

Cells run seed by seed (every row of the first seed, in ``RUN_ORDER``, then the next seed);
a cell whose result file is there, made with the same settings (:func:`cell_settings`), is
skipped, so a stopped study resumes where it stopped. The rows and the result files are
:mod:`ectskin.study.reading_rows`; the table and figure (:mod:`ectskin.study.reading_table`)
are made from whatever results exist. ``docs/paper-reading.md`` describes the rows and the results.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ectskin._check import EctskinError
from ectskin._files import to_jsonable, write_json_atomic
from ectskin.study.reading_rows import (
    ROW_NAMES,
    WORK,
    Row,
    cell_settings,
    get_rows,
    read_result,
    result_path,
)
from ectskin.twin.protocol import Protocol

log = logging.getLogger(__name__)


def _measure(protocol: Protocol, row: Row, work: Path, workers: int, keep: bool) -> dict[str, Any]:
    from ectskin.study.reading_eval import measure

    return measure(protocol, row.split, work, workers, keep_data=keep)


def run_reading(
    out: str | Path,
    seeds: Sequence[int] = (0, 1, 2),
    rows: Sequence[str] | None = None,
    *,
    workers: int = 2,
    base: Protocol | None = None,
    measure: Callable[[Protocol, Row, Path, int, bool], dict[str, Any]] | None = None,
) -> list[Path]:
    """Run the ablation's cells into ``out`` (module docstring): for each seed, each row; a
    cell with a result file of the same settings is skipped. ``base``: the protocol the rows
    change (default the paper's; a smaller one for a quick look; its seed is replaced by each
    seed). ``measure(protocol, row, work folder, workers, keep the data)``: what computes a cell
    (default :func:`ectskin.study.reading_eval.measure`). Returns the result files of the cells
    asked for."""
    out = Path(out)
    chosen = get_rows(rows)
    seeds = [_check_seed(s) for s in seeds]
    if not seeds:
        raise EctskinError("study reading: --seeds needs at least one seed")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise EctskinError(f"study reading: workers must be an integer >= 1, got {workers!r}")
    compute = measure or _measure
    paths: list[Path] = []
    for seed in seeds:
        todo = []
        for row in chosen:
            path = result_path(out, row, seed)
            settings = cell_settings(row, seed, base)
            found = read_result(path)
            if found is not None and found.get("settings") == settings:
                log.info("reading ablation: %s seed %d done before (%s)", row.name, seed, path)
            else:
                todo.append((row, path, settings))
            paths.append(path)
        for i, (row, path, settings) in enumerate(todo):
            later = {r.data_name for r, _, _ in todo[i + 1 :]}
            work = out / WORK / f"{row.data_name}_s{seed}"
            log.info("reading ablation: %s seed %d ...", row.name, seed)
            keep = row.data_name in later
            body = compute(row.protocol(seed, base), row, work, workers, keep)
            write_json_atomic(path, {"settings": settings, **to_jsonable(body)})
            log.info(
                "reading ablation: %s seed %d: paper recipe %.2f %% (epoch %s of %s), robust "
                "%.2f %%, %s %.2f %%; simulate %.0f s, train %.0f + %.0f s",
                row.name, seed, 100 * body["paper"]["accuracy"], body["paper"]["best_epoch"],
                body["paper"]["epochs"], 100 * body["robust"]["accuracy"],
                body["best_baseline"]["name"], 100 * body["best_baseline"]["accuracy"],
                body["seconds"]["simulate"], body["seconds"]["train_paper"],
                body["seconds"]["train_robust"],
            )
    return paths


def _check_seed(seed: Any) -> int:
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise EctskinError(f"study reading: seeds must be integers >= 0, got {seed!r}")
    return seed


# ---------------------------------------------------------------------------- command line
HELP = "the ablation of the twin's reading of the paper's experiment (touch accuracy per row)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--out", required=True, type=Path,
                   help="output folder (results/, the table and the figure)")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2], metavar="SEED",
                   help="protocol, split and training seeds (default 0 1 2)")
    p.add_argument("--rows", nargs="+", choices=ROW_NAMES, default=None, metavar="ROW",
                   help=f"rows to run (default all): {', '.join(ROW_NAMES)}")
    p.add_argument("--workers", type=int, default=2,
                   help="simulation processes (default 2; the results do not depend on it)")
    p.add_argument("--table-only", action="store_true",
                   help="only write the table and figure from the results already there")


def run(args: argparse.Namespace) -> int:
    from ectskin.study.reading_table import write_table

    if not args.table_only:
        run_reading(args.out, args.seeds, args.rows, workers=args.workers)
    table, figure = write_table(args.out)
    print(f"table: {table}")
    if figure is not None:
        print(f"figure: {figure}")
    return 0
