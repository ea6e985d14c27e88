"""`lolacli bus timing`."""

from __future__ import annotations

from lolacli.cli.bus import app  # noqa: F401  (commands register on the bus group)
