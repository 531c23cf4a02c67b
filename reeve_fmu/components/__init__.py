"""The co-simulation components built on the engine, with their parameter tables and factories.

plant      the reeving system as a torque-driven component (what the plant FMU steps); joint inputs
craneplant a crane as a component: hoist torque, a torque (force) or speed per joint in, payload sway out
cranedrive hoist and slew (first axis) speed loops (what the crane drive FMU steps)
drive      the electric drive (trip sequencer, speed/position loops, torque path, brake)
elevator   the [elevator] table of a scene: loads, landings, drive sizing

They import only from core; the FMI layer (fmu/), the studies and the HIL bench import them.
"""
