"""City tariffs and their rules: the calendar, single-charge, daily cap, a zone once a day — as pure functions, with
known answers from the Gothenburg and Stockholm schemes and properties (order, splitting over logs)."""

import datetime as dt
from decimal import Decimal

import pytest
from city_drives import GOTHENBURG, ZONE_TARIFF
from conftest import REPO
from hypothesis import given, settings
from hypothesis import strategies as st

from tollcli.charging.city_rules import Charge, apply_rules, invoice_charges
from tollcli.charging.city_tariff import is_city_tariff, load_city_tariff
from tollcli.errors import DataError

STOCKHOLM = REPO / "geoobjects" / "example-stockholm.toml"
CET = dt.timezone(dt.timedelta(hours=1))


def crossing(tariff, local: str, gantry: str = "G1", day: dt.date = dt.date(2026, 3, 3), key: str = "") -> Charge:
    hh, mm = (int(v) for v in local.split(":"))
    when = dt.datetime(day.year, day.month, day.day, hh, mm, tzinfo=CET).astimezone(dt.UTC)
    rate, amount = tariff.crossing_price((when.timestamp(),), gantry, "left_to_right", "car")
    return Charge("crossing", gantry, when, amount, rate.name, "left_to_right", True, key or f"{gantry}@{local}")


def test_the_example_tariffs_read_and_say_they_are_city_tariffs():
    for path in (GOTHENBURG, STOCKHOLM, ZONE_TARIFF):
        assert is_city_tariff(str(path))
    assert not is_city_tariff(str(REPO / "geoobjects" / "example-tariff.toml"))
    gbg = load_city_tariff(str(GOTHENBURG))
    assert (gbg.currency, gbg.daily_cap, gbg.single_charge_min) == ("SEK", Decimal(60), 60.0)


@pytest.mark.parametrize("local, amount", [("06:00", 9), ("06:29", 9), ("06:30", 16), ("07:59", 22), ("08:00", 16),
                                           ("12:00", 9), ("15:00", 16), ("16:59", 22), ("17:30", 16), ("18:29", 9)])  # fmt: skip
def test_gothenburg_bands(local, amount):
    assert crossing(load_city_tariff(str(GOTHENBURG)), local).amount == amount


def test_outside_the_charging_hours_no_rate_holds():
    tariff = load_city_tariff(str(GOTHENBURG))
    when = dt.datetime(2026, 3, 3, 18, 30, tzinfo=CET).timestamp()
    assert tariff.crossing_price((when,), "G1", "left_to_right", "car") is None
    assert tariff.crossing_price((dt.datetime(2026, 3, 3, 7, 0, tzinfo=CET).timestamp(),), "G1", "left_to_right", "bus")[1] is None


def test_single_charge_and_the_cap_known_answer():
    """Gothenburg: 16 + 16 + 22 within 60 minutes → 22; the day's 103 SEK capped at 60."""
    t = load_city_tariff(str(GOTHENBURG))
    day = [crossing(t, hm, key=hm) for hm in ("06:35", "06:38", "07:20", "08:40", "10:00", "12:00", "15:10", "16:30", "17:45")]
    paid, rules, days, total = apply_rules(day, t)
    assert [r["rule"] for r in rules] == ["single_charge", "daily_cap"]
    assert rules[0]["said"] == "single-charge: 3 passages 06:35–07:20 → 22 SEK" and rules[0]["change"] == "-32"
    assert rules[1]["change"] == "-43" and days[0]["before_rules"] == "135"
    assert total == 60 and paid["07:20"] == 22 and paid["06:35"] == paid["06:38"] == 0


@pytest.mark.parametrize("day, why", [(dt.date(2026, 3, 7), "free weekday (sat)"), (dt.date(2026, 4, 3), "public holiday"),
                                      (dt.date(2026, 4, 2), "day before a public holiday"), (dt.date(2026, 7, 7), "free month (july)")])  # fmt: skip
def test_free_days_charge_nothing_and_say_why(day, why):
    t = load_city_tariff(str(GOTHENBURG))
    charges = [crossing(t, "10:00", day=dt.date(2026, 3, 3), key="a")]
    moved = [Charge(c.kind, c.obj, c.time_utc.replace(year=day.year, month=day.month, day=day.day), c.amount, c.rate, c.direction, True, c.key)
             for c in charges]  # fmt: skip
    _, rules, days, total = apply_rules(moved, t)
    assert total == 0 and rules[0]["rule"] == "free_day" and why in rules[0]["said"] and days[0]["free"] == why


def test_stockholm_july_is_charged_on_its_first_five_weekdays():
    cal = load_city_tariff(str(STOCKHOLM)).calendar
    charged = [d for d in range(1, 32) if not cal.free_reason(dt.date(2026, 7, d))]
    assert charged == [1, 2, 3, 6, 7]  # Wed 1 … Tue 7 (the weekend between is free)
    assert load_city_tariff(str(GOTHENBURG)).calendar.free_reason(dt.date(2026, 7, 1)) == "free month (july)"


def test_stockholm_high_season_costs_more():
    t = load_city_tariff(str(STOCKHOLM))
    march = crossing(t, "08:00", day=dt.date(2026, 3, 3))
    january = crossing(t, "08:00", day=dt.date(2026, 1, 13))
    assert (march.amount, january.amount) == (45, 35)


def test_a_zone_is_charged_once_a_day():
    t = load_city_tariff(str(ZONE_TARIFF))
    day = dt.datetime(2026, 3, 3, tzinfo=dt.UTC)
    visits = [Charge("zone", "Z1", day.replace(hour=h), Decimal(150), "congestion", "", True, f"v{h}") for h in (8, 10, 14)]
    paid, rules, days, total = apply_rules(visits, t)
    assert total == 150 and [r["rule"] for r in rules] == ["zone_once_a_day"] and "3 presences" in rules[0]["said"]


@pytest.mark.parametrize("text, said", [
    ('scheme = "city"\ncurrency = "SEK"\ntimezone = "Europe/Stockholm"\n[[rate]]\nstart = "07:00"\nend = "08:00"\namount = 5\ncolour = 1\n', ":8: rate 1: unknown key 'colour'"),
    ('scheme = "city"\ncurrency = "SEK"\ntimezone = "Europe/Stockholm"\n[[rate]]\nstart = "7h"\nend = "08:00"\namount = 5\n', "time '7h' is not HH:MM"),
    ('scheme = "city"\ncurrency = "SEK"\ntimezone = "Europe/Stockholm"\n[[rate]]\nstart = "07:00"\nend = "08:00"\namount = { lorri = 5 }\n', "unknown vehicle class 'lorri'"),
    ('scheme = "city"\ncurrency = "SEK"\ntimezone = "Mars/Olympus"\n[[rate]]\nstart = "07:00"\nend = "08:00"\namount = 5\n', ":3: unknown time zone"),
    ('scheme = "city"\ncurrency = "SEK"\ntimezone = "Europe/Stockholm"\n[calendar]\nholidays = ["2026-13-01"]\n[[rate]]\nstart = "07:00"\nend = "08:00"\namount = 5\n', "not a date"),
    ('scheme = "city"\ncurrency = "SEK"\ntimezone = "Europe/Stockholm"\n[[rate]]\nstart = "07:00"\nend = "08:00"\namount = "5"\n', "not text"),
    ('scheme = "city"\ncurrency = "SEK"\ntimezone = "Europe/Stockholm"\n', "needs a [[rate]] or a [[zone_charge]]"),
])  # fmt: skip
def test_a_bad_city_tariff_is_one_line_naming_the_place(tmp_path, text, said):
    path = tmp_path / "t.toml"
    path.write_text(text)
    with pytest.raises(DataError) as err:
        load_city_tariff(str(path))
    assert said in str(err.value) and "\n" not in str(err.value) and str(path) in str(err.value)


LOCAL_TIMES = st.lists(st.tuples(st.integers(6, 18), st.integers(0, 59), st.sampled_from(["G1", "G2", "G5"])), min_size=1, max_size=14)


@settings(max_examples=60, deadline=None)
@given(LOCAL_TIMES, st.randoms(use_true_random=False), st.integers(0, 14))
def test_any_order_and_any_split_over_logs_give_the_same_total(times, rnd, cut):
    """Rules are a function of the set of crossings: shuffled, or split into two invoices of the day (as batch joins
    them), the total is the same."""
    t = load_city_tariff(str(GOTHENBURG))
    charges = []
    for k, (h, m, g) in enumerate(times):
        if h == 18 and m >= 30:
            m = 29
        charges.append(crossing(t, f"{h:02d}:{m:02d}", g, key=f"k{k}"))
    _, _, _, total = apply_rules(charges, t)
    shuffled = charges[:]
    rnd.shuffle(shuffled)
    assert apply_rules(shuffled, t)[3] == total
    cut = min(cut, len(charges))

    def as_invoice(part, log):
        return {"inputs": {"log": log}, "lines": [{"kind": c.kind, "geoobject": c.obj, "time_utc": c.time_utc.isoformat().replace("+00:00", "Z"),
                                                   "fee": str(c.amount), "rate": c.rate, "direction": c.direction} for c in part]}  # fmt: skip

    joined = invoice_charges(as_invoice(shuffled[:cut], "a"), t) + invoice_charges(as_invoice(shuffled[cut:], "b"), t)
    assert apply_rules(joined, t)[3] == total
    assert total <= 60
