"""Named link profiles: a ``[link]`` table for a kind of link people fly over (Wi-Fi, LTE, a telemetry
radio, satellites), shipped in ``bridge/link/profiles/*.toml``, or any such file by path (what
``bsst link fit`` writes).

In:  a profile name (``lte``) or a profile TOML path; the file: ``name``, ``description``, ``sources``
     (the measurements and datasheets its numbers come from), ``[link]`` (a mission's ``[link]`` table,
     ``[link.up]`` / ``[link.down]`` included) and optionally ``[fit]`` (``bsst link fit``'s figures,
     not read)
Out: :class:`LinkProfile`: its ``[link]`` table, trace paths made absolute against the profile's folder;
     a bad file or name is a ``ConfigError`` naming it

The table is validated by the link model (bridge.link.model, ``[link] profile = NAME`` or
``--link-profile NAME``), where the mission's own ``[link]`` keys are laid over it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from bridge.link.trace import absolute_link_paths, is_profile_path
from params import ConfigError, Table, load_toml

PROFILE_DIR = Path(__file__).parent / "profiles"


@dataclass(frozen=True)
class LinkProfile:
    name: str
    path: Path
    description: str
    sources: tuple[str, ...]
    link: dict[str, Any] = field(default_factory=dict)


def profile_names() -> list[str]:
    """The shipped profiles, by name."""
    return sorted(p.stem for p in PROFILE_DIR.glob("*.toml"))


def profile_path(name: str) -> Path:
    """The file a profile name or path stands for (``ConfigError`` for an unknown name)."""
    if is_profile_path(name):
        return Path(name).expanduser()
    p = PROFILE_DIR / f"{name}.toml"
    if not p.is_file():
        raise ConfigError(f"unknown link profile {name!r}; shipped profiles: {', '.join(profile_names())} "
                          f"(or a profile TOML path)")
    return p


def load_link_profile(name: str) -> LinkProfile:
    """Read a profile by name or path; its ``[link]`` table is checked by the link model."""
    p = profile_path(name)
    src = str(p)
    t = Table(load_toml(p), src)
    title = t.string("name", p.stem)
    description = t.string("description", "")
    raw_sources = t.raw("sources", [])
    if not isinstance(raw_sources, list) or not all(isinstance(s, str) for s in raw_sources):
        raise t.error("sources", "expected a list of strings (the measurements and datasheets the numbers come from)")
    link = t.raw("link", None)
    if not isinstance(link, dict):
        raise t.error("link", "a link profile needs a [link] table")
    if "profile" in link:
        raise ConfigError.at(src, "link.profile", "a profile cannot name another profile")
    t.raw("fit", None)  # bsst link fit's goodness-of-fit figures: for the reader, not the model
    t.done()
    return LinkProfile(title, p, description, tuple(raw_sources), absolute_link_paths(link, p.parent))
