"""The options every charging command takes (``process``, ``batch``), declared once and turned into settings once.

``@charge_options`` adds them to a command's own parameters (what ``--help`` lists, in this order, after the
command's own) and hands the command one :class:`ChargeOptions`; :meth:`ChargeOptions.settings` builds the
:class:`~tollcli.job.pipeline.ChargeSettings` both commands charge with.
"""

from __future__ import annotations

import functools
import inspect
from dataclasses import dataclass
from typing import Annotated, Literal, Optional

import typer

from tollcli.cli import options as opt
from tollcli.job.pipeline import ChargeSettings

Geo = Annotated[str, typer.Option("--geo", help="Geo-objects (GeoJSON from 'tollcli geoobjects build').")]
Tariff = Annotated[str, typer.Option("--tariff", help="Tariff (TOML).")]
Roads = Annotated[Optional[str], typer.Option("--roads", help="Road network (GeoJSON LineStrings, tolled and free) for map-matching integrity.")]
Policy = Annotated[Optional[Literal[opt.POLICIES]], typer.Option("--policy", help="Checks that may veto a position, on evidence of a fault only: raim, raim+speed, raim+mm, all (default: the strictest the inputs support).")]

_REQUIRED = inspect.Parameter.empty
#: (parameter, annotation, default), in the order ``--help`` lists them
CHARGE_PARAMETERS = (
    ("geo", Geo, _REQUIRED), ("tariff", Tariff, _REQUIRED),
    ("vehicle_class", opt.TariffVehicleClass, "car"), ("vehicle_attr", opt.VehicleAttr, None),
    ("input_format", opt.InputFormat, "auto"), ("nav", opt.Nav, None), ("roads", Roads, None), ("policy", Policy, None),
    ("integrity_sources", opt.IntegritySources, "auto"), ("raim", opt.RaimMode, "ss"), ("positioning", opt.Positioning, "auto"),
    ("environment", opt.Environment, "auto"),
    ("p_sat", opt.PSat, 1e-5), ("p_const", opt.PConst, 1e-8), ("p_md", opt.PMd, 5e-5), ("p_fa", opt.PFa, 5e-3),
    ("fde", opt.Fde, False), ("sigma_model", opt.SigmaModel, "nominal"), ("sigma", opt.Sigma, 5.0), ("tc", opt.Tc, 5.0),
    ("n_th", opt.NTh, 1), ("require_authenticated", opt.RequireAuthenticated, False), ("osnma_merkle", opt.OsnmaMerkle, None),
    ("osnma_public_key", opt.OsnmaPublicKey, None), ("strict", opt.Strict, False), ("date", opt.DateOpt, None),
    ("start_time", opt.StartTime, None), ("max_bad", opt.MaxBad, None),
)  # fmt: skip


@dataclass(frozen=True)
class ChargeOptions:
    """The charging options as given (names as the options'); :meth:`settings` is what a charge uses."""

    geo: str
    tariff: str
    vehicle_class: str
    vehicle_attr: list[str] | None
    input_format: str
    nav: str | tuple[str, ...] | None
    roads: str | None
    policy: str | None
    integrity_sources: str
    raim: str
    positioning: str
    environment: str
    p_sat: float
    p_const: float
    p_md: float
    p_fa: float
    fde: bool
    sigma_model: str
    sigma: float
    tc: float
    n_th: int
    require_authenticated: bool
    osnma_merkle: str | None
    osnma_public_key: list[str] | None
    strict: bool
    date: object
    start_time: str | None
    max_bad: int | None

    def __post_init__(self) -> None:
        object.__setattr__(self, "nav", opt.nav_files(self.nav))  # one file recorded as before, several as a list

    def settings(self, vehicle: str | None = None, input_format: str | None = None) -> ChargeSettings:
        """The settings of a charge (``input_format``: the input's format when the command settled it otherwise)."""
        return ChargeSettings(
            vehicle_class=self.vehicle_class, vehicle_attrs=opt.vehicle_attrs(self.vehicle_attr), vehicle=vehicle, raim=self.raim,
            p_md=self.p_md, p_fa=self.p_fa, fde=self.fde, environment=self.environment, p_sat=self.p_sat, p_const=self.p_const,
            sigma_model=self.sigma_model, sigma_m=self.sigma, tc_s=self.tc, n_th=self.n_th, strict=self.strict,
            date=self.date.date().isoformat() if self.date else None, start_time=self.start_time, policy=self.policy,
            integrity_sources=self.integrity_sources, input_format=opt.check_input_format(input_format or self.input_format),
            require_authenticated=self.require_authenticated, positioning=self.positioning,
        )  # fmt: skip


def charge_options(command):
    """Give ``command`` the charging options: its signature gains them (keyword-only, after its own), and it is called
    with ``charge=ChargeOptions(...)`` in their place."""
    own = [p for p in inspect.signature(command, eval_str=True).parameters.values() if p.name != "charge"]
    extra = [inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default, annotation=annotation)
             for name, annotation, default in CHARGE_PARAMETERS]  # fmt: skip
    names = [name for name, _, _ in CHARGE_PARAMETERS]

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        charge = ChargeOptions(**{name: kwargs.pop(name) for name in names})
        return command(*args, charge=charge, **kwargs)

    wrapper.__signature__ = inspect.Signature(own + extra)
    wrapper.__annotations__ = {p.name: p.annotation for p in own + extra}
    del wrapper.__wrapped__  # Typer reads the signature above, not the command's own
    return wrapper
