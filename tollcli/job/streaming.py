"""The charging steps after reading, on a sliding tail of a long log: memory stays that of a chunk.

``process`` reads a log chunk by chunk (satellites, RAIM and geo-object pairs per chunk). What
follows needs neighbouring epochs: the speed and map-matching checks look back a few epochs, the
findings over runs and baselines, the passages over the positions inside a geo-object.
:class:`TailCharger` keeps only the epochs still needed. Every round (once ``ROUND_ROWS`` epochs
wait, and at the end) it

* recomputes the policy checks and the findings over its tail and commits the epochs up to a
  frontier ``LOOKAHEAD_ROWS`` before the tail's end (every epoch at the end of the log);
* commits a finding in the round that commits its last epoch (a finding still open at the frontier
  waits), so each finding is computed once, with all of its epochs and its context;
* groups the committed positions into passages; a passage closes once the frontier is more than
  the passage gap after its last position, and only open passages keep their positions;
* then keeps, before the frontier and before every open finding, at least ``CONTEXT_ROWS`` epochs,
  ``CONTEXT_S`` seconds and ``CONTEXT_FIXES`` fixes (the longest look-back of any check: 30-epoch
  and 30-second windows), from the last fix before the frontier (a gap's first fix), and from the
  start of the map-matching run there (the matching's state is carried, so it restarts exactly).

Memory is the tail's: a chunk, its context and the longest episode still open (a finding, a
passage, a stretch on one road), not the log's length.

For a log whose times never go back, the invoice is the one the whole log at once gives (tested
byte for byte against ``rounds=False``). Two log-level quantities come from the first round's
epochs (the first chunk) rather than from the whole log: whether the log has speeds (the default
policy) and its epoch interval (the speed check's regular window). After a backward time step the
C/N0 baselines count epochs from there on (the whole log at once counts them everywhere), and a
passage is not reopened across it.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from tollcli.charging.invoice import passage_details
from tollcli.charging.recognition import (
    PAIR_COLUMNS,
    PASSAGE_GAP_S,
    charges,
    concat_pairs,
    pair_verdicts,
    passage_gaps_s,
    passages,
    utc_seconds_or_nan,
)
from tollcli.enforcement.findings import FindingSettings, trip_findings
from tollcli.enforcement.trip import times_increase
from tollcli.errors import DataError, UsageError
from tollcli.integrity.map_matching import MatchState
from tollcli.times import epoch_seconds

#: epochs a round leaves uncommitted at the tail's end (≥ the 30-epoch RAIM-alarm window, which marks back)
LOOKAHEAD_ROWS = 64
#: context kept before the frontier and every open finding: epochs, seconds, fixes
CONTEXT_ROWS = 64
CONTEXT_S = 90.0
CONTEXT_FIXES = 32
#: a round once this many epochs wait uncommitted (the tail's compact columns: ~200 bytes an epoch)
ROUND_ROWS = 10_000
VALID = ("valid", "excluded_valid")


def choose_policy(has_speed: bool, policy: str | None, roads: str | None) -> tuple[str, tuple[str, ...]]:
    """The policy in force and the checks it needs (UsageError when the inputs cannot support it)."""
    from tollcli.integrity.verdict import POLICIES, default_policy

    policy = policy or default_policy(has_speed, roads is not None)
    if policy not in POLICIES:
        raise UsageError(f"--policy {policy}: one of {', '.join(POLICIES)}")
    needs = POLICIES[policy]
    if "mm" in needs and roads is None:
        raise UsageError(f"--policy {policy} needs the road network (--roads)")
    if "speed" in needs and not has_speed:
        raise UsageError(f"--policy {policy}: the log has no speed over ground (RMC/VTG) to check")
    if "mm" in needs and not has_speed:
        raise UsageError(f"--policy {policy}: map matching needs the speed and heading the log does not have (RMC/VTG)")
    return policy, needs


def policy_columns(checks: pd.DataFrame, needs: tuple[str, ...]) -> pd.DataFrame:
    """The check columns :func:`~tollcli.charging.recognition.pair_verdicts` reads, for the checks a policy needs."""
    cols = (("speed_status",) if "speed" in needs else ()) + (("matched_road", "mm_status", "match_dist_m") if "mm" in needs else ())
    return checks[list(cols)].reset_index(drop=True)


def with_geo_roads(pairs: dict[str, np.ndarray], roads, geo, epochs: pd.DataFrame, rows: np.ndarray) -> dict[str, np.ndarray]:
    """``pairs`` with each geo-object's road in the network (``geo_road``, '' when none) and the position's (epoch
    ``rows``) distance to it (``geo_road_dist_m``, NaN when none): what map matching's veto weighs."""
    from tollcli.integrity.map_matching import distance_to_road_m, roads_of_geoobjects

    objs, which = np.unique(pairs["obj"], return_inverse=True)  # the geo-objects these positions are in, not the network's
    road = roads_of_geoobjects(roads, geo.ids[objs])[which]
    lat, lon = epochs["lat_deg"].to_numpy(float)[rows], epochs["lon_deg"].to_numpy(float)[rows]
    return {**pairs, "geo_road": road, "geo_road_dist_m": distance_to_road_m(roads, road, lat, lon)}


def has_speeds(epochs: pd.DataFrame) -> bool:
    """More than half of the epochs carry a speed over ground."""
    return "speed_mps" in epochs and bool(np.isfinite(epochs["speed_mps"].to_numpy(float)).mean() > 0.5)


class PassageStream:
    """Positions committed in epoch order → closed passages' charges, statuses and evidence."""

    def __init__(self, geo, tc_s: float, n_th: int, gap_s: float = PASSAGE_GAP_S):
        self.geo, self.tc_s, self.n_th, self.gap_s = geo, tc_s, n_th, gap_s
        self.open: dict[str, np.ndarray] | None = None
        self.charge_parts: list[pd.DataFrame] = []
        self.statuses: dict = {}
        self.evidence: dict = {}
        self.next_passage = 0

    def add(self, cols: dict[str, np.ndarray], t_frontier_s: float | None) -> None:
        """Add positions (pair columns + ``valid``, ``verdict``, ``t_s``, ``time_utc``); None: the log ended."""
        if self.open is not None:
            cols = {k: _concat(self.open[k], cols[k]) for k in self.open} if cols else self.open
        self.open = None
        if not cols or cols["obj"].size == 0:
            return
        pos = passages(cols, self.geo, self.tc_s, self.gap_s, first_passage=self.next_passage)
        order = np.lexsort((cols["t_s"], cols["obj"]))  # the order ``passages`` gave its rows: passages one after another
        number = pos["passage"].to_numpy()
        self.next_passage = int(number[-1]) + 1
        if t_frontier_s is None:
            closed = np.ones(number.size, bool)
        else:
            start = np.flatnonzero(np.r_[True, number[1:] != number[:-1]])
            last_t = np.repeat(np.maximum.reduceat(cols["t_s"][order], start), np.diff(np.r_[start, number.size]))
            gap_s = passage_gaps_s(self.geo, self.gap_s)[cols["obj"][order]]  # longer in a geo-object with a tunnel
            closed = (t_frontier_s - last_t) > gap_s  # a later position is further than the gap after it
        if closed.any():
            done = pos[closed] if not closed.all() else pos
            self.charge_parts.append(charges(done, self.n_th))
            statuses, evidence = passage_details(done)
            self.statuses.update(statuses)
            self.evidence.update(evidence)
        if not closed.all():
            keep = order[~closed]
            self.open = {k: v[keep] for k, v in cols.items()}

    def result(self) -> tuple[pd.DataFrame, tuple[dict, dict]]:
        """All passages (in entry order) and their (statuses, evidence)."""
        parts = [p for p in self.charge_parts if len(p)]
        if not parts:
            return charges(pd.DataFrame(), self.n_th), (self.statuses, self.evidence)
        table = pd.concat(parts, ignore_index=True) if len(parts) > 1 else parts[0]
        table = table.sort_values(["entry_utc", "geoobject"], kind="stable").reset_index(drop=True)
        return table, (self.statuses, self.evidence)


def _concat(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    if isinstance(a, np.ndarray):
        return np.concatenate([a, b])
    return a._concat_same_type([a, b])  # pandas extension arrays (tz-aware times)


class TailCharger:
    """Policy checks, findings and passages of one log, fed chunk by chunk (module docstring).

    ``rounds=False`` keeps every chunk and does all at the end (the whole log at once: the reference).
    """

    def __init__(self, geo, settings, roads: str | None, rounds: bool = True):
        self.geo, self.settings, self.roads_path, self.rounds = geo, settings, roads, rounds
        self.finding_settings = FindingSettings.for_class(settings.vehicle_class)
        self.epochs: pd.DataFrame | None = None  # the tail: kept epoch columns + RAIM + C/N0 summary
        self.start = 0  # log row of the tail's first epoch
        self.committed = 0  # log rows before this are committed
        self.pending: list[dict[str, np.ndarray]] = []  # pairs of uncommitted rows
        self.passages = PassageStream(geo, settings.tc_s, settings.n_th)
        self.findings: list[dict] = []
        self.policy: str | None = None
        self.needs: tuple[str, ...] = ()
        self.roads = None
        self.step_s: float | None = None
        self.increasing = True
        self.match_state = MatchState()
        self.first_utc = self.last_utc = None
        self.any_pairs = self.undated = False

    def independent_after(self, seconds: float) -> None:
        """Positions count as independent evidence only ``seconds`` apart or more (a trajectory's correlation time, when
        it exceeds ``--tc``): call before the first chunk."""
        self.passages.tc_s = max(self.passages.tc_s, float(seconds))

    def add(self, epochs: pd.DataFrame, raim: pd.DataFrame, cn0: pd.DataFrame, pairs: dict[str, np.ndarray]) -> None:
        """One chunk: its kept epoch columns, per-epoch RAIM columns, C/N0 summary and geo-object pairs."""
        part = pd.concat([epochs.reset_index(drop=True).add_prefix("epoch:"), raim.reset_index(drop=True).add_prefix("raim:"),
                          cn0.reset_index(drop=True).add_prefix("cn0:")], axis=1)  # fmt: skip
        self.epochs = part if self.epochs is None else pd.concat([self.epochs, part], ignore_index=True)
        dated = epochs["time_utc"].dropna()
        if len(dated):
            lo, hi = dated.min(), dated.max()
            self.first_utc = lo if self.first_utc is None else min(self.first_utc, lo)
            self.last_utc = hi if self.last_utc is None else max(self.last_utc, hi)
        self.undated |= len(dated) < len(epochs)
        if pairs and pairs["epoch_row"].size:
            self.pending.append(pairs)
            self.any_pairs = True
        if self.rounds and len(self.epochs) - (self.committed - self.start) >= ROUND_ROWS:
            self._round(final=False)

    def finish(self):
        """(policy, passages table, (statuses, evidence), findings, (first, last) dated epoch or None)."""
        if self.epochs is None:
            raise DataError("no epoch to charge")
        self._round(final=True)
        table, details = self.passages.result()
        self.findings.sort(key=lambda f: (f["start_utc"], f["kind"]))
        period = (self.first_utc, self.last_utc) if self.first_utc is not None else None
        return self.policy, table, details, self.findings, period

    # -- one round -------------------------------------------------------------------------------
    def _round(self, final: bool) -> None:
        tail = self.epochs
        n = len(tail)
        frontier = n if final else n - LOOKAHEAD_ROWS  # tail rows before it are committed this round
        done = self.committed - self.start
        if frontier <= done:
            if final:  # everything committed already: close what is open
                self.passages.add({}, None)
            return
        epochs, raim, cn0 = (_columns(tail, prefix) for prefix in ("epoch:", "raim:", "cn0:"))
        t = epoch_seconds(epochs)
        if self.policy is None:
            self.policy, self.needs = choose_policy(has_speeds(epochs), self.settings.policy, self.roads_path)
            if "mm" in self.needs:
                from tollcli.integrity.map_matching import load_roads

                self.roads = load_roads(self.roads_path)
            from tollcli.integrity.speed import nominal_step_s

            self.step_s = nominal_step_s(t)
        why, checks, trace = self._checks(epochs, raim)
        self._commit_positions(epochs, done, frontier, final, why, checks)
        self.increasing = self.increasing and times_increase(t)
        found = trip_findings(epochs, None, raim, self.geo, self.finding_settings, cn0=cn0, keep_rows=True,
                              times_increase=self.increasing)  # fmt: skip
        still_open = []
        for f in found:
            first, last = f.pop("_rows")
            if last >= frontier:
                still_open.append(first)
            elif last >= done:
                self.findings.append(f)
        self.committed = self.start + frontier
        if final:
            return
        keep = self._keep_from(epochs, t, frontier, still_open)
        if trace is not None:
            keep, self.match_state = trace.restart(keep)
        if keep > 0:
            self.epochs = tail.iloc[keep:].reset_index(drop=True)
            self.start += keep

    def _checks(self, epochs: pd.DataFrame, raim: pd.DataFrame):
        """Per tail row: the fault an epoch-level check found ('' when none), the policy's check columns (None
        without checks: :func:`~tollcli.charging.recognition.pair_verdicts`), and the matching trace."""
        if not self.needs:
            return self._authenticated(None, epochs), None, None
        from tollcli.integrity.verdict import epoch_checks_traced, failed_check

        epochs = epochs.assign(raim_status=raim["raim_status"].to_numpy())
        checks, trace = epoch_checks_traced(epochs, self.roads if "mm" in self.needs else None, step_s=self.step_s,
                                            match_state=self.match_state)  # fmt: skip
        return self._authenticated(failed_check(checks, self.policy), epochs), policy_columns(checks, self.needs), trace

    def _authenticated(self, why, epochs: pd.DataFrame):
        """``why`` with authenticated navigation data as one more condition when the settings require it."""
        if not self.settings.require_authenticated:
            return why
        from tollcli.integrity.nav_authentication import require_authenticated

        return require_authenticated(why, epochs["nav_auth"].to_numpy(object))

    def _commit_positions(self, epochs: pd.DataFrame, done: int, frontier: int, final: bool, why, checks) -> None:
        if self.any_pairs and self.undated:
            raise DataError("some epochs have no date (a log without RMC/ZDA): give --date")
        pending = concat_pairs(self.pending) if self.pending else {}
        self.pending = []
        cols: dict[str, np.ndarray] = {}
        if pending:
            local = pending["epoch_row"] - self.start
            now = local < frontier
            if not now.all():
                self.pending.append({k: v[~now] for k, v in pending.items()})
            if now.any():
                pairs = {k: v[now] for k, v in pending.items()}
                rows = pairs["epoch_row"] - self.start
                if checks is not None and "matched_road" in checks:
                    pairs = with_geo_roads(pairs, self.roads, self.geo, epochs, rows)
                verdicts = pair_verdicts(pairs, self.geo, why, checks, row_offset=self.start)
                times = epochs["time_utc"].array[rows]
                cols = {**{k: pairs[k] for k in (*PAIR_COLUMNS, "hpl_m", "separation_ratio", "part") if k in pairs}, **verdicts,
                        "t_s": utc_seconds_or_nan(times), "time_utc": times}  # fmt: skip
                if "nav_auth" in epochs:  # whether the position's navigation data were authenticated (OSNMA)
                    cols["nav_auth"] = epochs["nav_auth"].to_numpy(object)[rows]
        if final:
            self.passages.add(cols, None)
            return
        t_front = utc_seconds_or_nan(epochs["time_utc"].array[[frontier]])[0]
        self.passages.add(cols, t_front if np.isfinite(t_front) else -np.inf)

    @staticmethod
    def _keep_from(epochs: pd.DataFrame, t: np.ndarray, frontier: int, open_starts: list[int]) -> int:
        """The first tail row the next round needs (module docstring)."""
        valid = epochs["fix_valid"].to_numpy(bool) if "fix_valid" in epochs else np.ones(len(epochs), bool)
        lat, lon = epochs["lat_deg"].to_numpy(float), epochs["lon_deg"].to_numpy(float)
        fix_rows = np.flatnonzero(valid & np.isfinite(lat) & np.isfinite(lon) & np.isfinite(t))
        targets = [frontier, *open_starts]
        before = fix_rows[fix_rows < frontier]
        if before.size:
            targets.append(int(before[-1]))
        keep = frontier
        for row in targets:
            k = int(np.searchsorted(fix_rows, row))  # fixes before the row
            by_fixes = int(fix_rows[k - CONTEXT_FIXES]) if k >= CONTEXT_FIXES else 0
            with np.errstate(invalid="ignore"):
                early = np.flatnonzero(t[:row] <= t[row] - CONTEXT_S) if row < len(t) else np.zeros(0, np.int64)
            by_time = int(early[-1]) if early.size else 0
            keep = min(keep, row - CONTEXT_ROWS, by_fixes, by_time)
        return max(keep, 0)


def _columns(tail: pd.DataFrame, prefix: str) -> pd.DataFrame:
    """One of the tail's three tables (epoch columns, RAIM columns, C/N0 summary), its names without the prefix."""
    return tail[[c for c in tail.columns if c.startswith(prefix)]].rename(columns=lambda c: c[len(prefix) :])
