"""Covers controller.supertwisting, controller.bsst and bridge.record.metrics: the implicit super-twisting step.

Issue 24. The closed form of :func:`controller.supertwisting.implicit_twisting` solves its implicit (backward
Euler) equation, on random inputs; the command it gives is continuous in (s, xi), across the dead zone too.
``implicit`` is the default wherever a law is built; ``explicit``, asked for by name, stays the paper's law to
the bit (the sine's 2.4093284288839256e-06 m); ``implicit`` flies the sine at 250 Hz with a period-2 component
of u2, u3, u4 <= 0.01 N, a total variation of u2, u3 <= 35 /s and a 3-D RMS <= 1e-5 m, and at 100 Hz a
period-2 component <= 0.02 N. The mission's ``discretization`` key and the Mission field refuse a bad value in
one line naming it. :func:`bridge.record.metrics.period2` is seen on known signals.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bridge.cli import build_parser, main
from bridge.core.overrides import Overrides
from bridge.loop import simulate
from bridge.record.metrics import period2
from bridge.swarm import fleet_flights
from bridge.sweep.grid import Cell, cell_overrides
from controller import Controller, Gains, Nominal
from controller.bsst import BacksteppingSuperTwisting
from controller.law import make_law
from controller.supertwisting import advance_xi_implicit, implicit_twisting
from missions import DEFAULT_DISCRETIZATION, Mission, Sine, load_mission
from params import ConfigError
from plant import load_profile

ROOT = Path(__file__).resolve().parents[1]
SINE = ROOT / "missions" / "sine.toml"


def _sign(v: float) -> float:
    return 1.0 if v > 0.0 else -1.0 if v < 0.0 else 0.0


def test_the_closed_form_solves_the_implicit_step() -> None:
    """s~ = s + h u, u = -k1 |s~|^1/2 Sign(s~) + xi1, xi1 = xi - h k2 Sign(s~), Sign(0) in [-1, 1]."""
    rng = np.random.default_rng(24)
    zone = 0
    for _ in range(20000):
        h = float(rng.choice([1e-3, 4e-3, 1e-2]))
        k1, k2 = float(rng.uniform(0.5, 10.0)), float(rng.uniform(0.5, 8.0))
        scale = float(10.0 ** rng.uniform(-8, 1))
        s, xi = float(rng.normal(0.0, scale)), float(rng.normal(0.0, scale / h))  # s and h xi alike
        u, xi1 = implicit_twisting(s, xi, k1, k2, h)
        st = s + h * u
        tol = 1e-12 * (1.0 + abs(s) + h * abs(xi) + h * abs(u))
        if abs(s + h * xi) <= h * h * k2:  # s~ = 0: the set-valued sign is the multiplier (xi - xi1) / (h k2)
            zone += 1
            assert abs(st) <= tol
            assert -1.0 - 1e-9 <= (xi - xi1) / (h * k2) <= 1.0 + 1e-9
            assert u == xi1
        else:  # sign(s~) = sg and u = -k1 r sg + xi1 with r = |s~|^1/2 >= 0: s~ = sg r^2
            sg = 1.0 if xi1 < xi else -1.0
            assert xi1 == xi - h * k2 * sg
            r = (xi1 - u) / (k1 * sg)
            assert r >= 0.0 and abs(st - sg * r * r) <= tol, (s, xi, k1, k2, h)
    assert zone > 100  # the dead zone was visited


def test_the_command_is_continuous_across_the_dead_zone() -> None:
    h, k1, k2, xi = 4e-3, 5.0, 4.0, 0.3
    dz = h * h * k2
    for edge in (dz, -dz):  # w = s + h xi on the dead zone's edge, from both sides
        s = edge - h * xi
        inside = implicit_twisting(s - 1e-15 * _sign(edge), xi, k1, k2, h)
        outside = implicit_twisting(s + 1e-15 * _sign(edge), xi, k1, k2, h)
        assert abs(inside[0] - outside[0]) < 1e-9 and abs(inside[1] - outside[1]) < 1e-9


def test_the_integrator_holds_and_clamps() -> None:
    assert advance_xi_implicit(0.7, 1.0, 5.0, 4.0, 4e-3, 20.0, True) == 0.7
    assert advance_xi_implicit(0.0, -1e-5, 5.0, 4.0, 4e-3, 1e-3, False) == 1e-3  # dead zone: -s/h = 2.5e-3, clamped
    assert advance_xi_implicit(0.0, 1.0, 5.0, 4.0, 4e-3, 20.0, False) == pytest.approx(-4.0 * 4e-3)


def test_period2_of_known_signals() -> None:
    k = np.arange(200)
    assert period2(0.3 + 0.8 * (-1.0) ** k) == pytest.approx(0.8)
    assert period2(np.sin(2 * np.pi * k / 200)) < 1e-3
    assert period2(np.array([1.0, 2.0])) == 0.0
    assert period2(np.array([1.0, np.nan, 1.0, -1.0, 1.0])) == pytest.approx(1.0)


def test_explicit_is_the_paper_law_to_the_bit(tmp_path: Path) -> None:
    """``bsst sim missions/sine.toml --discretization explicit``: asked for by name, the default being
    ``implicit`` (test_the_default_is_implicit_wherever_a_law_is_built)."""
    assert main(["sim", str(SINE), "--discretization", "explicit", "--no-plots", "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["discretization"] == "explicit" and summary["rms_3d"] == 2.4093284288839256e-06
    assert summary["inputs"]["u2"]["period2"] == pytest.approx(0.705, abs=0.005)  # issue 24's figure


def test_the_default_is_implicit_wherever_a_law_is_built() -> None:
    """Issue 24's rule: ``implicit`` keeps every acceptance figure of the paper (tests/test_scenarios.py flies
    them with the default), so it is the default of the mission file, the Mission, the sweep's cell and the
    controller's own constructors alike; ``explicit`` only when asked for."""
    assert DEFAULT_DISCRETIZATION == "implicit"
    m = load_mission(SINE)  # no discretization key
    assert m.discretization == "implicit" and m.to_dict()["discretization"] == "implicit"
    assert Mission(Sine(), duration_s=1.0).discretization == "implicit"
    assert Cell("bsst", 250.0, 0.0, 0.0, 0.0, 0.0, 0).discretization == "implicit"
    nominal = Nominal.from_profile(load_profile("paper"))
    assert BacksteppingSuperTwisting(nominal, Gains(), 250.0).implicit
    assert make_law("bsst", nominal, Gains(), 250.0).implicit  # type: ignore[attr-defined]
    assert Controller("bsst", nominal).law.implicit  # type: ignore[attr-defined]
    assert not BacksteppingSuperTwisting(nominal, Gains(), 250.0, discretization="explicit").implicit
    assert build_parser().parse_args(["sim", str(SINE)]).discretization is None  # no flag: the mission's


def test_only_bsst_records_a_discretization() -> None:
    """Only ``bsst`` has a super-twisting step to discretize (docs/law.md): ``summary.json``'s ``discretization`` is
    its scheme, and null for ``smc``, ``pid`` and a law of one's own, which have none (until the third wave's
    thirty-seventh session it said ``implicit`` for every law). The flag that would change nothing is refused:
    tests/test_bad_input.py."""
    short = Mission(Sine(), duration_s=1.0, name="short")
    own = f"{ROOT / 'examples' / 'my_law.py'}:MyLaw"
    for law, want in (("bsst", "implicit"), ("smc", None), ("pid", None), (own, None)):
        assert simulate(short, controller=law, plots=False).summary["discretization"] == want, law
    assert simulate(short, discretization="explicit", plots=False).summary["discretization"] == "explicit"


def test_a_discretization_for_a_law_without_a_super_twisting_step_is_refused_by_the_api_too(tmp_path: Path) -> None:
    """``discretization=`` laid over a flight whose law has no super-twisting step is refused by ``bridge.simulate``
    as ``bsst sim --discretization`` is, by ``prepare``, the one path every way to fly takes (until the third wave's
    thirty-eighth session only the command refused it: the API flew it, summary.json's discretization null). A
    fleet's is refused where no vehicle flies bsst; where one does, the vehicles that fly bsst take it. A sweep's
    cell of such a law lays none (the axis is the bsst cells')."""
    short = Mission(Sine(), duration_s=1.0, name="short")
    for law in ("smc", "pid"):
        with pytest.raises(ConfigError) as refused:
            simulate(short, controller=law, discretization="explicit", plots=False)
        assert str(refused.value) == (f"--discretization explicit: only bsst has a super-twisting step to discretize: "
                                      f"{law} flies the same under both (docs/law.md); drop the flag, or fly "
                                      "--controller bsst")
    fleet = tmp_path / "fleet.toml"
    fleet.write_text('duration_s = 1.0\n[trajectory]\nkind = "sine"\n[[vehicles]]\nid = 1\ncontroller = "smc"\n'
                     "[[vehicles]]\nid = 2\noffset = [0.0, 3.0, 0.0]\n")
    m = load_mission(fleet)
    flights = fleet_flights(m, Overrides(discretization="explicit"))
    assert [(f.mission.controller, f.mission.discretization) for f in flights] == [("smc", DEFAULT_DISCRETIZATION),
                                                                                   ("bsst", "explicit")]
    with pytest.raises(ConfigError, match="^--discretization explicit: only bsst has .*: smc flies the same"):
        fleet_flights(m, Overrides(controller="smc", discretization="explicit"))
    assert cell_overrides(Cell("smc", 250.0, 0.0, 0.0, 0.0, 0.0, 0, discretization="explicit")).discretization is None


@pytest.fixture(scope="module")
def implicit_sine() -> dict[float, dict]:
    m = load_mission(SINE).with_overrides(discretization="implicit")
    return {rate: simulate(m, rate_hz=rate, plots=False).summary for rate in (250.0, 100.0)}


def test_implicit_sine_is_smooth_and_accurate(implicit_sine: dict[float, dict]) -> None:
    s = implicit_sine[250.0]
    assert s["outcome"] == "completed"
    assert s["rms_3d"] <= 1e-5
    for u in ("u2", "u3", "u4"):
        assert s["inputs"][u]["period2"] <= 0.01, (u, s["inputs"][u])
    for u in ("u2", "u3"):
        assert s["inputs"][u]["tv_per_s"] <= 35.0, (u, s["inputs"][u])
    slow = implicit_sine[100.0]
    assert slow["outcome"] == "completed"
    assert all(slow["inputs"][u]["period2"] <= 0.02 for u in ("u2", "u3", "u4")), slow["inputs"]


def test_a_bad_discretization_is_one_line(tmp_path: Path) -> None:
    f = tmp_path / "m.toml"
    f.write_text('duration_s = 2.0\ndiscretization = "trapezoid"\n[trajectory]\nkind = "sine"\n')
    with pytest.raises(ConfigError, match=r"m\.toml: discretization: must be one of explicit, implicit"):
        load_mission(f)
    with pytest.raises(ConfigError, match="discretization: must be one of explicit, implicit"):
        replace(load_mission(SINE), discretization="backward")
    f.write_text('duration_s = 2.0\ndiscretization = "implicit"\n[trajectory]\nkind = "sine"\n')
    m = load_mission(f)
    assert m.discretization == "implicit" and m.to_dict()["discretization"] == "implicit"
