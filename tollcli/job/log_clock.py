"""A log's clock before it is charged: a log of seconds from its start placed at ``--start-time``, a ``--date``
that contradicts the log's own refused, a log dated after today refused — an invoice is priced on a calendar, and
never on an invented one (1970-01-01, a night band) or a guessed one (a GPS week-number rollover two decades on).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.errors import DataError, UsageError


def start_time_utc(value) -> pd.Timestamp | None:
    """``--start-time`` as a UTC timestamp (None: not a date and time with its offset)."""
    if not isinstance(value, str):
        return None
    try:
        t = pd.Timestamp(value)
    except (TypeError, ValueError):
        return None
    return t.tz_convert("UTC") if t.tzinfo is not None and 1980 <= t.year <= 2200 else None


#: logs whose times are seconds from the start of the recording: no date, no time of day (readers.librsf)
RELATIVE_CLOCK_KINDS = ("librsf",)


def on_the_clock(epochs: pd.DataFrame, name: str, settings) -> pd.DataFrame:
    """A relative-clock log's epochs placed at ``--start-time`` (its ``time_utc`` start at ``LIBRSF_T0``).

    Without it no invoice can be made: time bands, day types and the period would be priced on an invented clock
    (1970-01-01, a night). ``--date`` alone gives no time of day, so it is refused for such a log.
    """
    from tollcli.readers.librsf import LIBRSF_T0

    start = start_time_utc(settings.start_time) if settings.start_time is not None else None
    if start is None:
        example = f"{settings.date or '2019-06-01'}T08:00:00+02:00"
        given = f"--date {settings.date} gives no time of day; " if settings.date else ""
        raise DataError(f"{name}: its times are seconds from the start of the recording, with no date or time of day, "
                        f"and an invoice is priced on the clock: {given}give --start-time (e.g. {example})")  # fmt: skip
    if settings.date and settings.date != f"{start:%Y-%m-%d}":
        raise UsageError(f"--date {settings.date} contradicts --start-time {settings.start_time} (UTC date {start:%Y-%m-%d})")
    return epochs.assign(time_utc=epochs["time_utc"] + (start - LIBRSF_T0))


#: how far after today a log's epochs may be dated (time zones, a receiver's clock a little ahead), days
FUTURE_SLACK_DAYS = 1


def check_not_future(epochs: pd.DataFrame, name: str) -> None:
    """DataError when an epoch is dated more than a day after today: no receiver logged it then — a GPS week-number
    rollover guessed wrong (gpsd dates a 2015 log in 2034), or a damaged clock; an invoice on that calendar is wrong."""
    if "time_utc" not in epochs or not len(epochs):
        return
    latest = epochs["time_utc"].max()
    limit = pd.Timestamp.now(tz="UTC") + pd.Timedelta(days=FUTURE_SLACK_DAYS)
    if pd.notna(latest) and latest > limit:
        row = int(np.argmax((epochs["time_utc"] > limit).to_numpy()))
        line = f":{int(epochs['line'].iat[row])}" if "line" in epochs and pd.notna(epochs["line"].iat[row]) else ""
        raise DataError(f"{name}{line}: dated {epochs['time_utc'].iat[row]:%Y-%m-%d}, after today ({limit - pd.Timedelta(days=FUTURE_SLACK_DAYS):%Y-%m-%d}): "
                        f"no receiver logged it then (a GPS week-number rollover guessed wrong, or a damaged clock): "
                        f"no invoice on that calendar")  # fmt: skip


def check_given_date(epochs: pd.DataFrame, name: str, date: str) -> None:
    """DataError when ``--date`` contradicts the date of a log that carries its own (its first dated epoch's)."""
    dated = epochs["time_utc"].dropna() if "time_utc" in epochs else pd.Series([], dtype=object)
    if len(dated) and f"{dated.iat[0]:%Y-%m-%d}" != date:
        raise DataError(f"{name}: --date says {date}, the log's own first date is {dated.iat[0]:%Y-%m-%d}: leave --date out "
                        f"(it is for logs without dates)")  # fmt: skip
