"""The report holds the table rows and the numbers of a given metrics dict; it writes atomically."""

from __future__ import annotations

import base64

import pytest

from ectskin._check import EctskinError
from ectskin.report import results_table, write_report

METRICS = {
    "profile": "quick",
    "touch": {
        "accuracy": 0.99512,
        "n_test_frames": 28800,
        "n_misclassified": 141,
        "n_misclassified_adjacent": 120,
        "confusions": [{"true": 2, "pred": 3, "count": 77, "adjacent": True}],
        "baselines": {
            "majority": {"accuracy": 0.1719, "n_misclassified": 23850},
            "knn": {"accuracy": 0.9123, "n_misclassified": 2526},
        },
        "training": {"seconds": 61.2, "epochs": 30, "device": "cpu"},
        "split": {"train": 125, "val": 32, "test": 32},
    },
    "track": {
        "ad_mm_mean": 1.234,
        "ad_mm_std": 0.987,
        "examples": {"ad_mm": [1.0, 2.0], "worst_ad_mm": 2.0},
        "worst_trajectory": {"name": "trial_0042", "ad_mm_mean": 4.321},
        "per_marker": {"M1": {"ad_mm_mean": 0.5, "ad_mm_std": 0.1}},
        "baselines": {"no_motion": {"ad_mm_mean": 5.678, "ad_mm_std": 3.21}},
        "ablations": {
            "no_prior": {"ad_mm_mean": 7.5, "ad_mm_std": 2.0},
            "window_1": {"ad_mm_mean": 1.5, "ad_mm_std": 1.0},
        },
        "training": {"seconds": 150.0, "epochs": 20, "device": "cpu"},
    },
    "timings_s": {"simulate": 80.0, "train_touch": 61.2},
    "reused": ["simulate"],
    "machine": {"cpu_count": 2, "torch": "2.13.0"},
}


def _png(path):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(1, 1))
    fig.add_subplot().plot([0, 1], [0, 1])
    fig.savefig(path)
    return path


def test_table_rows_hold_paper_and_run_numbers():
    rows = {r[0]: r[1:] for r in results_table(METRICS)}
    assert rows["Touch: test accuracy"][:2] == ("99.88 %", "99.51 %")
    assert "majority class 17.19 %" in rows["Touch: test accuracy"][2]
    assert "k-NN 91.23 %" in rows["Touch: test accuracy"][2]
    assert rows["Touch: misclassified test frames"][:2] == ("34 of 28 800", "141 of 28 800")
    assert rows["Touch: confusions between adjacent regions"][1] == "120 of 141"
    ad = rows["Tracking: average distance AD (Eq. 3)"]
    assert ad[0] == "2.905 ± 2.207 mm" and ad[1] == "1.234 ± 0.987 mm"
    assert ad[2] == "markers do not move 5.678 ± 3.210 mm"
    assert rows["Tracking: worst of 6 shown examples"][:2] == ("3.754 mm", "2.000 mm")
    assert rows["Touch: training time"][0].startswith("10 min")
    assert rows["Touch: training time"][1] == "61.2 s on cpu, 30 epochs"
    assert rows["Tracking: training time"][1].startswith("2.5 min")
    assert rows["Touch: trials train / val / test"] == (
        "125 / 32 / 32 trials",
        "125 / 32 / 32 trials (28 800 test frames)",
        "—",
    )


def test_write_report_markdown_and_html(tmp_path):
    figs = {"Fig. 7: confusion map": _png(tmp_path / "fig7.png")}
    (tmp_path / "characterize").mkdir()
    _png(tmp_path / "characterize" / "fig3_inflation.png")
    md_path, html_path = write_report(tmp_path, METRICS, figs)
    md = md_path.read_text()
    assert "| metric | paper | this run | baselines |" in md
    assert "| Touch: test accuracy | 99.88 % | 99.51 % |" in md
    assert "| Tracking: average distance AD (Eq. 3) | 2.905 ± 2.207 mm | 1.234 ± 0.987 mm |" in md
    # margin over the no-motion baseline: 5.678 - 1.234 = 4.444 mm
    assert "4.444 mm below the 'markers do not move' baseline" in md
    assert "without prior knowledge" in md and "+6.266 mm" in md  # 7.5 - 1.234
    assert "1 frame instead of 10" in md
    assert "![Fig. 7: confusion map](fig7.png)" in md
    assert "(characterize/fig3_inflation.png)" in md  # the twin's Fig. 3 found by itself
    assert "| simulate | 80.0 s | reused (time of the earlier run) |" in md
    assert "| train_touch | 61.2 s |  |" in md
    html = html_path.read_text()
    assert html.count("data:image/png;base64,") == 2  # self-contained
    b64 = base64.b64encode((tmp_path / "fig7.png").read_bytes()).decode()
    assert b64 in html
    assert "<td>99.51 %</td>" in html and "<td>34 of 28 800</td>" in html
    leftovers = [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert leftovers == []


def test_report_says_when_the_model_loses_to_the_baseline(tmp_path):
    m = {
        "track": {
            "ad_mm_mean": 6.0,
            "ad_mm_std": 1.0,
            "baselines": {"no_motion": {"ad_mm_mean": 5.0, "ad_mm_std": 1.0}},
        }
    }
    md = write_report(tmp_path, m)[0].read_text()
    assert "does NOT beat the 'markers do not move' baseline" in md
    assert "Touch:" not in md  # no touch section without touch metrics


def test_report_errors(tmp_path):
    with pytest.raises(EctskinError, match="does not exist"):
        write_report(tmp_path / "missing", METRICS)
    with pytest.raises(EctskinError, match="nope.png"):
        write_report(tmp_path, METRICS, {"x": "nope.png"})


def test_report_shows_the_robust_recipe(tmp_path):
    words = "mixup (Beta 0.4, 0.4), weights of the best validation accuracy"
    robust = {"accuracy": 0.97, "recipe_description": words}
    m = {**METRICS, "touch": {**METRICS["touch"], "robust": robust}}
    md = write_report(tmp_path, m)[0].read_text()
    assert f"trained with the `robust` profile instead of the paper's recipe: {words}. It" in md
    del robust["recipe_description"]  # a metrics.json without the words still renders
    md = write_report(tmp_path, m)[0].read_text()
    assert "instead of the paper's recipe. It is evaluated on the same test trials" in md


def test_the_report_imports_no_data_or_learning_code():
    """report/ renders a dict: importing it loads neither torch nor the layers that make data."""
    import subprocess
    import sys

    code = (
        "import sys, ectskin.report; "
        "print(sorted(m for m in sys.modules if m == 'torch' or m.split('.')[:2] in "
        "[['ectskin', p] for p in ('io', 'twin', 'learn', 'pipeline', 'electrostatics')]))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_report_says_which_command_made_it(tmp_path):
    metrics = {**METRICS, "command": "ectskin demo --seed 3 --out 'my out'"}
    md_path, html_path = write_report(tmp_path, metrics, {})
    assert "Made by `ectskin demo --seed 3 --out 'my out'`." in md_path.read_text()
    assert "<code>ectskin demo --seed 3 --out &#x27;my out&#x27;</code>" in html_path.read_text()
