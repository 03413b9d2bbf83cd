"""Covers controller.law.

Every control law fits the one interface (controller/law.py), and a user's own law flies.

As RotorPy's controller template and its test: the built-in laws and the template
``examples/my_law.py`` are each built, stepped on a hover and checked against the
``Law`` protocol; the template flies the sine mission offline and as a lockstep SITL
session (real processes, real UDP), and the two traces agree. A law that cannot be
found or does not fit is bad input: exit 2, one line naming it, no traceback.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bridge import simulate
from bridge.record.runlog import read_trace
from bridge.session import instance_slot
from controller import Controller, Gains, Nominal
from controller.law import BUILTIN, Law, law_problem, make_law, resolve_law
from missions import Mission, Sine, load_mission
from params import ConfigError
from plant import load_profile
from tests.sitlkit import ENV, run_bsst

pytestmark = pytest.mark.process  # starts processes or opens sockets: not in make test-fast

ROOT = Path(__file__).resolve().parents[1]
MY_LAW = f"{ROOT / 'examples' / 'my_law.py'}:MyLaw"
HOVER = (0.0,) * 12
REF = ((0.0,) * 5, (0.0,) * 5, (1.0, 0.0, 0.0, 0.0, 0.0), (0.0,) * 5)


@pytest.fixture(scope="module")
def nominal() -> Nominal:
    return Nominal.from_profile(load_profile("paper"))


@pytest.mark.parametrize("spec", [*BUILTIN, MY_LAW])
def test_every_law_fits_the_interface(spec: str, nominal: Nominal) -> None:
    law = make_law(spec, nominal, Gains(), 250.0)
    assert isinstance(law, Law)
    assert law_problem(law) is None
    u = law.update(0.0, HOVER, REF, 0.0)
    assert len(u) == 4 and all(math.isfinite(v) for v in u)
    assert u[0] > 0.0, "below its reference the law asks for thrust"
    law.advance((False,) * 4, hold=False)
    law.advance((True,) * 4, hold=True)
    law.reset()
    assert len(law.desired) == 2 and all(math.isfinite(v) for v in law.desired)
    ctl = Controller(spec, nominal, Gains(), 250.0)
    cmd = ctl.step(0.0, HOVER, REF)
    assert len(cmd.normalised) == 4 and all(math.isfinite(v) for v in cmd.normalised)


class NoDesired:
    def __init__(self, nominal: Nominal, gains: Gains, rate_hz: float) -> None:
        pass

    def update(self, t, state, ref, omega_d):
        return (0.0, 0.0, 0.0, 0.0)

    def advance(self, saturated, hold=False):
        pass

    def reset(self):
        pass


def test_a_law_without_desired_does_not_fit(nominal: Nominal) -> None:
    with pytest.raises(ConfigError, match="does not fit the Law interface.*desired"):
        make_law(NoDesired, nominal, Gains(), 250.0)


def _sine(tmp_path: Path, duration_s: float) -> Path:
    """missions/sine.toml flown for ``duration_s``, not 30 s, and ended in hold (every other key as shipped): the
    same steps compared, fewer of them (the 30 s sine's lockstep-equals-offline is tests/test_sitl.py's). The tests
    read the mission's rows and its summary only: the end landing (3.5 s more, with COM_DISARM_LAND) flew for nobody,
    and trace.csv, the mission's steps, is the same either way."""
    path = tmp_path / "sine.toml"
    text = (ROOT / "missions" / "sine.toml").read_text()
    assert "duration_s = 30.0" in text and "[end]" not in text
    path.write_text(text.replace("duration_s = 30.0", f"duration_s = {duration_s}") + '[end]\naction = "hold"\n')
    return path


def test_the_template_flies_the_sine_offline_and_in_lockstep_alike(tmp_path: Path) -> None:
    sine = _sine(tmp_path, 12.0)
    offline = simulate(sine, controller="examples/my_law.py:MyLaw", plots=False)
    assert offline.outcome == "completed"
    assert offline.rms < 0.02
    with instance_slot() as n:
        r = run_bsst("sitl", str(sine), "--controller", "examples/my_law.py:MyLaw", "--instance", str(n),
                     "--no-plots", "--out", str(tmp_path / "sitl"), cwd=ROOT, timeout=240)
    assert r.returncode == 0, r.stderr
    lock = read_trace(tmp_path / "sitl" / "trace.csv")
    assert len(lock["t"]) == len(offline.trace["t"])
    for c in ("x", "y", "z"):
        assert np.max(np.abs(lock[c] - offline.trace[c])) < 1e-4
    flown = load_mission(tmp_path / "sitl" / "mission.toml")
    assert flown.controller == MY_LAW  # the run records the law's file, absolute


def test_a_mission_names_a_law_relative_to_its_own_folder(tmp_path: Path) -> None:
    law = tmp_path / "laws" / "mine.py"
    law.parent.mkdir()
    law.write_text((ROOT / "examples" / "my_law.py").read_text())
    mission = tmp_path / "m.toml"
    mission.write_text('duration_s = 2.0\ncontroller = "laws/mine.py:MyLaw"\n[trajectory]\nkind = "sine"\n')
    m = load_mission(mission)
    assert m.controller == f"{law}:MyLaw"
    run = simulate(m, plots=False)
    assert run.outcome == "completed"


def test_a_module_law_is_found_by_import(nominal: Nominal) -> None:
    sys.path.insert(0, str(ROOT / "examples"))
    try:
        assert resolve_law("my_law:MyLaw").__name__ == "MyLaw"
    finally:
        sys.path.remove(str(ROOT / "examples"))


def test_a_module_law_is_imported_from_the_working_directory(tmp_path: Path, monkeypatch) -> None:
    """``module:Class`` is looked for in the working directory first (docs/usage.md), in a script using the API
    too (its own folder, not the working directory, is first on its ``sys.path``): it was ``no module named``;
    and the process's ``sys.path`` is left as it was."""
    name = f"here_{tmp_path.name}"  # (one name a test: a module imported stays imported in this process)
    (tmp_path / f"{name}.py").write_text((ROOT / "examples" / "my_law.py").read_text())
    monkeypatch.chdir(tmp_path)
    before = list(sys.path)
    assert resolve_law(f"{name}:MyLaw").__name__ == "MyLaw"
    assert sys.path == before


def test_a_law_file_imports_a_module_beside_it_as_a_script_would(tmp_path: Path, monkeypatch) -> None:
    """A law file's own folder is first on ``sys.path`` while it loads, as Python runs a script: its helper module
    beside it is found from any working directory (it was ``no module named``); ``sys.path`` is left as it was."""
    folder = tmp_path / "laws"
    folder.mkdir()
    helper = f"gains_{tmp_path.name}"  # (one name a test: a module imported stays imported in this process)
    (folder / f"{helper}.py").write_text("SCALE = 1.0\n")
    (folder / "law.py").write_text((ROOT / "examples" / "my_law.py").read_text()
                                   + f"\nfrom {helper} import SCALE  # noqa: E402\n")
    monkeypatch.chdir(tmp_path)  # (not the law's folder)
    before = list(sys.path)
    assert resolve_law(f"{folder / 'law.py'}:MyLaw").__name__ == "MyLaw"
    assert sys.path == before


def test_two_law_files_each_import_their_own_module_of_one_name(tmp_path: Path) -> None:
    """Two folders, each a law file beside its own ``helpers`` module: each law gets its own (the second got the
    first's, left in ``sys.modules`` under its plain name), and an edited helper is read at its law's next load."""
    name = f"helpers_{tmp_path.name}"
    laws = {}
    for folder in ("a", "b"):
        d = tmp_path / folder
        d.mkdir()
        (d / f"{name}.py").write_text(f"WHO = {folder!r}\n")
        (d / "law.py").write_text((ROOT / "examples" / "my_law.py").read_text()
                                  + f"\nimport {name}  # noqa: E402\nMyLaw.who = {name}.WHO\n")
        laws[folder] = d / "law.py"
    assert [resolve_law(f"{laws[f]}:MyLaw").who for f in ("a", "b")] == ["a", "b"]
    assert name not in sys.modules
    (tmp_path / "a" / f"{name}.py").write_text("WHO = 'a, edited'\n")
    laws["a"].write_text(laws["a"].read_text() + "\n")  # (the law's own bytes change: its next load)
    assert resolve_law(f"{laws['a']}:MyLaw").who == "a, edited"


def test_the_bsst_script_flies_a_module_law_from_the_working_directory(tmp_path: Path) -> None:
    """The ``bsst`` console script has its own folder first on ``sys.path``, not the working directory as
    ``python -m bridge`` has: ``bsst sim ... --controller here:MyLaw`` said ``no module named 'here'``."""
    (tmp_path / "here.py").write_text((ROOT / "examples" / "my_law.py").read_text())
    script = tmp_path / "bin" / "bsst"  # as pip writes the console script (.venv/bin/bsst), in a folder of its own
    script.parent.mkdir()
    script.write_text("import sys\nfrom bridge.__main__ import main\nsys.exit(main())\n")
    r = subprocess.run([sys.executable, str(script), "sim", str(_sine(tmp_path, 2.0)), "--controller", "here:MyLaw",
                        "--out", str(tmp_path / "run"), "--no-plots"], cwd=tmp_path, capture_output=True, text=True,
                       env={**ENV, "PYTHONPATH": str(ROOT)}, stdin=subprocess.DEVNULL, timeout=120)
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["outcome"] == "completed"


EDITED = """
import sys
sys.path.insert(0, {examples!r})
from my_law import MyLaw


class L(MyLaw):
    def update(self, t, state, ref, omega_d):
        if t >= 0.1:
            raise RuntimeError("version {n}")
        return super().update(t, state, ref, omega_d)
"""


@pytest.mark.usefixtures("sys_path_restored")  # (the law file puts examples/ on sys.path itself)
def test_an_edited_law_file_is_flown_at_its_next_flight(tmp_path: Path) -> None:
    """One process (a script, a notebook) flies a law file, the user edits it, and flies it again: the edit flies
    (it was the first version, silently: one module per file per process). Same bytes, same class (a sweep's
    hundreds of flights load the file once)."""
    law = tmp_path / "edit_me.py"
    spec = f"{law}:L"
    mission = Mission(Sine(), duration_s=0.5, name="short")
    for n in (1, 2):
        law.write_text(EDITED.format(examples=str(ROOT / "examples"), n=n))
        run = simulate(mission, controller=spec, plots=False)
        assert run.outcome == "law_failed" and f"version {n}" in run.summary["ended_by"]["how"], run.summary
    assert resolve_law(spec) is resolve_law(spec)


BAD_LAWS = {  # file name -> source of a law file that does not fit, and what the one line must name
    "no_update.py": ("class L:\n    desired = (0.0, 0.0)\n    def advance(self, s, h=False): pass\n"
                     "    def reset(self): pass\n    def __init__(self, n, g, r): pass\n", "update"),
    "bad_init.py": ("class L:\n    desired = (0.0, 0.0)\n    def __init__(self): pass\n"
                    "    def update(self, *a): return (0, 0, 0, 0)\n    def advance(self, *a): pass\n"
                    "    def reset(self): pass\n", "TypeError"),
    "raises.py": ("raise RuntimeError('broken on import')\n", "broken on import"),
    "syntax.py": ("class L(:\n", "SyntaxError"),
}


@pytest.mark.parametrize("command", ["sim", "sitl", "controller", "sweep"])
@pytest.mark.parametrize("spec, names", [
    ("examples/nowhere.py:MyLaw", "nowhere.py"),
    ("examples/my_law.py:NoSuchLaw", "NoSuchLaw"),
    ("no_such_package.laws:MyLaw", "no_such_package"),
    ("json:JSONDecoder", "JSONDecoder"),
    ("README.md:MyLaw", "README.md is not a .py file"),  # a file, not a module: it said no module named 'README'
])
def test_a_law_that_cannot_be_flown_is_refused_in_one_line(command: str, spec: str, names: str) -> None:
    r = run_bsst(command, "missions/sine.toml", "--controller", spec, cwd=ROOT, timeout=60)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and names in lines[0] and "Traceback" not in r.stderr, r.stderr


@pytest.mark.parametrize("name", sorted(BAD_LAWS))
def test_a_law_file_that_does_not_fit_is_named(tmp_path: Path, name: str) -> None:
    source, names = BAD_LAWS[name]
    (tmp_path / name).write_text(source)
    r = run_bsst("sim", "missions/sine.toml", "--controller", f"{tmp_path / name}:L", cwd=ROOT, timeout=60)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert names in lines[0] and name in lines[0], lines[0]


def test_a_sweep_compares_a_users_law_with_the_built_in_ones(tmp_path: Path) -> None:
    from bridge.sweep import Grid, sweep

    m = Mission(Sine(), duration_s=3.0, name="short")
    rows = sweep(m, Grid(controller=("bsst", "examples/my_law.py:MyLaw")), jobs=1, report=False)
    assert [r["outcome"] for r in rows] == ["completed", "completed"]
    assert rows[1]["controller"] == "examples/my_law.py:MyLaw"


@pytest.mark.parametrize("scheme", ["explicit", "implicit"])
def test_bsst_flies_the_same_in_lockstep_and_offline_with_either_scheme(tmp_path: Path, scheme: str) -> None:
    """Issue 24: ``--discretization`` reaches the controller process (through the flown mission.toml), and the
    lockstep session flies what ``bsst sim`` flies with either scheme, within the float32 wire's 1e-4 m; the
    command's period-2 component (the explicit scheme's alternation, the implicit's absence of it) is the
    offline one's over the wire too."""
    sine = _sine(tmp_path, 15.0)  # the period-2 component is measured from 10 s on
    mission = load_mission(sine).with_overrides(discretization=scheme)
    offline = simulate(mission, plots=False)
    with instance_slot() as n:
        r = run_bsst("sitl", str(sine), "--discretization", scheme, "--instance", str(n), "--no-plots", "--out",
                     str(tmp_path / "sitl"), cwd=ROOT, timeout=240)
    assert r.returncode == 0, r.stderr
    assert load_mission(tmp_path / "sitl" / "mission.toml").discretization == scheme
    lock = read_trace(tmp_path / "sitl" / "trace.csv")
    assert np.array_equal(lock["t"], offline.trace["t"])
    worst = max(float(np.max(np.abs(lock[c] - offline.trace[c]))) for c in ("x", "y", "z"))
    assert worst < 1e-4, worst
    p2 = json.loads((tmp_path / "sitl" / "summary.json").read_text())["inputs"]["u2"]["period2"]
    want = offline.summary["inputs"]["u2"]["period2"]
    assert abs(p2 - want) <= 0.05 * want + 1e-3, (p2, want)
    assert (p2 <= 0.01) if scheme == "implicit" else (p2 >= 0.5)  # smooth over the wire too, or alternating
