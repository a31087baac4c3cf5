"""The car emulator: a car on a python-can bus sending its make's DBC frames, with a stock ACC
that reacts to button frames and acceleration requests, and a leader it follows. Steppable by a
simulation clock; `acc.SimulatedAccCar` is the same ACC without CAN for the simulator."""
