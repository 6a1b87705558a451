"""A partner package extending aveas-format through entry points (docs/extending.md).

Its ``pyproject.toml`` would declare::

    [project.entry-points."aveas_format.converters"]
    partner-csv = "aveas_partner_plugin.converter"
    [project.entry-points."aveas_format.rules"]
    partner = "aveas_partner_plugin.rules"
    [project.entry-points."aveas_format.derivations"]
    partner_speed = "aveas_partner_plugin.derivation"
    [project.entry-points."aveas_format.commands"]
    partner-hello = "aveas_partner_plugin.command"
"""
