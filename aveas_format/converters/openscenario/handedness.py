"""The coordinate convention of a scenario file: OpenSCENARIO's right-handed frame, or CARLA's.

OpenSCENARIO and OpenDRIVE use a right-handed frame (x east, y north, heading counter-clockwise).
CARLA's world is left-handed (y mirrored, yaw clockwise), and CARLA's scenario_runner reads a file
whose ``FileHeader`` ``description`` starts with ``CARLA:`` as written in CARLA's frame (its
``use_carla_coordinate_system``); any other file it mirrors into CARLA's frame itself. Such a file,
read as the standard says, lands mirrored across the x axis: on no road of its map.

:func:`handedness` decides the convention (option ``handedness``: ``auto`` detects it from the
header, ``left``/``right`` force one); :func:`mirror` turns what a left-handed file states in
world terms into the right-handed frame, in place: ``WorldPosition`` ``y`` and ``h``, the lateral
``dy`` of ``RelativeWorldPosition``/``RelativeObjectPosition``, every ``Orientation`` ``h``
(absolute or relative: a yaw of the mirrored frame), clothoid curvatures and heading offsets, and
the lateral offset of a ``BoundingBox`` centre. Road and lane positions (``roadId``, ``s``, ``t``,
``laneId``, ``offset``) are in the map's own terms and stay as they are; so do geographic
positions.
"""

from __future__ import annotations

#: the FileHeader description prefix of files written in CARLA's left-handed frame
CARLA_PREFIX = "CARLA:"

#: per element: its attributes that change sign in the mirrored frame
_MIRRORED = {
    "WorldPosition": ("y", "h"),
    "RelativeWorldPosition": ("dy",),
    "RelativeObjectPosition": ("dy",),
    "Orientation": ("h",),
    "Clothoid": ("curvature", "curvaturePrime", "curvatureDot"),
    "ClothoidSplineSegment": ("curvatureStart", "curvatureEnd", "hOffset"),
    "Center": ("y",),
}


def handedness(root, option: str) -> tuple[str, str]:
    """``(left | right, why)``: the frame the file's world positions are in."""
    if option in ("left", "right"):
        return option, f"option handedness={option}"
    hdr = root.find("FileHeader")
    desc = (hdr.get("description") or "").strip() if hdr is not None else ""
    if desc.upper().startswith(CARLA_PREFIX):
        return "left", (f"FileHeader description {desc[:40]!r} starts with {CARLA_PREFIX!r} "
                        "(CARLA's left-handed frame, as scenario_runner reads it)")
    return "right", "OpenSCENARIO's right-handed frame (the FileHeader names no other)"


def mirror(el) -> None:
    """Mirror the world terms under ``el`` (and ``el`` itself) from a left-handed frame into the
    right-handed one, in place (module doc). Values that are no numbers are left for the reader
    of the element to report."""
    for node in el.iter(*_MIRRORED):
        if node.tag == "Orientation" and node.getparent() is not None \
                and node.getparent().tag == "GeoPosition":
            continue  # a geographic heading (from north): not in the file's x/y frame
        if node.tag == "Center" and (node.getparent() is None
                                     or node.getparent().tag != "BoundingBox"):
            continue
        for name in _MIRRORED[node.tag]:
            v = node.get(name)
            if v is None:
                continue
            try:
                f = float(v)
            except ValueError:
                continue
            node.set(name, repr(-f) if f else v)
