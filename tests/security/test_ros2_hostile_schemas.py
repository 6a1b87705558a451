"""Hostile message definitions in a ROS 2 MCAP (the schema text is the submitter's): recursive,
very deep, absurd arrays, garbage. The CDR decoders (rosbags, then mcap-ros2-support) must end in
a located one-line error, quickly."""

from __future__ import annotations

import time

import pytest
from helpers_common import STRAIGHT_MAP

from aveas_format.converters import convert
from aveas_format.errors import AveasError

SEP = "=" * 80
SCHEMAS = {
    "self_reference": f"pkg/Loop next\n{SEP}\nMSG: pkg/Loop\npkg/Loop next\n",
    "deep_chain": "\n".join(["pkg/T1 a"] + [f"{SEP}\nMSG: pkg/T{i}\npkg/T{i + 1} a" for i in range(1, 3000)]
                            + [f"{SEP}\nMSG: pkg/T3000\nint32 x"]),
    "huge_fixed_array": "int32[4294967295] x\n",
    "garbage": "\x00\x01 {{{{ ))) ===\n" * 100,
}


@pytest.mark.parametrize("name", list(SCHEMAS))
def test_hostile_schema_is_a_located_error(name, tmp_path):
    from mcap.writer import Writer

    p = tmp_path / f"{name}.mcap"
    with open(p, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("nav_msgs/msg/Odometry", "ros2msg", SCHEMAS[name].encode())
        cid = w.register_channel("/odom", "cdr", sid)
        w.add_message(cid, 1, b"\x00\x01\x00\x00" + b"\x00" * 64, 1)
        w.finish()
    t0 = time.perf_counter()
    with pytest.raises(AveasError, match=r"topic /odom message 0: cannot decode") as e:
        convert("ros2-mcap", [p], map_source=STRAIGHT_MAP)
    assert time.perf_counter() - t0 < 10
    assert "\n" not in str(e.value) and str(p) in str(e.value)
