"""The environment an operator declares a tolled road runs in: ``open`` (a motorway outside built-up land) or
``urban`` (a street between buildings) — what the ``model`` level assumes there when a receiver gives no residuals.

A receiver that reports only its satellites (GSA+GSV, the commonest tracker output) shows no sign of a street canyon
or of open sky; without a declaration its positions get the urban σ everywhere and a motorway is never charged.
The declaration is the operator's statement about the road, recorded on each geo-object (``environment``) and on
every invoice line it charges; it assumes what it says — that no building, cutting or overpass stands where the road
is declared open — and never overrides what the residuals measure, nor an explicit ``--environment urban``.

Declared by ``geoobjects build --environment``: ``open`` or ``urban`` for every road, ``CLASS=open`` for one road
class (``motorway=open``; repeated), or per road by its own ``environment`` property in the roads file (which wins).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from tollcli.errors import UsageError

DECLARED = ("open", "urban")


@dataclass(frozen=True)
class DeclaredEnvironments:
    """The declarations: for every road (``default``, '' none) and per road class."""

    default: str = ""
    by_class: dict[str, str] = field(default_factory=dict)

    def for_road(self, props: dict) -> str:
        """A road's declared environment: its own ``environment`` property, else its class's, else the default."""
        own = props.get("environment")
        if own not in (None, ""):
            return str(own)
        return self.by_class.get(str(props.get("road_class") or ""), self.default)

    def describe(self) -> str:
        parts = ([f"every road {self.default}"] if self.default else []) + [f"{c} {e}" for c, e in sorted(self.by_class.items())]
        return ", ".join(parts) or "none"


def parse_declared_environments(specs: list[str] | None) -> DeclaredEnvironments:
    """``--environment`` values → :class:`DeclaredEnvironments` (UsageError for anything but open/urban)."""
    default, by_class = "", {}
    for spec in specs or []:
        name, sep, value = spec.partition("=")
        value = (value if sep else name).strip()
        if value not in DECLARED or (sep and not name.strip()):
            raise UsageError(f"--environment {spec!r}: expected open, urban or CLASS=open|urban (e.g. motorway=open)")
        if sep:
            by_class[name.strip()] = value
        else:
            default = value
    return DeclaredEnvironments(default, by_class)
