"""``tollcli info``: what a receiver log, a geo-object file or an invoice holds (as ``fio info``, ``gpsprof``)."""

from __future__ import annotations

import json
from typing import Annotated

import typer

from tollcli.cli import options as opt


def info(
    path: Annotated[str, typer.Argument(metavar="LOG|GEOOBJECTS|INVOICE", help="A receiver log (any kind the tool reads, .gz too, - for stdin), a geo-object file or an invoice.", show_default=False)],
    min_hal: Annotated[float, typer.Option("--min-hal", help="Geo-objects: also give the tolled length covered by geo-objects of at least this HAL, m.", min=0.0)] = 25.0,
    nav: opt.Nav = None,
    as_json: Annotated[bool, typer.Option("--json", help="Everything as JSON on stdout.")] = False,
    quiet: opt.Quiet = False,
) -> None:
    """What a file holds, before anything is charged on it.

    A log: its kind (what --input-format auto recognises), its messages (NMEA
    sentence types, UBX messages, gpsd report classes, GnssLogger records, RTKLIB
    solutions), and for a receiver's own solutions the epochs, their span and
    rate, the fixes by quality, how many epochs carry each integrity source's
    evidence (residuals, the receiver's RAIM, its error ellipse, satellites) and
    the level --integrity-sources auto would settle on; where the log is and how
    far it drove (from the receiver's speed where it gave one, else along the
    positions: the trajectory's for a pseudorange log it can place, never the
    noise of the fixes summed). A geo-object file: as
    'tollcli geoobjects info'. An invoice: its vehicle, period, charges and total.
    """
    from tollcli.job.file_info import file_info

    summary = file_info(path, min_hal, opt.nav_files(nav))
    if as_json:
        typer.echo(json.dumps(summary, sort_keys=True, default=str))
        return
    typer.echo("\n".join(text_lines(summary)))


def text_lines(s: dict) -> list[str]:
    """The summary as lines of text."""
    if s["kind"] == "geoobjects":
        h = s["hal_m"]
        return [f"{s['file']}: geo-objects, {s['geoobjects']} ({s['sections_skipped']} tolled sections skipped at build)",
                f"HAL {h['min']:g}–{h['max']:g} m, median {h['median']:g} m; covered {100 * (s['covered_share'] or 0):.1f} % of "
                f"{(s['tolled_length_m'] or 0) / 1000:.3f} tolled km ('tollcli geoobjects info' lists each)"]  # fmt: skip
    if s["kind"] == "invoice":
        return [f"{s['file']}: invoice of {s['vehicle']}, {s['charged']} charged, {s['not_charged']} seen but not charged, "
                f"total {s['total']} {s['currency']}; integrity level {s['integrity_sources_used']}"]  # fmt: skip
    lines = [f"{s['file']}: {s['kind']}" + (f", {s['bytes']} bytes" if s.get("bytes") is not None else "")]
    if s.get("messages"):
        lines.append("messages: " + ", ".join(f"{k} {v}" for k, v in s["messages"].items()))
    if s.get("problem"):
        lines.append(f"nothing to read: {s['problem']}")
        return lines
    if s["kind"] == "unknown":
        return lines + [s["needs"]]
    if "solved_by" in s:
        lines.append(f"solved by {s['solved_by']}" + (f"; needs {s['needs']}" if s["needs"] else ""))
    if "epochs" in s:
        lines += _where(s)
        if s.get("fix_quality"):
            lines.append("fix quality (GGA): " + ", ".join(f"{k}: {v}" for k, v in s["fix_quality"].items()))
    if s.get("positions"):
        lines.append(s["positions"])
    if "integrity_evidence_epochs" in s:
        ev = s["integrity_evidence_epochs"]
        lines.append("integrity evidence (epochs): " + ", ".join(f"{k} {v}" for k, v in ev.items())
                     + f"; level under --integrity-sources auto: {s['integrity_level']}")
    if s.get("skipped_lines"):
        first = f" (first: {s['first_problem']})" if s.get("first_problem") else " (--strict names the first)"
        lines.append(f"skipped lines: {s['skipped_lines']}{first}")
    return lines


def _where(s: dict) -> list[str]:
    """Epochs, span, rate, and where the log is: its box and the distance driven."""
    span = f"{s['first_utc']} – {s['last_utc']}" if s.get("first_utc") else "no time"
    if s.get("clock", "").startswith("seconds"):
        span = f"{s['span_s']:g} s from its start (no date: process needs --start-time)"
    out = [f"epochs: {s['epochs']} ({s['epochs_with_position']} with a position), {span}"
           + (f", every {s['interval_s']:g} s ({s['rate_hz']:g} Hz)" if s.get("interval_s") else "")]  # fmt: skip
    if s.get("box_deg"):
        b = s["box_deg"]
        out.append(f"where: longitude {b[0]:.5f} – {b[2]:.5f}, latitude {b[1]:.5f} – {b[3]:.5f}; "
                   f"{s['distance_m'] / 1000:,.2f} km driven" + (f" (from {s['distance_from']})" if s.get("distance_from") else ""))  # fmt: skip
    return out
