"""Bus Variables in a dozen lines: the LOLA chain in virtual time, one knee moved 5000 counts."""

import lolacli
from lolacli.emulator.slave import build_chain
from lolacli.master import BusInt32, ChainTransport, Cia402Drive, Master

eni = lolacli.load_eni()  # the embedded LOLA chain
master = Master(eni, ChainTransport(build_chain(eni)))  # the emulated chain, virtual time
actual = master.link("Joint04 L Knee.Inputs.Position actual value", BusInt32.input())
knee = Cia402Drive(master, "Joint04 L Knee")  # statusword, controlword, target position
master.bring_up()  # INIT -> PREOP -> SAFEOP -> OP by the ENI's InitCmds
knee.enable()
master.run(10)  # the drive's state machine reaches "operation enabled"
knee.target_position = knee.actual_position + 5000
master.run(3)  # sent in this cycle's frame, the drive follows, read back two cycles later
print(f"knee enabled={knee.enabled} actual={actual.value}")
