"""`lolacli bus …`: the group. Commands live in their own modules (bus_timing, bus_emulate,
bus_simulate, bus_scan) and register themselves on :data:`app` when :mod:`lolacli.cli.main`
imports them."""

from __future__ import annotations

import typer

app = typer.Typer(no_args_is_help=True, help="Bus timing model, emulated chain, scanning.")
