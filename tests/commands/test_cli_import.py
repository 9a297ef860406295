"""`ectskin import` and `ectskin simulate` speak the CLI's one vocabulary (commands/_options.py):
-o/--out, --overwrite (alias --force), examples at the end of --help, messages naming flags."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin.cli import main
from ectskin.io.hdf5 import read_recording


def _help(capsys, argv):
    with pytest.raises(SystemExit) as e:
        main([*argv, "--help"])
    assert e.value.code == 0
    return capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, example",
    [
        (["simulate"], "ectskin simulate -o twin.h5"),
        (["import"], "ectskin import generic data.npz -o rec.h5"),
        (["import", "capacitance"], "ectskin import capacitance readout.csv -o rec.h5"),
        (["import", "mocap"], "ectskin import mocap take.csv --markers"),
        (["import", "build"], "ectskin import build --manifest trials.json -o rec.h5"),
        (["import", "generic"], "ectskin import generic frames.csv -o rec.h5 --frame-rate 30"),
    ],
)
def test_help_ends_with_examples(capsys, argv, example):
    out = _help(capsys, argv)
    assert "examples:" in out and example in out
    assert out.index("examples:") > out.index("options:")


@pytest.mark.parametrize("argv", [["simulate"], ["import", "generic"], ["import", "build"],
                                  ["import", "capacitance"]])
def test_output_and_overwrite_options_are_spelled_the_same(capsys, argv):
    out = _help(capsys, argv)
    assert "-o OUT, --out OUT" in out and "--overwrite, --force" in out


def _generic_csv(path, scale=1.0):
    rows = ["# frame_rate_hz: 30", "group,label,c:a,c:b,c:c"]
    rows += [f"g{k // 4},{k % 2},{scale * (1 + k / 10):.3f},1.2,0.9" for k in range(8)]
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def test_import_generic_overwrite_and_its_alias(tmp_path, capsys):
    src = _generic_csv(tmp_path / "g.csv")
    out = tmp_path / "g.h5"
    assert main(["import", "generic", str(src), "--out", str(out)]) == 0
    first = out.read_bytes()
    _generic_csv(src, scale=2.0)
    assert main(["import", "generic", str(src), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "file exists; use --overwrite to replace it" in err and "overwrite=True" not in err
    assert out.read_bytes() == first
    assert main(["import", "generic", str(src), "-o", str(out), "--force"]) == 0
    assert read_recording(out).trials[0].capacitance[0, 0] == pytest.approx(2.0)
    assert main(["import", "generic", str(src), "-o", str(out), "--overwrite"]) == 0


@pytest.mark.parametrize("kind", ["generic", "build"])
def test_import_without_output_names_the_flag(tmp_path, capsys, kind):
    src = _generic_csv(tmp_path / "g.csv")
    argv = ["import", kind, str(src)] if kind == "generic" else ["import", kind,
                                                                  "--capacitance", str(src)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "give -o/--out PATH" in err and err.count("\n") == 1


def test_library_errors_name_the_flag(tmp_path, capsys):
    p = tmp_path / "nofps.npz"
    np.savez(p, readouts=np.ones((3, 2)), group=np.zeros(3), labels=np.zeros(3))
    assert main(["import", "generic", str(p), "-o", str(tmp_path / "o.h5")]) == 2
    err = capsys.readouterr().err
    assert "--frame-rate on the command line" in err and "load_generic(" not in err


def test_an_os_error_is_one_line_without_a_traceback(tmp_path, capsys, monkeypatch):
    """A full disk met by a command that writes outside the atomic writers (e.g. a stream) is
    one line naming the file and the reason, never a traceback."""
    import errno

    from ectskin.commands import import_

    def full(rec, args):
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "o.h5"))

    monkeypatch.setattr(import_, "_write", full)
    src = _generic_csv(tmp_path / "g.csv")
    assert main(["import", "generic", str(src), "-o", str(tmp_path / "o.h5")]) == 2
    err = capsys.readouterr().err
    assert err == f"ectskin import: error: {tmp_path / 'o.h5'}: No space left on device\n"
