"""Source labels -> the 13 classes, and which labels are no traffic participant at all.

Datasets label more than road users. A label is one of three kinds:

- ``road_user``: a traffic participant, imported with its class;
- ``not_road_user``: a real object that takes no part in traffic (a barrier, a traffic sign, a
  plane on an airfield, a person sitting on a bench, a reflection of a pedestrian in a shop window,
  an occluder). Converters skip these by default and say how many they skipped; their option
  ``keep_non_road_users`` imports them (with the class given here, mostly ``other``);
- ``ignore``: an annotation artefact, no object (KITTI's ``DontCare`` regions with sentinel sizes,
  a crowd region, ``noise``). Always skipped, with a note.

:data:`LABELS` is the one table of the label vocabularies of the common datasets and their
converters (names normalised: lower case, ``-``/space -> ``_``). Hierarchical names (nuScenes
``vehicle.bus.rigid``, ``movable_object.barrier``; OpenLABEL ``vehicle/car``) are looked up whole,
then by their last and first component. Unknown names are road users of class ``other``.

| source | road users | not road users | ignore |
|---|---|---|---|
| KITTI (object, tracking) | Car, Van, Truck, Pedestrian, Cyclist, Tram, Misc (other) | Person_sitting | DontCare |
| nuScenes | vehicle.*, human.pedestrian.*, animal, movable_object.pushable_pullable | movable_object.barrier / trafficcone / debris, static_object.bicycle_rack | noise |
| Waymo Open | TYPE_VEHICLE, TYPE_PEDESTRIAN, TYPE_CYCLIST, TYPE_UNKNOWN (other) | TYPE_SIGN | |
| A2D2 | Car, Pedestrian, Truck, VanSUV, Cyclist, Bus, MotorBiker, Bicycle, UtilityVehicle, Motorcycle, CaravanTransporter, Animal, Trailer, EmergencyVehicle | | |
| Argoverse 2 | REGULAR_VEHICLE, LARGE_VEHICLE, BOX_TRUCK, TRUCK_CAB, BUS, SCHOOL_BUS, ARTICULATED_BUS, VEHICULAR_TRAILER, PEDESTRIAN, OFFICIAL_SIGNALER, BICYCLE, BICYCLIST, MOTORCYCLE, MOTORCYCLIST, WHEELED_DEVICE, WHEELED_RIDER, WHEELCHAIR, STROLLER, DOG, ANIMAL, RAILED_VEHICLE | BOLLARD, CONSTRUCTION_CONE, CONSTRUCTION_BARREL, SIGN, STOP_SIGN, MOBILE_PEDESTRIAN_SIGN, MESSAGE_BOARD_TRAILER, TRAFFIC_LIGHT_TRAILER | |
| TUM Traffic (A9) | CAR, TRUCK, TRAILER, VAN, MOTORCYCLE, BUS, PEDESTRIAN, BICYCLE, EMERGENCY_VEHICLE, OTHER | | |
| MOTChallenge (MOT16/17/20 ground truth, class ids 1-13) | 1 pedestrian, 3 car, 4 bicycle, 5 motorbike, 6 non motorized vehicle | 2 person on vehicle (the rider of a labelled vehicle), 7 static person, 8 distractor, 9 occluder, 10 occluder on the ground, 11 occluder full, 12 reflection | 13 crowd |
| DOTA v1.0/1.5/2.0 | small-vehicle (car), large-vehicle (truck) | plane, ship, storage-tank, baseball-diamond, tennis-court, basketball-court, ground-track-field, harbor, bridge, helicopter, roundabout, soccer-ball-field, swimming-pool, container-crane, airport, helipad | |
| Autoware ObjectClassification | CAR, TRUCK, BUS, TRAILER, MOTORCYCLE, BICYCLE, PEDESTRIAN, ANIMAL, UNKNOWN (other) | HAZARD, OVER_DRIVABLE, UNDER_DRIVABLE | |
| derived_object_msgs Object | PEDESTRIAN, BIKE, CAR, TRUCK, MOTORCYCLE, OTHER_VEHICLE, UNKNOWN* (other) | BARRIER, SIGN | |
| OSDaR23 / OSDaR26 (rail, OpenLABEL) | person, train, wagons/wagon (railvehicle), road_vehicle (car; its box's ``type`` attribute van, truck, bus, constructionVehicle, trailer: that class), bicycle, motorcycle, scooter, wheelchair, pram, animal | static infrastructure: track, transition, switch, catenary_pole, signal_pole, signal, signal_bridge, buffer_stop; drag_shoe, personal_item, flame, smoke | crowd, group_of_bicycles, group_of_animals, ignore_tracks |
| nuScenes lidarseg (first part) | | flat.*, static.* (surfaces, buildings, vegetation) | noise |

Static infrastructure (rail tracks, switches, poles, signals, buffer stops; traffic lights and signs
of road datasets) is no participant: the format keeps the map for it. Its labels jitter from frame to
frame, which a participant's derivations would read as motion (hundreds of m/s^2). A note names it
apart from the other labels that are no road user.

A participant's label decides; a sanity rule on sizes (:func:`implausible_size`) catches sentinel
values (KITTI's -1000) whatever the label says.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

import numpy as np

ROAD_USER, NOT_ROAD_USER, IGNORE = "road_user", "not_road_user", "ignore"

#: class synonyms of road users (the 13 class names map to themselves)
CLASS_SYNONYMS: dict[str, str] = {
    "person": "pedestrian", "ped": "pedestrian", "walker": "pedestrian", "child": "pedestrian",
    "adult": "pedestrian", "human": "pedestrian", "police_officer": "pedestrian",
    "construction_worker": "pedestrian", "official_signaler": "pedestrian",
    "bike": "bicycle", "cyclist": "bicycle", "bicyclist": "bicycle",
    "motorbike": "motorcycle", "motorcyclist": "motorcycle", "moped": "motorcycle",
    "motorbiker": "motorcycle",
    "scooter": "mobility_device", "e_scooter": "mobility_device", "wheelchair": "mobility_device",
    "personal_mobility": "mobility_device", "wheeled_device": "mobility_device",
    "wheeled_rider": "mobility_device",
    "stroller": "pushable_pullable", "pram": "pushable_pullable",
    "non_motorized_vehicle": "pushable_pullable",
    "passenger_car": "car", "vehicle": "car", "emergency_vehicle": "car", "taxi": "car",
    "regular_vehicle": "car", "type_vehicle": "car", "egocar": "car", "ego": "car",
    "ego_vehicle": "car", "sedan": "car", "suv": "car", "police_car": "car", "emergency": "car",
    "police": "car", "ambulance": "van", "small_vehicle": "car",
    "pickup": "van", "vansuv": "van", "utilityvehicle": "van", "utility_vehicle": "van",
    "lorry": "truck", "heavy_truck": "truck", "semi": "truck", "tractor": "truck",
    "large_vehicle": "truck", "box_truck": "truck", "truck_cab": "truck", "construction": "truck",
    "caravantransporter": "truck", "caravan_transporter": "truck",
    "vehicular_trailer": "trailer",
    "coach": "bus", "bendy": "bus", "rigid": "bus", "school_bus": "bus", "articulated_bus": "bus",
    "tram": "railvehicle", "train": "railvehicle", "railed_vehicle": "railvehicle",
    "wagons": "railvehicle", "wagon": "railvehicle", "locomotive": "railvehicle",
    "rail_vehicle": "railvehicle", "road_vehicle": "car", "constructionvehicle": "truck",
    "construction_vehicle": "truck",
    "dog": "animal", "deer": "animal",
    "type_pedestrian": "pedestrian", "type_cyclist": "bicycle",
    "unknown": "other", "misc": "other", "type_unknown": "other", "other_vehicle": "other",
    "unknown_small": "other", "unknown_medium": "other", "unknown_big": "other",
}

#: not road users: name -> class when kept (``keep_non_road_users``)
NOT_ROAD_USERS: dict[str, str] = {
    # persons that are no traffic participant (MOT, KITTI)
    "static_person": "pedestrian", "person_sitting": "pedestrian", "person_on_vehicle": "pedestrian",
    "distractor": "other", "reflection": "other", "occluder": "other",
    "occluder_on_the_ground": "other", "occluder_on_ground": "other", "occluder_full": "other",
    # street furniture and obstacles (nuScenes, Waymo, Argoverse 2, Autoware, derived_object_msgs)
    "barrier": "other", "trafficcone": "other", "traffic_cone": "other", "debris": "other",
    "bicycle_rack": "other", "sign": "other", "type_sign": "other", "traffic_sign": "other",
    "stop_sign": "other", "traffic_light": "other", "pole": "other", "bollard": "other",
    "construction_cone": "other", "construction_barrel": "other",
    "mobile_pedestrian_sign": "other", "message_board_trailer": "trailer",
    "traffic_light_trailer": "trailer", "hazard": "other", "over_drivable": "other",
    "under_drivable": "other",
    # rail (OSDaR23/26) and other objects on a scene that take no part in traffic
    "drag_shoe": "other", "personal_item": "other", "flame": "other", "smoke": "other",
    "movable_object": "other", "static_object": "other", "static": "other", "flat": "other",
    # DOTA (aerial images): everything but small/large vehicles
    "plane": "other", "ship": "other", "storage_tank": "other", "baseball_diamond": "other",
    "tennis_court": "other", "basketball_court": "other", "ground_track_field": "other",
    "harbor": "other", "bridge": "other", "helicopter": "other", "roundabout": "other",
    "soccer_ball_field": "other", "swimming_pool": "other", "container_crane": "other",
    "airport": "other", "helipad": "other",
}

#: static infrastructure: not road users either (the map's, never a participant); named apart in notes
STATIC_INFRASTRUCTURE: dict[str, str] = {
    "track": "other", "rail": "other", "transition": "other", "switch": "other", "catenary_pole": "other",
    "signal_pole": "other", "signal": "other", "signal_bridge": "other", "buffer_stop": "other",
    "railway_signal": "other", "level_crossing": "other", "platform": "other",
    "traffic_light": "other", "traffic_sign": "other", "sign": "other", "type_sign": "other",
    "stop_sign": "other", "pole": "other",
}
NOT_ROAD_USERS.update(STATIC_INFRASTRUCTURE)

#: annotation artefacts: never imported
IGNORED: frozenset[str] = frozenset({
    "dontcare", "dont_care", "don't_care", "ignore", "ignored", "ignore_region", "noise", "void",
    "unlabeled", "unlabelled", "crowd", "group_of_bicycles", "group_of_animals", "group_of_people",
    "ignore_tracks",
})

#: MOTChallenge ground-truth class ids (MOT16/17; 13 = crowd in MOT20)
MOT_CLASS_IDS: dict[int, str] = {
    1: "pedestrian", 2: "person_on_vehicle", 3: "car", 4: "bicycle", 5: "motorbike",
    6: "non_motorized_vehicle", 7: "static_person", 8: "distractor", 9: "occluder",
    10: "occluder_on_the_ground", 11: "occluder_full", 12: "reflection", 13: "crowd",
}


def normalise(name: object) -> str:
    return str(name).strip().lower().replace("-", "_").replace(" ", "_")


def label_kind(name: object, extra: dict[str, str] | None = None) -> tuple[str, str]:
    """``(class, kind)`` of a source label: ``extra`` (a converter's ``class_map``: source name ->
    one of the 13 classes) first, which makes the label a road user; then :data:`LABELS`."""
    from aveas_format.schema.taxonomy import CLASSES

    raw = str(name)
    if extra:
        for k in (raw, normalise(raw)):
            if k in extra:
                return extra[k], ROAD_USER
    key = normalise(raw)
    parts = [p for p in key.replace("/", ".").split(".") if p]
    for k in dict.fromkeys([key, *(parts[-1:] + parts[:1] if len(parts) > 1 else [])]):
        if k in IGNORED:
            return "other", IGNORE
        if k in NOT_ROAD_USERS:
            return NOT_ROAD_USERS[k], NOT_ROAD_USER
        if k in CLASSES:
            return k, ROAD_USER
        if k in CLASS_SYNONYMS:
            return CLASS_SYNONYMS[k], ROAD_USER
    if len(parts) > 1 and parts[0] in ("human", "animal"):  # nuScenes human.pedestrian.*
        return ("pedestrian" if parts[0] == "human" else "animal"), ROAD_USER
    return "other", ROAD_USER


#: generic labels whose subtype names the class: a box's text attribute ``type`` (OSDaR's
#: ``road_vehicle`` of type car, van, truck, bus, constructionVehicle, trailer)
SUBTYPED: frozenset[str] = frozenset({"road_vehicle", "vehicle"})


def refine(name: object, subtype: object = None) -> str:
    """The class of a road user's label ``name`` (:func:`label_kind`), made specific by its
    ``subtype`` where the label is generic (:data:`SUBTYPED`) and the subtype names a road user's
    class other than ``other``."""
    cls = label_kind(name)[0]
    if subtype is not None and normalise(name) in SUBTYPED:
        sub, kind = label_kind(subtype)
        if kind == ROAD_USER and sub != "other":
            return sub
    return cls


def is_infrastructure(name: object) -> bool:
    """Whether a label names static infrastructure (:data:`STATIC_INFRASTRUCTURE`; hierarchical
    names by their last or first part)."""
    key = normalise(name)
    parts = [p for p in key.replace("/", ".").split(".") if p]
    return any(k in STATIC_INFRASTRUCTURE for k in (key, *parts[-1:], *parts[:1]))


def class_of(name: str, extra: dict[str, str] | None = None) -> str:
    """One of the 13 classes for a class name of a source (case- and separator-insensitive);
    ``extra`` maps source names first; unknown names become ``other``. Whether the label is a road
    user at all: :func:`label_kind`."""
    return label_kind(name, extra)[0]


def class_pmf(labels: Sequence[str] | np.ndarray, confidence: float = 1.0) -> np.ndarray:
    """(n, 13) PMF matrix for hard class labels: ``confidence`` on the label, the rest spread evenly
    over the other 12 classes (``confidence`` = 1: one-hot)."""
    from aveas_format.schema.pmf import one_hot

    oh = one_hot(np.asarray(labels, dtype=object), "class").astype(np.float64)
    k = oh.shape[1]
    pm = oh * confidence + (1.0 - oh) * (1.0 - confidence) / (k - 1)
    return pm.astype(np.float32)


class LabelFilter:
    """Decides per label whether a participant is imported, and counts what it skipped.

    ``keep_non_road_users`` keeps the ``not_road_user`` labels (never the ``ignore`` ones)."""

    def __init__(self, keep_non_road_users: bool = False, extra: dict[str, str] | None = None):
        self.keep_nru = keep_non_road_users
        self.extra = extra
        self.skipped: Counter = Counter()
        self.kept_nru: Counter = Counter()

    def __call__(self, name: object) -> str | None:
        """The class to import the label as, or None (skipped; counted)."""
        cls, kind = label_kind(name, self.extra)
        if kind == IGNORE or (kind == NOT_ROAD_USER and not self.keep_nru):
            self.skipped[(str(name), kind)] += 1
            return None
        if kind == NOT_ROAD_USER:
            self.kept_nru[str(name)] += 1
        return cls

    def note(self, what: str = "participants") -> str | None:
        """One line for a warning: how many ``what`` were skipped and why, or None."""
        if not self.skipped:
            return None
        parts = []
        for kind, infra, why in ((NOT_ROAD_USER, True, "static infrastructure: the map's, no participant"),
                                 (NOT_ROAD_USER, False, "no road user"),
                                 (IGNORE, False, "ignore-type label: an annotation artefact, no object")):
            got = {n: c for (n, k), c in self.skipped.items() if k == kind and infra == is_infrastructure(n)}
            if got:
                parts.append(", ".join(f"{c} {n}" for n, c in sorted(got.items())) + f" ({why})")
        total = sum(self.skipped.values())
        keep = ("; option keep_non_road_users=true imports the ones that are no road user"
                if any(k == NOT_ROAD_USER for _, k in self.skipped) else "")
        return f"skipped {total} {what}: {'; '.join(parts)}{keep}"


#: the largest plausible size of any participant's box side (m): a long train
MAX_SIZE_M = 400.0


def implausible_size(size: np.ndarray) -> np.ndarray:
    """Per row of ``size`` (n, 2 or 3: length, width[, height]): True where a value is a sentinel
    or impossible — not finite, <= 0 (KITTI's -1000, a -1 for "unknown") or above
    :data:`MAX_SIZE_M`. A missing height (NaN, or 0 as the AVEAS profile writes an unknown one in
    the third column) is allowed; a negative one is not."""
    s = np.asarray(size, np.float64).reshape(len(size), -1)
    lw = s[:, :2]
    bad = ~np.isfinite(lw).all(axis=1) | (lw <= 0).any(axis=1) | (lw > MAX_SIZE_M).any(axis=1)
    if s.shape[1] > 2:
        h = s[:, 2]
        bad |= (h < 0) | (h > MAX_SIZE_M)
    return bad


#: an assumed size per class, where a source states none (or 0): ``(length, width, height)`` m
#: and its 1-sigma ``(length_std, width_std, height_std)`` m, large on purpose: the spread of the
#: class in traffic (a car 3.6-5.3 m long, a truck a 7.5 t box van to a 16.5 m articulated
#: lorry...), so that no measure treats an assumed size as a measured one
CLASS_SIZE: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "car": ((4.5, 1.8, 1.5), (0.6, 0.15, 0.2)),
    "van": ((5.5, 2.0, 2.2), (0.8, 0.15, 0.4)),
    "truck": ((12.0, 2.5, 3.5), (4.0, 0.1, 0.4)),
    "bus": ((12.0, 2.55, 3.2), (2.5, 0.05, 0.3)),
    "trailer": ((8.0, 2.5, 3.0), (3.0, 0.1, 0.8)),
    "motorcycle": ((2.2, 0.8, 1.4), (0.3, 0.15, 0.2)),
    "bicycle": ((1.8, 0.6, 1.7), (0.2, 0.1, 0.2)),
    "pedestrian": ((0.5, 0.6, 1.75), (0.15, 0.15, 0.15)),
    "mobility_device": ((1.0, 0.7, 1.4), (0.4, 0.2, 0.3)),
    "pushable_pullable": ((1.0, 0.6, 1.0), (0.4, 0.2, 0.3)),
    "animal": ((1.5, 0.6, 1.2), (0.8, 0.3, 0.5)),
    "railvehicle": ((30.0, 2.65, 3.5), (10.0, 0.2, 0.5)),
    "other": ((2.0, 1.0, 1.5), (1.5, 0.7, 0.8)),
}
