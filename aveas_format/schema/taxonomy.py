"""Category sets of the format's PMFs, in the order the format fixes.

``CLASSES`` is the 13-class participant taxonomy in AVEAS OpenLABEL order (the order of
``classification/uncertainties`` in the AVEAS profile); a ``class_pmf`` struct column has exactly these
float32 fields in this order.
"""

from __future__ import annotations

CLASSES: tuple[str, ...] = (
    "animal",
    "bicycle",
    "bus",
    "car",
    "pedestrian",
    "mobility_device",
    "motorcycle",
    "other",
    "pushable_pullable",
    "railvehicle",
    "trailer",
    "truck",
    "van",
)

#: Classes that drive on lanes and obey vehicle kinematics (used by plausibility rules).
VEHICLE_CLASSES: frozenset[str] = frozenset(
    {"bus", "car", "motorcycle", "railvehicle", "trailer", "truck", "van"}
)
#: Vulnerable road users.
VRU_CLASSES: frozenset[str] = frozenset({"bicycle", "pedestrian", "mobility_device", "pushable_pullable"})

WEATHER: tuple[str, ...] = ("clear", "cloudy", "rain", "snow", "fog")
LIGHTING: tuple[str, ...] = ("day", "twilight", "darkness_lit", "darkness_unlit")
ROAD_SURFACE: tuple[str, ...] = ("dry", "wet", "slippery", "snow_ice")
#: Where the driver's attention is (interior.driver_focus); FORMAT.md names the column but not its
#: categories, so the project fixes them here (docs/format.md records the choice).
DRIVER_FOCUS: tuple[str, ...] = (
    "road_ahead",
    "mirrors",
    "instrument_cluster",
    "infotainment",
    "handheld_device",
    "other",
)

#: Every category set a PMF column may use, by name.
CATEGORY_SETS: dict[str, tuple[str, ...]] = {
    "class": CLASSES,
    "weather": WEATHER,
    "lighting": LIGHTING,
    "road_surface": ROAD_SURFACE,
    "driver_focus": DRIVER_FOCUS,
}

#: Tolerance of PMF normalisation (FORMAT.md 2: fields sum to 1 within 1e-3).
PMF_TOLERANCE = 1e-3
