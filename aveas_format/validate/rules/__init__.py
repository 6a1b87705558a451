"""Rule modules, one per family; importing this package registers every rule."""

from aveas_format.validate.rules import structure  # noqa: F401
