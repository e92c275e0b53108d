"""Simulation: the event-driven motion on Pi2, pulses and actuators, fidelities, Lyapunov exponents."""
