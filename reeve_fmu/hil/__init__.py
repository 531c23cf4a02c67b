"""Motor controller in the loop over CAN: a simulated CiA 402 drive in front of the plant (docs/hil.md).

protocol   CiA 402 constants, the DBC (cantools) and EDS (canopen) files, fast frame codecs from the DBC
drive402   the drive's state machine, CST/CSV, object dictionary behind a canopen LocalNode
plants     the plant FMU through fmpy, or the same Plant in process
bridge     the bench loop: SYNC producer, lock-step or real time, watchdog, fault injection
controller the built-in controller: the demo's ElectricDrive as a CANopen master
buses      bus construction, the udp_multicast probe, --multicast route
runners    `reeve-fmu hil` runs: configuration, bench + controller, in-process reference runs
review     the run's summary, verdicts, written results and report
cli        `reeve-fmu hil` and `python -m reeve_fmu.hil controller|bench`
"""
