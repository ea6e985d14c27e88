"""Our master against an emulated chain in virtual time: the composition above
:mod:`lolacli.master` and :mod:`lolacli.emulator` (neither knows the other).

* :class:`VirtualBus` — the emulated chain of an ENI behind the master's in-process
  transport (the ``sdo`` commands' default bus, the tests' bus).
* :class:`Simulation` / :func:`simulate` — ``lolacli bus simulate``: bring the chain to
  OP, move the drives, report ``lolacli.simulate/1``; :func:`simulate` also runs the same
  on a live bus in real time (``options.iface``).

    from lolacli.files import load_eni
    from lolacli.simulate import SimulateOptions, simulate

    result = simulate(load_eni("lolacli/eni_examples/lola.xml"), SimulateOptions(cycles=2000))
"""

from lolacli.simulate.bus import EmulateOptions, VirtualBus
from lolacli.simulate.options import (
    SimulateOptions,
    SimulationResult,
    SimulationSeries,
    options_from_cli,
)
from lolacli.simulate.report import SCHEMA
from lolacli.simulate.run import Simulation, simulate

__all__ = [
    "SCHEMA",
    "EmulateOptions",
    "SimulateOptions",
    "Simulation",
    "SimulationResult",
    "SimulationSeries",
    "VirtualBus",
    "options_from_cli",
    "simulate",
]
