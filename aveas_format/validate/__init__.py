"""Validation: a rule registry, a runner and renderers (text, JSON).

``aveas_format.validate(path_or_recording, ...)`` is the API: this package module is callable and
forwards to :func:`aveas_format.validate.runner.validate`, so that the function and the package can
share the name without one hiding the other.
"""

import sys
import types

from aveas_format.validate.registry import REGISTRY, Hit, Hits, Rule, load_rules, rule, select_rules
from aveas_format.validate.report import (
    Finding,
    Location,
    Report,
    RuleResult,
    Severity,
    ToolFailure,
)
from aveas_format.validate.runner import validate


class _CallableModule(types.ModuleType):
    def __call__(self, *args, **kwargs) -> Report:  # type: ignore[no-untyped-def]
        return validate(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule

__all__ = [
    "REGISTRY", "Finding", "Hit", "Hits", "Location", "Report", "Rule", "RuleResult", "Severity",
    "ToolFailure", "load_rules", "rule", "select_rules", "validate",
]
