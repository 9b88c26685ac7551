"""Write ``docs/receivers.md``: what every gpsd regression log gives the integrity checks, and its findings judged.

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


def log_row(log: Path) -> dict | None:
    """One row of the table, or None when the log has no NMEA epoch."""
    from tollcli.enforcement.findings import trip_findings
    from tollcli.errors import DataError
    from tollcli.integrity.raim import RaimParams
    from tollcli.job.log_integrity import iter_integrity
    from tollcli.readers.nmea import ReadStats

    data = log.read_bytes()
    try:
        chunks = list(iter_integrity(str(log), "nmea", RaimParams(), stats=ReadStats()))
    except DataError:
        chunks = []
    chunks = [c for c in chunks if len(c.table)]
    if not chunks:
        return None
    table = pd.concat([c.table for c in chunks], ignore_index=True)
    sats = pd.concat([c.satellites for c in chunks], ignore_index=True)
    present = [s for s, col in (("grs", "residual_status"), ("gbs", "gbs_status"), ("gst", "gst_status"))
               if (table[col].astype(str) != "").any() or (s == "grs" and (table["test_stat_source"] == "grs").any())]  # fmt: skip
    decided = Counter(zip(table["raim_status"].astype(str), table["integrity_source"].astype(str)))
    ignored = int((table["gst_rms_note"].astype(str) != "").sum())
    kinds = Counter(f["kind"] for f in trip_findings(table, sats, table))
    return {
        "log": log.name, "receiver": receiver_name(data.decode("latin-1")), "types": sentence_types(data),
        "sources": ", ".join(present) or "—", "epochs": len(table),
        "statuses": ", ".join(f"{n} {status} ({source})" for (status, source), n in sorted(decided.items())),
        "gst_rms_ignored": ignored,
        "findings": ", ".join(f"{n} {k}" for k, n in sorted(kinds.items())),
    }  # fmt: skip


def render(folder: Path = DATA) -> str:
    rows = [r for r in (log_row(p) for p in sorted(folder.glob("*.log"))) if r is not None]
    unjudged = [r["log"] for r in rows if r["findings"] and r["log"] not in JUDGEMENTS]
    if unjudged:
        raise SystemExit(f"findings not judged (add them to JUDGEMENTS): {', '.join(unjudged)}")
    stale = sorted(set(JUDGEMENTS) - {r["log"] for r in rows if r["findings"]})
    if stale:
        raise SystemExit(f"judged logs without findings now (remove them from JUDGEMENTS): {', '.join(stale)}")
    total = Counter()
    for r in rows:
        for part in r["statuses"].split(", "):
            n, rest = part.split(" ", 1)
            total[rest] += int(n)
    out = [
        "# Receivers: what the gpsd regression logs give the integrity checks",
        "",
        "Generated by `python docs/receivers_table.py` from every log of `../shared/data/gpsd/` that has an NMEA "
        "epoch (gpsd's regression suite, BSD-2-Clause); `tests/test_receivers_doc.py` fails when this file is stale. "
        "Settings: `tollcli integrity` defaults (solution separation, environment auto, HAL 50 m, P_MD 5e-5, `--integrity-sources auto`); findings as "
        "`tollcli findings` (car). Sources: `grs` (residual test on GRS), `gbs` (the receiver's own RAIM), `gst` "
        "(its error ellipse; its RMS field only where it is a plausible range RMS). Statuses are `status (deciding "
        "source)`; \"GST RMS ignored\" counts epochs whose RMS field was no range RMS (u-blox writes values of "
        "10⁵ m there).",
        "",
        f"{len(rows)} logs with epochs, {sum(r['epochs'] for r in rows)} epochs: "
        + ", ".join(f"{n} {k}" for k, n in sorted(total.items(), key=lambda kv: -kv[1])) + ".",
        "",
        "| log | receiver | sentence types | sources | epochs | statuses (source) | GST RMS ignored | findings | judgement |",
        "| --- | --- | --- | --- | ---: | --- | ---: | --- | --- |",
    ]
    for r in rows:
        out.append(f"| `{r['log']}` | {r['receiver']} | {r['types']} | {r['sources']} | {r['epochs']} | {r['statuses']} | "
                   f"{r['gst_rms_ignored']} | {r['findings'] or '—'} | {JUDGEMENTS.get(r['log'], '')} |")  # fmt: skip
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
