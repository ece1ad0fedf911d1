"""Simulated devices (import name ``gonio.sim``) speaking the same wire protocols as the hardware."""
