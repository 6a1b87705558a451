"""The built-in rules, one module per family (``structure``, ``participants``, ``time``, ...).

Each module registers its rules with :func:`aveas_format.validate.registry.rule` when it is
imported; :func:`~aveas_format.validate.registry.load_rules` imports every module of this package
(and the rule modules of partner packages) through :mod:`aveas_format.plugins`, so a new family is
one new module here: no list to edit (docs/extending.md).
"""
