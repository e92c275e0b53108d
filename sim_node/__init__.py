"""Simulator node of grazing_control: integrates the impact oscillator with the exact flow."""
