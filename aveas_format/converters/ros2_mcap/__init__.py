"""ROS 2 recordings of a road vehicle in MCAP -> recording (the ``ros2-mcap`` importer).

The converter's documentation (what is read from which message type, the frames, the uncertainty
propagation) is the docstring of :mod:`.converter`, which ``docs/converters.md`` shows. What lives
where, from the bottom up:

- ``options``: :class:`Ros2McapOptions` and the message-type tables (supported types, preferred
  topics, class labels).
- ``decode``: opening the MCAP files and decoding their CDR messages (``_channels``; ``_Decoders``:
  rosbags' generated deserialisers, mcap-ros2-support's decoder as the fallback; the errors a
  corrupt file raises).
- ``tree``: the transform samples (``_Edges``) and the transform tree (``_Tree``: interpolated
  lookups chained to the map frame, with the ego's pose covariance).
- ``messages``: the per-message readers (object arrays, odometry, NavSatFix, tf) -> flat rows.
- ``read``: which topics to read and the one pass over their messages (``_read``).
- ``frames``: the frame and covariance maths (``_cov3``, ``_to_map``, ``_twist_to_map``,
  ``_apply_offset``).
- ``converter``: ``convert_ros2_mcap`` (registered as ``ros2-mcap``) and its steps: the ego track,
  the objects in the map frame, the states, the participants.

Importing this package registers the converter (once: the registry imports the package, the
package imports ``converter``).
"""

from aveas_format.converters.ros2_mcap.converter import convert_ros2_mcap
from aveas_format.converters.ros2_mcap.options import Ros2McapOptions

__all__ = ["Ros2McapOptions", "convert_ros2_mcap"]
