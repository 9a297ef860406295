"""Touch recognition at inflation levels never trained on (``ectskin study unseen-inflation``,
:func:`unseen_inflation`).

Per seed, a touch run is trained on a recording of the training levels (default {0, 10, 20} ml
per chamber, the paper's) and evaluated on a recording of other levels (default {0, 5, 15} ml):
every state with a 5 or 15 ml chamber is unseen, and every test trial is a new draw (the test
experiment draws from random streams of its own, ``Protocol.stream`` = :data:`TEST_STREAM`; a
test trial whose readouts equal a training trial's is an error). Both recordings are simulated
in the twin (``OUT/data/train_s<seed>.h5``, ``test_s<seed>.h5``; an existing file of the same
protocol is reused), or the training one is given (``train_data``, e.g. the demo's
``data.h5``; ``{seed}`` in the path is replaced by the seed): the test protocol is then the
training recording's own (its finger, hand, readout, manipulator) with the test levels.

Each seed trains one run per training profile (``profiles``, default the paper's optimiser in
its CPU setting ``quick`` and ``robust``) and Eq. 2 reference (``references``, default
``rest``, ``state``, ``inflation``: :mod:`ectskin.io.inflation_reference`) with
:func:`ectskin.learn.train.train_from_recording` (the run's own trial split of the training
recording, seed = the seed; ``OUT/runs/s<seed>/<profile>_<reference>``, resumed if there) and
evaluates it (into ``OUT/evals/s<seed>/<profile>_<reference>/unseen``; an evaluation newer
than the run's model is reused) on the whole test recording with :func:`ectskin.learn.evaluate.evaluate_run` (the
run's reference re-applied: the test recording's own rest or per-state no-contact trials, or
the inflation model stored in the run). The touch baselines are fit on the same calibrated
training trials and scored on the same test frames, once per (seed, reference).

``OUT/unseen_inflation.json`` (written atomically): per seed, profile and reference the test
accuracy, the kept epoch, the accuracy per test state and per group of states (by the unseen
levels they hold) and the baselines; a summary per profile and reference over the seeds with
the strongest baseline. ``OUT/unseen_inflation.png``: the accuracy per test state and overall,
per profile and reference, beside the strongest baseline.
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ectskin._check import EctskinError, check_option, check_seed

log = logging.getLogger(__name__)

HELP = (
    "touch recognition at unseen inflation levels: train at {0,10,20} ml, test at {0,5,15} ml, "
    "per training profile and Eq. 2 reference, with the baselines"
)
EXAMPLES = """\
  ectskin study unseen-inflation -o unseen                          # simulate, seeds 0 1 2
  ectskin study unseen-inflation -o unseen --train-data 'demo{seed}/data.h5'  # reuse the demo's
  ectskin study unseen-inflation -o unseen --profiles robust --references state,inflation
"""

RESULT_FILE = "unseen_inflation.json"
FIGURE_FILE = "unseen_inflation.png"
FORMAT = "ectskin.unseen_inflation"
VERSION = 1
#: the test experiment's random streams (Protocol.stream): not the paper's (0), not the contact
#: experiment's (1)
TEST_STREAM = 2
PROFILES = ("quick", "robust")
REFERENCES = ("rest", "state", "inflation", "state-offset", "inflation-offset")
#: the references the study runs by default
DEFAULT_REFERENCES = ("rest", "state", "inflation")


@dataclass(frozen=True)
class UnseenInflationConfig:
    """What :func:`unseen_inflation` does (module docstring). ``train_data`` / ``test_data``:
    recording paths with ``{seed}`` for the seed (None: simulated into ``OUT/data``);
    ``epochs``, ``counts``: overrides of the profiles' epochs and of the trial split (default
    the task's); ``own_split``: also evaluate each run on its own test split of the training
    recording (seen levels); ``workers``: simulation processes; ``overwrite``: replace a
    simulated recording in ``OUT/data`` that holds another protocol (else refused);
    ``coverage``: the ``robust`` runs also train on the twin's coverage trials of the training
    protocol (:mod:`ectskin.twin.coverage`; the training levels only, so the test levels stay
    unseen; ``OUT/data/coverage_s<seed>.h5``), as the demo's robust run does."""

    seeds: tuple[int, ...] = (0, 1, 2)
    train_levels_ml: tuple[float, ...] = (0.0, 10.0, 20.0)
    test_levels_ml: tuple[float, ...] = (0.0, 5.0, 15.0)
    profiles: tuple[str, ...] = PROFILES
    references: tuple[str, ...] = DEFAULT_REFERENCES
    train_data: str | None = None
    test_data: str | None = None
    epochs: int | None = None
    counts: tuple[float, float, float] | None = None
    baselines: bool = True
    own_split: bool = True
    workers: int | None = None
    progress: bool = False
    test_stream: int = TEST_STREAM
    overwrite: bool = False  # a simulated recording of OUT/data of another protocol is replaced
    coverage: bool = True  # robust runs also train on the twin's coverage trials (train levels)

    def __post_init__(self) -> None:
        if not self.seeds or not self.profiles or not self.references:
            raise EctskinError("unseen-inflation: seeds, profiles and references must not be empty")
        for s in self.seeds:
            check_seed("seed", s, source="unseen-inflation")
        from ectskin.learn.profiles import profiles_for

        for p in self.profiles:
            check_option("profile", p, profiles_for("touch"), source="unseen-inflation")
        for r in self.references:
            check_option("reference", r, REFERENCES, source="unseen-inflation")
        if not set(self.test_levels_ml) - set(self.train_levels_ml) and self.test_data is None:
            raise EctskinError(
                f"unseen-inflation: the test levels {list(self.test_levels_ml)} ml hold no level "
                f"outside the training levels {list(self.train_levels_ml)} ml"
            )
        if self.test_stream < 1:
            raise EctskinError(
                f"unseen-inflation: test_stream must be >= 1 (0 draws the paper's experiment "
                f"again), got {self.test_stream}"
            )


# ----------------------------------------------------------------------------- recordings
def unseen_protocol(train_protocol: Any, levels_ml: tuple[float, ...], stream: int) -> Any:
    """The test experiment: the training ``Protocol`` with the test ``levels_ml``, drawing from
    random streams of its own (``stream``, or the next one if the training used it)."""
    if train_protocol.stream == stream:
        stream += 1
    return replace(train_protocol, levels_ml=tuple(float(v) for v in levels_ml), stream=stream)


def _simulated(path: Path, protocol: Any, like: Any, config: UnseenInflationConfig) -> Path:
    """``path`` holding the simulation of ``protocol`` (on the layout and body of the recording
    ``like``, else the paper's): reused when it exists with the same protocol; one of another
    protocol is replaced only with ``config.overwrite``."""
    from ectskin._files import to_jsonable
    from ectskin.io import read_recording, write_recording
    from ectskin.twin.mechanics import recording_manipulator
    from ectskin.twin.simulate import simulate_experiment

    want = to_jsonable(protocol.to_dict())
    if path.exists():
        found = to_jsonable(read_recording(path).meta.get("protocol")) or {}
        if found == want:
            log.info("reusing %s (same protocol)", path)
            return path
        if not config.overwrite:
            differ = sorted(k for k in want if found.get(k) != want[k])
            raise EctskinError(
                f"{path}: protocol: expected the study's, found another (differs in {differ}); "
                "pass --overwrite to simulate it again in its place, or use another --out"
            )
        log.info("%s holds another protocol: simulating it again (--overwrite)", path)
    kw: dict[str, Any] = {}
    if like is not None:
        kw["layout"] = like.layout
        kw["manipulator"] = recording_manipulator(like.meta)[0]
    log.info("simulating %s: levels %s ml, seed %d", path, list(protocol.levels_ml), protocol.seed)
    rec = simulate_experiment(protocol, workers=config.workers, progress=config.progress, **kw)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_recording(rec, path, overwrite=True)


def recordings(
    out: Path, seed: int, config: UnseenInflationConfig
) -> tuple[Path, Path, Path | None]:
    """The training and test recordings of ``seed`` (module docstring), checked to share no
    trial (by readouts), and the coverage trials of the training protocol (None without
    ``config.coverage``, a robust profile, or a training protocol to derive them from)."""
    from ectskin.io import read_recording
    from ectskin.learn.splits import trial_digests
    from ectskin.twin.protocol import Protocol

    train_rec = None
    if config.train_data is not None:
        train_path = Path(config.train_data.replace("{seed}", str(seed)))
        train_rec = read_recording(train_path)
        if "protocol" not in train_rec.meta and config.test_data is None:
            raise EctskinError(
                f"{train_path}: has no twin protocol (meta 'protocol') to simulate the test "
                "levels from; give the test recording too (--test-data)"
            )
        proto = train_rec.meta.get("protocol")
        base = Protocol.from_dict(proto) if proto is not None else None
    else:
        base = Protocol(levels_ml=tuple(config.train_levels_ml), seed=seed)
        train_path = _simulated(out / "data" / f"train_s{seed}.h5", base, None, config)
        train_rec = read_recording(train_path)
    if config.test_data is not None:
        test_path = Path(config.test_data.replace("{seed}", str(seed)))
    else:
        assert base is not None  # a training recording without a protocol was refused above
        proto = unseen_protocol(base, tuple(config.test_levels_ml), config.test_stream)
        test_path = _simulated(out / "data" / f"test_s{seed}.h5", proto, train_rec, config)
    test_rec = read_recording(test_path)
    shared = set(trial_digests(train_rec).values()) & set(trial_digests(test_rec).values())
    if shared:
        raise EctskinError(
            f"{test_path}: {len(shared)} trial(s) have the readouts of a trial of {train_path}; "
            "the test trials must be new draws (another Protocol.stream)"
        )
    cover = None
    if config.coverage and "robust" in config.profiles and base is not None:
        from ectskin.twin.coverage import coverage_protocol

        cover_protocol = coverage_protocol(base, train_rec.layout)
        cover = _simulated(out / "data" / f"coverage_s{seed}.h5", cover_protocol, train_rec, config)
    return train_path, test_path, cover


# ----------------------------------------------------------------------------- the study
def _states(path: Path) -> dict[str, tuple[float, ...]]:
    from ectskin.io import read_recording

    return {t.name: tuple(t.inflation) for t in read_recording(path).trials}


def _group(state: tuple[float, ...], seen: set[float]) -> str:
    """The group of a test state: "seen levels" or the unseen levels it holds ("5 ml", ...)."""
    unseen = sorted({v for v in state if v not in seen})
    return "seen levels" if not unseen else " and ".join(f"{v:g}" for v in unseen) + " ml"


def _per_state(metrics: dict, states: dict, seen: set[float]) -> tuple[list, dict]:
    """Accuracy per test state and per group of states, from the per-trial accuracies."""
    per: dict[tuple, list[float]] = {}
    for t in metrics["per_trial"]:
        state = states[t["name"]]
        right = per.setdefault(state, [0.0, 0.0])
        right[0] += t["accuracy"] * t["n_frames"]
        right[1] += t["n_frames"]
    rows: list[dict[str, Any]] = [
        {"state_ml": list(s), "group": _group(s, seen), "accuracy": a / n, "n_frames": int(n)}
        for s, (a, n) in sorted(per.items())
    ]
    groups: dict[str, list[float]] = {}
    for r in rows:
        g = groups.setdefault(r["group"], [0.0, 0.0])
        g[0] += r["accuracy"] * r["n_frames"]
        g[1] += r["n_frames"]
    return rows, {k: a / n for k, (a, n) in groups.items()}


def _evaluated(run: Path, data: Path | None, folder: Path, baselines: bool) -> dict[str, Any]:
    """The touch metrics of ``run`` on ``data`` (None: its own test split), written to
    ``folder`` (outside the run directory, which training resumes); an evaluation there newer
    than the run's model (with baselines if asked) is reused."""
    from ectskin._files import read_json
    from ectskin.learn.evaluate import evaluate_run

    path = folder / "metrics.json"
    if path.exists() and path.stat().st_mtime > (run / "model.pt").stat().st_mtime:
        m = read_json(path)["touch"]
        if m.get("baselines") or not baselines:
            log.info("reusing %s", path)
            return m
    return evaluate_run(run, data, figures=False, baselines=baselines, out=folder, overwrite=True)[
        "touch"
    ]


def _one_run(
    out: Path,
    seed: int,
    profile: str,
    reference: str,
    paths: tuple[Path, Path, Path | None],
    baselines: bool,
    config: UnseenInflationConfig,
) -> dict[str, Any]:
    from ectskin.learn.train import TrainConfig, train_from_recording

    train_path, test_path, cover = paths
    extra = (str(cover),) if cover is not None and profile == "robust" else ()
    run = out / "runs" / f"s{seed}" / f"{profile}_{reference}"
    tc = TrainConfig(
        profile=profile,
        seed=seed,
        epochs=config.epochs,
        counts=config.counts,
        progress=config.progress,
        reference=reference,
        extra_train=extra,
    )
    summary = train_from_recording("touch", train_path, run, tc)
    evals = out / "evals" / f"s{seed}" / f"{profile}_{reference}"
    m = _evaluated(run, test_path, evals / "unseen", baselines)
    states = _states(test_path)
    seen = {v for s in _states(train_path).values() for v in s}
    per_state, per_group = _per_state(m, states, seen)
    own = None
    if config.own_split:
        o = _evaluated(run, None, evals / "own_split", baselines)
        own = {
            "accuracy": o["accuracy"],
            "n_test_frames": o["n_test_frames"],
            "baselines": {k: b["accuracy"] for k, b in (o.get("baselines") or {}).items()},
        }
    return {
        "seed": seed,
        "profile": profile,
        "reference": reference,
        "own_split": own,
        "accuracy": m["accuracy"],
        "n_test_frames": m["n_test_frames"],
        "n_misclassified": m["n_misclassified"],
        "best_epoch": summary.get("best_epoch"),
        "extra_train": list(extra),
        "calibration": m["reference"]["text"],
        "test_trials": m["test_data"]["n_trials"],
        "per_state": per_state,
        "per_group": per_group,
        "baselines": {k: b["accuracy"] for k, b in (m.get("baselines") or {}).items()},
        "run": str(run),
    }


def _strongest(results: list[dict[str, Any]], part: str | None) -> dict[tuple, tuple[str, float]]:
    """(seed, reference) → the baseline of highest accuracy (name, accuracy), on the unseen
    test data (``part`` None) or on the runs' own split (``part`` "own_split")."""
    best: dict[tuple, tuple[str, float]] = {}
    for r in results:
        block = r if part is None else (r.get(part) or {})
        for name, acc in (block.get("baselines") or {}).items():
            key = (r["seed"], r["reference"])
            if key not in best or acc > best[key][1]:
                best[key] = (name, acc)
    return best


def _compare(rows: list[dict[str, Any]], part: str | None, best: dict) -> dict[str, Any]:
    """Accuracy per seed, mean, minimum, the strongest baseline per seed and whether the model
    beat it in every seed (None where a baseline is missing)."""
    blocks: list[Any] = [r if part is None else r.get(part) for r in rows]
    if any(b is None for b in blocks):
        return {}
    acc = [b["accuracy"] for b in blocks]
    base = [best.get((r["seed"], r["reference"])) for r in rows]
    return {
        "accuracy": acc,
        "accuracy_mean": float(np.mean(acc)),
        "accuracy_min": float(np.min(acc)),
        "strongest_baseline": [
            None if b is None else {"name": b[0], "accuracy": b[1]} for b in base
        ],
        "beats_strongest_baseline": None
        if any(b is None for b in base)
        else all(a > b[1] for a, b in zip(acc, base, strict=True) if b is not None),
    }


def _summary(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per profile and reference over the seeds (:func:`_compare`): on the unseen test data,
    and (``own_split``) on the runs' own test split of the training recording."""
    unseen, own = _strongest(results, None), _strongest(results, "own_split")
    out = []
    for profile, reference in dict.fromkeys((r["profile"], r["reference"]) for r in results):
        rows = [r for r in results if (r["profile"], r["reference"]) == (profile, reference)]
        out.append(
            {
                "profile": profile,
                "reference": reference,
                "seeds": [r["seed"] for r in rows],
                **_compare(rows, None, unseen),
                "own_split": _compare(rows, "own_split", own),
            }
        )
    return out


def _document(config, data, results, *, complete: bool) -> dict[str, Any]:
    return {
        "format": FORMAT,
        "version": VERSION,
        "complete": complete,
        "config": asdict(config),
        "data": data,
        "results": results,
        "summary": _summary(results),
    }


def unseen_inflation(out: str | Path, config: UnseenInflationConfig | None = None) -> dict:
    """Run the study (module docstring) into ``out``; return the document written to
    ``OUT/unseen_inflation.json`` (the figure beside it)."""
    from ectskin._files import save_figure_atomic, write_json_atomic

    config = config or UnseenInflationConfig()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    results, data = [], {}
    for seed in config.seeds:
        paths = recordings(out, seed, config)
        data[str(seed)] = {"train": str(paths[0]), "test": str(paths[1])}
        if paths[2] is not None:
            data[str(seed)]["coverage"] = str(paths[2])
        for reference in config.references:
            for i, profile in enumerate(config.profiles):
                baselines = config.baselines and i == 0
                row = _one_run(out, seed, profile, reference, paths, baselines, config)
                log.info(
                    "seed %d, %s, reference %s: %.2f %% on unseen inflation",
                    seed,
                    profile,
                    reference,
                    100 * row["accuracy"],
                )
                results.append(row)
                doc = _document(config, data, results, complete=False)
                write_json_atomic(out / RESULT_FILE, doc)  # so far, rewritten after each run
    doc = _document(config, data, results, complete=True)
    write_json_atomic(out / RESULT_FILE, doc)
    save_figure_atomic(plot_unseen_inflation(doc), out / FIGURE_FILE)
    log.info("wrote %s and %s", out / RESULT_FILE, out / FIGURE_FILE)
    return doc


def plot_unseen_inflation(doc: dict[str, Any], axes: Any = None) -> Any:
    """Two panels: the accuracy per test state (mean over seeds) per profile and reference,
    and the overall accuracy per profile and reference (seeds as dots, the strongest
    baseline of each seed as a cross). Returns the figure (the caller saves it)."""
    import matplotlib.pyplot as plt

    if axes is None:
        fig, axes = plt.subplots(1, 2, figsize=(13, 4.6), gridspec_kw={"width_ratios": [2.2, 1]})
    else:
        fig = axes[0].figure
    ax, bx = axes
    summary = doc["summary"]
    labels = [f"{s['profile']} / {s['reference']}" for s in summary]
    for s, label in zip(summary, labels, strict=True):
        rows = [
            r
            for r in doc["results"]
            if (r["profile"], r["reference"]) == (s["profile"], s["reference"])
        ]
        names = ["/".join(f"{v:g}" for v in p["state_ml"]) for p in rows[0]["per_state"]]
        acc = np.mean([[p["accuracy"] for p in r["per_state"]] for r in rows], axis=0)
        ax.plot(np.arange(len(names)), 100 * acc, marker="o", ms=3, label=label)
    ax.set_xticks(np.arange(len(names)), names, rotation=90, fontsize=7)
    ax.set_xlabel("test state (ml per chamber)")
    ax.set_ylabel("accuracy (%), mean over seeds")
    ax.set_title("touch accuracy per test state")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    for k, s in enumerate(summary):
        bx.scatter([k] * len(s["accuracy"]), 100 * np.array(s["accuracy"]), color="C0", s=18)
        bx.bar(k, 100 * s["accuracy_mean"], color="C0", alpha=0.35)
        base = [b["accuracy"] for b in s["strongest_baseline"] if b]
        if base:
            bx.scatter([k] * len(base), 100 * np.array(base), color="C3", marker="x", s=24)
    bx.scatter([], [], color="C3", marker="x", label="strongest baseline (per seed)")
    bx.set_xticks(np.arange(len(labels)), labels, rotation=45, ha="right", fontsize=8)
    low = min([min(s["accuracy"]) for s in summary] + [0.9])
    bx.set_ylim(100 * low - 2, 100.5)
    bx.axhline(95, color="k", lw=0.8, ls="--")
    bx.set_ylabel("accuracy on unseen inflation (%)")
    bx.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------- the command
def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--out", required=True, help="output folder")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="default 0 1 2")
    p.add_argument("--train-levels", default="0,10,20", help="ml (default 0,10,20)")
    p.add_argument("--test-levels", default="0,5,15", help="ml (default 0,5,15)")
    p.add_argument("--profiles", default=",".join(PROFILES), help=f"default {','.join(PROFILES)}")
    p.add_argument(
        "--references",
        default=",".join(DEFAULT_REFERENCES),
        help=f"Eq. 2 references, of {', '.join(REFERENCES)} "
        f"(default {','.join(DEFAULT_REFERENCES)})",
    )
    p.add_argument(
        "--train-data",
        default=None,
        help="training recording per seed, '{seed}' replaced (default: simulated into OUT/data)",
    )
    p.add_argument("--test-data", default=None, help="test recording per seed, '{seed}' replaced")
    p.add_argument("--epochs", type=int, default=None, help="override the profiles' epochs")
    p.add_argument("--no-baselines", action="store_true", help="skip the baselines")
    p.add_argument(
        "--no-own-split",
        action="store_true",
        help="do not also evaluate each run on its own test split of the training recording",
    )
    p.add_argument("--workers", type=int, default=None, help="simulation processes")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a simulated recording in OUT/data of another protocol")
    p.add_argument("--no-coverage", action="store_true",
                   help="train the robust runs without the twin's coverage trials")


def run(args: argparse.Namespace) -> int:
    from ectskin._check import parse_floats

    config = UnseenInflationConfig(
        seeds=tuple(args.seeds),
        train_levels_ml=tuple(parse_floats("--train-levels", args.train_levels)),
        test_levels_ml=tuple(parse_floats("--test-levels", args.test_levels)),
        profiles=tuple(v.strip() for v in args.profiles.split(",") if v.strip()),
        references=tuple(v.strip() for v in args.references.split(",") if v.strip()),
        train_data=args.train_data,
        test_data=args.test_data,
        epochs=args.epochs,
        baselines=not args.no_baselines,
        own_split=not args.no_own_split,
        workers=args.workers,
        progress=not args.no_progress,
        overwrite=args.overwrite,
        coverage=not args.no_coverage,
    )
    doc = unseen_inflation(args.out, config)
    for line in summary_lines(doc):
        log.info("%s", line)
    return 0


def summary_lines(doc: dict[str, Any]) -> list[str]:
    """Per profile and reference: the accuracy per seed and the strongest baseline."""
    lines = []
    for s in doc["summary"]:
        accs = ", ".join(f"{100 * a:.2f}" for a in s["accuracy"])
        base = ", ".join(
            "-" if b is None else f"{b['name']} {100 * b['accuracy']:.2f}"
            for b in s["strongest_baseline"]
        )
        lines.append(
            f"{s['profile']:>7} / {s['reference']:<16} unseen: {accs} % (mean "
            f"{100 * s['accuracy_mean']:.2f}); strongest baseline: {base}"
        )
        own = s.get("own_split") or {}
        if own:
            accs = ", ".join(f"{100 * a:.2f}" for a in own["accuracy"])
            base = ", ".join(
                "-" if b is None else f"{b['name']} {100 * b['accuracy']:.2f}"
                for b in own["strongest_baseline"]
            )
            lines.append(f"{'':>26} own split: {accs} %; strongest baseline: {base}")
    return lines
