"""Covers bridge.record.halves: a SITL side's half of the trace as binary records (vehicle.bin, controller.bin),
written and read back as the vehicle, the controller and the session do, on real files; and the link read from the
halves alone (bridge.record.linkextract.extract_halves)."""

from __future__ import annotations

import json
import math
import random
from pathlib import Path

import numpy as np
import pytest

from bridge.record.columns import CONTROLLER_COLUMNS, VEHICLE_COLUMNS, ControllerRow
from bridge.record.halves import HalfReader, HalfWriter, count_records, header_line, read_half
from bridge.record.linkextract import extract_halves


def _values(rng: random.Random) -> list[float]:
    special = [math.nan, math.inf, -0.0, 5e-324, 1.7976931348623157e308, 0.1]
    return [rng.choice(special) if rng.random() < 0.2 else rng.uniform(-1e6, 1e6) for _ in CONTROLLER_COLUMNS]


def test_every_value_comes_back_to_the_bit_by_both_readers(tmp_path: Path) -> None:
    rng = random.Random(7)
    rows = [_values(rng) for _ in range(257)]
    out = HalfWriter(tmp_path / "controller.bin", CONTROLLER_COLUMNS, batch=10)
    for r in rows:
        out.write(r)
    out.close()
    back = HalfReader(tmp_path / "controller.bin", ControllerRow).read()
    assert np.array(back, dtype="<f8").tobytes() == np.array(rows, dtype="<f8").tobytes()
    assert all(type(r) is ControllerRow for r in back)
    arrays = read_half(tmp_path / "controller.bin")
    assert list(arrays) == list(CONTROLLER_COLUMNS)
    got = np.column_stack([arrays[c] for c in CONTROLLER_COLUMNS])
    assert got.tobytes() == np.array(rows, dtype="<f8").tobytes()  # the bits, NaNs and signed zeros included
    assert count_records(tmp_path / "controller.bin") == 257


def test_a_record_cut_short_is_read_when_it_is_whole(tmp_path: Path) -> None:
    """The session reads while the side writes: a header or a record not yet whole is left for the next read,
    and a record a killed writer cut short is never read as one."""
    path = tmp_path / "controller.bin"
    record = np.arange(len(CONTROLLER_COLUMNS), dtype="<f8").tobytes()
    head = header_line(CONTROLLER_COLUMNS)
    reader = HalfReader(path, ControllerRow)
    assert reader.read() == [] and reader.last() is None  # no file yet
    with open(path, "wb", buffering=0) as f:
        f.write(head[:10])
        assert reader.read() == [] and count_records(path) == 0
        f.write(head[10:] + record + record[:13])
        assert [r.k for r in reader.read()] == [0.0]
        assert count_records(path) == 1 and len(read_half(path)["k"]) == 1
        assert reader.last().k == 0.0  # the whole one, not the one cut short
        f.write(record[13:] + (2 * np.arange(len(CONTROLLER_COLUMNS), dtype="<f8")).tobytes())
        assert [r.t for r in reader.read()] == [1.0, 2.0]
        assert reader.read() == []
        assert reader.last().t == 2.0
    reader.close()



def test_the_newest_record_is_seen_without_a_read_after_the_header_came(tmp_path: Path) -> None:
    """A lockstep session reads the vehicle's half until the flight's time 0 is known, then only looks at its
    newest record (the progress line): a header that came after the last read is read by the look itself, which
    moves no read on (a CI run's progress callback saw nothing for a whole flight: the header had come late)."""
    path = tmp_path / "vehicle.bin"
    records = [np.full(len(CONTROLLER_COLUMNS), float(i), dtype="<f8").tobytes() for i in range(3)]
    reader = HalfReader(path, ControllerRow)
    with open(path, "wb", buffering=0) as f:
        assert reader.read() == [] and reader.last() is None  # the file, no header yet
        f.write(header_line(CONTROLLER_COLUMNS) + records[0] + records[1])
        assert reader.last().k == 1.0
        f.write(records[2])
        assert reader.last().k == 2.0
        assert [r.k for r in reader.read()] == [0.0, 1.0, 2.0]  # the look read nothing on
        assert reader.read() == [] and reader.last().k == 2.0
    reader.close()


@pytest.mark.parametrize(("first_line", "says"), [
    (b"k,t,x_ref\n", "not a JSON header"),
    (json.dumps({"format": "other", "version": 1, "columns": ["k"], "dtype": "<f8"}).encode() + b"\n", "format"),
    (json.dumps({"format": "bsst-half", "version": 2, "columns": ["k"], "dtype": "<f8"}).encode() + b"\n",
     "version 2"),
    (json.dumps({"format": "bsst-half", "version": 1, "columns": ["k"], "dtype": ">f4"}).encode() + b"\n", "dtype"),
    (json.dumps({"format": "bsst-half", "version": 1, "columns": "k", "dtype": "<f8"}).encode() + b"\n",
     "not a list"),
])
def test_a_file_that_is_not_a_half_is_an_error_that_names_it(tmp_path: Path, first_line: bytes, says: str) -> None:
    path = tmp_path / "vehicle.bin"
    path.write_bytes(first_line + b"\0" * 64)
    for read in (lambda: read_half(path), lambda: HalfReader(path, ControllerRow).read(), lambda: count_records(path)):
        with pytest.raises(ValueError, match=says) as exc:
            read()
        assert str(path) in str(exc.value)


# -- the link read from the halves alone (bsst link extract of a run without its tlogs) -----------------------------
def _halves(out: Path, counted: bool) -> tuple[Path, Path]:
    """A 250 Hz flight of steps 0..9, 10 ms down and 10 ms up (walls in s): the controller took state 3 with state 4
    in one tick and never got state 6; the vehicle took the targets of steps 1 and 2 in one tick, never got 5's.
    ``counted`` False: halves written before the counts (no ``odo_arrived``, ``cmd_arrived``)."""
    vcols = VEHICLE_COLUMNS if counted else VEHICLE_COLUMNS[:-1]
    ccols = CONTROLLER_COLUMNS if counted else CONTROLLER_COLUMNS[:-1]
    sent = {k: 1.0 + k * 0.004 for k in range(10)}
    # each tick answers the state it took with a target of the same step
    ctl = [{"k": k, "odo_recv_wall": sent[k] + 0.010, "cmd_sent_wall": sent[k] + 0.011,
            "odo_arrived": 2 if k == 4 else 1} for k in (0, 1, 2, 4, 5, 7, 8, 9)]
    in_force = [(-1, 0), (0, 1), (0, 0), (2, 2), (2, 0), (4, 1), (4, 0), (7, 1), (8, 1), (9, 1)]  # (cmd_k, arrived)
    veh = [{"k": step, "odo_sent_wall": sent[step], "cmd_k": key,
            "cmd_recv_wall": sent[key] + 0.021 if key >= 0 else math.nan, "cmd_arrived": n}
           for step, (key, n) in enumerate(in_force)]
    out.mkdir(exist_ok=True)
    paths = out / "vehicle.bin", out / "controller.bin"
    for path, cols, rows in ((paths[0], vcols, veh), (paths[1], ccols, ctl)):
        half = HalfWriter(path, cols, batch=1)
        for r in rows:
            half.write([float(r.get(c, 0.0)) for c in cols])
        half.close()
    return paths


def _by_step(records: list, sent_s: float) -> dict[int, float | None]:
    return {round((t - sent_s) / 0.004): d for t, d in records}


def test_a_step_superseded_in_its_readers_tick_is_delivered_by_the_readers_count(tmp_path: Path) -> None:
    ex = extract_halves(*_halves(tmp_path / "new", counted=True))
    down, up = _by_step(ex.down.records, 0.0), _by_step(ex.up.records, 0.011)
    assert [k for k, d in down.items() if d is None] == [6]
    assert down[3] == pytest.approx(0.014) and down[4] == pytest.approx(0.010)  # 3 taken in 4's read
    assert [k for k, d in up.items() if d is None] == [5]
    assert up[1] == pytest.approx(0.014) and up[2] == pytest.approx(0.010)
    assert "approximate" not in ex.notes[0]
    # halves written before the counts: each superseded step reads as lost, and the note says so
    old = extract_halves(*_halves(tmp_path / "old", counted=False))
    assert [k for k, d in _by_step(old.down.records, 0.0).items() if d is None] == [3, 6]
    assert [k for k, d in _by_step(old.up.records, 0.011).items() if d is None] == [1, 5]
    assert "approximate" in old.notes[0] and "superseded" in old.notes[0]
