"""``tollcli verify``: confirm an invoice is reproduced byte for byte from its inputs."""

from __future__ import annotations

import json
from typing import Annotated

import typer

from tollcli.cli import options as opt
from tollcli.cli.console import note
from tollcli.job.verify import verify_invoice


def verify(
    invoice: Annotated[str, typer.Argument(metavar="INVOICE", help="An invoice JSON written by 'tollcli process'.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print what was checked as JSON on stdout.")] = False,
    use_cache: Annotated[bool, typer.Option("--use-cache", help="Let the re-run use the cache (compiled geo-objects, stored "
                                            "thresholds) for speed; the summary says so. Without it verify recomputes "
                                            "from the inputs alone.")] = False,
    quiet: opt.Quiet = False,
) -> None:
    """Check the invoice's own hash and its inputs' hashes, re-run the processing and compare byte for byte.

    Exit 0 when reproduced; 1 with the reason (content modified, an input changed or
    missing, or a different result, named by where it differs) otherwise. No cache is read
    unless --use-cache is given.
    """
    summary = verify_invoice(invoice, use_cache=use_cache)
    if as_json:
        typer.echo(json.dumps({"reproduced": True, **summary}, sort_keys=True))
    note(f"{invoice}: reproduced byte for byte (content {summary['content_sha256'][:12]}…; cache {summary['cache']})", quiet)
