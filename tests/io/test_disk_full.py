"""A full disk: one clear error, no partial file, no crash (issue 12, defect 5).

HDF5 does not survive a failed write: closing the file writes its caches again, and a second
failure inside the library's close crashed the process (rc 139) when the handles were released.
The real failure is made without a small file system by a file-size limit (``RLIMIT_FSIZE``: a
write beyond it fails with EFBIG, as one beyond a full disk fails with ENOSPC) in a subprocess, so a
crash cannot take the test run with it; a tiny tmpfs is used where one can be mounted.
"""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.cli import main
from ectskin.io.hdf5 import RecordingWriter, read_recording, write_recording
from ectskin.io.hdf5 import append as append_mod

resource = pytest.importorskip("resource")  # POSIX: RLIMIT_FSIZE

LIMIT_BYTES = 150_000  # far less than the files written below


def _big_npz(path, n=20_000):
    rng = np.random.default_rng(0)
    np.savez(
        path,
        readouts=rng.normal(1.0, 0.01, (n, 28)),
        group=np.arange(n) // 100,
        labels=rng.integers(0, 5, n),
        frame_rate_hz=30.0,
    )
    return path


def _run_limited(args, limit=LIMIT_BYTES, timeout=120):
    """Run ``python args...`` with writes limited to ``limit`` bytes per file."""

    def limit_writes():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return subprocess.run(
        [sys.executable, *args],
        preexec_fn=limit_writes,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=os.environ.copy(),
    )


def _one_clear_error(proc, command):
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith(f"ectskin {command}: error")]
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    assert len(errors) == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    return errors[0]


def test_import_generic_beyond_a_write_limit_is_one_clear_error(tmp_path):
    """Before: the h5py file was written on disk; the failed close crashed at exit (rc 139)."""
    src = _big_npz(tmp_path / "big.npz")
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    proc = _run_limited(["-m", "ectskin", "import", "generic", str(src), "-o", str(out_dir / "r.h5")])
    line = _one_clear_error(proc, "import")
    assert "cannot write the recording (File too large)" in line
    assert "nothing was written there" in line
    assert list(out_dir.iterdir()) == []  # no file, no hidden temporary file


def test_recording_writer_beyond_a_write_limit_stops_cleanly(tmp_path):
    """Before: RuntimeError traceback, then a segfault; the broken file stayed."""
    out = tmp_path / "live.h5"
    script = textwrap.dedent(
        f"""
        import numpy as np
        from ectskin import EctskinError
        from ectskin.io.hdf5 import RecordingWriter
        from ectskin.layout import default_layout
        lay = default_layout()
        try:
            with RecordingWriter({str(out)!r}, lay, 30.0, flush_interval_s=0) as w:
                w.start_trial("t0")
                for k in range(100_000):
                    w.append(np.ones(lay.n_pairs), k / 30)
        except EctskinError as exc:
            print("EctskinError:", exc)
        import gc
        gc.collect()
        """
    )
    proc = _run_limited(["-c", script])
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr
    assert "EctskinError:" in proc.stdout and "File too large" in proc.stdout
    assert "the unfinished file was removed" in proc.stdout
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------- injected ENOSPC, in process
def _enospc(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_write_recording_enospc_leaves_no_file(tmp_path, monkeypatch, make_recording):
    rec = make_recording(n_frames=5)
    out = tmp_path / "r.h5"
    monkeypatch.setattr("ectskin._files.os.fsync", _enospc)  # where the bytes reach the disk
    with pytest.raises(EctskinError, match=r"No space left on device\); nothing was written"):
        write_recording(rec, out)
    assert list(tmp_path.iterdir()) == []
    # an earlier file is left as it was
    monkeypatch.undo()
    write_recording(rec, out)
    before = out.read_bytes()
    monkeypatch.setattr("ectskin._files.os.fsync", _enospc)
    with pytest.raises(EctskinError, match="No space left on device"):
        write_recording(make_recording(n_frames=7), out, overwrite=True)
    assert out.read_bytes() == before and sorted(tmp_path.iterdir()) == [out]


def test_simulate_enospc_is_one_clear_error(tmp_path, monkeypatch, capsys):
    out = tmp_path / "s.h5"
    monkeypatch.setattr("ectskin._files.os.fsync", _enospc)
    argv = ["simulate", "-o", str(out), "--levels", "0", "--touch-trials", "1", "--duration",
            "0.2", "--dwells", "1", "--workers", "1", "--no-progress"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "No space left on device" in err and "Traceback" not in err
    assert err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_writer_refuses_a_flush_the_disk_cannot_hold(tmp_path, monkeypatch, layout):
    """The free space is checked before HDF5 writes: a full disk never reaches the library."""
    out = tmp_path / "live.h5"
    w = RecordingWriter(out, layout, 30.0, flush_interval_s=1e9)
    w.start_trial("t0")
    w.append(np.ones((10, layout.n_pairs)), np.arange(10) / 30)
    monkeypatch.setattr(append_mod, "_free_bytes", lambda folder: 4096)
    with pytest.raises(EctskinError, match=r"the disk is full: 0\.00 MB free") as info:
        w.flush()
    assert "stopped after 10 frames" in str(info.value)
    assert "the unfinished file was removed" in str(info.value)
    assert w.closed and not out.exists()
    w.close()  # idempotent after the abort
    with pytest.raises(EctskinError, match="closed"):
        w.append(np.ones(layout.n_pairs), 1.0)


def test_writer_failed_write_aborts_and_removes_the_file(tmp_path, monkeypatch, layout):
    """An h5py write that fails all the same (ENOSPC) ends in one error and no file."""
    out = tmp_path / "live.h5"
    with pytest.raises(EctskinError, match=r"No space left on device\); the recording stopped"):
        with RecordingWriter(out, layout, 30.0, flush_interval_s=1e9) as w:
            w.start_trial("t0")
            w.append(np.ones((3, layout.n_pairs)), np.arange(3) / 30)
            monkeypatch.setattr(RecordingWriter, "_write_frames", _enospc)
            w.flush()
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_writer_close_on_a_full_disk_aborts(tmp_path, monkeypatch, layout):
    out = tmp_path / "live.h5"
    w = RecordingWriter(out, layout, 30.0, flush_interval_s=1e9)
    w.start_trial("t0")
    w.append(np.ones((3, layout.n_pairs)), np.arange(3) / 30)
    monkeypatch.setattr(RecordingWriter, "_finish", _enospc)
    with pytest.raises(EctskinError, match="No space left on device"):
        w.close()
    assert not out.exists()


def test_writer_still_records_with_room(tmp_path, layout):
    out = tmp_path / "ok.h5"
    with RecordingWriter(out, layout, 30.0, flush_interval_s=0) as w:
        w.start_trial("t0")
        for k in range(5):
            w.append(np.ones(layout.n_pairs), k / 30)
    assert read_recording(out).n_frames == 5


# ---------------------------------------------------------------------- a real full file system
def _can_mount_tmpfs() -> bool:
    if sys.platform != "linux" or shutil.which("unshare") is None:
        return False
    probe = subprocess.run(
        ["unshare", "--mount", "--map-root-user", "sh", "-c",
         "d=$(mktemp -d) && mount -t tmpfs -o size=64k tmpfs $d && umount $d && rmdir $d"],
        capture_output=True,
    )
    return probe.returncode == 0


@pytest.mark.skipif(not _can_mount_tmpfs(), reason="cannot mount a tmpfs (needs user namespaces)")
def test_real_full_tmpfs(tmp_path):
    """``import generic`` and the append writer on a 64 KiB tmpfs: one message each, no file."""
    src = _big_npz(tmp_path / "big.npz")
    mnt = tmp_path / "tiny"
    mnt.mkdir()
    writer = textwrap.dedent(
        f"""
        import numpy as np
        from ectskin import EctskinError
        from ectskin.io.hdf5 import RecordingWriter
        from ectskin.layout import default_layout
        lay = default_layout()
        try:
            with RecordingWriter({str(mnt / "live.h5")!r}, lay, 30.0, flush_interval_s=0) as w:
                w.start_trial("t0")
                for k in range(100_000):
                    w.append(np.ones(lay.n_pairs), k / 30)
        except EctskinError as exc:
            print("EctskinError:", exc)
        """
    )
    (tmp_path / "writer.py").write_text(writer)
    script = (
        f"mount -t tmpfs -o size=64k tmpfs {mnt} && "
        f"{sys.executable} -m ectskin import generic {src} -o {mnt / 'r.h5'}; echo rc=$?; "
        f"{sys.executable} {tmp_path / 'writer.py'}; echo rc=$?; ls -A {mnt}"
    )
    proc = subprocess.run(
        ["unshare", "--mount", "--map-root-user", "sh", "-c", script],
        capture_output=True, text=True, timeout=120, env=os.environ.copy(),
    )
    out = proc.stdout.splitlines()
    assert out[0] == "rc=2", proc.stderr[-2000:]
    assert "No space left on device" in proc.stderr and "Traceback" not in proc.stderr
    assert out[1].startswith("EctskinError:") and "the disk is full" in out[1]
    assert out[2] == "rc=0"
    assert out[3:] == []  # nothing left on the file system
