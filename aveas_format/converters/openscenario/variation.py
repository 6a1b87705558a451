"""Logical scenarios: OpenSCENARIO 1.x parameter variation files.

A parameter variation file has no storyboard of its own: under its root it holds a
``ParameterValueDistribution`` naming a template scenario (``ScenarioFile filepath``, relative to
the file) and distributions of the template's global parameters. Such a file describes many
concrete scenarios, not one: the import says so (:func:`logical_scenario_error`, naming the
template) unless one concrete variation is asked for (``-O variation=N``).

The concrete variations are those of the ``Deterministic`` distributions:

- ``DeterministicSingleParameterDistribution``: one parameter over a ``DistributionSet`` (its
  ``Element`` values) or a ``DistributionRange`` (``Range lowerLimit..upperLimit`` in steps of
  ``stepWidth``, both limits included);
- ``DeterministicMultiParameterDistribution/ValueSetDistribution``: a list of
  ``ParameterValueSet`` (several parameters assigned together).

Several of them combine as every combination (the cartesian product), in document order with the
last varying fastest: variation ``N`` is the N-th of the nested loops. ``Stochastic``
distributions are not expanded (they name no concrete values): their parameters keep the
template's declared values, and the import says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from aveas_format.errors import FormatError
from aveas_format.numeric import fmt_num

#: the most values one DistributionRange may have (a step far too small for its range is an error)
MAX_RANGE_VALUES = 100_000


@dataclass
class Variations:
    """The concrete variations of a parameter variation file: the template it varies, one list of
    parameter assignments per deterministic distribution (combined as every combination) and the
    parameters of its stochastic distributions (not expanded)."""

    path: Path
    template: Path
    factors: list[list[dict[str, str]]] = field(default_factory=list)
    stochastic: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return math.prod(len(f) for f in self.factors)

    def __getitem__(self, n: int) -> dict[str, str]:
        """The parameter values of variation ``n`` (0-based; the last factor varies fastest)."""
        total = len(self)
        if not 0 <= n < total:
            raise FormatError(f"variation {n}: the file has {total} concrete variation"
                              f"{'s' if total != 1 else ''} (variation=0..{total - 1})",
                              path=self.path)
        out: dict[str, str] = {}
        for f in reversed(self.factors):
            n, k = divmod(n, len(f))
            out.update(f[k])
        return out


def is_logical(root) -> bool:
    """Whether an ``<OpenSCENARIO>`` root is a parameter variation file (no storyboard)."""
    return root.find("ParameterValueDistribution") is not None and root.find("Storyboard") is None


def template_of(root, path: Path) -> tuple[str | None, Path | None]:
    """The ``ScenarioFile filepath`` a parameter variation file names, and where it is (relative
    to the file); ``(None, None)`` where it names none."""
    sf = root.find("ParameterValueDistribution/ScenarioFile")
    name = sf.get("filepath") if sf is not None else None
    return (name, path.parent / name) if name else (None, None)


def logical_scenario_error(root, path: Path) -> FormatError:
    """The error of importing a parameter variation file as a scenario: what it is, the template
    it points at, how to convert the template or one concrete variation."""
    name, template = template_of(root, path)
    if name is None:
        return FormatError("a logical scenario (an OpenSCENARIO parameter variation file: a "
                           "ParameterValueDistribution), not a concrete one, and it names no "
                           "template scenario (no ScenarioFile filepath)", path=path)
    where = "" if template.is_file() else f" (not found at {template})"
    try:
        count = len(variations(root, path, check_template=False))
        many = (f"; or one of its {count} concrete variation{'s' if count != 1 else ''} with "
                f"-O variation=N (N = 0..{count - 1})")
    except FormatError as e:
        many = f"; its variations cannot be expanded: {e.message}"
    return FormatError(f"a logical scenario (an OpenSCENARIO parameter variation file: a "
                       f"ParameterValueDistribution over the template scenario {name!r}{where}), "
                       f"not a concrete one: convert the template {template}{many}", path=path)


def variations(root, path: Path, check_template: bool = True) -> Variations:
    """The concrete variations of a parameter variation file (module doc); an error naming the
    XML line for a distribution that cannot be expanded."""
    name, template = template_of(root, path)
    if name is None:
        raise logical_scenario_error(root, path)
    if check_template and not template.is_file():
        raise FormatError(f"the template scenario {name!r} of the parameter variation is not at "
                          f"{template}", path=path)
    out = Variations(path, template)
    pvd = root.find("ParameterValueDistribution")
    for det in pvd.iterfind("Deterministic"):
        for d in det:
            if not isinstance(d.tag, str):
                continue
            if d.tag == "DeterministicSingleParameterDistribution":
                pname = d.get("parameterName")
                out.factors.append([{pname: v} for v in _single(d, path)])
            elif d.tag == "DeterministicMultiParameterDistribution":
                sets = [{a.get("parameterRef"): a.get("value", "")
                         for a in s.iterfind("ParameterAssignment")}
                        for s in d.iterfind("ValueSetDistribution/ParameterValueSet")]
                if not sets:
                    raise FormatError("<DeterministicMultiParameterDistribution> without a "
                                      "ParameterValueSet", path=path, line=d.sourceline)
                out.factors.append(sets)
    for st in pvd.iterfind("Stochastic/StochasticDistribution"):
        out.stochastic.append(st.get("parameterName") or "?")
    return out


def _single(d, path: Path) -> list[str]:
    """The values of one ``DeterministicSingleParameterDistribution``."""
    if not d.get("parameterName"):
        raise FormatError("<DeterministicSingleParameterDistribution> without parameterName",
                          path=path, line=d.sourceline)
    dset, drange = d.find("DistributionSet"), d.find("DistributionRange")
    if dset is not None:
        values = [e.get("value", "") for e in dset.iterfind("Element")]
        if not values:
            raise FormatError(f"parameter {d.get('parameterName')!r}: <DistributionSet> without "
                              "an Element", path=path, line=dset.sourceline)
        return values
    if drange is not None:
        rng = drange.find("Range")
        try:
            step = float(drange.get("stepWidth", ""))
            lo, hi = float(rng.get("lowerLimit", "")), float(rng.get("upperLimit", ""))
        except (AttributeError, ValueError):
            raise FormatError(f"parameter {d.get('parameterName')!r}: <DistributionRange> needs "
                              "a number stepWidth and a <Range lowerLimit upperLimit>", path=path,
                              line=drange.sourceline) from None
        if not (step > 0 and math.isfinite(step) and math.isfinite(lo) and math.isfinite(hi)
                and hi >= lo):
            raise FormatError(f"parameter {d.get('parameterName')!r}: <DistributionRange> "
                              f"stepWidth {fmt_num(step)} over {fmt_num(lo)}..{fmt_num(hi)}: the "
                              "step must be positive and lowerLimit <= upperLimit", path=path,
                              line=drange.sourceline)
        n = int(math.floor((hi - lo) / step + 1e-9)) + 1
        if n > MAX_RANGE_VALUES:
            raise FormatError(f"parameter {d.get('parameterName')!r}: <DistributionRange> has "
                              f"{n} values (more than {MAX_RANGE_VALUES})", path=path,
                              line=drange.sourceline)
        return [_text(lo + k * step) for k in range(n)]
    raise FormatError(f"parameter {d.get('parameterName')!r}: neither a DistributionSet nor a "
                      "DistributionRange", path=path, line=d.sourceline)


def _text(v: float) -> str:
    """A range value as parameter text: without float noise (``0.30000000000000004`` -> ``0.3``),
    integers without a decimal point."""
    v = round(v, 10)
    return str(int(v)) if v.is_integer() else repr(v)
