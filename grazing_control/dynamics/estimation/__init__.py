"""Estimation: the Pi2 state from a sensor stream, the stream's sections, the clock relation, the watchful filter and the refit in the loop."""
