"""Simulated devices (import name ``gonio.sim``).

Two kinds of simulated rig live here:

- :mod:`gonio.sim.rig` and the device modules beside it speak the wire protocols of the hardware
  (Dynamixel Protocol 2.0, Zaber ASCII, Modbus TCP) over pseudo-terminals and sockets, so the
  real drivers run against them unchanged.
- :mod:`gonio.sim.memrig` is a rig in memory that implements the :mod:`gonio.hal` interfaces
  directly, with no wire protocol and no processes: for fast tests of the engine, worker and
  service, notebooks and dry experiments (``from gonio.sim.memrig import MemRig``).
"""
