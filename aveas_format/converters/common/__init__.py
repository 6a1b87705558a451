"""What every converter shares: a converter reads and maps its source, this package does the rest.

The shared step (a partner's converter uses these names from here)::

    from aveas_format.converters.common import Boxes, Rows, Sensor, read_table, to_recording

    t = read_table(path, required=("id", "time", "x", "y"), numeric=("time", "x", "y"))
    pid, ids = factorize(t.column("id"))
    boxes = Boxes(pid, column_numpy(t, "time"), column_numpy(t, "x"), column_numpy(t, "y"),
                  source_ids=ids, rows=Rows([path], place=np.arange(t.num_rows) + 2))
    return to_recording(boxes, Sensor(method="aerial", platform="drone"), converter="NAME",
                        inputs=[path], options=options, map_bytes=load_map_bytes(map_source),
                        participants={"class": ["car"] * len(ids), "length": ..., "width": ...})

Modules, one concern each:

- ``boxes``: the step's input: :class:`Boxes` (box batches as columns; the duplicates policy;
  the one sort by participant and time), :class:`Rows` (where each box came from), the sensor
  description :class:`Sensor` with its coverage (:class:`Footprint`, :class:`Range`) and size
  aggregation (:class:`Sizes`).
- ``assemble``: the step itself, :func:`to_recording` (velocities, per-participant aggregation,
  nulls, coverage, recording.json, the hand-off to map-referencing); for a time-major source read
  in bounded memory, ``bounded_states`` and ``write_by_buckets`` (the states made and written a
  bucket of whole participants at a time).
- ``tables``: reading CSV/Parquet with located errors; source ids -> participant codes.
- ``timestamps``: timestamps whose unit and epoch a format leaves open; ISO 8601; UTC text.
- ``geometry``: reference points, angle conventions, quaternions and 2D rotations, covariances,
  box corners, a projected source CRS -> the map's frame.
- ``coverage``: the rows of the ``unobserved`` table: outside a footprint, a range, a field of
  view; ground shadows.
- ``provenance``: SHA-256 of the inputs (in the background) and the ``source`` block.
- ``companion``: the map an exporter writes next to its output.
- ``fastpath``: how a fast decoder refuses what it does not take (:class:`FastPathUnsupported`)
  and which path read a file (logged; ``--verbose``).
"""

from aveas_format.converters.common.assemble import to_recording
from aveas_format.converters.common.boxes import Boxes, Footprint, Range, Rows, Sensor, Sizes
from aveas_format.converters.common.tables import factorize, read_table

__all__ = ["Boxes", "Footprint", "Range", "Rows", "Sensor", "Sizes", "factorize", "read_table",
           "to_recording"]
