"""Write ``docs/receivers.md``: what every gpsd regression log, of every protocol, gives the integrity checks, and its
findings judged.

Run from the repository root (reads ``../shared/data/gpsd/``, gpsd's BSD-2-Clause logs):

    python docs/receivers_table.py            # rewrite docs/receivers.md
    python docs/receivers_table.py --check    # exit 1 when the file is stale (tests/test_receivers_doc.py)
"""

from __future__ import annotations

import argparse
import re
import sys
from collections import Counter
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "gpsd"
OUT = REPO / "docs" / "receivers.md"

#: every finding on a gpsd log, judged (docs/enforcement.md explains each at length)
JUDGEMENTS = {
    "ac12.log": "receiver quirk: ZDA 2 s ahead of GGA/RMC, time 'runs backwards' at each GGA",
    "ac12_binary.log": "receiver quirk: as ac12.log",
    "bt451.log": "log artefact: two recordings concatenated",
    "bu353-glonass.log": "receiver quirk: no satellite report for 3 s during acquisition",
    "ericsson-gru04.log": "log artefact: hand-made example, unrelated times",
    "garmin-10x.log": "true event: signal loss of a weak receiver (likely indoors)",
    "gp-320fw-2019-04-07-coldboot.log": "receiver quirk: cold boot with week-rollover dates before the fix",
    "iTrek.log": "log artefact: two recordings concatenated (the first one's two no-fix epochs take the second's date)",
    "humminbird-M37.log": "receiver quirk: RMC time lags GGA by 13 s",
    "nl2008u.log": "true event: a 20 min gap of a handheld log",
    "sl869.log": "receiver quirk: a one-epoch position glitch",
    "ublox-lea-4h.log": "true event: a 67 s gap while driving",
    "unicore-um621.log": "true event: loses and regains its fix (submitter's note)",
    "navisys-gr701w.log": "true event: loses and regains its fix (submitter's note): C/N0 19.5 → 7 dB-Hz, 11 → 3 satellites",
    "trimble-res720-dr.log": "true event: a dead-reckoning test (DR receiver): every signal lost for 13 s",
    "trimble-ressmt360-dr.log": "true event: a dead-reckoning test (DR receiver): every satellite lost twice",
    "trimble-smtx-dr.log": "true event: a dead-reckoning test (DR receiver): signals lost for 25 s",
}
_SENTENCE = re.compile(rb"\$(?:(P)[A-Z]{3}|([A-Z]{2})([A-Z]{3}))[,*]")
_MAKE = re.compile(r"^#\s*(?:Chipset|Receiver|Name|Model)\s*[:=]\s*(.+)$", re.I)


def receiver_name(text: str) -> str:
    """The make/model the log's header names (gpsd logs open with '# Chipset: …' or '# Name: …')."""
    names = [m.group(1).strip() for line in text.splitlines()[:40] if (m := _MAKE.match(line.strip()))]
    chipset = [n for n in names if not n.endswith(".log")]
    return (chipset[0] if chipset else "")[:48].replace("|", "/")


def sentence_types(data: bytes) -> str:
    counts: Counter[str] = Counter()
    for m in _SENTENCE.finditer(data):
        counts["P…" if m.group(1) else m.group(3).decode()] += 1
    return " ".join(sorted(counts))


#: a verdict other than these two says something about the position (valid, unavailable, a fault, …)
NO_VERDICT = ("unmonitored", "insufficient")


def gpsd_fixes(log: Path) -> int:
    """gpsd's TPV fixes (2-D/3-D, with a position) of a log, from its regression output."""
    chk = log.with_name(log.name + ".chk")
    if not chk.exists():
        return 0
    return sum(1 for line in chk.read_text(encoding="latin-1").splitlines()
               if line.startswith('{"class":"TPV"') and '"lat"' in line and '"mode":1' not in line)  # fmt: skip


def _integrity(path: Path, kind: str):
    from tollcli.errors import DataError
    from tollcli.integrity.raim import RaimParams
    from tollcli.job.log_integrity import iter_integrity
    from tollcli.readers.nmea import ReadStats

    try:
        return [c for c in iter_integrity(str(path), kind, RaimParams(), stats=ReadStats()) if len(c.table)]
    except DataError:
        return []


def log_row(log: Path) -> dict | None:
    """One row of the table (the log read as recognised; where that gives no position, gpsd's JSON of it), or None
    when neither gives an epoch."""
    from tollcli.enforcement.findings import trip_findings
    from tollcli.io.sources import sniff_format

    data = log.read_bytes()
    kind = sniff_format(str(log))
    # a binary protocol: gpsd's own JSON of it (its regression output), not what this machine's gpsdecode makes of it
    chunks = [] if kind == "gpsd-binary" else _integrity(log, kind)
    if not any(c.table["lat_deg"].notna().any() for c in chunks) and log.with_name(log.name + ".chk").exists():
        chunks, kind = _integrity(log.with_name(log.name + ".chk"), "gpsd-json"), "gpsd-json (gpsd's)"
    if not chunks:
        return None
    table = pd.concat([c.table for c in chunks], ignore_index=True)
    sats = [c.satellites for c in chunks if c.satellites is not None]
    sats = pd.concat(sats, ignore_index=True) if sats else None
    present = [s for s, col in (("grs", "residual_status"), ("gbs", "gbs_status"), ("gst", "gst_status"))
               if (table[col].astype(str) != "").any() or (s == "grs" and (table["test_stat_source"] == "grs").any())]  # fmt: skip
    if table["hpl_model_m"].notna().any():
        present.append("model")
    decided = Counter(zip(table["raim_status"].astype(str), table["integrity_source"].astype(str)))
    ignored = int((table["gst_rms_note"].astype(str) != "").sum())
    kinds = Counter(f["kind"] for f in trip_findings(table, sats, table))
    if "--show" in sys.argv and kinds:
        print(log.name, dict(kinds), [(f["kind"], f.get("detail", f.get("why", ""))) for f in trip_findings(table, sats, table)][:3])
    return {
        "log": log.name, "receiver": receiver_name(data.decode("latin-1")), "format": kind, "types": sentence_types(data),
        "positions": int(table["lat_deg"].notna().sum()), "gpsd_fixes": gpsd_fixes(log),
        "verdict": bool(set(table["raim_status"].astype(str)) - {"unmonitored"}),
        "decisive": bool(set(table["raim_status"].astype(str)) - set(NO_VERDICT)),
        "sources": ", ".join(present) or "—", "epochs": len(table),
        "statuses": ", ".join(f"{n} {status} ({source})" for (status, source), n in sorted(decided.items())),
        "gst_rms_ignored": ignored,
        "findings": ", ".join(f"{n} {k}" for k, n in sorted(kinds.items())),
    }  # fmt: skip


#: logs with gpsd fixes where no position gets a verdict other than unmonitored, and why (checked: a log that
#: gets one now must leave this list)
NO_EVIDENCE = {
    "april6_2019.log": "RMC only: no satellites, no DOP",
    "firefly-II.log": "GGA with an empty quality field (its HDOP is not read) + RMC + ZDA: no satellites",
    "magellan-ec10.log": "RMC + RMB only: no satellites, no DOP",
    "meinberg-gps164.log": "RMC only: no satellites, no DOP",
    "saab-r4.log": "GGA without satellites or HDOP (an AIS transponder's position)",
    "sounder.log": "GLL only (an echo sounder's position)",
    "trimble-smt-360.log": "gpsd reports no satellites and no DOP for this TSIP receiver",
    "zodiac.log": "gpsd reports no satellites and no DOP for this Zodiac receiver",
}


def render(folder: Path = DATA) -> str:
    rows = [r for r in (log_row(p) for p in sorted(folder.glob("*.log"))) if r is not None]
    unjudged = [r["log"] for r in rows if r["findings"] and r["log"] not in JUDGEMENTS]
    if unjudged:
        raise SystemExit(f"findings not judged (add them to JUDGEMENTS): {', '.join(unjudged)}")
    stale = sorted(set(JUDGEMENTS) - {r["log"] for r in rows if r["findings"]})
    if stale:
        raise SystemExit(f"judged logs without findings now (remove them from JUDGEMENTS): {', '.join(stale)}")
    with_fixes = [p for p in sorted(folder.glob("*.log")) if gpsd_fixes(p)]
    by_log = {r["log"]: r for r in rows}
    no_position = [p.name for p in with_fixes if not by_log.get(p.name, {}).get("positions")]
    silent = sorted(p.name for p in with_fixes if p.name in by_log and not by_log[p.name]["verdict"])
    if set(silent) != set(NO_EVIDENCE):
        raise SystemExit(f"logs without a verdict changed: now {silent}; listed {sorted(NO_EVIDENCE)}")
    n_fix = len(with_fixes)
    n_verdict = sum(1 for p in with_fixes if by_log.get(p.name, {}).get("verdict"))
    n_decisive = sum(1 for p in with_fixes if by_log.get(p.name, {}).get("decisive"))
    total = Counter()
    for r in rows:
        for part in r["statuses"].split(", "):
            n, rest = part.split(" ", 1)
            total[rest] += int(n)
    formats = Counter(r["format"] for r in rows)
    out = [
        "# Receivers: what the gpsd regression logs give the integrity checks",
        "",
        "Generated by `python docs/receivers_table.py` from every log of `../shared/data/gpsd/` (gpsd's regression "
        "suite, BSD-2-Clause), each read as `tollcli` recognises it (`format`: NMEA, u-blox NAV messages); a log "
        "whose own protocol gives no position (SiRF, Trimble TSIP, Javad GREIS, Garmin, Motorola Oncore, iTalk, "
        "Zodiac binary) is read through gpsd's JSON of it — its regression output, what `gpspipe -w` gives "
        "(`tollcli` runs gpsdecode on such a log itself where it is installed, as `gpsdecode < log | tollcli integrity -` "
        "does, where gpsdecode decodes positions: SiRF, GREIS, Oncore, …; not Trimble TSIP; this table reads gpsd's "
        "own output so that it does not depend on the version of gpsdecode installed). `tests/test_receivers_doc.py` fails when this file is stale. Settings: "
        "`tollcli integrity` defaults (solution separation, environment auto, HAL 50 m, P_MD 5e-5, "
        "`--integrity-sources auto`); findings as `tollcli findings` (car). Sources: `grs` (residual test on GRS, "
        "NAV-SAT or SKY prRes), `gbs` (the receiver's own RAIM), `gst` (its error ellipse, or u-blox hAcc / NAV-PL; "
        "its RMS field only where it is a plausible range RMS), `model` (the used satellites' geometry, or the "
        "HDOP, and the error model: urban σ unless the residuals measured open sky). Statuses are `status "
        "(deciding source)`; \"GST RMS ignored\" counts epochs whose RMS field was no range RMS (u-blox writes "
        "values of 10⁵ m there).",
        "",
        f"**{n_fix} logs have gpsd fixes; {n_fix - len(no_position)} give positions here; {n_verdict} "
        f"({n_verdict / max(n_fix, 1):.1%}) a verdict other than `unmonitored`, {n_decisive} ({n_decisive / max(n_fix, 1):.1%}) "
        "one beyond `insufficient` (valid, unavailable, fault_detected, …).** Without positions: "
        + (", ".join(f"`{n}`" for n in no_position) or "none") + ". Without a verdict (nothing in the log to check "
        "a position with):",
        "",
        *[f"- `{name}`: {why}" for name, why in sorted(NO_EVIDENCE.items())],
        "",
        f"{len(rows)} logs with epochs ({', '.join(f'{n} {k}' for k, n in sorted(formats.items()))}), "
        f"{sum(r['epochs'] for r in rows)} epochs: "
        + ", ".join(f"{n} {k}" for k, n in sorted(total.items(), key=lambda kv: -kv[1])) + ".",
        "",
        "| log | receiver | format | sentence types | sources | epochs | gpsd fixes | statuses (source) | GST RMS ignored | findings | judgement |",
        "| --- | --- | --- | --- | --- | ---: | ---: | --- | ---: | --- | --- |",
    ]
    for r in rows:
        out.append(f"| `{r['log']}` | {r['receiver']} | {r['format']} | {r['types']} | {r['sources']} | {r['epochs']} | "
                   f"{r['gpsd_fixes']} | {r['statuses']} | {r['gst_rms_ignored']} | {r['findings'] or '—'} | "
                   f"{JUDGEMENTS.get(r['log'], '')} |")  # fmt: skip
    return "\n".join(out) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 when docs/receivers.md differs from what the code gives")
    args = parser.parse_args()
    text = render()
    if args.check:
        if not OUT.exists() or OUT.read_text(encoding="utf-8") != text:
            print(f"{OUT} is stale: run python docs/receivers_table.py", file=sys.stderr)
            sys.exit(1)
        return
    OUT.write_text(text, encoding="utf-8")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
