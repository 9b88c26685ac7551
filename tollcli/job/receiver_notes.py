"""What a receiver's outputs were not, said on the invoice (``receiver_notes``): a GST that contradicted itself (no
evidence, neither bound nor fault), and what gpsd's JSON dropped of a receiver's evidence.
"""

from __future__ import annotations

import numpy as np
import pandas as pd


#: what gpsd's JSON does not carry of a receiver's evidence (the invoice's ``receiver_notes``, the integrity summary)
GPSD_DROPPED = ("gpsd's JSON carries no range residuals here (no prRes), and never the receiver's own RAIM (NMEA GBS) or "
                "its GRS residuals: the positions were checked only against what is left (GST, the satellites' geometry); "
                "the receiver's raw log may hold the residual test (u-blox NAV-SAT, NMEA GRS): process it for the "
                "strongest evidence")  # fmt: skip


#: receiver outputs an invoice says were no evidence (``gst_rms_note`` values), and what the invoice calls them
IGNORED_OUTPUTS = {"contradictory": "gst_contradictory"}


def count_ignored(raim: pd.DataFrame, epochs: pd.DataFrame, ignored: dict) -> None:
    """Count a chunk's epochs whose receiver output contradicted itself (``ignored``: note → [epochs, first line])."""
    if "gst_rms_note" not in raim:
        return
    notes = raim["gst_rms_note"].astype(str).to_numpy()
    for note in IGNORED_OUTPUTS:
        hit = np.flatnonzero(notes == note)
        if hit.size:
            line = int(epochs["line"].iat[hit[0]]) if "line" in epochs else -1
            seen = ignored.setdefault(note, [0, line])
            seen[0] += int(hit.size)


def receiver_notes(ignored: dict) -> dict[str, str]:
    """The invoice's ``receiver_notes``: each receiver output that was no evidence, what it means, how often, from where."""
    from tollcli.gnss.receiver_outputs import GST_RMS_NOTE_MEANINGS, GST_TRACE_RATIO_MAX

    out = {}
    for note, (n, line) in sorted(ignored.items()):
        where = f", first at line {line}" if line >= 0 else ""
        out[IGNORED_OUTPUTS[note]] = GST_RMS_NOTE_MEANINGS[note].format(trace=GST_TRACE_RATIO_MAX) + f" ({n} epochs{where})"
    return out
