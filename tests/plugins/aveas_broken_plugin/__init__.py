"""A plugin whose import fails: it needs a package that is not installed."""

from __future__ import annotations

import aveas_partner_dependency_that_is_not_installed  # noqa: F401
