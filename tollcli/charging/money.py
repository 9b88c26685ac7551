"""Money from tariff files: Decimal amounts read without loss, exact sums and products, one rounding half-up.

Shared by the flat fee tables and the per-km rate tables (``tariffs.py``, ``rate_tables.py``).
"""

from __future__ import annotations

import re
from decimal import (
    MAX_EMAX,
    MIN_EMIN,
    ROUND_HALF_UP,
    Decimal,
    Inexact,
    InvalidOperation,
    localcontext,
)

from tollcli.errors import DataError

#: fees, rates (and band factors) are below this: invoice totals stay exact in Decimal's 28 digits
MAX_FEE = Decimal("1e12")
#: significant digits an amount in a tariff may have (more than any currency or rate needs)
MAX_DIGITS = 60


def line_of(text: str, key: str, after: int = 0) -> int:
    """The 1-based line of the file where ``key`` is set or opened as a table (0 when not found)."""
    pattern = re.compile(rf"""^\s*(\[\[?\s*)?["']?{re.escape(key)}["']?\s*(=|\]|\.)""")
    for number, line in enumerate(text.splitlines(), 1):
        if number > after and pattern.match(line):
            return number
    return 0


def where(path: str, text: str, key: str, after: int = 0) -> str:
    """``path:line`` of ``key`` (after line ``after``), or ``path`` when it is not found."""
    number = line_of(text, key, after)
    return f"{path}:{number}" if number else path


def money(value, where_: str, limit: Decimal = MAX_FEE) -> Decimal:
    """A fee or rate as read from TOML (an int or a Decimal: TOML numbers are read as Decimal) → Decimal ≥ 0, or a
    DataError naming ``where_``. Text is refused, even text that reads as a number: ``"0.95"`` quoted is a typo's
    way of hiding a number (``"0,95"``, ``"O.95"``) and a TOML tariff writes numbers as numbers."""
    if isinstance(value, str):
        raise DataError(f"{where_}: a fee must be a number, not text: write {value} without quotes" if _numeric_text(value)
                        else f"{where_}: not a number: {value!r}")  # fmt: skip
    if isinstance(value, bool) or not isinstance(value, (int, Decimal)):
        raise DataError(f"{where_}: a fee must be a number, got {value!r}")
    try:
        amount = Decimal(value)
    except InvalidOperation:
        raise DataError(f"{where_}: not a number: {value!r}") from None
    if not amount.is_finite() or amount < 0:
        raise DataError(f"{where_}: a fee must be a finite amount ≥ 0, got {value}")
    if amount >= limit:
        raise DataError(f"{where_}: {value} is not below {limit:,f}")
    if len(amount.as_tuple().digits) > MAX_DIGITS:
        raise DataError(f"{where_}: {value} has more than {MAX_DIGITS} significant digits")
    return amount


def exact(value_of):
    """``value_of()`` computed with every digit kept (a DataError if Decimal would have to round)."""
    with localcontext() as ctx:
        ctx.prec, ctx.Emax, ctx.Emin = 1000, MAX_EMAX, MIN_EMIN
        ctx.traps[Inexact] = True
        try:
            return value_of()
        except Inexact:  # not reachable with amounts of ≤ MAX_DIGITS digits below MAX_FEE
            raise DataError("an amount needs more than 1000 digits") from None


def exact_fee(amount: Decimal, factor: Decimal, minor_unit: int) -> Decimal:
    """``amount × factor`` rounded once, half-up, to ``minor_unit`` decimals (no rounding before: the product is exact)."""
    quantum = Decimal(1).scaleb(-minor_unit)
    product = exact(lambda: amount * factor)
    with localcontext() as ctx:
        ctx.prec, ctx.Emax, ctx.Emin = 1000, MAX_EMAX, MIN_EMIN
        return product.quantize(quantum, rounding=ROUND_HALF_UP)


def _numeric_text(text: str) -> bool:
    try:
        return Decimal(text).is_finite()
    except InvalidOperation:
        return False


def at_least_minor_unit(amount: Decimal, minor_unit: int, where_: str) -> Decimal:
    """A flat fee of 0 or of at least the currency's minor unit (a DataError naming ``where_`` otherwise): a fee below it
    is charged as 0.00 by the one rounding — a file that says 1e-320 EUR meant something else."""
    if 0 < amount < Decimal(1).scaleb(-minor_unit):
        raise DataError(f"{where_}: a fee of {amount} is below the currency's minor unit ({Decimal(1).scaleb(-minor_unit)}): "
                        f"it would be charged as 0; give 0 or a fee of at least the minor unit")  # fmt: skip
    return amount
