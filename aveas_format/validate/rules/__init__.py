"""Rule modules, one per family; importing this package registers every rule."""

from aveas_format.validate.rules import structure  # noqa: F401
from aveas_format.validate.rules import participants  # noqa: F401
from aveas_format.validate.rules import time  # noqa: F401
from aveas_format.validate.rules import kinematics  # noqa: F401
from aveas_format.validate.rules import uncertainty  # noqa: F401
from aveas_format.validate.rules import geo  # noqa: F401
from aveas_format.validate.rules import map  # noqa: F401
from aveas_format.validate.rules import unobserved  # noqa: F401
from aveas_format.validate.rules import interactions  # noqa: F401
from aveas_format.validate.rules import metadata  # noqa: F401
