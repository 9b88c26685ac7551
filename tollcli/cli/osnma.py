"""``tollcli osnma``: which satellites' navigation data Galileo OSNMA authenticated, epoch by epoch."""

from __future__ import annotations

import json
from typing import Annotated, Optional

import typer

from tollcli.cli import options as opt
from tollcli.cli.console import note


def osnma(
    log: Annotated[str, typer.Argument(metavar="LOG", help="A u-blox log with RXM-SFRBX Galileo I/NAV pages (and NAV-TIMEGAL), or an OSNMA ICD test-vector CSV.", show_default=False)],
    output: opt.Output = "-",
    out_fmt: opt.TableFormat = None,
    satellites: Annotated[Optional[str], typer.Option("--satellites", help="Also write one row per epoch and satellite (nav_authenticated, nav_auth_adkd0, nav_auth_adkd12, nav_auth_gst_s, iod) here.")] = None,
    tags: Annotated[Optional[str], typer.Option("--tags", help="Also write one row per tag checked (subframe, PRN_A, PRN_D, ADKD, COP, verified) here.")] = None,
    failures: Annotated[Optional[str], typer.Option("--failures", help="Also write what failed (tag, key, MACSEQ, KROOT signature, public key) with satellite and time here.")] = None,
    merkle: Annotated[Optional[str], typer.Option("--merkle", help="The OSNMA Merkle tree file (GSC XML); default: OSNMA_MerkleTree.xml beside the log.")] = None,
    public_key: Annotated[Optional[list[str]], typer.Option("--public-key", help="An OSNMA public key file (GSC XML), repeatable; default: OSNMA_PublicKey*.xml beside the log. Without one the key is taken from the signal (DSM-PKR).")] = None,
    sync_bound_s: Annotated[float, typer.Option("--sync-bound-s", help="How far the receiver's clock may be from Galileo system time, s: up to 30 every tag is used, up to 330 only slow-MAC (ADKD 12) tags, beyond none.", min=0.0)] = 30.0,
    strict: opt.Strict = False,
    quiet: opt.Quiet = False,
    as_json: opt.JsonSummary = False,
) -> None:
    """Verify Galileo OSNMA (navigation message authentication) in a log.

    The public key is checked against the Merkle tree root, the TESLA root key
    against its ECDSA signature, every TESLA key back to that root, and each MAC
    tag over the ephemeris, clock and status (ADKD 0, 12) or time conversion
    (ADKD 4) data it covers. Writes per epoch how many used Galileo satellites
    had authenticated data (-o; for a u-blox log also nav_auth and the position
    from the authenticated satellites alone, auth_lat_deg, auth_lon_deg, with its
    distance to the fix auth_sep_m and that distance's no-fault bound
    auth_sep_threshold_m), and on request per epoch and satellite
    (--satellites), each tag (--tags) and each failure (--failures). A failure
    names satellite and time: forged or replayed data, or a damaged log.
    Authentication covers the data, not the ranging (see docs/osnma.md).
    """
    from tollcli.io.writers import TableWriter, format_for
    from tollcli.job.osnma_check import check_osnma

    if as_json and output == "-":
        output = ""
    from tollcli.io.log_run import LogRun

    with LogRun(log) as run:  # opened once: pages, satellites and fixes read the same bytes
        with run.named_errors():
            check = check_osnma(log, merkle, public_key, sync_bound_s, strict, data=run.replay_path(), kind=run.kind)
    tables = [(output, check.epochs), (satellites, check.satellites.drop(columns=["gst_s"])), (tags, check.result.tags),
              (failures, check.result.failures)]  # fmt: skip
    writers = [(TableWriter(path, format_for(path, fmt=out_fmt)), table) for path, table in tables if path]
    try:
        for writer, table in writers:
            writer.write(table)
        for writer, _ in writers:  # every table written before any is moved into place
            writer.commit()
    finally:
        for writer, _ in writers:
            writer.__exit__(None, None, None)
    s = check.summary
    if as_json:
        typer.echo(json.dumps(s, sort_keys=True, default=str))
        return
    note(f"{log}: {s['pages']} pages; {s['kroots_authenticated']} root keys, {s['tesla_keys_verified']} TESLA keys, "
         f"{s['tags_authenticated']} tags and {s['data_authenticated']} data sets authenticated; "
         f"first authenticated fix {s['first_authenticated_fix_gst']}; {s['failures']} failures", quiet)  # fmt: skip
    for f in s["first_failures"]:
        note(f"osnma failure at {f['gst']}: E{int(f['svid']):02d} {f['kind']}: {f['detail']}", quiet)
