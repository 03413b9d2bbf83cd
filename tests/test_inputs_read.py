"""Covers params and bridge.record.runlog: the files one command or one API call reads, which ``--overwrite`` keeps.

``params.inputs_read`` was the whole process's record: a Python user who had read ``runs/x/mission.toml`` in one
call was refused, in a later call, an ``overwrite`` of ``runs/x`` by any mission. It is one command's
(``bridge.cli.main``) or one API call's (``bridge.simulate``, ``bridge.sitl``, ``bridge.sweep.sweep``, ...) now:
the command line keeps its protection, and a finished call's reads are forgotten. In-process flights of 0.2 s.
"""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from bridge import simulate
from bridge.cli import main
from bridge.loop import simulate as simulate_one
from missions import Mission, Sine, load_mission
from params import ConfigError, input_scope, inputs_read, note_input, reads_inputs

TINY = 'name = "tiny"\nduration_s = 0.2\n[trajectory]\nkind = "sine"\n'


def _a_run_holding_its_mission(tmp_path: Path) -> tuple[Path, Path]:
    """A run directory ``ow`` (one flight's files) with the mission it was flown from saved in it as
    ``mission.toml``, a run file's name; (the directory, the mission)."""
    out = tmp_path / "ow"
    simulate_one(Mission(Sine(), duration_s=0.2, name="first"), out=out, plots=False)
    mission = out / "mission.toml"
    mission.write_text(TINY)
    return out, mission


def test_a_scope_records_what_is_read_in_it_and_forgets_it_after() -> None:
    note_input("outside.toml")  # no command, no call under way: recorded nowhere
    assert inputs_read() == {}
    with input_scope() as outer:
        note_input("a.toml")
        with input_scope() as inner:  # a call inside a command: the command's record
            assert inner is outer
            note_input("b.toml")
        assert sorted(inputs_read().values()) == ["a.toml", "b.toml"]
    assert inputs_read() == {}

    seen: list[dict[str, str]] = []
    with input_scope():
        note_input("here.toml")
        worker = threading.Thread(target=lambda: seen.append(inputs_read()))  # another thread: its own
        worker.start()
        worker.join()
    assert seen == [{}]

    @reads_inputs
    def call() -> dict[str, str]:
        note_input("c.toml")
        return inputs_read()

    assert list(call().values()) == ["c.toml"] and inputs_read() == {}


def test_an_api_call_refuses_to_overwrite_its_own_input_but_not_an_earlier_calls(tmp_path: Path) -> None:
    out, mission = _a_run_holding_its_mission(tmp_path)
    with pytest.raises(ConfigError, match="an input of this command, which --overwrite would overwrite"):
        simulate(mission, out=out, overwrite=True, plots=False)  # read by this call: kept
    assert mission.read_text() == TINY
    read_before = load_mission(mission)  # a call of its own, finished
    simulate(str(mission), plots=False)  # read (and flown, writing nothing) by a finished call
    run = simulate(Mission(Sine(), duration_s=0.2, name="second"), out=out, overwrite=True, plots=False)
    assert run.outcome == "completed" and read_before.name == "tiny"
    assert 'name = "second"' in mission.read_text()  # the new run's own mission.toml


def test_the_command_line_keeps_its_protection_and_forgets_a_finished_commands_reads(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out, mission = _a_run_holding_its_mission(tmp_path)
    assert main(["sim", str(mission), "--out", str(out), "--overwrite", "--no-plots"]) == 2
    assert "an input of this command, which --overwrite would overwrite" in capsys.readouterr().err
    assert mission.read_text() == TINY
    other = tmp_path / "other.toml"
    other.write_text(TINY.replace("tiny", "other"))
    assert main(["sim", str(other), "--out", str(out), "--overwrite", "--no-plots"]) == 0  # the last command's
    assert 'name = "other"' in mission.read_text()  # read is no input of this one
