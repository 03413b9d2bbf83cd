"""Covers bridge.link.model and bridge.cli.linkflags.

Every ``[link]`` key has its flag, one range, and a line in the README (a meta-test, as
python-control's kwargs_test walks its functions' keywords).

The keys are the link model's own tables (:data:`bridge.link.model.LINK_KEYS`); the test
checks first that those tables are the whole of what ``link_from_table`` reads. For each
key: a ``bsst`` flag sets it (``bsst sim``'s parser, read back by ``link_table_from_args``);
for a number, the mission loader and the flag accept the same bounds and refuse the same
values just outside them; and a line of docs/usage.md (the front page's reference) names the key and its flag.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path
from typing import Any

import pytest

from bridge.cli import build_parser, link_table_from_args
from bridge.cli.flags import UsageError
from bridge.cli.linkflags import GUARD_FLAGS, LINK_FLAGS
from bridge.core.flight import prepare
from bridge.link import model as link_model
from bridge.link.model import (
    BLACKOUT_DURATION_RANGE_S,
    DIRECTION_KEYS,
    GUARD_RANGES,
    HI_OPEN,
    LINK_KEYS,
    LO_OPEN,
    NEEDS,
    NUMBER_RANGES,
    SEED_RANGE,
    LinkConfig,
    idle_problem,
    link_from_table,
    unmet_key,
)
from bridge.loop import simulate
from missions import load_mission
from params import ConfigError

ROOT = Path(__file__).resolve().parents[1]
# the flag of each key that no LINK_FLAGS / GUARD_FLAGS row names
OTHER_FLAGS = {"jitter": "--jitter-dist", "seed": "--link-seed", "blackouts": "--blackout",
               "compensation": "--compensation", "trace": "--link-trace", "trace_loop": "--link-trace-loop",
               "profile": "--link-profile", "shared": "--shared-link"}
SAMPLE = {"jitter": "normal", "seed": "7", "blackouts": "3:1", "compensation": "predict", "stop_ms": "100",
          "trace": str(ROOT / "examples" / "link-trace.csv"), "profile": "wifi"}


def flag_of(key: str) -> str:
    flags = {k: f"--{stem}" for stem, k, *_ in LINK_FLAGS} | {k: f for f, k, *_ in GUARD_FLAGS} | OTHER_FLAGS
    assert key in flags, f"[link] key {key} has no command-line flag"
    return flags[key]


def parse(*argv: str) -> dict[str, Any]:
    return link_table_from_args(build_parser().parse_args(["sim", "missions/sine.toml", *argv]))


def accepted(table: dict[str, Any]) -> bool:
    try:
        link_from_table(table, "test.toml")
    except ConfigError:
        return False
    return True


def flag_accepts(flag: str, value: float) -> bool:
    try:
        parse(flag, repr(value))
    except (UsageError, ConfigError):  # (a flag type's refusal is a ConfigError, typed)
        return False
    return True


def test_the_key_tables_are_all_that_the_loader_reads() -> None:
    tree = ast.parse(Path(link_model.__file__).read_text())
    read = set()
    for node in ast.walk(tree):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr in ("number", "string", "integer", "boolean", "has", "raw", "table", "error")
                and node.args and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
            read.add(node.args[0].value)
    names_in_loops = set(NUMBER_RANGES) | {"up", "down"}  # read in loops: t.number(name, ...), t.table(d)
    assert read | names_in_loops == set(LINK_KEYS) | {"up", "down"} | {"burst_len"}, read
    assert not accepted({"no_such_key": 1})


@pytest.mark.parametrize("key", LINK_KEYS)
def test_every_key_has_its_flag(key: str) -> None:
    flag = flag_of(key)
    value = SAMPLE.get(key, "1")
    if key == "burst_len":
        table = parse(flag, "2", "--loss", "10")
    elif key == "command_lag_ms":
        table = parse(flag, value, "--compensation", "predict")
    else:
        table = parse(flag, value)
    if key in DIRECTION_KEYS:
        assert key in table["up"] and key in table["down"], table
        up = parse(flag.replace("--", "--up-", 1), value, *(["--up-loss", "10"] if key == "burst_len" else [])) \
            if key not in OTHER_FLAGS or key == "blackouts" else None
        if up is not None:
            assert key in up["up"] and key not in up.get("down", {}), up
    else:
        assert key in table, table
    assert accepted(table), table


@pytest.mark.parametrize("key", [*NUMBER_RANGES, *GUARD_RANGES])
def test_every_number_has_one_range(key: str) -> None:
    lo, hi = {**NUMBER_RANGES, **GUARD_RANGES}[key]
    flag = flag_of(key)
    extra: dict[str, Any] = {"compensation": "predict"} if key == "command_lag_ms" else {}
    if key == "stale_ms":
        extra["stop_ms"] = hi
    pre = ["--compensation", "predict"] if key == "command_lag_ms" else []
    if key == "stale_ms":
        pre = ["--stop-after", repr(hi)]
    outside = (hi * 1.001 + 1.0, lo - 1.0)
    for v in outside:
        assert not accepted({key: v, **extra}), (key, v)
        assert not flag_accepts(flag, v), (flag, v)
    for v, ok in ((hi, key not in HI_OPEN), (lo, key not in LO_OPEN), (math.nan, False), (math.inf, False)):
        if key == "burst_len" and v == hi:
            extra_b = {"loss_pct": 50.0}
            assert accepted({key: v, **extra_b})
            continue
        assert accepted({key: v, **extra}) == ok, (key, v)
        try:
            parse(*pre, flag, repr(v))
            took = True
        except (UsageError, ConfigError):
            took = False
        assert took == ok, (flag, v)


def test_the_seed_and_the_blackouts_have_one_range() -> None:
    lo, hi = SEED_RANGE
    assert accepted({"seed": hi}) and not accepted({"seed": hi + 1}) and not accepted({"seed": lo - 1})
    assert parse("--link-seed", str(hi))["up"]["seed"] == hi
    for bad in (str(hi + 1), str(lo - 1)):
        with pytest.raises(ConfigError):
            parse("--link-seed", bad)
    d_lo, d_hi = BLACKOUT_DURATION_RANGE_S
    assert accepted({"blackouts": [[0.0, d_hi]]}) and not accepted({"blackouts": [[0.0, d_lo]]})
    assert parse("--blackout", f"0:{d_hi:g}")
    with pytest.raises(ConfigError):
        parse("--blackout", f"0:{d_lo:g}")


@pytest.mark.parametrize("key", LINK_KEYS)
def test_every_key_has_a_line_in_the_usage_page(key: str) -> None:
    flag = flag_of(key)
    lines = [ln for ln in (ROOT / "docs/usage.md").read_text().splitlines() if f"`{key}`" in ln and flag in ln]
    assert lines, f"docs/usage.md has no line naming [link] key `{key}` with its flag {flag}"


@pytest.mark.parametrize("key", list(NEEDS))
def test_a_key_that_needs_another_has_one_rule_for_its_flag_and_its_table(key: str) -> None:
    """``NEEDS`` (bridge.link.config), the one table of a key that acts only with another: both are a direction's keys
    with a flag; a table giving the key and never its need is unmet (in ``[link]`` for both directions, in
    ``[link.up]`` for that one), given the need (as 0 too) or given it by a flag or a swept axis it is not; its flag
    where no link has the need is idle, where one has it not (docs/links.md, "A key that needs another")."""
    need = NEEDS[key][0]
    assert {key, need} <= set(DIRECTION_KEYS) and flag_of(key) and flag_of(need)
    value = {"burst_len": 3.0, "queue_ms": 300.0, "trace_loop": True}[key]
    on = {"loss_pct": 2.0, "rate_bps": 9000.0, "trace": "t.csv"}[need]
    assert unmet_key({key: value}) is not None and unmet_key({key: value}, given=[need]) is None
    assert unmet_key({"up": {key: value}, "down": {need: on}})[0] == f"up.{key}"
    assert unmet_key({key: value, "down": {need: on}}) is None  # ([link]'s acts on both: the down link uses it)
    assert unmet_key({key: value, need: 0.0 if need != "trace" else ""}) is None  # given as 0: a choice
    assert idle_problem(key, [{need: 0.0 if need != "trace" else None}]) is not None
    assert idle_problem(key, [{need: 0.0 if need != "trace" else None}, {need: on}]) is None
    assert idle_problem(key, [LinkConfig()]) is not None


@pytest.mark.parametrize("key", list(NEEDS))
def test_a_mission_files_idle_link_key_is_refused_by_the_python_api_too(tmp_path: Path, key: str) -> None:
    """A key of a mission file's own ``[link]`` whose need nobody gives is refused by ``bridge.simulate`` as ``bsst
    sim`` refuses it, naming the file and the key: by ``prepare``, the one path every way to fly takes (until the
    third wave's thirty-eighth session only the command refused it, and the API flew it: the same flight as without
    it). Given its need by what is laid over it (in one direction, or as 0), or by a campaign's swept axis, it flies;
    laid over with another key only, it is refused still."""
    need, does, _ = NEEDS[key]
    value = {"burst_len": "3", "queue_ms": "300", "trace_loop": "true"}[key]
    on = {"loss_pct": 2.0, "rate_bps": 9000.0, "trace": SAMPLE["trace"]}[need]
    mission = tmp_path / "m.toml"
    mission.write_text(f'name = "m"\nduration_s = 0.2\n[trajectory]\nkind = "sine"\n[link]\n{key} = {value}\n')
    with pytest.raises(ConfigError) as refused:
        simulate(mission, plots=False)
    assert str(refused.value) == (f"{mission}: link.{key}: changes nothing: {does}, and no {need} is given; give "
                                  f"{need} too, or remove {key}")
    with pytest.raises(ConfigError, match=f"^{mission}: link.{key}: changes nothing"):
        prepare(load_mission(mission), link={"delay_ms": 5.0})
    for given in ({need: on}, {"down": {need: on}}, {need: 0.0 if need != "trace" else ""}):
        assert prepare(mission, link=given).mission.link[key] is not None, given
    assert prepare(mission, axes=(need,)).mission.link[key] is not None  # (a sweep's or a margin's axis gives it)


@pytest.mark.parametrize("key", list(NEEDS))
def test_a_key_a_python_caller_lays_over_a_mission_without_its_need_is_refused_as_laid_over(tmp_path: Path,
                                                                                         key: str) -> None:
    """``bridge.simulate(mission, link={key: ...})`` whose key changes nothing on every direction it is given for is
    refused by the rule ``bsst sim --burst 3`` is (bridge.link.config.idle_problem), named as what the caller laid
    over (until the third wave's thirty-eighth session it flew, the same flight as without it); given for both
    directions it flies where one direction has its need, as ``--burst 3 --up-loss 2`` does."""
    need, does, missing = NEEDS[key]
    value = {"burst_len": 3.0, "queue_ms": 300.0, "trace_loop": True}[key]
    on = {"loss_pct": 2.0, "rate_bps": 9000.0, "trace": SAMPLE["trace"]}[need]
    mission = tmp_path / "m.toml"
    mission.write_text('name = "m"\nduration_s = 0.2\n[trajectory]\nkind = "sine"\n')
    shown = {"burst_len": "3.0", "queue_ms": "300.0", "trace_loop": "True"}[key]
    for laid, where in (({key: value}, key), ({"up": {key: value}, "down": {need: on}}, f"up.{key}")):
        with pytest.raises(ConfigError) as refused:
            simulate(mission, plots=False, link=laid)
        zero = "none" if need == "trace" else "0"
        assert str(refused.value).startswith(
            f"{mission}: link.{where}: changes nothing: {does}, and {missing} ({need} {zero}); "
            f"give {need} too, or remove {key} (with these laid over the mission's [link]: link.{where} = {shown}")
    assert prepare(mission, link={key: value, "up": {need: on}}).mission.link[key] is not None
    assert prepare(mission, link={key: value}, laid_named=True).mission.link[key] is not None  # (named by its caller)
    with_need = tmp_path / "n.toml"
    with_need.write_text(mission.read_text() + f"[link]\n{need} = {on!r}\n".replace("'", '"'))
    assert prepare(with_need, link={key: value}).mission.link[key] is not None
