"""The design HAL of a geo-object network: the horizontal alert limit each tolled road is built for.

Paper 001 and the thesis place geo-objects where a road is isolated enough for the HAL the receivers can
support — 25–50 m for single-frequency RAIM — not the other way round. A design HAL is a range
``[low, high]`` (metres): a road gets the largest HAL up to ``high`` that the roads it keeps clear of allow,
and the stretches of it where a road it does not meet comes closer than ``2 · low`` are cut out of its
geo-object, so that HAL never falls below ``low`` for a nearby ramp or service road. A road's own
``hal_m`` property is its design HAL (low = high). Only where no stretch of a road can have ``low`` does
the build fall back to a smaller HAL (down to ``--hal-min``), and lists it.

``--hal`` values: ``25`` (low = high = 25 m), ``25-50`` (a range) or ``CLASS=VALUE`` for one road class
(``motorway=40-50``), repeated; the default is the papers' range, 25–50 m.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from tollcli.errors import UsageError

#: the papers' range of HAL a single-frequency receiver's RAIM can protect, m (paper 001 §II, thesis §3.4)
DEFAULT_DESIGN_HAL_M = (25.0, 50.0)
#: the smallest HAL a build falls back to where no stretch of a road can have its design HAL, m
HAL_FLOOR_M = 5.0


@dataclass(frozen=True)
class DesignHal:
    """Design HAL ranges: the default and per road class (``road_class`` of a GeoJSON road, ``highway`` of OSM)."""

    default: tuple[float, float] = DEFAULT_DESIGN_HAL_M
    by_class: dict[str, tuple[float, float]] = field(default_factory=dict)

    def for_road(self, props: dict) -> tuple[float, float]:
        """(low, high) for a road: its own ``hal_m``, else its class's range, else the default, m."""
        own = props.get("hal_m")
        if own not in (None, ""):
            try:
                value = float(own)
            except (TypeError, ValueError):
                value = float("nan")
            if value > 0:
                return value, value
        return self.by_class.get(str(props.get("road_class") or ""), self.default)

    @property
    def highest_m(self) -> float:
        return max(high for _, high in (self.default, *self.by_class.values()))

    def describe(self) -> str:
        def one(r):
            return f"{r[0]:g}" if r[0] == r[1] else f"{r[0]:g}–{r[1]:g}"

        classes = "".join(f", {name} {one(r)}" for name, r in sorted(self.by_class.items()))
        return f"{one(self.default)} m{classes}"


def parse_range(text: str, what: str) -> tuple[float, float]:
    """``25`` → (25, 25); ``25-50`` → (25, 50) (metres; UsageError for anything else)."""
    low, sep, high = text.strip().partition("-")
    try:
        lo = float(low)
        hi = float(high) if sep else lo
    except ValueError:
        raise UsageError(f"--hal {what!r}: expected metres, e.g. 25, 25-50 or motorway=40-50") from None
    if not (0 < lo <= hi < float("inf")):
        raise UsageError(f"--hal {what!r}: need 0 < low ≤ high (metres)")
    return lo, hi


def parse_design_hal(specs: list[str] | None) -> DesignHal:
    """The ``--hal`` options → a :class:`DesignHal` (the papers' 25–50 m where no default is given)."""
    default, by_class = DEFAULT_DESIGN_HAL_M, {}
    for spec in specs or []:
        name, sep, value = spec.partition("=")
        if sep:
            if not name.strip():
                raise UsageError(f"--hal {spec!r}: expected CLASS=METRES, e.g. motorway=40-50")
            by_class[name.strip()] = parse_range(value, spec)
        else:
            default = parse_range(spec, spec)
    return DesignHal(default, by_class)
