"""Scenario configuration of the SUMO runner: network, vehicle classes, demand, behaviour models.

A scenario is a pydantic model, loadable from TOML (:meth:`Scenario.from_toml`). The defaults are the
paper's setup (section "Model parameterization"): a 3-lane autobahn section of 4,000 m preceded by a
1,500 m inflow section that is excluded from analysis, 1,680 cars/h and 320 trucks/h with Poisson
arrivals, trucks banned from the left lane, Wiedemann 99 car following with Vissim's defaults
cc0..cc9 (all set explicitly: SUMO's own defaults differ), LC2013 lane changing (keep right) and a
desired speed ~ N(mu, sigma) per class.

How the desired speed is expressed in SUMO: lanes get a speed of ``lane_speed_kmh`` (300 km/h, so no
limit binds), each class gets ``desiredMaxSpeed = mu`` and a speed factor ``f`` with mean 1 and
standard deviation ``sigma / mu``, truncated at +-4 sigma; the desired speed is then ``f * mu``.
``maxSpeed`` (the vehicle's technical limit) is raised above ``mu + 4.5 sigma`` so that it does not
cut the distribution (SUMO's truck default is 130 km/h).

Random numbers: ``random_numbers = "common"`` (default) generates the vehicles in Python: Poisson
arrival times and a standard-normal draw ``z`` per vehicle from ``seed``; the vehicle's speed factor
is ``1 + z * sigma / mu``. With fixed seeds two scenarios that differ only in mu/sigma have the same
arrivals and the same ``z`` (common random numbers), which makes the fitting objective smooth.
``random_numbers = "sumo"`` writes ``<flow period="exp(rate)">`` and ``speedFactor="normc(...)"`` and
lets SUMO draw.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from aveas_format.errors import AveasError

#: Vissim's Wiedemann 99 defaults (the paper's table "Variation of Wiedemann99 parameters");
#: cc0 becomes SUMO's ``minGap``.
W99_DEFAULTS: dict[str, float] = {
    "cc0": 1.5, "cc1": 0.9, "cc2": 4.0, "cc3": -8.0, "cc4": -0.35,
    "cc5": 0.35, "cc6": 11.44, "cc7": 0.25, "cc8": 3.5, "cc9": 1.5,
}
#: the paper's sensitivity ranges (start, end) per W99 parameter
W99_RANGES: dict[str, tuple[float, float]] = {
    "cc0": (0.25, 2.5), "cc1": (0.1, 1.0), "cc2": (1.0, 5.5), "cc3": (-2.0, -11.0),
    "cc4": (-0.1, -0.55), "cc5": (0.1, 0.55), "cc6": (8.44, 12.94), "cc7": (0.1, 0.55),
    "cc8": (1.0, 5.5), "cc9": (0.5, 5.0),
}
#: SUMO's car-following model names
CF_MODELS = {"W99": "W99", "Krauss": "Krauss", "IDM": "IDM"}


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class VehicleClass(_Model):
    """One vehicle class: a SUMO vType plus its demand."""

    name: str = Field(description="vType id (and flow id prefix)")
    vclass: str = Field("passenger", description="SUMO vClass (passenger -> class car, truck -> truck)")
    flow: float = Field(gt=0, description="vehicles per hour")
    speed_mean_kmh: float = Field(gt=0, description="mean desired speed mu (km/h)")
    speed_std_kmh: float = Field(0.0, ge=0, description="standard deviation of the desired speed (km/h)")
    max_speed_kmh: float | None = Field(None, description="technical maximum speed; default max(mu + "
                                        "4.5 sigma, 160 km/h)")
    length: float | None = Field(None, gt=0, description="m (default: SUMO's per vClass)")
    width: float | None = Field(None, gt=0)
    height: float | None = Field(None, gt=0)
    accel: float | None = Field(None, gt=0, description="m/s² (Krauss/IDM; W99 uses cc8/cc9)")
    decel: float | None = Field(None, gt=0, description="comfortable deceleration m/s²")
    car_following: Literal["W99", "Krauss", "IDM"] = "W99"
    cf_params: dict[str, float] = Field(default_factory=dict, description="car-following parameters: "
                                        "cc0..cc9 for W99 (defaults: Vissim's), or SUMO vType "
                                        "attributes (tau, sigma, delta, minGap, ...)")
    lane_change: dict[str, float | str] = Field(default_factory=lambda: {"lcKeepRight": 1.0},
                                                description="LC2013 vType attributes")

    def w99(self) -> dict[str, float]:
        unknown = set(self.cf_params) - set(W99_DEFAULTS)
        if unknown:
            raise AveasError(f"class {self.name!r}: unknown W99 parameters {sorted(unknown)} "
                             "(use cc0..cc9)")
        return {**W99_DEFAULTS, **self.cf_params}

    def vtype_attributes(self) -> dict[str, str]:
        mu = self.speed_mean_kmh / 3.6
        sig = self.speed_std_kmh / 3.6
        vmax = self.max_speed_kmh / 3.6 if self.max_speed_kmh else max(mu + 4.5 * sig, 160 / 3.6)
        a: dict[str, str] = {"id": self.name, "vClass": self.vclass,
                             "carFollowModel": CF_MODELS[self.car_following], "laneChangeModel": "LC2013",
                             "desiredMaxSpeed": _f(mu), "maxSpeed": _f(vmax)}
        r = sig / mu
        a["speedFactor"] = f"normc(1,{_f(r)},{_f(max(1 - 4 * r, 0.01))},{_f(1 + 4 * r)})" if r > 0 else "1"
        for k in ("length", "width", "height", "accel", "decel"):
            if getattr(self, k) is not None:
                a[k] = _f(getattr(self, k))
        if self.car_following == "W99":
            p = self.w99()
            a["minGap"] = _f(p["cc0"])
            for k in [f"cc{i}" for i in range(1, 10)]:
                a[k] = _f(p[k])
        else:
            for k, v in self.cf_params.items():
                a[k] = _f(v)
        for k, v in self.lane_change.items():
            a[k] = v if isinstance(v, str) else _f(v)
        return a


class Network(_Model):
    """The road network: the paper's highway (built) or an OpenDRIVE map (e.g. a recording's)."""

    map: Path | None = Field(None, description="an OpenDRIVE file or a recording (.aveas) whose map "
                             "is used; default: build the highway below")
    length: float = Field(4000.0, gt=0, description="measurement section (m)")
    inflow: float = Field(1500.0, ge=0, description="inflow section before it, excluded from analysis (m)")
    lanes: int = Field(3, ge=1)
    lane_width: float = Field(3.5, gt=0)
    geo_reference: str = Field("+proj=tmerc +lat_0=48.9 +lon_0=8.35 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 "
                               "+units=m +no_defs", description="PROJ string of the built highway's "
                               "map (a recording needs a CRS)")
    lane_speed_kmh: float = Field(300.0, gt=0, description="lane speed limit; high so it does not bind")
    ban_left_lanes: dict[str, int] = Field(default_factory=lambda: {"truck": 1},
                                           description="vClass -> number of leftmost lanes it may not use")
    from_edge: str | None = Field(None, description="SUMO edge where vehicles depart (default: the "
                                  "built highway's, or the only edge without predecessors)")
    to_edge: str | None = Field(None, description="SUMO edge where they arrive")
    measure_edges: list[str] | None = Field(None, description="edges of the measurement section "
                                            "(default: the built highway's edge, else all)")
    measure_pos: tuple[float, float] | None = Field(None, description="position range (m) along the "
                                                    "measurement edges; default [inflow, inflow + "
                                                    "length] on the built highway")


class Scenario(_Model):
    """A complete SUMO run."""

    network: Network = Field(default_factory=Network)
    classes: list[VehicleClass] = Field(default_factory=lambda: [
        VehicleClass(name="car", vclass="passenger", flow=1680.0, speed_mean_kmh=130.0, speed_std_kmh=15.0),
        VehicleClass(name="truck", vclass="truck", flow=320.0, speed_mean_kmh=88.0, speed_std_kmh=5.0),
    ])
    duration: float = Field(3600.0, gt=0, description="demand period (s)")
    drain: bool = Field(True, description="keep simulating after the demand ends until all vehicles "
                        "arrived (so the last ones cross the measurement section)")
    step_length: float = Field(0.5, gt=0, le=1.0, description="s; <= 0.5 recommended for W99")
    seed: int = 42
    random_numbers: Literal["common", "sumo"] = "common"
    speed_sampling: Literal["random", "stratified"] = Field(
        "random", description="with common random numbers: the standard-normal draws z of a class "
        "are random (a sample, the default) or stratified (the normal's quantiles at (i + 0.5) / n "
        "in random order: the desired speeds' sample mean and spread then match mu and sigma "
        "without sampling error, which the fitter uses for its simulated side)")
    lane_change_duration: float = Field(3.0, ge=0, description="s a lane change takes (SUMO's "
                                        "--lanechange.duration; 0 = instantaneous jumps, which the "
                                        "validator flags as position jumps)")
    fcd_period: float | None = Field(None, gt=0, description="FCD sampling period (s); default every step")
    depart_speed: str = Field("desired", description="SUMO departSpeed")
    depart_lane: str = Field("best", description="SUMO departLane")
    extra_args: list[str] = Field(default_factory=list, description="extra sumo command-line arguments")

    @model_validator(mode="after")
    def _check(self) -> Scenario:
        names = [c.name for c in self.classes]
        if len(set(names)) != len(names):
            raise ValueError(f"class names must be unique: {names}")
        if not self.classes:
            raise ValueError("a scenario needs at least one vehicle class")
        if self.speed_sampling == "stratified" and self.random_numbers != "common":
            raise ValueError('speed_sampling = "stratified" needs random_numbers = "common"')
        return self

    @classmethod
    def from_toml(cls, path: str | Path) -> Scenario:
        p = Path(path)
        try:
            data = tomllib.loads(p.read_text())
        except (OSError, tomllib.TOMLDecodeError) as e:
            raise AveasError(f"cannot read scenario: {e}", path=p) from None
        net = data.get("network", {})
        if isinstance(net.get("map"), str) and not Path(net["map"]).is_absolute():
            net["map"] = str((p.parent / net["map"]).resolve())
        try:
            return cls.model_validate(data)
        except ValueError as e:
            raise AveasError(f"invalid scenario: {e}", path=p) from None

    def cls(self, name: str) -> VehicleClass:
        for c in self.classes:
            if c.name == name:
                return c
        raise KeyError(name)

    def with_desired_speeds(self, speeds: dict[str, tuple[float, float]]) -> Scenario:
        """A copy with (mu, sigma) in km/h replaced per class name."""
        s = self.model_copy(deep=True)
        for c in s.classes:
            if c.name in speeds:
                c.speed_mean_kmh, c.speed_std_kmh = (float(v) for v in speeds[c.name])
        return s

    def with_cf_params(self, name: str, **params: float) -> Scenario:
        s = self.model_copy(deep=True)
        c = s.cls(name)
        c.cf_params = {**c.cf_params, **params}
        return s

    # --- SUMO input files ---------------------------------------------------------------------

    def routes_xml(self, from_edge: str, to_edge: str) -> str:
        lines = ["<routes>"]
        for c in self.classes:
            lines.append("    <vType " + _attrs(c.vtype_attributes()) + "/>")
        common = f'from="{from_edge}" to="{to_edge}" departLane="{self.depart_lane}" ' \
                 f'departSpeed="{self.depart_speed}"'
        if self.random_numbers == "sumo":
            for c in self.classes:
                lines.append(f'    <flow id="{c.name}" type="{c.name}" begin="0" end="{_f(self.duration)}" '
                             f'period="exp({_f(c.flow / 3600.0)})" {common}/>')
        else:
            vehicles = []
            for c, (times, z) in zip(self.classes, self.draws(), strict=True):
                r = c.speed_std_kmh / c.speed_mean_kmh
                for i, (t, zi) in enumerate(zip(times, z, strict=True)):
                    vehicles.append((t, f'    <trip id="{c.name}.{i}" type="{c.name}" depart="{t:.2f}" '
                                        f'speedFactor="{max(1 + zi * r, 0.01):.6f}" {common}/>'))
            vehicles.sort(key=lambda v: v[0])
            lines.extend(v for _, v in vehicles)
        lines.append("</routes>")
        return "\n".join(lines) + "\n"

    def draws(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per class: Poisson arrival times in [0, duration) and standard-normal draws z (|z| <= 4;
        with ``speed_sampling = "stratified"`` the quantiles ``ndtri((i + 0.5) / n)`` in random
        order), from ``seed`` and the class's position (common random numbers)."""
        from scipy.special import ndtri

        out = []
        for k, c in enumerate(self.classes):
            rng = np.random.default_rng([self.seed, k])
            n = int(rng.poisson(c.flow * self.duration / 3600.0 * 1.5) + 20)
            t = np.cumsum(rng.exponential(3600.0 / c.flow, n))
            while t[-1] < self.duration:  # pragma: no cover — 1.5x the expected count suffices
                t = np.concatenate([t, t[-1] + np.cumsum(rng.exponential(3600.0 / c.flow, n))])
            z = rng.standard_normal(len(t))
            z = np.where(np.abs(z) > 4, rng.standard_normal(len(t)).clip(-4, 4), z)
            keep = t < self.duration
            t, z = t[keep], z[keep]
            if self.speed_sampling == "stratified":
                z = ndtri((rng.permutation(len(t)) + 0.5) / max(len(t), 1))
            out.append((t, z))
        return out


def _f(v: float) -> str:
    return f"{float(v):.6g}"


def _attrs(a: dict[str, str]) -> str:
    from xml.sax.saxutils import quoteattr

    return " ".join(f"{k}={quoteattr(str(v))}" for k, v in a.items())
