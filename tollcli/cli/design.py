"""``tollcli design``: the RAIM and charging parameter derivations as a calculator."""

from __future__ import annotations

import json
import math
from typing import Annotated, Optional

import typer

from tollcli.cli import options as opt
from tollcli.errors import UsageError
from tollcli.integrity import design as d


def design(
    dof: Annotated[Optional[int], typer.Option("--dof", help="Degrees of freedom k = measurements − unknowns.", min=1)] = None,
    p_fa: Annotated[Optional[float], typer.Option("--p-fa", help="Probability of false alarm (classic RAIM).")] = None,
    p_md: Annotated[Optional[float], typer.Option("--p-md", help="Probability of missed detection.")] = None,
    hal_over_slope: Annotated[Optional[float], typer.Option("--hal-over-slope", help="HAL / slope_max (ETC RAIM).", min=1e-6, max=1e6)] = None,
    invoice_share: Annotated[Optional[float], typer.Option("--invoice-share", help="I: share of invoices within the error, % (0–100).", min=0.0, max=100.0)] = None,
    invoice_error: Annotated[Optional[float], typer.Option("--invoice-error", help="M_e: invoice error, % (0–100).", min=0.0, max=100.0)] = None,
    n_potential: Annotated[Optional[int], typer.Option("--n-potential", help="N_PFGoR: segments that could be falsely recognised.", min=1)] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON object instead of a table.")] = False,
    quiet: opt.Quiet = False,
) -> None:
    """Derive thresholds and probabilities (paper 001 eqs. 16–24; thesis eqs. 5.5, 5.10).

    --dof K --p-fa X --p-md Y: classic RAIM threshold and lambda_det.
    --dof K --p-md Y --hal-over-slope R: ETC RAIM threshold and the resulting p_fa.
    --invoice-share I --invoice-error ME [--n-potential N]: p_mgor (and p_fgor).
    """
    out: dict[str, float] = {}
    for name, value in (("p_fa", p_fa), ("p_md", p_md)):
        if value is not None and not 0 < value < 1:
            raise UsageError(f"--{name.replace('_', '-')} {value}: a probability strictly between 0 and 1")
    if dof is not None:
        if p_md is None:
            raise UsageError("--dof needs --p-md (and --p-fa for the classic RAIM or --hal-over-slope for the ETC RAIM)")
        if hal_over_slope is not None:
            lam = hal_over_slope**2
            th = float(d.etc_threshold(p_md, dof, lam))
            out.update(threshold=th, lambda_det=lam, p_fa=float(d.false_alarm_probability(th, dof)), p_md=p_md)
        elif p_fa is not None:
            out.update(threshold=float(d.classic_threshold(p_fa, dof)),
                       lambda_det=float(d.classic_lambda_det(p_fa, p_md, [dof])[0]), p_fa=p_fa, p_md=p_md)  # fmt: skip
        else:
            raise UsageError("--dof with --p-md needs --p-fa (classic) or --hal-over-slope (ETC)")
    if invoice_share is not None or invoice_error is not None:
        if invoice_share is None or not 0 < invoice_share < 100:
            raise UsageError("--invoice-share: a percentage strictly between 0 and 100")
        if invoice_error is None or not 0 < invoice_error < 50:
            raise UsageError("--invoice-error: a percentage strictly between 0 and 50")
        out["p_mgor"] = d.p_mgor_max(invoice_share, invoice_error)
        if n_potential is not None:
            out["p_fgor"] = d.p_fgor_max(invoice_share, n_potential)
    if not out:
        raise UsageError("nothing to derive: give --dof with --p-md and --p-fa or --hal-over-slope, or --invoice-share with --invoice-error")
    if as_json:
        typer.echo(json.dumps(out, sort_keys=True))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table("quantity", "value")
    for key, value in out.items():
        table.add_row(key, f"{value:.6g}")
        if key == "lambda_det":
            table.add_row("sqrt_lambda_det", f"{math.sqrt(value):.6g}")
    Console().print(table)
