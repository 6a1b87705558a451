"""The partner's rule family ``partner``."""

from __future__ import annotations

from collections.abc import Iterator

from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hit, rule


@rule("partner.single_participant", "info", "The recording holds one participant",
      "participants.parquet: the recording holds {actual} participant(s)")
def single_participant(ctx: Context) -> Iterator[Hit]:
    """The partner's analyses need interactions, so a recording with fewer than two participants
    is worth a note."""
    n = ctx.num_rows("participants")
    if n is not None and n < 2:
        yield Hit(file="participants.parquet", table="participants", actual=n)
