"""Terminal output on stderr: messages and progress (silent with --quiet or off a TTY)."""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager

#: the stderr console, made on first use: a quiet command never imports rich (30 ms of its start)
err = None


def _stderr():
    global err
    if err is None:
        from rich.console import Console

        err = Console(stderr=True, highlight=False, no_color=bool(os.environ.get("NO_COLOR")))
    return err


def note(message: str, quiet: bool = False) -> None:
    """A line for the user on stderr: a summary, a reason, a warning (silent with --quiet; errors are never notes)."""
    if not quiet:
        _stderr().print(message, markup=False, soft_wrap=True)


@contextmanager
def progress(description: str, quiet: bool, log: str | None = None, total: int | None = None, unit: str = "epochs"):
    """Yield ``advance(n, line=None)``: ``n`` more ``unit`` done (``line``: the log's line reached); a rich bar only on an
    interactive stderr.

    With a percentage when the size is known: ``total`` units, or a plain (uncompressed) ``log`` file whose lines are
    counted first (a byte scan, done only when the bar is drawn); else a spinner and the count."""
    if quiet or not sys.stderr.isatty():
        yield lambda n, line=None: None
        return
    from rich.progress import (
        BarColumn,
        Progress,
        SpinnerColumn,
        TaskProgressColumn,
        TextColumn,
        TimeElapsedColumn,
    )

    lines = _line_count(log) if total is None and log is not None else None
    known = total if total is not None else lines
    columns = [SpinnerColumn(), TextColumn("{task.description}")]
    if known:
        columns += [BarColumn(bar_width=24), TaskProgressColumn()]
    columns += [TextColumn("{task.fields[done]} " + unit), TimeElapsedColumn()]
    with Progress(*columns, console=_stderr(), transient=True) as bar:
        task = bar.add_task(description, total=known or None, done=0)
        done = 0

        def advance(n: int, line: int | None = None) -> None:
            nonlocal done
            done += n
            if lines and line is not None:
                bar.update(task, completed=min(line, lines), done=done)
            elif total is not None:
                bar.update(task, completed=done, done=done)
            else:
                bar.update(task, done=done)

        yield advance


def _line_count(log: str) -> int | None:
    """The number of lines of a plain log file (None for stdin, compressed or unreadable files)."""
    if log == "-" or log.lower().endswith(".gz") or not os.path.isfile(log):
        return None
    try:
        with open(log, "rb") as fh:
            n = sum(block.count(b"\n") for block in iter(lambda: fh.read(1 << 22), b""))
    except OSError:
        return None
    return max(n, 1)


STATUS_STYLES = {"valid": "green", "excluded_valid": "green", "fault_detected": "red", "probable_false_alarm": "magenta", "unavailable": "yellow",
                 "unmonitored": "dim", "insufficient": "dim"}  # fmt: skip


#: an ISO time as the tables write it (2024-05-06T08:00:00.000Z)
TIME_WIDTH = 24


def _column(table, name: str, **kwargs) -> None:
    """A table column; one of times is never cut nor wrapped (other columns give way on a narrow terminal)."""
    if "(UTC)" in name:
        kwargs.update(no_wrap=True, min_width=TIME_WIDTH)
    table.add_column(name, **kwargs)


def city_invoice_tables(invoice: dict):
    """Rich renderables for a city invoice: the crossings and zone presences, the rules applied, the day totals."""
    from rich.table import Table

    table = Table(title=f"Invoice {invoice.get('vehicle', '')} ({invoice.get('vehicle_class', '')}), city")
    for col in ("kind", "geo-object", "direction", "local time", "rate", f"fee {invoice['currency']}", "charged"):
        _column(table, col, justify="right" if col.startswith(("fee", "charged")) else "left")
    for line in invoice["lines"]:
        table.add_row(line["kind"], line["geoobject"], line.get("direction", ""), line["time_local"], line["rate"], line["fee"], line["charged"])
    for line in invoice.get("not_charged", []):
        table.add_row(f"[red]{line['kind']}[/red]", line["geoobject"], line.get("direction", ""), line.get("time_utc") or "", "not charged",
                      "", "", style="dim")  # fmt: skip
        table.add_row("", f"[dim]why: {line['why']}[/dim]", "", "", "", "", "")
    for rule in invoice.get("rules", []):
        table.add_row("[bold]rule[/bold]", rule["said"], "", "", "", "", rule["change"])
    table.add_row("[bold]TOTAL[/bold]", "", "", "", "", "", f"[bold]{invoice['total']}[/bold]")
    return [table]


def invoice_tables(invoice: dict):
    """Rich renderables for an invoice: the charged passages with the total, and the statuses behind them."""
    from rich.table import Table

    if invoice.get("scheme") == "city":
        return city_invoice_tables(invoice)
    table = Table(title=f"Invoice {invoice.get('vehicle', '')} ({invoice.get('vehicle_class', '')})")
    per_km = any("tariff_table" in line for line in invoice["lines"])  # per-km tables: the length and rate charged
    extra = ("table", "km", "rate/km") if per_km else ()
    for col in ("geo-object", "entry (UTC)", "exit (UTC)", "positions", "band", *extra, f"fee {invoice['currency']}"):
        _column(table, col, justify="right" if col.startswith(("positions", "fee", "km", "rate")) else "left")
    for line in invoice["lines"]:
        more = tuple(str(line.get(k) or "") for k in ("tariff_table", "length_km", "rate_per_km")) if per_km else ()
        table.add_row(line["geoobject"], line["entry_utc"], line["exit_utc"], str(line["n_valid_independent"]), line["band"], *more, line["fee"])
    for line in invoice.get("not_charged", []):
        table.add_row(f"[red]{line['geoobject']}[/red]", line["entry_utc"], line["exit_utc"], str(line["n_valid_independent"]), "not charged",
                      *([""] * len(extra)), "", style="dim")  # fmt: skip
        if line.get("why"):
            table.add_row("", f"[dim]why: {line['why']}[/dim]", "", "", "", *([""] * len(extra)), "")
    table.add_row("[bold]TOTAL[/bold]", "", "", "", "", *([""] * len(extra)), f"[bold]{invoice['total']}[/bold]")
    counts: dict[str, int] = {}
    for line in invoice["lines"] + invoice.get("not_charged", []):
        for k, v in line.get("statuses", {}).items():
            counts[k] = counts.get(k, 0) + int(v)
    title = "Positions inside geo-objects, by RAIM status"
    caption = None
    if "probable_false_alarm" in counts:
        caption = ("probable_false_alarm: the test failed at a P_FA above p_fa — ETC keeps HPL = HAL by lowering its "
                   "threshold and pays in false alarms; not trusted, not charged on, no evidence of a fault")  # fmt: skip
    statuses = Table(title=title, caption=caption, min_width=len(title) + 4)
    statuses.add_column("status")
    statuses.add_column("epochs", justify="right")
    for k, v in sorted(counts.items()):
        statuses.add_row(f"[{STATUS_STYLES.get(k, 'white')}]{k}[/]", str(v))
    out = [table, statuses]
    items = (invoice.get("findings") or {}).get("items", [])
    if items:
        found = Table(title="Findings")
        for col in ("kind", "category", "start (UTC)", "end (UTC)"):
            _column(found, col)
        for f in items:
            found.add_row(f"[yellow]{f['kind']}[/yellow]", f["category"], f["start_utc"], f["end_utc"])
        out.append(found)
    return out


def audit_tables(report: dict):
    """Rich renderables for an audit report (truth or risk mode)."""
    from rich.table import Table

    out = []
    if report.get("mode") == "truth":
        t = Table(title=f"Audit against the truth ({report['runs']} runs)")
        for col in ("geo-object", "driven", "charged", "undercharges", "overcharges", "rate", "95 % interval"):
            t.add_column(col, justify="left" if col == "geo-object" else "right")
        for o in report["geoobjects"]:
            bad = o["undercharges"] or o["overcharges"]
            t.add_row(o["geoobject"], "yes" if o["driven"] else "no", str(o["charged"]),
                      f"[red]{o['undercharges']}[/red]" if o["undercharges"] else "0",
                      f"[red]{o['overcharges']}[/red]" if o["overcharges"] else "0",
                      f"{o['rate']:.3f}", f"{o['rate_ci95'][0]:.3f}–{o['rate_ci95'][1]:.3f}", style=None if bad else "green")  # fmt: skip
        out.append(t)
        causes = [(r["vehicle"], c) for r in report["invoices"] for c in r.get("undercharge_causes", [])]
        if causes:
            c = Table(title="Undercharges and their causes")
            for col in ("vehicle", "geo-object", "cause"):
                c.add_column(col)
            for vehicle, cause in causes:
                c.add_row(vehicle, cause["geoobject"], cause["cause"])
            out.append(c)
    elif report.get("mode") == "risk":
        t = Table(title=f"Revenue at risk ({report['runs']} runs): {report['money_at_risk']} not charged")
        for col in ("vehicle", "geo-object", "entry (UTC)", "inside", "valid", "why", "fee"):
            _column(t, col)
        for r in report["revenue_at_risk"]:
            t.add_row(r["vehicle"], r["geoobject"], r["entry_utc"], str(r["n_inside"]), str(r["n_valid"]),
                      ", ".join(f"{k} {v}" for k, v in r["why"].items()), r["fee"] or "")  # fmt: skip
        out.append(t)
    if report.get("integrity"):
        i = report["integrity"]
        t = Table(title="Integrity against the truth (Stanford regions)")
        t.add_column("region")
        t.add_column("epochs", justify="right")
        for k, v in i["regions"].items():
            t.add_row(f"[red]{k}[/red]" if k in ("misleading", "hazardous") and v else k, str(v))
        t.add_row("positioning failures", str(i["positioning_failures"]))
        t.add_row("undetected", f"[red]{i['undetected']}[/red]" if i["undetected"] else "0")
        out.append(t)
    if report.get("findings"):
        f = Table(title="Findings")
        for col in ("vehicle", "kind", "category", "start (UTC)", "end (UTC)"):
            _column(f, col)
        for item in report["findings"]:
            f.add_row(item["vehicle"], f"[yellow]{item['kind']}[/yellow]", item["category"], item["start_utc"], item["end_utc"])
        out.append(f)
    return out


def show(renderables, quiet: bool, to_stdout: bool = False) -> None:
    """Print rich tables on an interactive terminal only (stdout when it is the output, else stderr).

    ``renderables``: the tables, or a function making them (called only when they will be shown).
    """
    if quiet:
        return
    from rich.console import Console

    console = Console(no_color=bool(os.environ.get("NO_COLOR"))) if to_stdout else _stderr()
    if not console.is_terminal:
        return
    for r in renderables() if callable(renderables) else renderables:
        console.print(r)
