"""The simulation a recording describes: the default scenario of ``aveas-format fit`` (without
``--config``), so that the fitter simulates what was recorded rather than a fixed hour of the
paper's demand.

From the recordings' samples on the measurement section (``road_id``, ``road_s`` in ``s_range``,
as the recorded metric takes them):

- **demand per class**: the vehicles of the class that cross the middle of the section (a
  cross-section count, as a detector counts them) per hour between the first and the last crossing
  (a recording's own ``duration_s`` may include time without demand: a simulation drained after
  its demand ended); a class without a crossing vehicle: the vehicles with samples there per hour
  of ``duration_s``. Classes without recorded vehicles are not simulated;
- **duration**: that period (the recordings' ``duration_s`` where nothing crosses), summed over
  the recordings: the simulation sees about as many vehicles as were recorded;
- **desired speed per class** (the starting values; the desired-speed fit replaces them): the
  mean and standard deviation of the vehicles' mean speeds there — a vehicle's mean speed is at most
  its desired speed, so mu starts a few km/h low, as the fitter's data start does;
- **section**: the length of ``s_range``, else the extent of ``road_s`` on the road holding most
  samples; **lanes**: the most lanes seen in one direction there (distinct ``lane_id``);
- **lane changes**: instantaneous for the mean-speed metric (mean speeds hardly depend on it and a
  run costs less, as in the paper's experiment and its benchmark), otherwise the base scenario's
  (3 s): car-following metrics do depend on it (docs/tutorials/04).

The rest (inflow section, W99 parameters, step length, seed) is the base scenario's.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aveas_format.sim.scenario import Scenario

__all__ = ["RecordedScenario", "recorded_scenario"]


@dataclass
class RecordedScenario:
    """The scenario and what it was taken from (for messages and ``best.json``)."""

    scenario: Scenario
    duration_s: float
    flow_veh_h: dict[str, float]
    counted: dict[str, int]
    section_m: float | None
    lanes: int | None
    notes: list[str] = field(default_factory=list)

    def describe(self) -> str:
        """One line: what the default scenario simulates and why."""
        flows = ", ".join(f"{v:,.0f} {c}s/h" for c, v in self.flow_veh_h.items())
        sec = f", a {self.section_m:,.0f} m section" if self.section_m else ""
        lanes = f" with {self.lanes} lanes" if self.lanes else ""
        lc = self.scenario.lane_change_duration
        return (f"simulating what the recordings show: {self.duration_s:,.0f} s of demand, {flows}"
                f"{sec}{lanes}, lane changes {'instantaneous' if lc == 0 else f'of {lc:g} s'}")


def _section_table(rec, road_id: str | None, s_range: tuple[float, float] | None) -> pa.Table:
    from aveas_format.fit.metrics import section_states

    cols = [c for c in ("participant_id", "time", "road_id", "road_s", "lane_id") if c in rec.states.column_names]
    st = section_states(rec.states.select(cols), road_id, s_range)
    if "road_s" in st.column_names:
        st = st.filter(pc.is_valid(st["road_s"]))
    return st


def _main_road(tables: list[pa.Table], road_id: str | None) -> str | None:
    if road_id is not None:
        return road_id
    counts: dict[str, int] = {}
    for t in tables:
        if "road_id" not in t.column_names or t.num_rows == 0:
            continue
        for row in pc.value_counts(t["road_id"].cast(pa.string())).to_pylist():
            if row["values"] is not None:
                counts[row["values"]] = counts.get(row["values"], 0) + row["counts"]
    return max(counts, key=counts.get) if counts else None


def recorded_scenario(recordings: Iterable, *, classes: tuple[str, ...] = ("car", "truck"),
                      metric: str = "mean_speed", road_id: str | None = None,
                      s_range: tuple[float, float] | None = None,
                      base: Scenario | None = None) -> RecordedScenario:
    """The scenario ``recordings`` describe (see the module doc); ``base`` gives the rest."""
    from aveas_format.fit.metrics import participant_classes
    from aveas_format.fit.objective import recorded_mean_speeds

    base = base or Scenario()
    recs = list(recordings)
    duration = float(sum(float(r.meta.duration_s or 0.0) for r in recs))
    tables = [_section_table(r, road_id, s_range) for r in recs]
    road = _main_road(tables, road_id)
    on_road = [t.filter(pc.fill_null(pc.equal(t["road_id"].cast(pa.string()), road), False))
               if road is not None and "road_id" in t.column_names else t for t in tables]
    # the section: s_range, else the extent of road_s on the main road
    s_all = np.concatenate([t["road_s"].to_numpy(zero_copy_only=False) for t in on_road
                            if "road_s" in t.column_names] or [np.empty(0)])
    if s_range is not None:
        lo, hi = sorted(s_range)
    elif len(s_all):
        lo, hi = float(s_all.min()), float(s_all.max())
    else:
        lo = hi = float("nan")
    section = hi - lo if np.isfinite(hi - lo) and hi - lo >= 50.0 else None
    s_mid = 0.5 * (lo + hi)
    counted = dict.fromkeys(classes, 0)
    present = dict.fromkeys(classes, 0)
    lanes_seen: tuple[set, set] = (set(), set())
    period = 0.0  # s between the first and the last crossing, summed over the recordings
    for rec, t in zip(recs, on_road, strict=True):
        cls_of = participant_classes(rec)
        if t.num_rows == 0:
            continue
        if "lane_id" in t.column_names:
            lane = t["lane_id"].drop_null().to_numpy(zero_copy_only=False)
            lanes_seen[0].update(int(v) for v in np.unique(lane[lane > 0]))
            lanes_seen[1].update(int(v) for v in np.unique(lane[lane < 0]))
        t = t.sort_by([("participant_id", "ascending"), ("time", "ascending")])
        pid = t["participant_id"].to_numpy()
        s = t["road_s"].to_numpy(zero_copy_only=False)
        # a crossing: a sample at or past the middle right after one of the same vehicle before it
        cross = np.flatnonzero((pid[1:] == pid[:-1]) & (s[:-1] < s_mid) & (s[1:] >= s_mid)) + 1
        who, first = np.unique(pid[cross], return_index=True)
        when = t["time"].to_numpy(zero_copy_only=False).astype(np.float64)[cross[first]]
        names = np.array([cls_of.get(int(p)) for p in who], dtype=object)
        seen = np.array([cls_of.get(int(p)) for p in np.unique(pid)], dtype=object)
        for c in classes:
            counted[c] += int(np.sum(names == c))
            present[c] += int(np.sum(seen == c))
        if len(when) > 1:
            period += float(when.max() - when.min()) * len(when) / (len(when) - 1)
        else:
            period += float(rec.meta.duration_s or 0.0)
    notes = []
    flows: dict[str, float] = {}
    for c in classes:
        if counted[c] and period > 0:
            flows[c] = counted[c] / (period / 3600.0)
        elif present[c] and duration > 0:
            notes.append(f"no {c} crosses the middle of the section: its demand counts the "
                         f"{present[c]} {c}s seen there per hour of the recordings")
            flows[c] = present[c] / (duration / 3600.0)
    duration = period if period > 0 else duration
    speeds: dict[str, list[np.ndarray]] = {c: [] for c in flows}
    for rec in recs:
        v = recorded_mean_speeds(rec, classes=tuple(flows), road_id=road_id, s_range=s_range)
        for c in flows:
            speeds[c].append(v[c])
    classes_out = []
    for c in flows:
        try:
            vc = base.cls(c).model_copy(deep=True)
        except KeyError:
            from aveas_format.sim.scenario import VehicleClass

            vc = VehicleClass(name=c, vclass="truck" if c == "truck" else "passenger", flow=1.0,
                              speed_mean_kmh=100.0)
        vc.flow = float(flows[c])
        v = np.concatenate(speeds[c]) if speeds[c] else np.empty(0)
        if len(v) > 1:
            vc.speed_mean_kmh, vc.speed_std_kmh = float(v.mean()), float(v.std(ddof=1))
        classes_out.append(vc)
    lanes = max(len(lanes_seen[0]), len(lanes_seen[1])) or None
    update: dict = {}
    if classes_out:
        update["classes"] = classes_out
    if duration > 0:
        update["duration"] = duration
    net = {}
    if section is not None:
        net["length"] = section
    if lanes is not None:
        net["lanes"] = lanes
        # a class banned from the left lanes keeps at least one lane
        net["ban_left_lanes"] = {k: min(v, lanes - 1) for k, v in base.network.ban_left_lanes.items()
                                 if min(v, lanes - 1) > 0}
    if net:
        update["network"] = base.network.model_copy(update=net)
    if metric == "mean_speed":
        update["lane_change_duration"] = 0.0
    sc = base.model_copy(update=update)
    return RecordedScenario(Scenario.model_validate(sc.model_dump()), duration, flows,
                            {c: counted[c] for c in flows}, section, lanes, notes)
