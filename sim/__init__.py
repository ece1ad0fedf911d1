"""Simulated devices (import name ``gonio.sim``) speaking the wire protocols of the hardware."""
