"""Contact labels in the generic import (contact, position, force, height, surface;
docs/import-format.md): the Trial's ground truth, an HDF5 round trip, and the refusals."""

from __future__ import annotations

import numpy as np
import pytest

from ectskin import EctskinError
from ectskin.io import read_recording, write_recording
from ectskin.io.generic import load_generic

N = 12  # frames per group; groups "a" (front, a press), "b" (back, a press), "c" (no finger)


def _labels():
    """Per frame: readouts (3 channels), group, class, contact, position (x, z) mm, force N,
    height mm and surface; a press in the middle 6 frames of "a" and "b", the finger 3 mm
    above the skin in the frames just before and after, away otherwise."""
    rng = np.random.default_rng(4)
    n = 3 * N
    group = np.repeat(["a", "b", "c"], N)
    readouts = rng.uniform(1.0, 2.0, (n, 3))
    contact = np.zeros(n)
    pos = np.full((n, 2), np.nan)
    height = np.full(n, np.nan)
    for g in range(2):
        press = slice(g * N + 3, g * N + 9)
        contact[press] = 1
        pos[press] = rng.uniform(0, 40, (6, 2))
        height[press] = 0.0
        for i in (g * N + 2, g * N + 9):  # hovering over the skin
            pos[i] = rng.uniform(0, 40, 2)
            height[i] = 3.0
    force = np.where(contact == 1, rng.uniform(0.5, 4.0, n), 0.0)
    labels = np.where(contact == 1, np.repeat([1, 2, 0], N), 0)
    surface = np.repeat(["front", "back", ""], N)
    return group, readouts, labels, contact, pos, force, height, surface


def _csv(path, group, readouts, labels, contact, pos, force, height, surface, *, drop=()):
    cols = ["group", "label", "c:x1", "c:x2", "c:x3", "contact", "x_mm", "z_mm", "force_n"]
    cols += ["height_mm", "surface"]
    cols = [c for c in cols if c not in drop]

    def num(v):
        return "" if np.isnan(v) else repr(float(v))

    lines = ["# frame_rate_hz: 30", ",".join(cols)]
    for i in range(len(group)):
        cell = {
            "group": group[i],
            "label": str(int(labels[i])),
            "c:x1": num(readouts[i, 0]),
            "c:x2": num(readouts[i, 1]),
            "c:x3": num(readouts[i, 2]),
            "contact": str(int(contact[i])),
            "x_mm": num(pos[i, 0]),
            "z_mm": num(pos[i, 1]),
            "force_n": num(force[i]),
            "height_mm": num(height[i]),
            "surface": surface[i],
        }
        lines.append(",".join(cell[c] for c in cols))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _npz(path, group, readouts, labels, contact, pos, force, height, surface, **more):
    np.savez(
        path,
        readouts=readouts,
        group=group,
        labels=labels,
        contact=contact.astype(bool),
        position_mm=pos,
        force_n=force,
        height_mm=height,
        surface=surface,
        frame_rate_hz=30.0,
        **more,
    )
    return path


def _check(rec, contact, pos, force, height):
    """One finger per trial (finger 0 of the fingers axis)."""
    assert [t.name for t in rec.trials] == ["a", "b", "c"]
    assert [t.finger_surface for t in rec.trials] == [("front",), ("back",), (None,)]
    for k, t in enumerate(rec.trials):
        rows = slice(k * N, (k + 1) * N)
        assert t.n_fingers == 1 and t.contact.shape == (N, 1)
        f = t.finger(0)
        assert f.contact.dtype == bool and np.array_equal(f.contact, contact[rows] == 1)
        np.testing.assert_array_equal(f.uv_mm, pos[rows])  # NaN where no finger
        np.testing.assert_array_equal(f.height_mm, height[rows])
        np.testing.assert_array_equal(f.force, force[rows])
        assert t.has_ground_truth


@pytest.mark.parametrize("fmt", ["npz", "csv"])
def test_contact_labels_fill_the_ground_truth_and_survive_hdf5(tmp_path, fmt):
    group, readouts, labels, contact, pos, force, height, surface = _labels()
    src = tmp_path / f"rec.{fmt}"
    (_npz if fmt == "npz" else _csv)(
        src, group, readouts, labels, contact, pos, force, height, surface
    )
    rec = load_generic(src)
    _check(rec, contact, pos, force, height)
    write_recording(rec, tmp_path / "rec.h5")
    back = read_recording(tmp_path / "rec.h5")
    _check(back, contact, pos, force, height)


def test_without_contact_or_height_fields_contact_is_where_a_position_is(tmp_path):
    group, readouts, labels, contact, pos, force, height, surface = _labels()
    pos[contact == 0] = np.nan  # positions only where the finger presses
    src = _csv(
        tmp_path / "p.csv",
        group,
        readouts,
        labels,
        contact,
        pos,
        force,
        height,
        surface,
        drop=("contact", "height_mm"),
    )
    rec = load_generic(src)
    expected_height = np.where(contact == 1, 0.0, np.nan)
    _check(rec, contact, pos, force, expected_height)


def _refused(tmp_path, match, **change):
    group, readouts, labels, contact, pos, force, height, surface = _labels()
    values = {"contact": contact, "pos": pos, "force": force, "height": height, "surface": surface}
    for key, (i, v) in change.items():
        values[key] = values[key].copy()
        values[key][i] = v
    v = values
    src = _csv(
        tmp_path / "bad.csv",
        group,
        readouts,
        labels,
        v["contact"],
        v["pos"],
        v["force"],
        v["height"],
        v["surface"],
    )
    with pytest.raises(EctskinError, match=match):
        load_generic(src)


def test_inconsistent_contact_labels_are_refused_naming_row_and_column(tmp_path):
    # data rows start at line 3 (a comment line, then the header): frame i is line i + 3
    _refused(
        tmp_path,
        r"bad\.csv: line 8, columns 'x_mm', 'z_mm': expected a position where "
        r"contact is 1, found none",
        pos=(5, [np.nan, np.nan]),
    )
    _refused(tmp_path, r"line 4, column 'contact': expected 0 or 1, found 2\.0", contact=(1, 2))
    _refused(
        tmp_path,
        r"line 9, column 'force_n': expected a finite force >= 0 N, found -1\.0",
        force=(6, -1.0),
    )
    _refused(
        tmp_path,
        r"line 10, column 'height_mm': expected 0 \(or none\) in a contact frame, "
        r"found 2\.0",
        height=(7, 2.0),
    )
    _refused(
        tmp_path,
        r"line 5, columns 'x_mm', 'z_mm': expected two finite numbers",
        pos=(2, [1.0, np.nan]),
    )
    _refused(
        tmp_path,
        r"line 4, column 'surface': expected one of front, back, right, left, "
        r"found 'top'",
        surface=(1, "top"),
    )
    _refused(
        tmp_path,
        r"group 'a': surface must be one face per group, expected 'front' \(as "
        r"in its first rows\), found 'back' at line 9",
        surface=(6, "back"),
    )
    _refused(
        tmp_path,
        r"line 17, column 'height_mm': expected a height wherever a position is "
        r"given",
        height=(14, np.nan),
    )


def test_npz_contact_fields_shapes_and_a_hover_without_height(tmp_path):
    group, readouts, labels, contact, pos, force, height, surface = _labels()
    src = _npz(
        tmp_path / "s.npz", group, readouts, labels, contact, pos[:, :1], force, height, surface
    )
    with pytest.raises(EctskinError, match=r"field 'position_mm' must have shape \(36, 2\)"):
        load_generic(src)
    np.savez(
        tmp_path / "h.npz",
        readouts=readouts,
        group=group,
        labels=labels,
        position_mm=pos,
        frame_rate_hz=30.0,
    )
    # a position outside contact (the hover frames) without heights: contact is inferred from
    # the position, so every frame with one is a contact frame, and the import goes through
    rec = load_generic(tmp_path / "h.npz")
    assert np.array_equal(rec.trials[0].contact[:, 0], np.isfinite(pos[:N, 0]))
    np.savez(
        tmp_path / "c.npz",
        readouts=readouts,
        group=group,
        labels=labels,
        contact=contact,
        position_mm=pos,
        frame_rate_hz=30.0,
    )
    with pytest.raises(
        EctskinError,
        match=r"row 2, field 'position_mm': expected no position "
        r"outside contact without a height_mm field",
    ):
        load_generic(tmp_path / "c.npz")


# ------------------------------------------------------------------------ several fingers
def _fingers2():
    """Two groups of N frames: in "a" finger 0 presses the front throughout and finger 1 the
    back in frames 4..7, hovering 2 mm above it in frame 8 and away otherwise; in "b" finger 0
    presses, finger 1 stays away. Arrays on the fingers axis (n, 2[, 2])."""
    n = 2 * N
    rng = np.random.default_rng(7)
    contact = np.zeros((n, 2))
    contact[:, 0] = 1
    contact[4:8, 1] = 1
    pos = np.full((n, 2, 2), np.nan)
    pos[:, 0] = rng.uniform(0, 40, (n, 2))
    pos[4:9, 1] = rng.uniform(-20, 0, (5, 2))
    height = np.where(contact == 1, 0.0, np.nan)
    height[8, 1] = 2.0
    force = np.where(contact == 1, rng.uniform(0.5, 2.0, (n, 2)), 0.0)
    surface = np.full((n, 2), "", dtype="<U5")
    surface[:, 0] = "front"
    surface[:N, 1] = "back"
    group = np.repeat(["a", "b"], N)
    readouts = rng.uniform(1.0, 2.0, (n, 3))
    labels = np.where(contact[:, 0] == 1, 1, 0)
    return group, readouts, labels, contact, pos, force, height, surface


def _csv2(path, group, readouts, labels, contact, pos, force, height, surface, *, header=None):
    def num(v):
        return "" if np.isnan(v) else repr(float(v))

    cols = ["group", "label", "c:x1", "c:x2", "c:x3"]
    for pre in ("", "f1:"):
        cols += [f"{pre}{c}" for c in ("contact", "x_mm", "z_mm", "force_n", "height_mm", "surface")]
    lines = ["# frame_rate_hz: 30", ",".join(header or cols)]
    for i in range(len(group)):
        cells = [group[i], str(int(labels[i])), *(num(v) for v in readouts[i])]
        for k in range(2):
            cells += [str(int(contact[i, k])), num(pos[i, k, 0]), num(pos[i, k, 1])]
            cells += [num(force[i, k]), num(height[i, k]), str(surface[i, k])]
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


@pytest.mark.parametrize("fmt", ["npz", "csv"])
def test_two_fingers_import_on_the_fingers_axis(tmp_path, fmt):
    group, readouts, labels, contact, pos, force, height, surface = _fingers2()
    if fmt == "csv":
        src = _csv2(tmp_path / "two.csv", group, readouts, labels, contact, pos, force, height,
                    surface)
    else:
        src = _npz(tmp_path / "two.npz", group, readouts, labels, contact, pos, force, height,
                   surface)
    for rec in (load_generic(src), None):
        if rec is None:  # and the same after an HDF5 round trip
            rec = read_recording(write_recording(load_generic(src), tmp_path / "two.h5"))
        a, b = rec.trials
        assert (a.n_fingers, b.n_fingers) == (2, 2)
        assert a.finger_surface == ("front", "back") and b.finger_surface == ("front", None)
        for t, rows in ((a, slice(0, N)), (b, slice(N, 2 * N))):
            np.testing.assert_array_equal(t.contact, contact[rows] == 1)
            np.testing.assert_array_equal(t.finger_uv_mm, pos[rows])
            np.testing.assert_array_equal(t.finger_height_mm, height[rows])
            np.testing.assert_array_equal(t.force, force[rows])
        assert a.n_contacts.tolist() == [1] * 4 + [2] * 4 + [1] * 4
        assert a.finger(1).height_mm[8] == 2.0 and np.isnan(b.finger(1).uv_mm).all()


def test_two_finger_labels_are_refused_naming_finger_line_and_column(tmp_path):
    data = _fingers2()
    group, readouts, labels, contact, pos, force, height, surface = data
    bad = force.copy()
    bad[1, 1] = 0.5  # finger 1 is away in frame 1 (line 4)
    with pytest.raises(EctskinError, match=r"two\.csv: line 4, column 'f1:force_n': expected 0 N "
                       r"in a frame without contact, found 0\.5"):
        load_generic(_csv2(tmp_path / "two.csv", group, readouts, labels, contact, pos, bad,
                           height, surface))
    faces = surface.copy()
    faces[5, 1] = "left"
    with pytest.raises(EctskinError, match=r"group 'a': surface of finger 1 must be one face per "
                       r"group, expected 'back' \(as in its first rows\), found 'left' at line 8"):
        load_generic(_csv2(tmp_path / "two.csv", group, readouts, labels, contact, pos, force,
                           height, faces))
    skip = "group,label,c:x1,c:x2,c:x3,contact,force_n,f2:contact,f2:force_n"
    (tmp_path / "gap.csv").write_text(f"# frame_rate_hz: 30\n{skip}\na,1,1,1,1,1,1,0,0\n")
    with pytest.raises(EctskinError, match=r"gap\.csv: line 2: contact-label columns of finger 2 "
                       r"but none of finger 1"):
        load_generic(tmp_path / "gap.csv")
    fewer = "group,label,c:x1,c:x2,c:x3,contact,force_n,f1:contact"
    (tmp_path / "fewer.csv").write_text(f"# frame_rate_hz: 30\n{fewer}\na,1,1,1,1,1,1,0\n")
    with pytest.raises(EctskinError, match=r"line 2: finger 1 has the contact-label columns "
                       r"f1:contact, finger 0 contact, force_n; every finger gives the same"):
        load_generic(tmp_path / "fewer.csv")
    _npz(tmp_path / "mixed.npz", group, readouts, labels, contact, pos, force[:, 0], height,
         surface)
    with pytest.raises(EctskinError, match=r"mixed\.npz: the contact fields disagree on the "
                       r"number of fingers \('contact' 2, 'position_mm' 2, 'force_n' 1"):
        load_generic(tmp_path / "mixed.npz")
    far = pos.copy()
    far[2, 1] = [1.0, 2.0]  # finger 1 away in frame 2, but a position without a height
    _npz(tmp_path / "far.npz", group, readouts, labels, contact, far, force, height, surface)
    with pytest.raises(EctskinError, match=r"far\.npz: row 2, field 'height_mm' \(finger 1\): "
                       r"expected a height wherever a position is given"):
        load_generic(tmp_path / "far.npz")
