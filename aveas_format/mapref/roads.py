"""OpenDRIVE road coordinates of a states table.

Converters produce positions in the local frame; this module adds what the format requires on top
(FORMAT.md 5): ``road_id``, ``lane_id``, ``road_s``, ``road_t``, ``lane_offset`` through the map
(``lon``/``lat`` come from :mod:`aveas_format.crs`). Where a point lies on several roads
(junctions), the trajectory-aware projection chooses by continuity with the participant's previous
sample and agreement with its heading.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa


def road_coordinates(net, participant_id: np.ndarray, time: np.ndarray, x: np.ndarray,
                     y: np.ndarray, heading: np.ndarray | None = None) -> dict[str, pa.Array]:
    """Road coordinates of every sample as Arrow arrays (nulls where off-map).

    Rows must be sorted by (participant_id, time).
    """
    proj = net.world_to_road_track(np.asarray(x, np.float64), np.asarray(y, np.float64),
                                   None if heading is None else np.asarray(heading, np.float64),
                                   time=np.asarray(time, np.float64),
                                   track_id=np.asarray(participant_id))
    on = np.asarray(proj.n_candidates) > 0
    off = ~on
    road = np.where(on, proj.road_id, None).astype(object)
    return {
        "road_id": pa.array(road, pa.string()).dictionary_encode(),
        "lane_id": pa.array(np.asarray(proj.lane_id, np.int16), pa.int16(), mask=off),
        "road_s": pa.array(np.asarray(proj.s, np.float64), pa.float64(), mask=off),
        "road_t": pa.array(np.asarray(proj.t, np.float64), pa.float64(), mask=off),
        "lane_offset": pa.array(np.asarray(proj.lane_offset, np.float64), pa.float64(), mask=off),
    }

