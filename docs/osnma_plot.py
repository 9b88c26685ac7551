"""Draw docs/osnma_ublox.png: authenticated Galileo satellites per epoch of the real u-blox recording.

    python docs/osnma_plot.py [../shared/data/osnma/ublox/current_config.ubx] [docs/osnma_ublox.png]

Runs ``tollcli osnma``'s job on the recording (keys beside it) and plots, per epoch, the Galileo satellites the
receiver's fix used, those of them with authenticated navigation data (ADKD 0 or 12), and the tracked ones
authenticated; OSNMAlib's first authenticated fix is marked (measured with OSNMAlib on the same file).
"""

from __future__ import annotations

import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT = os.path.join(HERE, "..", "..", "shared", "data", "osnma", "ublox", "current_config.ubx")
#: OSNMAlib 35957d1 on the same file: "First Authenticated Fix at GST 1385 140641"
OSNMALIB_FIRST_FIX_TOW = 140641


def main(log: str = DEFAULT, out: str = os.path.join(HERE, "osnma_ublox.png")) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tollcli.job.osnma_check import check_osnma

    check = check_osnma(log)
    e = check.epochs
    tow = e["gst_s"].to_numpy() % 604800
    minutes = (tow - tow[0]) / 60
    fig, ax = plt.subplots(figsize=(9, 3.6), dpi=110)
    ax.step(minutes, e["n_galileo_used"], where="post", color="0.6", label="Galileo satellites used in the fix")
    ax.step(minutes, e["n_used_authenticated"], where="post", color="C0", label="… with authenticated data (ADKD 0 or 12)")
    ax.step(minutes, e["n_tracked_authenticated"], where="post", color="C2", lw=0.8, alpha=0.7, label="tracked, authenticated")
    ax.axvline((OSNMALIB_FIRST_FIX_TOW - tow[0]) / 60, color="C3", ls="--", lw=1, label="OSNMAlib: first authenticated fix")
    ax.axhline(4, color="k", lw=0.5, ls=":")
    ax.set_xlabel(f"minutes from GST TOW {int(tow[0])} (2026-03-09)")
    ax.set_ylabel("satellites")
    ax.set_ylim(0, max(int(e["n_galileo_tracked"].max()), 10) + 1)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title("u-blox recording, 4 753 epochs: Galileo OSNMA per epoch")
    fig.tight_layout()
    fig.savefig(out)
    print(out)


if __name__ == "__main__":
    main(*sys.argv[1:])
