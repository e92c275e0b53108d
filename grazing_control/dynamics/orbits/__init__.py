"""Orbits, shooting and continuation: periodic orbits, Floquet multipliers, branches and their bifurcations."""
