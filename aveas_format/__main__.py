"""``python -m aveas_format`` = ``aveas-format``."""

from aveas_format.cli import main

main()
