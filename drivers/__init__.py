"""Hardware drivers (import name ``gonio.drivers``): Dynamixel, Zaber ASCII, Modbus."""
