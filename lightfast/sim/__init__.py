"""Simulators and reference renderers (independent oracles the daylight radiosity is validated against)."""
