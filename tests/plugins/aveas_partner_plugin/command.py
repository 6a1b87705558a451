"""``aveas-format partner-hello``: proves that a partner's command is found."""

from __future__ import annotations

from aveas_format.cli.app import app


@app.command("partner-hello")
def partner_hello() -> None:
    """Greet from the partner plugin."""
    print("hello from aveas_partner_plugin")
