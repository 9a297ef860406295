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
    # margin over the strongest (here the only) tracking baseline: 5.678 - 1.234 = 4.444 mm
    assert (
        "C2DT's AD is 4.444 mm below the strongest baseline on the same test split, "
        "'markers do not move' (1.234 vs 5.678 mm, 78.3 % lower)." in md
    )
    assert (
        "TouchMLP reaches 99.51 %, 8.28 points above the strongest baseline on the same test "
        "split, 'k-NN' (91.23 %); always predicting the majority class gives 17.19 %." in md
    )
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
    assert (
        "C2DT does NOT beat the strongest baseline on the same test split, 'markers do not "
        "move': it loses by 1.000 mm (AD 6.000 vs 5.000 mm, 20.0 % higher)." in md
    )
    assert "Touch:" not in md  # no touch section without touch metrics


def test_every_margin_names_the_strongest_baseline_of_the_same_split(tmp_path):
    """The report compared C2DT only with "markers do not move" although ridge regression
    (0.522 mm) beat it (0.524 mm). Catches a margin that picks a fixed baseline (the old
    ``margin_text``: no_motion for tracking) instead of the strongest one."""
    track = {
        "ad_mm_mean": 0.524,
        "ad_mm_std": 0.3,
        "baselines": {
            "no_motion": {"ad_mm_mean": 1.871, "ad_mm_std": 1.0},
            "mean_pose": {"ad_mm_mean": 2.5, "ad_mm_std": 1.0},
            "ridge": {"ad_mm_mean": 0.522, "ad_mm_std": 0.3},
        },
        "ablations": {"window_1": {"ad_mm_mean": 0.6}, "no_prior": {"ad_mm_mean": 0.51}},
    }
    touch = {
        "accuracy": 0.90,
        "baselines": {
            "majority": {"accuracy": 0.17},
            "knn": {"accuracy": 0.93},
            "logreg": {"accuracy": 0.88},
        },
        "robust": {"accuracy": 0.95},
    }
    md = write_report(tmp_path, {"track": track, "touch": touch})[0].read_text()
    margins = md.split("## Margin over the strongest baseline")[1].split("##")[0]
    assert (
        "C2DT does NOT beat the strongest baseline on the same test split, 'ridge regression': "
        "it loses by 0.002 mm (AD 0.524 vs 0.522 mm, 0.4 % higher); 'markers do not move' "
        "(the initial coordinates as the answer) gives 1.871 mm." in margins
    )
    assert (
        "TouchMLP does NOT beat the strongest baseline on the same test split, 'k-NN': "
        "90.00 % against 93.00 % (3.00 points lower); always predicting the majority class "
        "gives 17.00 %." in margins
    )
    assert "+5.00 points versus the paper's recipe, +2.00 points versus 'k-NN'" in margins
    # every sentence of the section names the strongest baseline of its task
    sentences = [line for line in margins.splitlines() if line.startswith("- ")]
    assert len(sentences) == 3
    assert all("ridge regression" in t or "k-NN" in t for t in sentences)
    # the ablations are set beside it too; the one that loses to it says so
    assert (
        "For scale: the strongest baseline on the same test split, 'ridge regression', reaches "
        "0.522 mm. Variants that do NOT beat it: 1 frame instead of 10." in md
    )


def test_report_has_contents_and_a_readable_machine_table(tmp_path):
    """A table of contents links every section; the machine table has a header and writes an
    empty GPU list as "none (CPU only)" (it showed an empty header and "gpu []")."""
    metrics = {**METRICS, "machine": {"cpu_count": 2, "gpu": [], "torch": "2.13.0"}}
    md_path, html_path = write_report(tmp_path, metrics)
    md, page = md_path.read_text(), html_path.read_text()
    headings = [line[3:] for line in md.splitlines() if line.startswith("## ")]
    assert "Results" in headings and "Machine" in headings
    contents = md.split("**Contents**")[1].split("## ")[0]
    for title in headings:
        anchor = title.lower().replace(" ", "-")
        assert f"- [{title}](#{anchor})" in contents, title
        assert f'<a href="#{anchor}">' in page and f'<h2 id="{anchor}">' in page, title
    assert md.index("**Contents**") < md.index("## Results")
    assert "| component | value |" in md and "|  |  |" not in md
    assert "| GPU | none (CPU only) |" in md and "| CPU cores | 2 |" in md
    assert "[]" not in md and "<th></th>" not in page


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


def test_the_robust_run_is_set_beside_its_own_baselines(tmp_path):
    """The robust run's baselines are fitted on its own calibrated inputs: the report sets it
    beside those (row and margin), not beside the paper-recipe run's."""
    own = {"logreg": {"accuracy": 0.9688}, "knn": {"accuracy": 0.9483}}
    robust = {"accuracy": 0.9700, "n_test_frames": 28800, "baselines": own}
    m = {**METRICS, "touch": {**METRICS["touch"], "robust": robust}}
    md = write_report(tmp_path, m)[0].read_text()
    row = next(line for line in md.splitlines() if "robust recipe (ours)" in line and "|" in line)
    assert "logistic regression 96.88 %" in row and "k-NN 94.83 %" in row
    # 97.00 - 96.88 = +0.12 points over the most accurate of its own baselines (not the k-NN
    # of the paper-recipe run, 91.23 %)
    assert "+0.12 points versus 'logistic regression' on the same calibrated inputs)" in md
    # trained with extra (coverage) trials: its baselines were fitted on them too, and the
    # report says so, and why the run has them
    cover = [{"file": "coverage.h5", "trials": 999}]
    robust["training"] = {"recipe": {"extra_train": cover}}
    md = write_report(tmp_path, m)[0].read_text()
    assert "'logistic regression' on the same calibrated inputs and training trials)" in md
    assert "Its training split also holds the twin's coverage trials" in md
    del robust["training"], robust["baselines"]  # without its own: the paper-recipe run's strongest (k-NN 91.23 %)
    md = write_report(tmp_path, m)[0].read_text()
    assert "+5.77 points versus 'k-NN'" in md


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
